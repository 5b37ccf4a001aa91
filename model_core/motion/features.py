"""The feature representation of DESIGN.md and its exact inverse.

A frame's features (layout in :data:`conventions.LAYOUT`): joint positions in
the root's local frame (origin = hips projected on the ground, +Z = heading),
the root's ground velocity expressed in that frame (metres per frame), the yaw
rate (radians per frame, about +Y) and four foot contacts. The inverse
integrates the root from a start position and heading, so
``features_to_positions(*positions_to_features(p))`` gives ``p`` back.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .conventions import CONTACT_JOINTS, CONTACTS, JOINT_INDEX, JOINTS, LAYOUT, MODEL_FPS, PARENTS, ROOT, UP_AXIS
from .geometry import unit

# Contact thresholds: a foot joint is in contact when it is within this height
# of its own lowest level in the clip and moves slower than this ground speed.
CONTACT_HEIGHT = 0.05  # metres
CONTACT_SPEED = 0.6  # metres per second
HEADING_SIGMA_FRAMES = 3.0


def gaussian_taps(sigma: float) -> np.ndarray:
    """The normalised taps ``[2 r + 1]`` of :func:`gaussian_smooth` (radius ``r`` = 4 sigma, rounded)."""
    radius = int(4.0 * sigma + 0.5)
    taps = np.exp(-0.5 * (np.arange(-radius, radius + 1) / sigma) ** 2)
    return taps / taps.sum()


def gaussian_smooth(x: np.ndarray, sigma: float, ends: str = "nearest") -> np.ndarray:
    """Gaussian filter along axis 0 with edge padding; equals ``scipy.ndimage.gaussian_filter1d``
    (mode ``nearest``, truncate 4). NumPy only, because Blender's Python has no SciPy. ``ends="trend"``: padded
    instead by reflecting ``x`` through its first and last frames, so a steady trend goes on to the ends (a walk
    near the last frame is not held back towards where it stands there)."""
    taps = gaussian_taps(sigma)
    radius = len(taps) // 2
    if ends == "trend" and len(x) > 1:
        r = min(radius, len(x) - 1)
        before, after = 2 * x[:1] - x[r:0:-1], 2 * x[-1:] - x[-2:-r - 2:-1]
        padded = np.concatenate([np.repeat(before[:1], radius - r, 0), before, x, after,
                                 np.repeat(after[-1:], radius - r, 0)])
    else:
        padded = np.concatenate([np.repeat(x[:1], radius, 0), x, np.repeat(x[-1:], radius, 0)])
    return sum(w * padded[k:k + len(x)] for k, w in enumerate(taps))


@dataclass
class RootStart:
    """Where integration starts: ground position ``[3]`` (y = 0) and heading (radians)."""

    position: np.ndarray
    yaw: float


def yaw_matrix(yaw: np.ndarray) -> np.ndarray:
    """Rotations about +Y ``[..., 3, 3]`` taking +Z to (sin yaw, 0, cos yaw)."""
    c, s = np.cos(yaw), np.sin(yaw)
    z, o = np.zeros_like(yaw), np.ones_like(yaw)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def facing(pos: np.ndarray) -> np.ndarray:
    """Horizontal facing direction ``[F, ..., 3]`` (Y-up, not normalised) from the hips and shoulders of
    ``pos`` ``[F, ..., 21, 3]``: square to the line across them."""
    j = JOINT_INDEX
    across = ((pos[..., j["l_upleg"], :] - pos[..., j["r_upleg"], :])
              + (pos[..., j["l_arm"], :] - pos[..., j["r_arm"], :]))
    return np.cross(across, np.array([0.0, 1.0, 0.0]))


def heading(pos: np.ndarray, sigma: float = HEADING_SIGMA_FRAMES) -> np.ndarray:
    """Facing angle per frame ``[F, ...]`` (radians about +Y) from hips and shoulders (:func:`facing`) of
    ``pos`` ``[F, ..., 21, 3]`` (frames first: a batch of clips of one length is ``[F, B, 21, 3]``)."""
    fwd = facing(pos)
    fwd[..., UP_AXIS] = 0.0
    if sigma > 0 and len(fwd) > 1:
        fwd = gaussian_smooth(fwd, sigma)
    return np.unwrap(np.arctan2(fwd[..., 0], fwd[..., 2]), axis=0)


def root_and_local(pos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ground position of the hips ``[F, 3]``, heading ``[F]``, joints in the body's frame ``[F, J, 3]``)."""
    pos = np.asarray(pos, np.float64)
    yaw = heading(pos, sigma=0.0)
    root = pos[:, ROOT].copy()
    root[:, UP_AXIS] = 0.0
    local = np.einsum("fij,fkj->fki", yaw_matrix(-yaw), pos - root[:, None])
    return root, yaw, local


