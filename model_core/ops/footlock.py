"""Foot lock: pin feet on the ground while they are in contact, by two-bone leg IK.

Works on any canonical joint-position motion ``[F, 21, 3]`` (Y-up, any unit, any frame
rate): model output and mocap alike. Only the knee, ankle and toe of each leg move (and,
after ``fixed`` frames, the whole body up and down); every bone keeps its length on every frame.

- Contacts ``[F, 4]`` in :data:`conventions.CONTACTS` order (l_heel, l_toe, r_heel, r_toe):
  the model's contact channels (:func:`contacts_from_features`) or detected from heights
  and speeds (:func:`features.detect_contacts`, on the motion scaled to metres).
- Each contact span of a heel (read at the ankle) or a toe gets ONE ground target: the
  mean horizontal position of that joint over the span. Inside the span the joint is put
  on its target; the correction needed at the span's edges fades in before and out after
  it over ``blend_s`` seconds. Heels are locked first, then toes on the heel-locked foot
  (the foot keeps its orientation, so a toe lock moves the ankle with it).
- Heights: each contact span moves the foot up or down so that, on average over the span, its
  contact joint is at the height it has in contact on the take's floor (the ``fixed`` frames when
  there are some, the whole clip otherwise), faded in and out like the horizontal pull, so
  generated feet neither sink into the floor nor hover above it; and no heel or toe goes below
  that height at any frame. With ``ground`` (the height of the surface under each heel and toe on
  each frame: stairs, a slope, terrain) every height is measured from that surface instead of from
  one flat floor: contacts are found, and pinned, on whatever step the foot stands, and a toe down is
  brought to its own height over the ground, so a planted foot pitches with a slope. After ``fixed``
  frames, a body whose feet hover where they should stand comes down as a whole first (the legs
  alone could only reach by straightening). Next to ``fixed`` frames these height corrections ease
  in over ``blend_s``, so a foot that stands higher or lower there than on the rest of the floor
  moves off it without a step.
- Settling (``passes`` > 1): the result is locked again, along the ground only, on the contacts it has
  (the first pass's and any detected on the result), until its feet rest.
- Two-bone IK from the (unmoved) hip: the knee stays in its own plane (the plane of hip,
  knee and ankle, turned by the shortest arc onto the new hip-to-ankle axis), the foot
  keeps its orientation (the toe follows the ankle), and a target out of reach is eased
  towards a soft limit short of full extension (:data:`MIN_KNEE_DEG` of bend, or the input's
  own extension where that is straighter) instead of snapping the leg straight.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..motion.conventions import (
    CONTACT_JOINTS,
    CONTACTS,
    GROUND_AXES,
    JOINT_INDEX,
    LAYOUT,
    MODEL_FPS,
    STANDARD_LEG_LENGTH,
    UP_AXIS,
)
from ..motion.features import detect_contacts, facing, gaussian_smooth
from ..motion.geometry import shortest_arc
from ..motion.stance import GROUND_EASE, lift_needed
from ..rig.rigs import leg_length
from .normalise import fit_normalisation

LEGS = tuple(tuple(JOINT_INDEX[f"{s}_{j}"] for j in ("upleg", "knee", "foot", "toe")) for s in ("l", "r"))
_HIP, _KNEE, _ANKLE, _TOE = (np.array([leg[k] for leg in LEGS]) for k in range(4))  # each [2]: left, right
MIN_KNEE_DEG = 6.0  # the IK keeps at least this knee bend unless the input's leg was straighter
_STRAIGHT = 0.01  # sine of the thigh-to-leg-axis angle below which a leg counts as straight
# Contact channels of the left and right heel, and of the left and right toe.
_HEEL_CHANNELS = [[name for name, _ in CONTACTS].index(f"{s}_heel") for s in ("l", "r")]
_TOE_CHANNELS = [[name for name, _ in CONTACTS].index(f"{s}_toe") for s in ("l", "r")]


# Passes of a settled lock (the Foot Lock operator's, Fill Gap's and Extend's). One pass pins the contacts the
# input has; where the input's foot pitches while heel and toe are both down (the foot keeps its length, so
# one end slides), where a foot is lifted or lowered to the floor, or where it drifts slowly near the floor
# just outside a contact, the result still creeps. Locked again on the contacts the result has, its feet come
# to rest (the model card's section "The feet settle" gives the creep after 1, 4 and 8 passes).
SETTLE_PASSES = 8
_SETTLED = 1e-5  # legs' lengths: a pass that moves no joint further than this ends the settling


@dataclass
class FootLockSettings:
    blend_s: float = 0.15  # seconds over which a lock fades in before a span and out after it
    min_gap_s: float = 0.07  # contact gaps shorter than this (flicker) are filled before locking
    softness: float = 0.03  # fraction of the leg's reach over which an unreachable target eases out
    max_offset: float = 0.6  # legs' lengths: a span needing a bigger correction is no contact, left alone
    floor_tolerance: float = 0.01  # metres (for a standard body): contacts this close to the floor stay
    lower_body: bool = True  # after fixed frames, a body whose feet hover may come down as a whole
    passes: int = 1  # > 1: lock the result again on its own contacts until its feet rest (see SETTLE_PASSES)


def contacts_from_features(feats: np.ndarray) -> np.ndarray:
    """The model's contact channels of features ``[F, C]`` as 0/1 ``float32 [F, 4]``."""
    return np.round(np.clip(np.asarray(feats)[:, LAYOUT.contacts], 0.0, 1.0)).astype(np.float32)


