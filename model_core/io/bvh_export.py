"""Write canonical motion as a BVH file of the canonical skeleton.

Input is global positions ``[frames, 21, 3]`` in metres, Y-up (:mod:`conventions`).
The file keeps metres and Y-up, so Blender's BVH importer at its default scale
(1.0, up = Y) gives the right size. The skeleton:

- rest offsets: each bone's median length over the clip, laid along a T-pose
  direction (spine up, legs down, feet forward, arms out to the sides); the
  pelvis and clavicle bones take their median direction in the body's frame;
- a joint with several child bones (hips, spine1) gets a zero-offset "carrier"
  joint per side bone (``LHipJoint``, ``LeftShoulder``), so that every bone has
  its own rotation and joint positions are reproduced exactly while bone lengths
  are constant;
- rotations are swings from the rest direction to the current bone direction
  (hips and spine1 take a full frame from their bone and the hips/shoulder line,
  so the torso's twist is kept); Euler channels ``Zrotation Xrotation Yrotation``
  (R = Rz Rx Ry, degrees), plus ``X/Y/Zposition`` on the root.

Joint names follow the Mixamo convention (``Hips``, ``LeftUpLeg``, ...), so
:func:`rigs.detect_rig` maps a written file back onto the canonical joints.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..motion.conventions import JOINT_INDEX, MODEL_FPS
from ..motion.features import heading, yaw_matrix
from ..motion.geometry import shortest_arc, unit
from .files import write_text

_SIDE = {"l": "Left", "r": "Right"}
_LIMB_NAMES = {"upleg": "UpLeg", "knee": "Leg", "foot": "Foot", "toe": "ToeBase",
               "arm": "Arm", "elbow": "ForeArm", "wrist": "Hand", "fingertip": "HandMiddle4"}
_TORSO_NAMES = {"hips": "Hips", "spine": "Spine", "spine1": "Spine1", "neck": "Neck", "head": "Head"}

# T-pose direction of the bone ending at each joint (character faces +Z, its left is +X).
_REST_DIRECTION = {
    "spine": (0, 1, 0), "spine1": (0, 1, 0), "neck": (0, 1, 0), "head": (0, 1, 0),
    "knee": (0, -1, 0), "foot": (0, -1, 0), "toe": (0, 0, 1),
    "elbow": (1, 0, 0), "wrist": (1, 0, 0), "fingertip": (1, 0, 0),
}
# Bones whose rest direction is their median direction in the body frame (no T-pose rule).
_MEDIAN_DIRECTION = ("upleg", "arm")
_END_SITE_LENGTH = 0.05  # metres; a short stub past each leaf joint, along its bone


@dataclass
class Joint:
    """One BVH joint: ``canonical`` is the joint whose position it carries (None for carriers)."""

    name: str
    parent: int  # index into the joint list, -1 for the root
    canonical: str | None
    offset: np.ndarray  # float64 [3], metres, in the parent's rest frame (= world axes)
    target: str | None  # canonical joint its bone points at (its first child), None for leaves


def _bvh_name(joint: str) -> str:
    if joint in _TORSO_NAMES:
        return _TORSO_NAMES[joint]
    side, part = joint.split("_", 1)
    return _SIDE[side] + _LIMB_NAMES[part]


def _body_frame_vectors(pos: np.ndarray, joint: str, parent: str) -> np.ndarray:
    """Bone vectors ``[F, 3]`` from ``parent`` to ``joint`` in the body's heading frame."""
    inv = yaw_matrix(-heading(pos))
    v = pos[:, JOINT_INDEX[joint]] - pos[:, JOINT_INDEX[parent]]
    return np.einsum("fij,fj->fi", inv, v)


def _rest_offset(pos: np.ndarray, joint: str, parent: str) -> np.ndarray:
    """Rest offset ``[3]`` (metres) of ``joint`` from ``parent``: median length along the rest direction."""
    length = float(np.median(np.linalg.norm(pos[:, JOINT_INDEX[joint]] - pos[:, JOINT_INDEX[parent]], axis=-1)))
    part = joint.split("_", 1)[-1]
    if part in _MEDIAN_DIRECTION:
        d = np.median(_body_frame_vectors(pos, joint, parent), axis=0)
    else:
        d = np.array(_REST_DIRECTION[part], dtype=np.float64)
        if joint.startswith("r_") and part in ("elbow", "wrist", "fingertip"):
            d = -d  # the right arm points to -X
    n = np.linalg.norm(d)
    return d / n * length if n > 1e-9 else np.array([0.0, length, 0.0])