def wrap_angle(angle: np.ndarray) -> np.ndarray:
    """Angles (radians) brought into [-pi, pi)."""
    return (angle + np.pi) % (2 * np.pi) - np.pi


def lowest_foot(pos: np.ndarray) -> np.ndarray:
    """Height ``[F]`` of the lowest heel or toe joint of positions ``[F, J, 3]``."""
    return np.asarray(pos)[:, CONTACT_JOINTS, UP_AXIS].min(1)


def floor_height(pos: np.ndarray) -> float:
    """The floor a clip stands on: the 5th percentile of its lowest foot joint's height."""
    return float(np.percentile(lowest_foot(pos), 5))


def detect_contacts(pos: np.ndarray, fps: float = MODEL_FPS) -> np.ndarray:
    """Foot contacts ``float32 [F, ..., 4]`` from heights and speeds of heels and toes of ``[F, ..., 21, 3]``."""
    feet = pos[..., CONTACT_JOINTS, :]  # (F, ..., 4, 3)
    height = feet[..., UP_AXIS] - np.percentile(feet[..., UP_AXIS], 2, axis=0)
    ground = feet[..., [0, 2]]
    speed = np.zeros(height.shape)
    if len(pos) > 1:
        step = np.linalg.norm(np.diff(ground, axis=0), axis=-1) * fps
        speed[1:-1] = 0.5 * (step[1:] + step[:-1])
        speed[0], speed[-1] = step[0], step[-1]
    return ((height < CONTACT_HEIGHT) & (speed < CONTACT_SPEED)).astype(np.float32)


def positions_to_features(pos: np.ndarray, fps: float = MODEL_FPS,
                          contacts: np.ndarray | None = None) -> tuple[np.ndarray, RootStart]:
    """Global positions ``[F, 21, 3]`` (metres, Y-up) -> features ``float32 [F, LAYOUT.size]``.

    Returns the features and the :class:`RootStart` that :func:`features_to_positions`
    needs to put the motion back where it was. Clips of one length convert together frames first,
    ``[F, B, 21, 3]`` -> ``[F, B, C]``, each as on its own (the start then holds ``[B, 3]`` and ``[B]``).
    """
    pos = np.asarray(pos, dtype=np.float64)
    n = len(pos)
    yaw = heading(pos)
    root = pos[..., JOINT_INDEX["hips"], :].copy()
    root[..., UP_AXIS] = 0.0
    inv = yaw_matrix(-yaw)  # (F, ..., 3, 3) world -> local
    local = np.einsum("...ij,...kj->...ki", inv, pos - root[..., None, :])
    feats = np.zeros((*pos.shape[:-2], LAYOUT.size), dtype=np.float64)
    feats[..., LAYOUT.positions] = local.reshape(*local.shape[:-2], -1)
    if n > 1:
        vel = np.einsum("...ij,...j->...i", inv[:-1], np.diff(root, axis=0))
        dyaw = np.diff(yaw, axis=0)
        feats[:-1, ..., LAYOUT.velocity] = vel[..., [0, 2]]
        feats[:-1, ..., LAYOUT.yaw_rate] = dyaw
        feats[-1, ..., LAYOUT.root] = feats[-2, ..., LAYOUT.root]
    feats[..., LAYOUT.contacts] = detect_contacts(pos, fps) if contacts is None else contacts
    start = RootStart(root[0].copy(), float(yaw[0]) if np.ndim(yaw[0]) == 0 else yaw[0].copy())
    return feats.astype(np.float32), start


