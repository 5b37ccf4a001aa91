"""Motion put back on a body's bones: each bone keeps its direction and takes its length, from the hips out,
and each leg reaches its ankle by two-bone IK with the knee bending the body's way (:func:`on_skeleton`).

Moving joints one by one (a seam faded out, a continuation bent onto a target) stretches and shortens the
bones between them, which a rig cannot follow: its solve keeps its bones and misses. Fill Gap and Extend put
their frames back on the clip's bones with it. Positions are ``[F, 21, 3]``, Y-up.
"""

from __future__ import annotations

import numpy as np

from ..motion.conventions import PARENTS, ROOT
from ..motion.features import body_lengths
from ..motion.geometry import interpolate_frames, unit
from .footlock import LEGS, body_forward, place_leg
from .seam import blend_seam

_HIP, _KNEE, _ANKLE, _TOE = (np.array([leg[k] for leg in LEGS]) for k in range(4))  # [2]: left, right


# A knee bending less than this (the sine of the thigh's angle to the hip-ankle line) has no side of its own.
STRAIGHT_SINE = 0.05


def _knee_offsets(pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(each knee's offset from its hip-ankle line ``[F, 2, 3]``, the hip-ankle directions ``[F, 2, 3]``)."""
    hip, knee, ankle = pos[:, _HIP], pos[:, _KNEE], pos[:, _ANKLE]
    axis = unit(ankle - hip)
    return (knee - hip) - axis * np.sum((knee - hip) * axis, -1, keepdims=True), axis


def knee_side(pos: np.ndarray) -> float:
    """1 where the knees of ``pos`` ``[F, 21, 3]`` bend towards the way the body faces (people's knees
    do), -1 where they bend the other way (a rig built so), 1 where they never bend."""
    off, _ = _knee_offsets(np.asarray(pos, np.float64))
    thigh = np.linalg.norm(pos[:, _KNEE] - pos[:, _HIP], axis=-1)
    bent = np.linalg.norm(off, axis=-1) > STRAIGHT_SINE * thigh
    ahead = np.sum(off * body_forward(pos)[:, None], -1)
    return -1.0 if bent.any() and np.median(ahead[bent]) < 0.0 else 1.0


def bend_sides(pos: np.ndarray, side: float) -> np.ndarray:
    """Unit directions ``[F, 2, 3]`` in which each knee of ``pos`` ``[F, 21, 3]`` bends, never the other way
    than ``side`` (:func:`knee_side`) says: a knee bent backwards bends as far sideways only, and one that
    is nearly straight leans forwards (for ``side`` 1), the more the straighter, so that an IK on other
    lengths never flips it through the leg, as a continuation passing through a straight leg would."""
    off, axis = _knee_offsets(pos)
    ahead = side * body_forward(pos)[:, None]
    ahead = unit(ahead - axis * np.sum(ahead * axis, -1, keepdims=True))
    thigh = np.linalg.norm(pos[:, _KNEE] - pos[:, _HIP], axis=-1, keepdims=True)
    off = off - np.minimum(np.sum(off * ahead, -1, keepdims=True), 0.0) * ahead
    lean = np.maximum(STRAIGHT_SINE * thigh - np.linalg.norm(off, axis=-1, keepdims=True), 0.0)
    return unit(off + lean * ahead)  # a knee bent the right way keeps its side exactly


def on_skeleton(frames: np.ndarray, start: np.ndarray, end: np.ndarray, knees: float = 1.0) -> np.ndarray:
    """``frames`` ``[N + 1, J, 3]`` (a gap and the target's frame) put back on the body's bones, whose
    lengths go from the context's ``start`` ``[J]`` to the target's ``end`` ``[J]`` over the gap.

    Bending a continuation onto a target (and leaning on the interpolation) moves each joint by its own
    offset, so that a leg swinging the other way than the target's is shortened mid-gap (a shin by a
    quarter), which a rig cannot follow: its solve keeps its bones, misses the ankle by as much and turns
    the foot round to reach the toe. So every bone keeps its direction and takes its length, from the hips
    out, and each leg reaches the ankle that the gap has, by Foot Lock's two-bone IK on those lengths
    (:func:`footlock.place_leg`, within a soft limit short of straight, each knee bending the way ``knees``
    says: :func:`knee_side`, :func:`bend_sides`); the feet then point at their toes. The target's frame (the
    last) keeps the target's own lengths, so the gap still arrives at it."""
    frames = np.asarray(frames, np.float64)
    s = (np.arange(1, len(frames) + 1) / len(frames))[:, None]
    lengths = (1.0 - s) * start[None] + s * end[None]  # [N + 1, J]
    return _on_lengths(frames, lengths, knees).astype(np.float32)


def _on_lengths(frames: np.ndarray, lengths: np.ndarray, knees: float) -> np.ndarray:
    """``frames`` ``[F, J, 3]`` on bones of ``lengths`` ``[F, J]`` (:func:`on_skeleton`'s work) -> float64."""
    out = np.empty_like(frames)
    out[:, ROOT] = frames[:, ROOT]
    for j in range(1, frames.shape[1]):  # parents first
        p = PARENTS[j]
        out[:, j] = out[:, p] + unit(frames[:, j] - frames[:, p]) * lengths[:, j, None]
    l1, l2 = lengths[:, _KNEE], lengths[:, _ANKLE]
    side = bend_sides(frames, knees)
    knee, ankle = place_leg(out[:, _HIP], frames[:, _ANKLE], l1, l2, side, np.linalg.norm(
        out[:, _ANKLE] - out[:, _HIP], axis=-1))
    toe = ankle + unit(frames[:, _TOE] - frames[:, _ANKLE]) * lengths[:, _TOE, None]
    out[:, _KNEE], out[:, _ANKLE], out[:, _TOE] = knee, ankle, toe
    return out


def sampled_on_bones(seq: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``seq`` ``[N, J, 3]`` (frames on a body's bones, at the model's rate) at fractional frame indices ``t``
    ``[M]`` (clamped to the first and last) -> float64 ``[M, J, 3]``, every frame on the bones.

    Between two frames, linear interpolation shortens each bone that turns (a fighter's leg bones at 60 fps by up
    to 2.9 cm), which a rig cannot follow: its solve keeps its bones, so the knee bends further and the
    foot misses by as much on every frame between the model's, a shimmer in the legs at twice the model's rate.
    So a frame between two is put back on the bones (:func:`on_skeleton`'s way: each bone its direction and the
    two frames' lengths, the ankles where the interpolation has them, the knees bending the frames' way); a frame
    on one of ``seq``'s is that frame."""
    seq = np.asarray(seq, np.float64)
    t = np.clip(np.asarray(t, np.float64), 0, len(seq) - 1)
    out = interpolate_frames(seq, t)
    between = np.abs(t - np.round(t)) > 1e-6
    if between.any():
        bones = np.linalg.norm(seq[:, 1:] - seq[:, PARENTS[1:]], axis=-1)
        lengths = interpolate_frames(np.concatenate([np.zeros((len(seq), 1)), bones], 1), t[between])
        out[between] = _on_lengths(out[between], lengths, knee_side(seq))
    return out


def on_clip_bones(frames: np.ndarray, clip: np.ndarray) -> np.ndarray:
    """A continuation's ``frames`` ``[N, J, 3]`` on the bones of the ``clip`` ``[C, J, 3]`` it continues
    (:func:`on_skeleton` with the clip's lengths, its knees bending the clip's way): for the seam after a user's
    clip, which moves each joint by its own offset. Returns float64."""
    lengths = body_lengths(clip)
    return on_skeleton(frames, lengths, lengths, knee_side(clip)).astype(np.float64)


def join_clip(clip: np.ndarray, new: np.ndarray, momentum: float = 0.0, coast: float = 0.0,
              coast_frames: int = 0) -> np.ndarray:
    """``[1 + N, J, 3]``: the ``clip``'s last frame and its continuation ``new`` ``[N, J, 3]`` (same rate) joined as
    Extend joins them: the jump faded out (:func:`seam.blend_seam`, with ``momentum``, ``coast`` and
    ``coast_frames``) and every frame on the clip's bones (:func:`on_clip_bones`)."""
    seam = blend_seam(clip, new, momentum=momentum, coast=coast, coast_frames=coast_frames)
    return on_clip_bones(np.concatenate([clip[-1:], seam]), clip)