def detect_foot_contacts(pos: np.ndarray, fps: float = MODEL_FPS, scale: float | None = None,
                         ground: np.ndarray | None = None) -> np.ndarray:
    """Contacts ``float32 [F, 4]`` of positions ``[F, 21, 3]`` in any unit: ``scale`` (metres per
    unit; default: legs scaled to the standard length) makes the metre thresholds apply. ``ground`` ``[F, 4]``:
    heights are measured from the surface under each heel and toe (:func:`foot_lock`), not the take's lowest."""
    pos = np.asarray(pos, np.float64)
    if scale is None and ground is not None:  # the legs' scale, read before the heights are moved
        scale = fit_normalisation(pos).scale
    metres = above(pos, ground) * scale if scale else fit_normalisation(pos).to_model(pos)
    return detect_contacts(metres, fps)


def above(pos: np.ndarray, ground: np.ndarray | None) -> np.ndarray:
    """``pos`` ``[F, 21, 3]`` with each contact joint's height taken from the ``ground`` ``[F, 4]`` under it (the
    heel's from under the heel, the toe's from under the toe); ``pos`` itself without ground."""
    if ground is None:
        return pos
    out = np.array(pos, np.float64)
    for k, joint in enumerate(CONTACT_JOINTS):
        out[:, joint, UP_AXIS] -= ground[:, k]
    return out


def fill_gaps(mask: np.ndarray, frames: int) -> np.ndarray:
    """Bool ``[F, K]`` with off-runs of at most ``frames`` frames between two on-frames switched on."""
    idx = np.arange(len(mask))[:, None]
    prev_on = np.maximum.accumulate(np.where(mask, idx, -(10 ** 9)), axis=0)
    next_on = np.minimum.accumulate(np.where(mask, idx, 10 ** 9)[::-1], axis=0)[::-1]
    return mask | ((next_on - prev_on - 1 <= frames) & (prev_on >= 0) & (next_on < len(mask)))