def integrate_root(feats: np.ndarray, start: RootStart | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Root ground positions ``[F, ..., 3]`` and headings ``[F, ...]`` integrated from features ``[F, ..., C]``
    (frames first: clips of one length integrate together)."""
    start = start or RootStart(np.zeros(3), 0.0)
    feats = np.asarray(feats, dtype=np.float64)
    rate = feats[..., LAYOUT.yaw_rate]
    yaw = np.asarray(start.yaw) + np.concatenate([np.zeros_like(rate[:1]), np.cumsum(rate[:-1], 0)])
    vel = np.zeros((*feats.shape[:-1], 3))
    vel[..., [0, 2]] = feats[..., LAYOUT.velocity]
    step = np.einsum("...ij,...j->...i", yaw_matrix(yaw), vel)
    root = np.asarray(start.position, dtype=np.float64) + np.concatenate([np.zeros_like(step[:1]),
                                                                            np.cumsum(step[:-1], 0)])
    return root, yaw


def features_to_positions(feats: np.ndarray, start: RootStart | None = None) -> np.ndarray:
    """Features ``[F, C]`` -> global positions ``float32 [F, 21, 3]`` by integrating the root; clips of one
    length together frames first, ``[F, B, C]`` -> ``[F, B, 21, 3]``."""
    root, yaw = integrate_root(feats, start)
    feats = np.asarray(feats, dtype=np.float64)
    local = feats[..., LAYOUT.positions].reshape(*feats.shape[:-1], -1, 3)
    return (np.einsum("...ij,...kj->...ki", yaw_matrix(yaw), local) + root[..., None, :]).astype(np.float32)


def continue_positions(feats: np.ndarray, start: RootStart, new: np.ndarray) -> np.ndarray:
    """Global positions ``[N, 21, 3]`` of new feature frames ``new`` ``[N, C]`` that follow a clip's
    features ``feats`` ``[F, C]`` (integrated from ``start``): the root goes on from where the clip's
    last frame has it, as the clip's last velocity and yaw rate lead."""
    root, yaw = integrate_root(feats, start)
    joined = np.concatenate([feats[-1:], new])
    return features_to_positions(joined, RootStart(root[-1], float(yaw[-1])))[1:]


def body_lengths(pos: np.ndarray) -> np.ndarray:
    """Median length ``[..., 21]`` of each bone (joint to its parent; 0 for the hips) of joints ``[..., F, 21, 3]``."""
    pos = np.asarray(pos, np.float64)
    bones = np.linalg.norm(pos[..., 1:, :] - pos[..., PARENTS[1:], :], axis=-1)
    return np.concatenate([np.zeros(bones.shape[:-2] + (1,)), np.median(bones, -2)], -1)


def with_bone_lengths(pos: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Joints ``[F, 21, 3]`` with each bone ``lengths[j]`` ``[21]`` long and pointing as in ``pos``, the hips where
    they are: the same motion on a body of other proportions, and back again with the first body's lengths."""
    pos = np.asarray(pos, np.float64)
    out = np.empty_like(pos)
    out[..., 0, :] = pos[..., 0, :]
    for j in range(1, len(PARENTS)):  # parents first
        d = pos[..., j, :] - pos[..., PARENTS[j], :]
        out[..., j, :] = out[..., PARENTS[j], :] + d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12) \
            * lengths[j]
    return out


# Rigid parts: (parent joint, (left, right) joints that span it, the torso joint above it).
RIGID_PARTS = {"hips": (("l_upleg", "r_upleg"), "spine"), "spine1": (("l_arm", "r_arm"), "neck")}


def part_frames(pos: np.ndarray, parent: str) -> np.ndarray:
    """Orientation ``[F, 3, 3]`` (columns: across to the left, up the torso, their cross) of the rigid
    part at joint ``parent`` (:data:`RIGID_PARTS`) in joints ``[F, 21, 3]``."""
    (left, right), up = RIGID_PARTS[parent]
    x = pos[:, JOINT_INDEX[left]] - pos[:, JOINT_INDEX[right]]
    y = pos[:, JOINT_INDEX[up]] - pos[:, JOINT_INDEX[parent]]
    x = unit(x)
    y = unit(y - np.sum(y * x, -1, keepdims=True) * x)
    return np.stack([x, y, np.cross(x, y)], -1)


def with_lengths(pos: np.ndarray, rest: np.ndarray, hips: np.ndarray) -> np.ndarray:
    """Joints ``[F, 21, 3]`` moving like ``pos`` on the body of ``rest`` ``[21, 3]``: each bone points like
    ``pos``'s with ``rest``'s length, except that the joints of a rigid part (:data:`RIGID_PARTS`) keep their
    offsets in ``rest`` turned with ``pos``'s part; the hips at ``hips`` ``[F, 3]``."""
    pos = np.asarray(pos, dtype=np.float64)
    lengths = body_lengths(rest[None])
    turn = {}
    for parent, ((left, right), _) in RIGID_PARTS.items():
        spin = part_frames(pos, parent) @ part_frames(rest[None], parent)[0].T  # rest part -> each frame's
        for j in (left, right):
            turn[JOINT_INDEX[j]] = np.einsum("fij,j->fi", spin, rest[JOINT_INDEX[j]] - rest[JOINT_INDEX[parent]])
    out = np.empty_like(pos)
    out[:, 0] = hips
    for j in range(1, len(JOINTS)):  # parents first
        p = PARENTS[j]
        if j in turn:
            out[:, j] = out[:, p] + turn[j]
            continue
        out[:, j] = out[:, p] + unit(pos[:, j] - pos[:, p]) * lengths[j]
    return out


def on_body_of(motion: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Joints ``[F, 21, 3]`` of ``motion`` put on the body of ``pose`` ``[21, 3]`` (a rig's joints in one pose: as it
    stands, or the last frame of the clip a continuation follows) as Transfer Motion puts a take on a rig
    (:func:`with_lengths`: its bone lengths, its pelvis and chest turned whole), the hips over the same ground and
    each frame's lowest heel or toe as high as it was. A rig's solve keeps its bones, pelvis and chest: motion on
    another body comes out of it with the feet and the arms elsewhere."""
    motion = np.asarray(motion, np.float64)
    out = with_lengths(motion, np.asarray(pose, np.float64), motion[:, 0])
    out[..., UP_AXIS] += (lowest_foot(motion) - lowest_foot(out))[:, None]
    return out


def learnt_bodies(seeds: np.ndarray | None) -> np.ndarray | None:
    """Bone lengths ``[K, 21]`` of the bodies a model's seed windows (training windows, raw features ``[K, m, C]``)
    move, one per window; None without seeds."""
    if seeds is None or len(seeds) == 0:
        return None
    seeds = np.asarray(seeds, np.float64)
    return body_lengths(seeds[..., LAYOUT.positions].reshape(*seeds.shape[:2], -1, 3))


def learnt_seed(seeds: np.ndarray | None) -> int | None:
    """Index of the seed window whose body is nearest the seeds' median (:func:`learnt_bodies`): the body a model
    learnt most; None without seeds."""
    lengths = learnt_bodies(seeds)
    if lengths is None:
        return None
    return int(np.argmin(np.abs(lengths - np.median(lengths, 0)).sum(1)))


def learnt_body(seeds: np.ndarray | None) -> np.ndarray | None:
    """Bone lengths ``[21]`` of the body a model learnt most (:func:`learnt_seed`'s); None without seeds."""
    k = learnt_seed(seeds)
    return None if k is None else learnt_bodies(seeds)[k]


def _mirror_map() -> tuple[np.ndarray, np.ndarray]:
    """(source channel ``[C]``, sign ``[C]``) of the left-right mirror of a feature frame."""
    swap = {"l_": "r_", "r_": "l_"}
    src, sign = np.arange(LAYOUT.size), np.ones(LAYOUT.size, np.float32)
    for j, name in enumerate(JOINTS):
        other = JOINT_INDEX[swap.get(name[:2], name[:2]) + name[2:]] if name[:2] in swap else j
        src[3 * j:3 * j + 3] = np.arange(3 * other, 3 * other + 3)
        sign[3 * j] = -1.0  # the lateral axis (root-local X) flips
    sign[LAYOUT.velocity.start] = -1.0
    sign[LAYOUT.yaw_rate] = -1.0
    names = [c for c, _ in CONTACTS]
    for k, name in enumerate(names):
        src[LAYOUT.contacts.start + k] = LAYOUT.contacts.start + names.index(swap[name[:2]] + name[2:])
    return src, sign


MIRROR_SOURCE, MIRROR_SIGN = _mirror_map()
# The joint that each joint's mirror image is (left and right swapped).
MIRROR_JOINTS = MIRROR_SOURCE[LAYOUT.positions][::3] // 3


def mirror_positions(pos: np.ndarray) -> np.ndarray:
    """Positions ``[..., 21, 3]`` mirrored left to right in the plane X = 0 (the body's left side
    becomes its right); its own inverse. Their features are :func:`mirror_features` of the input's."""
    out = np.array(np.asarray(pos)[..., MIRROR_JOINTS, :])
    out[..., 0] *= -1.0
    return out


def mirror_features(feats: np.ndarray) -> np.ndarray:
    """Raw features ``[..., C]`` of the same motion mirrored left to right (the body's left side
    becomes its right, turns to the left become turns to the right): exact, as the features of the
    mirrored positions."""
    return feats[..., MIRROR_SOURCE] * MIRROR_SIGN


def read_mirrored(predict_once, context: np.ndarray) -> np.ndarray:
    """``predict_once`` (raw context ``[B, m, C]`` -> raw frames ``[B, n, C]``) of the context as it is and of its
    mirror image, in one batch, the two predictions averaged (the mirrored one mirrored back). A model trained
    on mirrored windows too errs differently on each reading, and what it predicts no longer depends on which
    side of the body was captured as the left."""
    context = np.asarray(context, np.float32)
    both = predict_once(np.concatenate([context, mirror_features(context)]))
    return 0.5 * (both[:len(context)] + mirror_features(both[len(context):]))


# Bones (by their lower joint) that body-proportion augmentation scales: the torso's (spine to head, and
# the shoulders' offsets from the chest) and the arms'. The legs are not: every clip is scaled to one leg
# length (conventions.STANDARD_LEG_LENGTH), in training and at run time alike.
PROPORTION_BONES = {
    "torso": np.array([JOINT_INDEX[j] for j in ("spine", "spine1", "neck", "head", "l_arm", "r_arm")]),
    "arms": np.array([JOINT_INDEX[f"{s}_{j}"] for s in "lr" for j in ("elbow", "wrist", "fingertip")]),
}


def scale_proportions(feats: np.ndarray, torso: np.ndarray, arms: np.ndarray) -> np.ndarray:
    """Raw features ``[B, T, C]`` of the same motion by a body of other proportions: window ``b``'s torso
    bones (:data:`PROPORTION_BONES`) ``torso[b]`` times as long and its arms' ``arms[b]`` times, each bone
    keeping its direction, the hips and legs (and so the feet and the root's motion) as they were."""
    out = np.array(feats, dtype=np.float32, copy=True)
    b, t = out.shape[:2]
    pos = out[..., LAYOUT.positions].reshape(b, t, len(JOINTS), 3)
    scale = np.ones((b, len(JOINTS)), np.float32)
    scale[:, PROPORTION_BONES["torso"]] = np.asarray(torso, np.float32)[:, None]
    scale[:, PROPORTION_BONES["arms"]] = np.asarray(arms, np.float32)[:, None]
    new = pos.copy()
    for j in range(1, len(JOINTS)):  # parents come before their children
        p = PARENTS[j]
        new[:, :, j] = new[:, :, p] + scale[:, None, j, None] * (pos[:, :, j] - pos[:, :, p])
    out[..., LAYOUT.positions] = new.reshape(b, t, -1)
    return out
