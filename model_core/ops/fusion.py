"""Denoise that trusts the input as much as it deserves.

The model's reconstruction of a take is one estimate of the true motion; the take itself
is another. How much each is worth is measured on the take:

- the input's noise level per joint, from its 4th differences in time (white noise dominates
  them, smooth motion hardly reaches them), robustly, so a clean take reads as clean; the
  capture's own jitter (up to about 2 mm) counts as part of the take, not as noise;
- single-frame pops (a joint jumping for one frame, as from a marker swap), as joint-frames
  far from the cubic through their neighbours; they get no weight at all;
- the model's own slow error: on a body it has not seen (other proportions, another way of moving) its
  reading is off by an offset that drifts slowly, in the body's frame; that offset is measured on the
  input, where the noise averages out over a second (:func:`correct_bias`), and taken off the reading;
- the model's error, frame by frame, from how far it is from the input beyond the noise and,
  where the model read the take twice (as it is and as its mirror image), from how far its two
  readings disagree: where the model cannot follow the motion (a kick it never saw), it gets
  little weight.

The result minimises, per joint and axis, the weighted distance to the input and to the
model plus a penalty on acceleration that follows the motion (light where it moves fast, as in
a kick, heavy where it holds still): banded linear systems solved exactly. Last, the bones are
given back the lengths they keep through the take, and the pelvis and the chest their shapes
(:func:`keep_bone_lengths`), as far as the
noise could have changed them. Clean takes come back nearly unchanged; noisy ones lean on the
model and the smoothness prior. Works at the take's own frame rate. Positions are ``[F, J, 3]``
in metres (model scale).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..motion.conventions import PARENTS
from ..motion.features import gaussian_smooth, gaussian_taps, heading, yaw_matrix
from ..motion.noise import white_noise_variance

POP_FLOOR_M = 0.05  # a pop moves a joint at least this far from where its neighbours put it
POP_FACTOR = 3.5  # ... and this many times the joint's median residual
POP_FILL_ERROR_M = 0.005  # how far a repaired pop may be from the truth
POP_SPEED_SHARE = 0.5  # ... and half the distance the joint travels per frame around it
MODEL_ERROR_FLOOR_M = 0.003  # the model is never trusted beyond this accuracy
NOISE_FLOOR_M = 0.0001  # nor the input beyond this one (clean capture reads as clean: it is kept)
D2_NOISE_GAIN = 6.0  # variance of the 2nd difference of unit white noise
# sigma of the low-pass that separates the model's error from the input's noise (0.07 s: chosen on the held-out
# CMU subject and martial arts, 0.3 to 0.6 % better than 0.1 s with Gaussian noise and rotation jitter at 30 and 60 fps)
BIAS_WINDOW_S = 0.07
TRUST_WINDOW_S = 0.1  # half-width of the running median over which the model's error is measured
PRIOR_WINDOW_S = 0.1  # sigma of the window over which the motion's acceleration is measured, frame by frame
HEADING_WINDOW_S = 0.1  # sigma of the smoothing of the body's heading, for the frame the model's offset is taken in
MODEL_MOTION_TRUST = 4.0  # the model's acceleration counts this much against the first pass's
PRIOR_FLOOR = 0.02  # the acceleration allowed anywhere: at least this share of the take's mean
BONE_PASSES = 10  # rounds of the bone-length projection
# Capture is never free of jitter: up to about 2 mm (what clean takes measure) it is kept as part of the
# take, and the motion-following prior and the bone lengths come in fully from 4 mm of noise on.
JITTER_KEPT_M = 0.002
JITTER_REMOVED_M = 0.004
# Where the model read the take as it is and as its mirror image, the readings' disagreement tells where it
# errs better than its gap to the noisy input does (on the validation split, 3 cm of noise: a log-log
# correlation with the true error of 0.70 against 0.17 for the gap's). The model's squared error per axis
# is read off the readings' half-difference, squared and low-passed as the gap is, as
# SPREAD_GAIN x spread2 ** SPREAD_POWER (m^2, model scale; the power fitted on the validation split: the
# error grows slower than the disagreement), and the gap's estimate keeps a say of GAP_SHARE in the
# geometric mean of the two. The gain is 12 x the validation split's regression: on motion the model has
# not seen its readings disagree less than it errs, and the gap's estimate is scaled the same way, to what
# the low-pass leaves of the input's noise (chosen on the held-out groups with the model trained without them).
SPREAD_GAIN = 0.986
SPREAD_POWER = 0.577
GAP_SHARE = 0.5
# The model's offset from the input, in the body's frame, is smoothed over about this time scale (a
# smoothing spline; chosen on the held-out CMU subject: 0.8 s to 1.6 s within 0.3 %, 0.4 s 1 to 2 % worse;
# without it, the subject and martial arts are 2 to 4 % worse).
BIAS_SPLINE_S = 1.2
JOINT_GROUP = 11  # joints measured and solved at a time: half a long take's working arrays, two passes of the solve


@dataclass
class Assessment:
    """What was measured on a take: noise std per joint and axis ``[J, 3]`` (m) and pops ``bool [F, J]``."""

    noise_m: np.ndarray
    pops: np.ndarray

    @property
    def joint_noise_m(self) -> np.ndarray:
        """Noise std per joint ``[J]`` (m), over its three axes."""
        return np.sqrt((np.asarray(self.noise_m) ** 2).mean(-1))


def noise_level(pos: np.ndarray) -> np.ndarray:
    """Robust std (m) of white noise per joint and axis ``[J, 3]`` of positions ``[F, J, 3]`` (F >= 5).
    Per axis, because noise need not be the same in every direction: jitter of a joint's rotation moves
    the joints below it across their bones, not along them."""
    return np.maximum(np.sqrt(white_noise_variance(pos)), NOISE_FLOOR_M)


def _cubic_from_neighbours(x: np.ndarray) -> np.ndarray:
    """Each frame of ``[F, ...]`` (F >= 5) as the cubic through the two frames on each side predicts it;
    the first and last two frames from the line through the next (previous) two."""
    pred = np.empty_like(x)
    pred[2:-2] = (-x[:-4] + 4 * x[1:-3] + 4 * x[3:-1] - x[4:]) / 6.0
    pred[:2] = 2 * x[1:3] - x[2:4]
    pred[-2:] = 2 * x[-3:-1] - x[-4:-2]
    return pred


def _extrapolated(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each frame of ``[F, ...]`` as the line through the two frames before it predicts it, and the
    line through the two after it (where a side has no two frames, the frame itself)."""
    left, right = np.empty_like(x), np.empty_like(x)
    left[2:] = 2 * x[1:-1] - x[:-2]
    right[:-2] = 2 * x[1:-1] - x[2:]
    left[:2], right[-2:] = x[:2], x[-2:]
    return left, right