def span_targets(x: np.ndarray, mask: np.ndarray, weight: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Mean of ``x`` ``[F, K, D]`` over each on-span of ``mask`` ``[F, K]``, weighted by ``weight`` ``[F]``.

    Returns ``span`` int ``[F, K]`` (index into the targets, -1 off contact) and the targets ``[S, D]``."""
    f, k = mask.shape
    starts = mask & ~np.concatenate([np.zeros((1, k), bool), mask[:-1]])
    order = starts.T.reshape(-1)  # number spans channel by channel
    ids = np.cumsum(order).reshape(k, f).T - 1  # [F, K]
    span = np.where(mask, ids, -1)
    n = int(order.sum())
    w = np.broadcast_to(np.ones(f) if weight is None else weight, (k, f)).T[mask]
    sums = np.zeros((n, x.shape[-1]))
    np.add.at(sums, span[mask], w[:, None] * x[mask])
    counts = np.bincount(span[mask], weights=w, minlength=n)[:, None]
    return span, sums / np.maximum(counts, 1e-12)


def _ramp(distance: np.ndarray, frames: float) -> np.ndarray:
    """Cosine fade: 1 at distance 0, 0 from ``frames + 1`` frames away."""
    t = np.clip(distance / (frames + 1.0), 0.0, 1.0)
    return 0.5 * (1.0 + np.cos(np.pi * t))


def _nearest(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For bool ``[F, K]``: the last on-frame at or before each frame (-1: none) and the first
    at or after it (F: none), both int ``[F, K]``."""
    f = len(mask)
    idx = np.broadcast_to(np.arange(f)[:, None], mask.shape)
    prev = np.maximum.accumulate(np.where(mask, idx, -1), axis=0)
    nxt = np.minimum.accumulate(np.where(mask, idx, f)[::-1], axis=0)[::-1]
    return prev, nxt


def _faded(values: np.ndarray, mask: np.ndarray, blend: float) -> tuple[np.ndarray, np.ndarray]:
    """Each on-frame's ``values`` ``[F, K, D]`` spread to the frames around it with a cosine fade over
    ``blend`` frames: (faded values ``[F, K, D]``, their weights ``[F, K]`` in [0, 1]). Between two on-frames
    the value passes from the one before to the one after, each counting the more the nearer it is and
    all of it at its own frame, so a correction reaches the next span's value exactly where the span
    starts (a plain weighted mean of the two would jump there when the last span ended close by)."""
    f, k = mask.shape
    idx, cols = np.arange(f)[:, None], np.arange(k)[None]
    fades, near = [], []
    for at in _nearest(mask):
        ok = (at >= 0) & (at < f)
        fades.append(np.where(ok, _ramp(np.abs(idx - at), blend), 0.0))
        near.append(values[np.clip(at, 0, f - 1), cols])
    (w1, w2), (v1, v2) = fades, near
    a, b = w1 * (1.0 - w2), w2 * (1.0 - w1)  # the earlier on-frame's share: 1 at it, 0 at the later one
    share = np.divide(a, a + b, out=np.full(a.shape, 0.5), where=a + b > 0)
    weight = 1.0 - (1.0 - w1) * (1.0 - w2)
    return weight[..., None] * (share[..., None] * v1 + (1.0 - share[..., None]) * v2), weight


def plausible_spans(ground: np.ndarray, mask: np.ndarray, limit: float, weight: np.ndarray | None = None) -> np.ndarray:
    """``mask`` ``[F, K]`` without the spans whose joint strays more than ``limit`` from the span's
    target (``ground`` ``[F, K, 2]``): a foot sliding that far is not standing on anything."""
    span, targets = span_targets(ground, mask, weight)
    if not len(targets):
        return mask
    stray = np.where(mask, np.linalg.norm(targets[span] - ground, axis=-1), 0.0)
    worst = np.zeros(len(targets))
    np.maximum.at(worst, span[mask], stray[mask])
    return mask & (worst <= limit)[np.maximum(span, 0)]


def lock_offsets(x: np.ndarray, mask: np.ndarray, blend: float, fixed: np.ndarray | None = None,
                 limit: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal pull of each channel onto its span targets: inside a span the joint is put on
    the target; outside, the correction needed at the nearest span's edge fades out over ``blend``.

    ``x`` ``[F, K, 3]`` positions, ``mask`` bool ``[F, K]``, ``blend`` frames of fade; ``fixed``
    bool ``[F]``: frames that stay where they are (a span through a fixed frame next to free ones
    is locked where that frame has it, and the pull fades in from zero there); spans that would
    move the joint further than ``limit`` are left alone (see :func:`plausible_spans`).
    Returns offsets ``[F, K, 3]`` (zero height) and weights ``[F, K]`` in [0, 1]."""
    border = None
    if fixed is not None:
        free = ~np.asarray(fixed, bool)
        border = ~free & (np.r_[free[1:], False] | np.r_[False, free[:-1]])  # fixed frames next to free ones
        mask = mask & (free | border)[:, None]
    ground = x[..., list(GROUND_AXES)]
    weight = None if border is None else 1.0 + 1e9 * border
    mask = plausible_spans(ground, mask, limit, weight)
    span, targets = span_targets(ground, mask, weight)
    edge_fix = (targets[span] if len(targets) else ground) - ground  # at contact frames: target - position
    pull, weight = _faded(np.where(mask[..., None], edge_fix, 0.0), mask, blend)
    if border is not None:  # no jump next to fixed frames: fade out the pull they would have had
        seam, _ = _faded(pull, np.broadcast_to(border[:, None], mask.shape), blend)
        pull = np.where(free[:, None, None], pull - seam, 0.0)
    out = np.zeros(x.shape)
    out[..., list(GROUND_AXES)] = pull
    return out, weight


def ankle_targets(pos: np.ndarray, contacts: np.ndarray, blend: float, fixed: np.ndarray | None = None,
                  limit: float = np.inf, rest: np.ndarray | None = None,
                  tolerance: float = 0.0, spans: bool = True, pitch: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Where each ankle and each toe should be, ``[F, 2, 3]`` each (left, right). Heels first: each heel span pins the
    ankle. Then toes, on the heel-locked foot (kept at its orientation): each toe span pins the
    toe, moving the ankle with it, so a heel lifting off rolls the foot about a planted toe; where
    the heel is held too, the heel stays and the foot turns about it to point at the planted toe
    (the toe target is returned beside the ankle's), so a flat foot slides at neither end.
    ``rest`` ``[4]``: the height of each contact joint (l_heel, l_toe, r_heel, r_toe) standing on
    the floor; contacts further than ``tolerance`` from it are brought to it (``spans`` False: not) and no
    heel or toe goes further than that below it (None: heights unchanged). ``pitch``: each toe span also brings its
    toe to its own rest height, so a foot flat on a slope (``rest`` frame by frame on a ground) pitches with it."""
    mask = np.asarray(contacts) > 0.5
    ankle = pos[:, _ANKLE]
    foot = pos[:, _TOE] - ankle  # [F, 2, 3] ankle-to-toe, kept
    pull, held = lock_offsets(ankle, mask[:, _HEEL_CHANNELS], blend, fixed, limit)
    ankle = ankle + pull
    pull, _ = lock_offsets(ankle + foot, mask[:, _TOE_CHANNELS], blend, fixed, limit)
    toe = ankle + foot + pull  # where the toe is pinned
    ankle = ankle + (1.0 - held)[..., None] * pull  # a held heel stays where it is
    if rest is not None:
        lift, tilt = _height_pull(ankle, foot, mask, blend, fixed, rest, tolerance, spans, pitch)
        ankle, toe = ankle + lift, toe + lift + tilt
    return ankle, toe


def _toe_pitch(need: np.ndarray, mask: np.ndarray, blend: float, fixed: np.ndarray | None) -> np.ndarray:
    """How far up ``[F, 2]`` each toe goes beyond its foot's lift: each toe span's mean of how far the toe still
    is from its rest height (``need`` ``[F, 2]``), faded like the horizontal pull (all of it: short of it by the
    floor's tolerance, the toe would count as below the floor and the foot would not turn)."""
    return _span_means(need, mask[:, _TOE_CHANNELS], blend, fixed)


def _span_means(need: np.ndarray, on: np.ndarray, blend: float, fixed: np.ndarray | None,
                tolerance: float = 0.0) -> np.ndarray:
    """``need`` ``[F, 2]`` replaced by its mean over each span of ``on`` ``[F, 2]`` (outside ``fixed`` frames), less
    ``tolerance`` (the take's own variation stays), faded in and out like the horizontal pull."""
    on = on & ~fixed[:, None] if fixed is not None else on
    span, level = span_targets(need[..., None], on)
    level = np.sign(level) * np.maximum(np.abs(level) - tolerance, 0.0)
    per_frame = np.where(on[..., None], level[span] if len(level) else 0.0, 0.0)
    return _faded(per_frame, on, blend)[0][..., 0]


def _height_pull(ankle: np.ndarray, foot: np.ndarray, mask: np.ndarray, blend: float, fixed: np.ndarray | None,
                 rest: np.ndarray, tolerance: float, spans: bool = True,
                 pitch: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Vertical move of each ankle ``[F, 2, 3]``: :func:`span_lift`, then, at every frame, up by what
    the heel or toe would still be below its rest height; and the toe's own further move (``pitch``, on toe
    spans: :func:`_toe_pitch`; else zero), which the foot turns to follow; nothing on ``fixed`` frames, eased in
    from them over ``blend`` frames (:func:`from_fixed`)."""
    heel_need, toe_need = _needs(ankle, foot, rest)
    lift = span_lift(ankle, foot, mask, blend, fixed, rest, tolerance) if spans else np.zeros(heel_need.shape)
    tilt = _toe_pitch(toe_need - lift, mask, blend, fixed) if pitch and spans else np.zeros(lift.shape)
    lift = lift + np.maximum(np.maximum(heel_need - lift, toe_need - lift - tilt) - tolerance, 0.0)
    ease = from_fixed(fixed, len(ankle), blend)[:, None]  # eased in from the frames kept: no step
    out = np.zeros((2, *ankle.shape))
    out[..., UP_AXIS] = lift * ease, tilt * ease
    return out[0], out[1]


def _needs(ankle: np.ndarray, foot: np.ndarray, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How far up ``[F, 2]`` each heel (at the ankle) and each toe is from its rest height."""
    return rest[..., _HEEL_CHANNELS] - ankle[..., UP_AXIS], rest[..., _TOE_CHANNELS] - (ankle + foot)[..., UP_AXIS]


def span_lift(ankle: np.ndarray, foot: np.ndarray, mask: np.ndarray, blend: float, fixed: np.ndarray | None,
              rest: np.ndarray, tolerance: float = 0.0) -> np.ndarray:
    """Vertical move ``[F, 2]`` of each foot: each contact span lifts (or lowers) it by the mean over the
    span of what its heel (or, with only the toe down, its toe) needs to reach its rest height, less
    ``tolerance``, faded like the horizontal pull, so the foot keeps its own roll within the span."""
    heel, toe = mask[:, _HEEL_CHANNELS], mask[:, _TOE_CHANNELS]
    heel_need, toe_need = _needs(ankle, foot, rest)
    return _span_means(np.where(heel, heel_need, toe_need), heel | toe, blend, fixed, tolerance)


def body_drop(pos: np.ndarray, mask: np.ndarray, blend: float, fixed: np.ndarray | None,
              rest: np.ndarray, tolerance: float) -> np.ndarray:
    """How far down ``[F]`` (<= 0) the whole body goes so that a hovering foot in contact can reach
    the floor, which the legs alone could only do by straightening: the lower of the two feet's
    span lifts where negative, smoothed over ``blend`` frames (fixed frames stay)."""
    ankle = pos[:, _ANKLE]
    lift = span_lift(ankle, pos[:, _TOE] - ankle, mask, blend, fixed, rest, tolerance)
    drop = gaussian_smooth(np.minimum(lift.min(1), 0.0), max(blend / 2.0, 1.0))
    return drop * from_fixed(fixed, len(pos), blend)


def from_fixed(fixed: np.ndarray | None, frames: int, blend: float) -> np.ndarray:
    """Weights ``[F]`` that ease a correction in away from ``fixed`` frames: 0 on them, rising by a cosine
    to 1 ``blend + 1`` frames from the nearest one (1 everywhere without fixed frames), so that a contact
    span running on from them is brought to the floor gradually instead of by a step at the seam."""
    if fixed is None or not np.any(fixed):
        return np.ones(frames)
    prev, nxt = _nearest(np.asarray(fixed, bool)[:, None])
    idx = np.arange(frames)
    distance = np.minimum(np.where(prev[:, 0] >= 0, idx - prev[:, 0], frames),
                          np.where(nxt[:, 0] < frames, nxt[:, 0] - idx, frames))
    return 1.0 - _ramp(distance.astype(np.float64), blend)


def rest_heights(pos: np.ndarray, contacts: np.ndarray, frames: np.ndarray | None = None) -> np.ndarray | None:
    """Height of each contact joint ``[4]`` (heel at the ankle, toe) standing on the floor: the median
    over its contact frames among ``frames`` (bool ``[F]``, default all), or over all its contact
    frames when it has none there; None when the clip has no contact at all."""
    on = np.asarray(contacts) > 0.5
    if not on.any():
        return None
    use = on & (np.ones(len(on), bool) if frames is None else np.asarray(frames, bool))[:, None]
    heights = np.asarray(pos)[:, CONTACT_JOINTS, UP_AXIS]
    out = []
    for k in range(on.shape[1]):
        pick = use[:, k] if use[:, k].any() else on[:, k]
        out.append(np.median(heights[pick, k]) if pick.any() else np.percentile(heights[:, k], 5))
    return np.array(out)


def _unit(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-12), n[..., 0]


def knee_limit_reach(l1: np.ndarray, l2: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """The furthest hip-to-ankle distance the IK may use: the leg with :data:`MIN_KNEE_DEG` of knee
    bend, or ``rest`` (the input's own) where that is longer."""
    bend = np.radians(MIN_KNEE_DEG)
    soft = np.sqrt(l1 ** 2 + l2 ** 2 + 2 * l1 * l2 * np.cos(bend))
    return np.minimum(np.maximum(soft, rest), l1 + l2)


def soft_reach(dist: np.ndarray, rest: np.ndarray, reach: np.ndarray, softness: float) -> np.ndarray:
    """Reachable hip-to-ankle distance: ``dist`` unchanged up to ``max(rest, (1 - softness) reach)``,
    then easing exponentially towards ``reach`` (so the original pose, ``dist == rest``, is exact)."""
    start = np.minimum(np.maximum(rest, (1.0 - softness) * reach), reach)
    span = reach - start
    over = np.maximum(dist - start, 0.0)
    eased = start + span * (1.0 - np.exp(-over / np.maximum(span, 1e-12)))
    return np.where(dist <= start, dist, np.where(span > 1e-12, eased, reach))


def two_bone_ik(hip: np.ndarray, knee: np.ndarray, ankle: np.ndarray, target: np.ndarray,
                softness: float = 0.03, forward: np.ndarray | None = None,
                rest: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Analytic two-bone IK: new knee and ankle ``[..., 3]`` putting the ankle on ``target``.

    ``hip``, ``knee``, ``ankle``, ``target`` ``[..., 3]``; the bone lengths of each frame are
    kept, the knee stays in the plane of the original leg (turned onto the new axis) and
    ``forward`` ``[..., 3]`` (optional) picks the bend direction of a nearly straight leg. ``rest`` ``[...]``:
    the hip-to-ankle distance up to which the leg may stretch without easing (default: the input's own)."""
    l1 = np.linalg.norm(knee - hip, axis=-1)
    l2 = np.linalg.norm(ankle - knee, axis=-1)
    axis0, d0 = _unit(ankle - hip)
    bend0 = (knee - hip) - axis0 * np.sum((knee - hip) * axis0, -1, keepdims=True)
    if forward is not None:  # a (nearly) straight leg has no plane of its own: bend towards the front
        fwd = forward - axis0 * np.sum(forward * axis0, -1, keepdims=True)
        sine = np.linalg.norm(bend0, axis=-1) / np.maximum(l1, 1e-12)
        lean = l1 * _STRAIGHT * np.clip(1.0 - sine / _STRAIGHT, 0.0, 1.0) ** 2  # 0 once the knee is bent
        bend0 = bend0 + lean[..., None] * _unit(fwd)[0]
    bend0 = _unit(bend0)[0]
    axis = _unit(target - hip)[0]
    return place_leg(hip, target, l1, l2, np.einsum("...ij,...j->...i", shortest_arc(axis0, axis), bend0),
                     d0 if rest is None else rest, softness)


def place_leg(hip: np.ndarray, target: np.ndarray, l1: np.ndarray, l2: np.ndarray, bend: np.ndarray,
              rest: np.ndarray, softness: float = 0.03) -> tuple[np.ndarray, np.ndarray]:
    """Knee and ankle ``[..., 3]`` of a leg of thigh ``l1`` and shin ``l2`` ``[...]`` from ``hip`` with the
    ankle on ``target`` (its reach eased short of straight: :func:`soft_reach`, :func:`knee_limit_reach`,
    ``rest`` the leg's own hip-ankle distance), the knee out towards ``bend`` ``[..., 3]`` (any direction off
    the hip-ankle line; only its part square to the line counts)."""
    axis, d = _unit(target - hip)
    d = soft_reach(d, rest, knee_limit_reach(l1, l2, rest), softness)
    d = np.maximum(d, np.abs(l1 - l2) + 1e-6 * (l1 + l2))
    along = (l1 ** 2 - l2 ** 2 + d ** 2) / (2.0 * np.maximum(d, 1e-12))
    height = np.sqrt(np.maximum(l1 ** 2 - along ** 2, 0.0))
    bend = _unit(bend)[0]
    bend = _unit(bend - axis * np.sum(bend * axis, -1, keepdims=True))[0]
    new_knee = hip + axis * along[..., None] + bend * height[..., None]
    return new_knee, hip + axis * d[..., None]


def face_along(foot: np.ndarray, towards: np.ndarray) -> np.ndarray:
    """``foot`` ``[..., 3]`` turned about the up axis so that its ground part points like ``towards``'s
    (length and height kept; unchanged where either has no ground part)."""
    ground = list(GROUND_AXES)
    f, t = foot[..., ground], towards[..., ground]
    fn, tn = np.linalg.norm(f, axis=-1, keepdims=True), np.linalg.norm(t, axis=-1, keepdims=True)
    ok = (fn > 1e-9) & (tn > 1e-9)
    out = foot.copy()
    out[..., ground] = np.where(ok, t / np.maximum(tn, 1e-12) * fn, f)
    return out


def body_forward(pos: np.ndarray) -> np.ndarray:
    """Horizontal facing direction ``[F, 3]`` (unit) from the hips and shoulders (Y-up): :func:`features.facing`."""
    return _unit(facing(pos))[0]


def legs_out_of_floor(pos: np.ndarray, floor: float | np.ndarray, ease: int = GROUND_EASE) -> np.ndarray:
    """Joints ``[F, 21, 3]`` or ``[B, F, 21, 3]`` (Y up) with each foot kept out of ``floor`` (a height, or one per
    clip ``[B]``; NaN: that clip is left as it is) by its own leg: where a leg's heel (read at the ankle) or toe is
    under it, the ankle and toe are raised by as much (the lift held ``ease`` frames either side and averaged over
    as many, as :func:`stance.ground`'s) and the knee bends to reach, by two-bone IK from the hip, which stays where
    it is. The hips and every other joint are left alone, and so is a foot on or over the floor: where the model
    has the hips right and its feet dip under the floor (a fighter's continuation), only the legs change."""
    pos = np.asarray(pos)
    single = pos.ndim == 3
    out = np.array(pos[None] if single else pos, np.float64)
    for hip, knee, ankle, toe in LEGS:
        need = lift_needed(np.minimum(out[..., ankle, UP_AXIS], out[..., toe, UP_AXIS]), floor, ease)
        up = need > 1e-6  # only the frames that need it (the IK eases a nearly straight leg it is given)
        if not up.any():
            continue
        leg = out[up]  # [N, 21, 3]
        target = leg[:, ankle].copy()
        target[:, UP_AXIS] += need[up]
        new_knee, new_ankle = two_bone_ik(leg[:, hip], leg[:, knee], leg[:, ankle], target)
        leg[:, toe] += new_ankle - leg[:, ankle]
        leg[:, knee], leg[:, ankle] = new_knee, new_ankle
        out[up] = leg
    out = out.astype(pos.dtype, copy=False)
    return out[0] if single else out


def foot_lock(pos: np.ndarray, fps: float = MODEL_FPS, contacts: np.ndarray | None = None,
              settings: FootLockSettings | None = None, fixed: np.ndarray | None = None,
              ground: np.ndarray | None = None, standing: np.ndarray | None = None) -> np.ndarray:
    """Foot-locked copy ``float32 [F, 21, 3]`` of positions ``pos`` ``[F, 21, 3]`` (Y-up, any unit) at ``fps``.

    ``contacts`` ``[F, 4]`` (0/1, :data:`conventions.CONTACTS` order; default: detected).
    ``fixed`` bool ``[F]``: frames left exactly as they are (say, the part of a clip already in
    the scene); locks next to them continue from where their feet are, without a jump.
    ``ground`` ``[F, 4]``: the height of the surface under each contact joint (heel at the ankle, toe) on each
    frame, in ``pos``'s units; default: one flat floor, the take's own. ``standing`` ``[4]``: how high each contact
    joint stands over the ground (default: measured on ``pos``; motion made on a flat floor and carried over a
    slope knows it better from its flat floor, where the foot's pitch did not hide it).
    ``settings.passes`` > 1 locks the result again, on its contacts and those detected on it, until no joint
    moves or the passes are spent: a settled lock (:data:`SETTLE_PASSES`)."""
    cfg = settings or FootLockSettings()
    pos = np.asarray(pos, np.float64)
    if pos.ndim != 3 or pos.shape[1:] != (len(JOINT_INDEX), 3):
        raise ValueError(f"foot lock needs positions [frames, {len(JOINT_INDEX)}, 3], got {pos.shape}")
    if ground is not None:
        ground = np.asarray(ground, np.float64)
        if ground.shape != (len(pos), len(CONTACTS)) or not np.isfinite(ground).all():
            raise ValueError(f"ground must be finite heights [{len(pos)}, {len(CONTACTS)}], got {ground.shape}")
    contacts = _check_contacts(pos, fps, contacts, ground)
    fixed = np.zeros(len(pos), bool) if fixed is None else np.asarray(fixed, bool)
    if len(pos) < 2 or fixed.all():
        return pos.astype(np.float32)
    rest = standing if standing is not None else rest_heights(
        above(pos, ground), fill_gaps(contacts > 0.5, _min_gap(cfg, fps)), fixed if fixed.any() else None)
    if rest is not None and ground is not None:
        rest = ground + rest  # each contact joint's height standing on the surface under it, frame by frame
    out = _lock(pos, fps, contacts, cfg, fixed, rest, pitch=ground is not None)  # on a ground, feet take its slope
    # Settling: each pass locks the last one's result on the contacts it has now, along the ground only (the
    # heights came right in the first pass; pulled again, a foot that cannot quite reach would be pulled
    # further each time and snap back; no heel or toe goes below the floor still), no leg stretching further
    # than the input's did, the body not lowered again
    reach = np.linalg.norm(pos[:, _ANKLE] - pos[:, _HIP], axis=-1)
    again, still = replace(cfg, lower_body=False), _SETTLED * leg_length(pos)
    for _ in range(cfg.passes - 1):
        contacts = np.maximum(contacts, detect_foot_contacts(out, fps, ground=ground))
        settled = _lock(out, fps, contacts, again, fixed, rest, reach)
        moved = np.abs(settled - out).max()
        out = settled
        if moved < still:
            break
    return out.astype(np.float32)


def _min_gap(cfg: FootLockSettings, fps: float) -> int:
    return int(round(cfg.min_gap_s * fps))


def _lock(pos: np.ndarray, fps: float, contacts: np.ndarray, cfg: FootLockSettings, fixed: np.ndarray,
          rest: np.ndarray | None, reach: np.ndarray | None = None, pitch: bool = False) -> np.ndarray:
    """One pass of :func:`foot_lock` (float64 out); ``rest``: :func:`rest_heights`. With ``reach`` ``[F, 2]``
    (:func:`two_bone_ik`'s ``rest``), a settling pass: contact spans are not brought to the floor again."""
    mask = fill_gaps(contacts > 0.5, _min_gap(cfg, fps))
    limit = cfg.max_offset * leg_length(pos)
    tolerance = cfg.floor_tolerance * leg_length(pos) / STANDARD_LEG_LENGTH
    if rest is not None and fixed.any() and cfg.lower_body:  # after the frames kept, a hovering body comes down
        pos = pos.copy()
        drop = body_drop(pos, mask, cfg.blend_s * fps, fixed if fixed.any() else None, rest, tolerance)
        pos[..., UP_AXIS] += drop[:, None]
    target, toe = ankle_targets(pos, mask, cfg.blend_s * fps, fixed if fixed.any() else None, limit, rest,
                                tolerance, spans=reach is None, pitch=pitch)
    fwd = body_forward(pos)[:, None].repeat(2, 1)
    knee, ankle = two_bone_ik(pos[:, _HIP], pos[:, _KNEE], pos[:, _ANKLE], target, cfg.softness, fwd, reach)
    out = pos.copy()
    # The foot points at its toe target with its own length (its orientation where the toe is free);
    # where that would put the toe below the floor, it only turns about the vertical to face it.
    foot = pos[:, _TOE] - pos[:, _ANKLE]
    aimed = _unit(toe - target)[0] * np.linalg.norm(foot, axis=-1, keepdims=True)
    if rest is not None:
        floor = rest[..., _TOE_CHANNELS] - tolerance
        low = (ankle + aimed)[..., UP_AXIS] < floor
        if pitch:  # a toe aimed at a target on a slope: turned back to its own pitch only where the target is low
            low &= toe[..., UP_AXIS] < floor - 1e-9
        aimed = np.where(low[..., None], face_along(foot, toe - target), aimed)
    out[:, _TOE] = ankle + aimed
    out[:, _KNEE], out[:, _ANKLE] = knee, ankle
    out[fixed] = pos[fixed]
    return out


def _check_contacts(pos: np.ndarray, fps: float, contacts: np.ndarray | None,
                    ground: np.ndarray | None = None) -> np.ndarray:
    """Given contacts checked against ``pos`` ``[F, 21, 3]``, or detected ones (on ``ground``): ``[F, 4]``."""
    if contacts is None:
        return detect_foot_contacts(pos, fps, ground=ground) if len(pos) > 1 else np.zeros((len(pos), len(CONTACTS)))
    contacts = np.asarray(contacts)
    if contacts.shape != (len(pos), len(CONTACTS)):
        raise ValueError(f"contacts must be [{len(pos)}, {len(CONTACTS)}], got {contacts.shape}")
    return contacts


# ------------------------------------------------------------------ metrics
def foot_skate_cm(pos: np.ndarray, contacts: np.ndarray, scale: float = 1.0) -> float:
    """Foot skate (cm / frame): mean horizontal speed of each contact joint (heel at the ankle,
    toe) over the steps from frame f to f + 1 where its contact is on at both frames.

    ``pos`` ``[F, 21, 3]`` Y-up in units of ``scale`` metres, ``contacts`` ``[F, 4]``. 0 when no contact."""
    feet = np.asarray(pos, np.float64)[:, CONTACT_JOINTS][..., list(GROUND_AXES)]  # [F, 4, 2]
    step = np.linalg.norm(np.diff(feet, axis=0), axis=-1)  # [F - 1, 4]
    on = np.asarray(contacts)[:-1] > 0.5
    on &= np.asarray(contacts)[1:] > 0.5
    return float(100.0 * scale * step[on].mean()) if on.any() else 0.0


def knee_angles(pos: np.ndarray) -> np.ndarray:
    """Knee flexion angles ``[F, 2]`` (degrees; 0 = straight) of the left and right leg."""
    pos = np.asarray(pos, np.float64)
    thigh = _unit(pos[:, _KNEE] - pos[:, _HIP])[0]
    shin = _unit(pos[:, _ANKLE] - pos[:, _KNEE])[0]
    return np.degrees(np.arccos(np.clip(np.sum(thigh * shin, -1), -1.0, 1.0)))


def knee_pops(pos: np.ndarray, threshold_deg: float = 30.0) -> int:
    """Number of (frame, leg) where the knee angle changes by more than ``threshold_deg`` in one frame."""
    return int((np.abs(np.diff(knee_angles(pos), axis=0)) > threshold_deg).sum())