def build_skeleton(pos: np.ndarray) -> list[Joint]:
    """The BVH joint list (parents before children) for canonical positions ``[F, 21, 3]``."""
    joints = [Joint("Hips", -1, "hips", np.zeros(3), "spine")]

    def chain(parent_idx: int, names: list[str], parent_joint: str):
        prev_idx, prev = parent_idx, parent_joint
        for i, j in enumerate(names):
            target = names[i + 1] if i + 1 < len(names) else None
            joints.append(Joint(_bvh_name(j), prev_idx, j, _rest_offset(pos, j, prev), target))
            prev_idx, prev = len(joints) - 1, j

    chain(0, ["spine", "spine1", "neck", "head"], "hips")
    spine1 = next(i for i, jt in enumerate(joints) if jt.canonical == "spine1")
    for s in ("l", "r"):
        joints.append(Joint(f"{_SIDE[s]}Shoulder", spine1, None, np.zeros(3), f"{s}_arm"))
        chain(len(joints) - 1, [f"{s}_arm", f"{s}_elbow", f"{s}_wrist", f"{s}_fingertip"], "spine1")
    for s in ("l", "r"):
        joints.append(Joint(f"{s.upper()}HipJoint", 0, None, np.zeros(3), f"{s}_upleg"))
        chain(len(joints) - 1, [f"{s}_upleg", f"{s}_knee", f"{s}_foot", f"{s}_toe"], "hips")
    return joints


def swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotations ``[F, 3, 3]`` taking unit vector ``a [3]`` onto unit vectors ``b [F, 3]``
    (:func:`geometry.shortest_arc`)."""
    return shortest_arc(np.broadcast_to(np.asarray(a, dtype=np.float64), b.shape), b)


def frame_rotation(rest_a, rest_b, cur_a: np.ndarray, cur_b: np.ndarray) -> np.ndarray:
    """Rotations ``[F, 3, 3]`` taking the rest frame (primary ``rest_a``, secondary ``rest_b``, ``[3]``)
    onto the current one (``cur_a``, ``cur_b``, ``[F, 3]``): the primary exactly, the secondary's plane."""

    def basis(a, b):
        x = unit(a)
        z = unit(np.cross(x, b))
        return np.stack([x, np.cross(z, x), z], axis=-1)  # columns

    rest = basis(np.asarray(rest_a, float)[None], np.asarray(rest_b, float)[None])[0]
    return np.einsum("fij,kj->fik", basis(cur_a, cur_b), rest)  # current basis @ rest basis^T


def _global_rotations(joints: list[Joint], pos: np.ndarray) -> np.ndarray:
    """Global rotations ``[F, J, 3, 3]`` for every BVH joint."""
    j = JOINT_INDEX
    n = len(pos)
    rest_world = np.zeros((len(joints), 3))
    for i, jt in enumerate(joints):
        rest_world[i] = jt.offset + (rest_world[jt.parent] if jt.parent >= 0 else 0.0)
    rest_of = {jt.canonical: rest_world[i] for i, jt in enumerate(joints) if jt.canonical}
    grot = np.broadcast_to(np.eye(3), (n, len(joints), 3, 3)).copy()
    for i, jt in enumerate(joints):
        if jt.target is None:
            grot[:, i] = grot[:, jt.parent]  # leaves keep their parent's rotation
            continue
        here = jt.canonical or joints[jt.parent].canonical
        rest_dir = rest_of[jt.target] - rest_of[here]
        cur_dir = pos[:, j[jt.target]] - pos[:, j[here]]
        if jt.canonical in ("hips", "spine1"):
            pair = ("l_upleg", "r_upleg") if jt.canonical == "hips" else ("l_arm", "r_arm")
            rest_across = rest_of[pair[0]] - rest_of[pair[1]]
            cur_across = pos[:, j[pair[0]]] - pos[:, j[pair[1]]]
            grot[:, i] = frame_rotation(rest_dir, rest_across, cur_dir, cur_across)
        else:
            grot[:, i] = swing(unit(rest_dir), unit(cur_dir))
    return grot


