"""Transfer Motion: a take's canonical joints put on another body's proportions (no bpy).

The source's motion is kept as directions: every canonical bone (joint to parent joint) points
where the source's does, with the target's own length, built outwards from the hips. The pelvis
and the shoulders are rigid in a body: the upper legs and upper arms keep the target's own
offsets from the hips and the chest, turned as the source's pelvis and chest turn. The root
path is scaled by the ratio of leg lengths and starts where the target stands; the body is then
raised or lowered frame by frame so that its lowest foot is as high above the target's floor as
the source's is above its own (scaled), so feet neither sink nor float where the source's touch.
The rig solve then turns the target's bones onto these joints.
"""

from __future__ import annotations

import numpy as np

from ..motion.conventions import GROUND_AXES, JOINTS, UP_AXIS
from ..motion.features import body_lengths, floor_height, lowest_foot, with_lengths
from ..rig.rigs import leg_length


def bone_lengths(pos: np.ndarray) -> np.ndarray:
    """Median length ``[21]`` of each canonical bone (joint to its parent; 0 for the hips) over
    frames ``[F, 21, 3]`` (:func:`features.body_lengths`)."""
    return body_lengths(pos)


def retarget(source: np.ndarray, target_rest: np.ndarray) -> np.ndarray:
    """The motion of ``source`` ``[F, 21, 3]`` on the body of ``target_rest`` (the target's joints in
    its reference pose, ``[21, 3]`` or ``[K, 21, 3]``), both in one world (Y up, same units).

    Returns ``[F, 21, 3]``: the target's bone lengths, the source's bone directions, the root path
    scaled by the leg-length ratio from where the target stands, feet as high above the target's
    floor as the source's (scaled) above its own."""
    source = np.asarray(source, dtype=np.float64)
    rest = np.asarray(target_rest, dtype=np.float64).reshape(-1, len(JOINTS), 3)
    if len(source) == 0:
        raise ValueError("the source has no frames to transfer")
    scale = leg_length(rest) / max(leg_length(source), 1e-9)
    floor_s, floor_t = floor_height(source), float(np.min(lowest_foot(rest)))
    hips = np.empty((len(source), 3))
    ground = list(GROUND_AXES)
    hips[:, ground] = rest[0, 0, ground] + scale * (source[:, 0, ground] - source[0, 0, ground])
    hips[:, UP_AXIS] = floor_t + scale * (source[:, 0, UP_AXIS] - floor_s)
    out = with_lengths(source, rest[0], hips)
    lift = floor_t + scale * (lowest_foot(source) - floor_s) - lowest_foot(out)
    out[..., UP_AXIS] += lift[:, None]
    return out
