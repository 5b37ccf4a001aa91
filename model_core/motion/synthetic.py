"""A procedural walking skeleton: small, deterministic motion for tests and examples.

:func:`walking_skeleton` gives canonical global positions ``float32 [frames, 21, 3]``
(metres, Y-up, :data:`conventions.MODEL_FPS`) of a body walking along a circular
arc, made by forward kinematics over fixed bone offsets, so every bone keeps
exactly its length. It is not mocap; it only has the right structure.
"""

from __future__ import annotations

import numpy as np

from .conventions import CONTACT_JOINTS, JOINTS, MODEL_FPS, PARENTS
from .features import yaw_matrix

# Rest offsets from the parent joint, metres; the body faces +Z, its left is +X, arms hang down.
_OFFSETS = {
    "hips": (0.0, 0.0, 0.0), "spine": (0.0, 0.10, -0.01), "spine1": (0.0, 0.22, 0.0),
    "neck": (0.0, 0.22, 0.01), "head": (0.0, 0.12, 0.03),
    "upleg": (0.10, -0.06, 0.0), "knee": (0.0, -0.44, 0.0), "foot": (0.0, -0.43, -0.01),
    "toe": (0.0, -0.05, 0.14), "arm": (0.17, 0.04, -0.02), "elbow": (0.0, -0.28, 0.0),
    "wrist": (0.0, -0.25, 0.0), "fingertip": (0.0, -0.18, 0.0),
}


def rest_offset(joint: str) -> np.ndarray:
    side, _, part = joint.partition("_")
    o = np.array(_OFFSETS[part if part else side], dtype=np.float64)
    if side == "r":
        o[0] = -o[0]
    return o


def _rot_x(angle: np.ndarray) -> np.ndarray:
    """Rotations about +X ``[F, 3, 3]``; positive angles swing -Y towards +Z (a leg forwards)."""
    c, s = np.cos(angle), np.sin(angle)
    z, o = np.zeros_like(angle), np.ones_like(angle)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def _local_rotations(phase: np.ndarray) -> dict[str, np.ndarray]:
    """Per-joint local rotations ``[F, 3, 3]`` of a gait cycle at ``phase`` (radians)."""
    swing_l, swing_r = 0.45 * np.sin(phase), 0.45 * np.sin(phase + np.pi)
    return {
        "l_upleg": _rot_x(swing_l), "r_upleg": _rot_x(swing_r),
        "l_knee": _rot_x(-0.35 * (1 - np.cos(phase + 0.6))),
        "r_knee": _rot_x(-0.35 * (1 - np.cos(phase + np.pi + 0.6))),
        "l_foot": _rot_x(0.15 * np.sin(phase + 1.0)), "r_foot": _rot_x(0.15 * np.sin(phase + np.pi + 1.0)),
        "l_arm": _rot_x(-0.6 * swing_l), "r_arm": _rot_x(-0.6 * swing_r),
        "l_elbow": _rot_x(0.3 + 0.1 * np.sin(phase)), "r_elbow": _rot_x(0.3 + 0.1 * np.sin(phase + np.pi)),
        "spine1": _rot_x(0.05 * np.sin(2 * phase)),
    }


def walking_skeleton(frames: int = 120, fps: float = MODEL_FPS, speed: float = 1.3, radius: float = 6.0,
                     cadence: float = 0.9) -> np.ndarray:
    """Canonical positions ``float32 [frames, 21, 3]`` (metres, Y-up) of a walk along a circle.

    ``speed`` in m/s, ``radius`` of the arc in metres (turning left), ``cadence`` in gait cycles per second.
    """
    t = np.arange(frames) / fps
    phase = 2 * np.pi * cadence * t
    angle = speed * t / radius  # arc angle travelled
    yaw = angle  # heading follows the tangent of the arc
    root = np.stack([radius * (1 - np.cos(angle)), 0.92 + 0.02 * np.cos(2 * phase), radius * np.sin(angle)], -1)
    local = _local_rotations(phase)
    eye = np.broadcast_to(np.eye(3), (frames, 3, 3))
    grot = np.zeros((frames, len(JOINTS), 3, 3))
    gpos = np.zeros((frames, len(JOINTS), 3))
    for j, name in enumerate(JOINTS):
        p = PARENTS[j]
        rot = local.get(name, eye)
        if p < 0:
            grot[:, j], gpos[:, j] = yaw_matrix(yaw) @ rot, root
        else:
            grot[:, j] = grot[:, p] @ rot
            gpos[:, j] = gpos[:, p] + np.einsum("fij,j->fi", grot[:, p], rest_offset(name))
    return gpos.astype(np.float32)


def up_a_slope(pos: np.ndarray, slope: float = 0.15) -> tuple[np.ndarray, np.ndarray]:
    """Motion ``pos`` ``[F, 21, 3]`` (Y-up) walked up a slope that rises ``slope`` per unit along its way (from the
    hips' first to their last place), each joint raised by the slope's height under it, and that height under each
    heel (at the ankle) and toe ``[F, 4]``: a take on uneven ground whose feet stand on it where the take's stood on
    the floor (Foot Lock's ground)."""
    way = (pos[-1, 0] - pos[0, 0]) * np.array([1.0, 0.0, 1.0])
    way = way / np.linalg.norm(way)
    height = slope * (pos - pos[0, 0]) @ way  # [F, 21]
    climbed = np.array(pos, np.float64)
    climbed[..., 1] += height
    return climbed.astype(np.float32), height[:, CONTACT_JOINTS]