def repair_pops(pos: np.ndarray, rounds: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """(positions with pops replaced by their neighbours' cubic, pops ``bool [F, J]``).

    A pop is a joint-frame off the lines through the two frames before it and the two after it,
    on both sides and the same way (a sudden stop is off only one of them), by a distance that is
    a local maximum in time and above :data:`POP_FLOOR_M`, :data:`POP_FACTOR` times the joint's
    median and :data:`POP_SPEED_SHARE` of its distance per frame. The first and last two frames
    are left to :func:`fuse`. Repeated ``rounds`` times, so that pops near each other are found
    one after the other."""
    x = np.array(pos, np.float64)
    pops = np.zeros(x.shape[:2], bool)
    if len(x) < 5:
        return x, pops
    for _ in range(rounds):
        left, right = _extrapolated(x)
        dl, dr = x - left, x - right
        # Off the lines from both sides, and the same way: a sudden stop is off only one of them.
        off = np.minimum(np.linalg.norm(dl, axis=-1), np.linalg.norm(dr, axis=-1))  # (F, J)
        r = off * ((dl * dr).sum(-1) > 0)
        speed = np.zeros_like(r)
        speed[1:-1] = 0.5 * np.linalg.norm(x[2:] - x[:-2], axis=-1)  # fast curves bend the lines too
        limit = np.maximum(np.maximum(POP_FACTOR * np.median(off, 0), POP_FLOOR_M), POP_SPEED_SHARE * speed)
        peak = r >= np.maximum(np.r_[r[:1] * 0, r[:-1]], np.r_[r[1:], r[-1:] * 0])
        peak[:2] = peak[-2:] = False  # the first and last two frames have a line on one side only
        new = (r > limit) & peak & ~pops
        if not new.any():
            break
        x[new] = _cubic_from_neighbours(x)[new]
        pops |= new
    return x, pops


def joint_groups(j: int) -> list[slice]:
    """Every measurement and solve here is joint by joint: a long take is worked on :data:`JOINT_GROUP`
    joints at a time, so its working arrays stay a fraction of the take's size."""
    return [slice(a, min(a + JOINT_GROUP, j)) for a in range(0, j, JOINT_GROUP)]


def assess(pos: np.ndarray) -> tuple[np.ndarray, Assessment]:
    """(pop-repaired positions, :class:`Assessment`) of a take ``[F, J, 3]``."""
    pos = np.asarray(pos, np.float64)
    parts = [repair_pops(pos[:, g]) for g in joint_groups(pos.shape[1])]
    fixed = np.concatenate([p[0] for p in parts], axis=1)
    return fixed, Assessment(noise_level(fixed), np.concatenate([p[1] for p in parts], axis=1))


def input_variance(var: np.ndarray, pops: np.ndarray) -> np.ndarray:
    """The input's error variance ``[F, J, 3]`` from its noise variance ``var`` ``[J, 3]``: at a repaired
    pop (``pops`` ``[F, J]``) the input is the cubic through its neighbours, so their noise and what the
    cubic misses."""
    return np.where(pops[..., None], 2.0 * var + POP_FILL_ERROR_M ** 2, var)


def correct_bias(pos: np.ndarray, model: np.ndarray, found: Assessment, fps: float) -> np.ndarray:
    """The model's reading ``model`` ``[F, 21, 3]`` less its slowly drifting offset from the input ``pos``:
    the gap, turned into the body's heading frame (from the reading, which is free of noise), smoothed
    by a spline that weighs each joint-frame by the input's noise (a pop, by what its repair may miss)
    over :data:`BIAS_SPLINE_S`, and turned back. A body the model has not seen is read with the
    proportions and habits of those it has; what differs holds for seconds, in the body's frame, and
    the input tells it, its noise averaged over that long."""
    x = np.asarray(pos, np.float64)
    m = np.asarray(model, np.float64)
    f = len(x)
    if f < 3:
        return m
    turn = yaw_matrix(heading(m, max(1.0, HEADING_WINDOW_S * fps)))  # [F, 3, 3]: body frame -> world
    stiffness = (BIAS_SPLINE_S * fps) ** 4  # a smoothing spline's time scale, in frames, to the 4th
    out = m.copy()
    for g in joint_groups(x.shape[1]):
        local = np.einsum("fji,fkj->fki", turn, x[:, g] - m[:, g])  # world -> body: R^T v
        w = (1.0 / input_variance(np.asarray(found.noise_m[g], np.float64) ** 2, found.pops[:, g])).reshape(f, -1)
        offset = solve_smooth(w, w * local.reshape(f, -1), stiffness * w.mean(0)).reshape(local.shape)
        out[:, g] += np.einsum("fij,fkj->fki", turn, offset)
    return out


def fuse(pos: np.ndarray, model: np.ndarray, found: Assessment, fps: float,
         spread2: np.ndarray | None = None) -> np.ndarray:
    """:func:`fuse_joints`, :data:`JOINT_GROUP` joints at a time."""
    return np.concatenate([fuse_joints(pos[:, g], model[:, g], Assessment(found.noise_m[g], found.pops[:, g]), fps,
                                       None if spread2 is None else spread2[:, g])
                           for g in joint_groups(np.shape(pos)[1])], axis=1)


def fuse_joints(pos: np.ndarray, model: np.ndarray, found: Assessment, fps: float,
                spread2: np.ndarray | None = None) -> np.ndarray:
    """The motion ``[F, J, 3]`` that weighs the pop-repaired input ``pos`` by its noise (less at the
    repaired pops) and the model's estimate ``model`` by its measured error, with a penalty on
    acceleration, solved exactly (:func:`solve_smooth`).

    The model's error comes from :func:`model_error2` (with ``spread2`` ``[F, J]``, the squared
    half-difference per axis of two readings of the take, from that too). The first and last two frames, where pops
    cannot be told from their neighbours, count as pops when the input is more than five sigma
    from the model there."""
    x = np.asarray(pos, np.float64)
    m = np.asarray(model, np.float64)
    f, j = x.shape[:2]
    sigma2 = np.asarray(found.noise_m) ** 2  # (J, 3)
    gap = x - m
    gap2 = (gap ** 2).sum(-1)  # (F, J)
    tau2 = model_error2(gap, sigma2, fps, spread2)
    pops = found.pops.copy()
    edge = np.r_[:min(2, f), max(f - 2, 0):f]
    pops[edge] |= gap2[edge] > np.maximum(POP_FLOOR_M ** 2, 25.0 * (sigma2.sum(-1) + 3.0 * tau2[edge]))
    x = np.where(pops[..., None] & ~found.pops[..., None], m, x)
    # The input is trusted to its noise, less the capture's own jitter, which is part of the take.
    share = noise_share(found.joint_noise_m)
    kept2 = np.maximum((share[:, None] * found.noise_m) ** 2, NOISE_FLOOR_M ** 2)  # (J, 3)
    w = 1.0 / input_variance(kept2, pops)  # (F, J, 3)
    v = 1.0 / tau2[..., None]
    # The prior's strength: the acceleration the motion itself has, the larger of what the input shows
    # beyond its noise and what the model's (noise-free) estimate shows.
    if f > 2:
        q = np.maximum((np.diff(x, n=2, axis=0) ** 2).mean(0) - D2_NOISE_GAIN * sigma2,
                       (np.diff(m, n=2, axis=0) ** 2).mean(0))
    else:
        q = np.ones((j, 3))
    q = np.maximum(q, 1e-10)  # (J, 3)
    weights = (w + v).reshape(f, -1)
    rhs = (w * x + v * m).reshape(f, -1)
    y = solve_smooth(weights, rhs, 1.0 / q.reshape(-1)).reshape(x.shape)
    if f < 8 or not share.any():
        return y
    # Second pass: the acceleration the motion has around each frame, from the first pass and the model.
    acc2 = np.maximum(np.diff(y, n=2, axis=0) ** 2, MODEL_MOTION_TRUST * np.diff(m, n=2, axis=0) ** 2)
    local = np.maximum(gaussian_smooth(acc2, max(1.0, PRIOR_WINDOW_S * fps)), PRIOR_FLOOR * q)
    following = solve_smooth(weights, rhs, 1.0 / local.reshape(f - 2, -1)).reshape(x.shape)
    return y + share[None, :, None] * (following - y)


def noise_share(noise_m: np.ndarray) -> np.ndarray:
    """How far each joint's measured noise ``[J]`` (m) is jitter to remove rather than the capture's own
    (0 up to :data:`JITTER_KEPT_M`, 1 from :data:`JITTER_REMOVED_M`)."""
    return np.clip((np.asarray(noise_m) - JITTER_KEPT_M) / (JITTER_REMOVED_M - JITTER_KEPT_M), 0.0, 1.0)


def rigid_pairs() -> list[tuple[int, int]]:
    """The joint pairs a skeleton keeps at one distance: each bone (parent, child), and the children of one
    joint with each other (the hips, spine and both thighs hang off the pelvis; the neck and both shoulders
    off the chest): in the canonical skeleton they are fixed offsets from their parent, so the pelvis and the
    chest move as rigid bodies. Held together, the noise each of their joints carries averages over the four."""
    bones = [(int(PARENTS[c]), int(c)) for c in np.flatnonzero(PARENTS >= 0)]
    siblings = [(int(a), int(b)) for p in range(len(PARENTS)) for i, a in enumerate(np.flatnonzero(PARENTS == p))
                for b in np.flatnonzero(PARENTS == p)[i + 1:]]
    return bones + siblings


def keep_bone_lengths(pos: np.ndarray, noise_m: np.ndarray) -> np.ndarray:
    """``pos`` ``[F, 21, 3]`` with each of :func:`rigid_pairs` (the bones, and the joints that hang off one
    parent) brought towards the distance it has through most of the take (its median), both ends moved
    alike, joint by joint at most the noise ``noise_m`` ``[21]`` (m) measured on the input, of jitter to
    remove (:func:`noise_share`): a skeleton's bones do not stretch, so what stretches them is noise, and a
    clean take (or a rig that animates its bones' length on purpose, without noise) is kept."""
    x = np.asarray(pos, np.float64)
    limit = noise_share(noise_m) * np.asarray(noise_m)
    if not limit.any():
        return x
    pairs = rigid_pairs()
    length = [float(np.median(np.linalg.norm(x[:, c] - x[:, p], axis=-1))) for p, c in pairs]
    y = x.copy()
    for _ in range(BONE_PASSES):
        for (p, c), want in zip(pairs, length):
            d = y[:, c] - y[:, p]
            n = np.linalg.norm(d, axis=-1, keepdims=True)
            half = 0.5 * (n - want) * d / np.maximum(n, 1e-12)
            y[:, c] -= half
            y[:, p] += half
    moved = y - x
    size = np.linalg.norm(moved, axis=-1, keepdims=True)
    return x + moved * np.minimum(1.0, limit[None, :, None] / np.maximum(size, 1e-12))


def model_error2(gap: np.ndarray, sigma2: np.ndarray, fps: float, spread2: np.ndarray | None = None) -> np.ndarray:
    """The model's squared error per axis ``[F, J]`` from its gap to the input ``[F, J, 3]`` (the input's
    noise variance per joint and axis ``sigma2`` ``[J, 3]``): the gap
    low-passed over :data:`BIAS_WINDOW_S` (where the input's noise averages out and the model's
    own, slowly varying, error stays), less what is left of the noise, taken as a running median
    over :data:`TRUST_WINDOW_S` on each side so that one bad frame does not make the model look
    wrong around it. With ``spread2`` ``[F, J]`` (two readings' squared half-difference per axis), the
    geometric mean of that estimate and one read off the readings' disagreement (:data:`SPREAD_GAIN`,
    :data:`GAP_SHARE`)."""
    sigma = max(1.0, BIAS_WINDOW_S * fps)
    taps = gaussian_taps(sigma)
    left = taps @ taps  # share of white noise variance left after the filter
    bias2 = ((gaussian_smooth(gap, sigma) ** 2).sum(-1) - left * np.asarray(sigma2).sum(-1)) / 3.0
    # The noise is white and the acceleration prior removes most of it, the model's error is slow and
    # stays: it is weighed against the input's noise as it is after the low-pass, not as it is raw.
    tau2 = np.maximum(running_median(bias2, int(round(TRUST_WINDOW_S * fps))), MODEL_ERROR_FLOOR_M ** 2) / left
    if spread2 is None:
        return tau2
    spread = np.maximum(SPREAD_GAIN * gaussian_smooth(spread2, sigma) ** SPREAD_POWER, MODEL_ERROR_FLOOR_M ** 2)
    return tau2 ** GAP_SHARE * spread ** (1.0 - GAP_SHARE)


def running_median(x: np.ndarray, radius: int) -> np.ndarray:
    """Median over ``2 radius + 1`` frames around each frame of ``[F, ...]`` (the window kept inside)."""
    f = len(x)
    if f <= 2 * radius + 1:
        return np.broadcast_to(np.median(x, 0), x.shape).copy()
    padded = np.concatenate([np.repeat(x[:1], radius, 0), x, np.repeat(x[-1:], radius, 0)])
    out = np.empty_like(x)
    for a in range(0, f, 4096):  # bounded memory on long takes
        b = min(a + 4096, f)
        out[a:b] = np.median(np.stack([padded[a + k:b + k] for k in range(2 * radius + 1)]), 0)
    return out


def solve_smooth(weights: np.ndarray, rhs: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """Solve ``(diag(weights) + D^T diag(lam) D) y = rhs`` per column (D: second differences in time).

    ``weights``, ``rhs``: ``[F, K]``; ``lam``: ``[K]`` (the same at every frame) or ``[F-2, K]`` (one per
    second difference). The matrix is symmetric pentadiagonal and positive definite; an LDL^T
    elimination over frames, vectorised over the K columns."""
    f = len(weights)
    a0 = weights.astype(np.float64).copy()
    if f < 3:
        return rhs / np.maximum(a0, 1e-12)
    lam = np.broadcast_to(np.asarray(lam, np.float64), (f - 2, a0.shape[1]))
    # Row k of D is [1, -2, 1] on frames k, k+1, k+2; it adds lam[k] times its outer product.
    a0[:-2] += lam
    a0[1:-1] += 4.0 * lam
    a0[2:] += lam
    a1 = np.zeros((f - 1, a0.shape[1]))
    a1[:-1] -= 2.0 * lam
    a1[1:] -= 2.0 * lam
    return _ldl_pentadiagonal(a0, a1, lam, rhs.astype(np.float64))


def _ldl_pentadiagonal(a0, a1, a2, b):
    f = len(a0)
    d = np.empty_like(a0)
    p = np.zeros_like(a0)  # L[i, i-1]
    q = np.zeros_like(a0)  # L[i, i-2]
    z = np.empty_like(b)
    for i in range(f):
        if i >= 2:
            q[i] = a2[i - 2] / d[i - 2]
        if i >= 1:
            p[i] = (a1[i - 1] - (q[i] * d[i - 2] * p[i - 1] if i >= 2 else 0.0)) / d[i - 1]
        d[i] = a0[i] - (p[i] ** 2 * d[i - 1] if i >= 1 else 0.0) - (q[i] ** 2 * d[i - 2] if i >= 2 else 0.0)
        z[i] = b[i] - (p[i] * z[i - 1] if i >= 1 else 0.0) - (q[i] * z[i - 2] if i >= 2 else 0.0)
    z /= d
    y = np.empty_like(b)
    for i in range(f - 1, -1, -1):
        y[i] = z[i] - (p[i + 1] * y[i + 1] if i + 1 < f else 0.0) - (q[i + 2] * y[i + 2] if i + 2 < f else 0.0)
    return y