def euler_zxy(r: np.ndarray) -> np.ndarray:
    """Rotation matrices ``[..., 3, 3]`` -> Euler angles ``[..., 3]`` (z, x, y) in degrees, R = Rz Rx Ry."""
    sx = np.clip(r[..., 2, 1], -1.0, 1.0)
    x = np.arcsin(sx)
    z = np.arctan2(-r[..., 0, 1], r[..., 1, 1])
    y = np.arctan2(-r[..., 2, 0], r[..., 2, 2])
    lock = np.abs(sx) > 1 - 1e-9  # gimbal lock: put all of the z/y freedom into y
    z = np.where(lock, 0.0, z)
    y = np.where(lock, np.arctan2(r[..., 0, 2], r[..., 0, 0]), y)
    return np.degrees(np.stack([z, x, y], axis=-1))


def _hierarchy_lines(joints: list[Joint]) -> list[str]:
    children = {i: [k for k, jt in enumerate(joints) if jt.parent == i] for i in range(len(joints))}
    lines: list[str] = ["HIERARCHY"]

    def emit(i: int, depth: int):
        jt, pad = joints[i], "  " * depth
        lines.append(f"{pad}{'ROOT' if jt.parent < 0 else 'JOINT'} {jt.name}")
        lines.append(pad + "{")
        lines.append(f"{pad}  OFFSET {' '.join(f'{v:.6f}' for v in jt.offset)}")
        pos_ch = "Xposition Yposition Zposition " if jt.parent < 0 else ""
        lines.append(f"{pad}  CHANNELS {6 if jt.parent < 0 else 3} {pos_ch}Zrotation Xrotation Yrotation")
        for k in children[i]:
            emit(k, depth + 1)
        if not children[i]:
            d = jt.offset / max(np.linalg.norm(jt.offset), 1e-9) * _END_SITE_LENGTH
            lines.extend([f"{pad}  End Site", pad + "  {", f"{pad}    OFFSET {d[0]:.6f} {d[1]:.6f} {d[2]:.6f}",
                          pad + "  }"])
        lines.append(pad + "}")

    emit(0, 0)
    return lines


def motion_channels(joints: list[Joint], pos: np.ndarray) -> np.ndarray:
    """The MOTION block's values ``float64 [F, 3 + 3J]``: root position (metres), then z, x, y degrees per joint."""
    grot = _global_rotations(joints, pos)
    local = grot.copy()
    for i, jt in enumerate(joints):
        if jt.parent >= 0:
            local[:, i] = np.einsum("fji,fjk->fik", grot[:, jt.parent], grot[:, i])  # parent^T @ child
    angles = np.unwrap(np.radians(euler_zxy(local)), axis=0)  # no 360-degree jumps between frames
    root = pos[:, JOINT_INDEX["hips"]].astype(np.float64)
    return np.concatenate([root, np.degrees(angles).reshape(len(pos), -1)], axis=1)


def write_bvh(path: str | Path, positions: np.ndarray, fps: float = MODEL_FPS) -> Path:
    """Write canonical positions ``[F, 21, 3]`` (metres, Y-up) to ``path`` as BVH, atomically.

    Returns the path. Raises ``ValueError`` for a wrong shape or non-finite values.
    """
    pos = np.asarray(positions, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[1:] != (len(JOINT_INDEX), 3) or len(pos) == 0:
        raise ValueError(f"{path}: expected positions [frames, {len(JOINT_INDEX)}, 3], got {list(pos.shape)}")
    if not np.all(np.isfinite(pos)):
        raise ValueError(f"{path}: positions contain NaN or infinite values; nothing written")
    joints = build_skeleton(pos)
    values = motion_channels(joints, pos)
    lines = _hierarchy_lines(joints) + ["MOTION", f"Frames: {len(pos)}", f"Frame Time: {1.0 / fps:.10f}"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in values]
    return write_text(path, "\n".join(lines) + "\n")
