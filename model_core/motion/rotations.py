"""Rotation conversions between matrices, quaternions, Euler angles and axis-angle,
vectorised over leading dimensions (no bpy, no mathutils).

Glossary
--------
- M: rotation matrix ``[..., 3, 3]`` acting on column vectors (``v' = M @ v``).
- Q: unit quaternion ``[..., 4]`` in (w, x, y, z) order, Blender's order.
- E: Euler angles ``[..., 3]`` stored as (x, y, z) angles in radians whatever the
  order; the order string names the axes in the order they are applied, as in
  Blender's ``rotation_mode``: ``"XYZ"`` means ``M = Rz @ Ry @ Rx``.
- A: axis-angle ``[..., 4]`` as (angle, x, y, z), Blender's ``rotation_axis_angle``.
"""

from __future__ import annotations

import numpy as np

from .geometry import rotvec_to_matrix

EULER_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
_AXIS = {"X": 0, "Y": 1, "Z": 2}


def axis_matrix(axis: int, angle: np.ndarray) -> np.ndarray:
    """Rotations about one axis ``[..., 3, 3]`` by ``angle`` ``[...]`` radians."""
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros(angle.shape + (3, 3))
    a, b = [(1, 2), (2, 0), (0, 1)][axis]
    m[..., axis, axis] = 1.0
    m[..., a, a] = c
    m[..., b, b] = c
    m[..., a, b] = -s
    m[..., b, a] = s
    return m


def euler_to_matrix(e: np.ndarray, order: str) -> np.ndarray:
    """Euler angles ``[..., 3]`` (x, y, z radians) in Blender ``order`` -> ``[..., 3, 3]``."""
    e = np.asarray(e, dtype=np.float64)
    m = None
    for ax in order:  # first axis applied first: M = R_last @ ... @ R_first
        r = axis_matrix(_AXIS[ax], e[..., _AXIS[ax]])
        m = r if m is None else r @ m
    return m


def matrix_to_euler(m: np.ndarray, order: str) -> np.ndarray:
    """Rotation matrices ``[..., 3, 3]`` -> Euler angles ``[..., 3]`` (x, y, z) in ``order``.

    The middle angle lies in [-pi/2, pi/2]; at gimbal lock the last axis angle is 0.
    """
    m = np.asarray(m, dtype=np.float64)
    i, j, k = (_AXIS[a] for a in order)
    s = 1.0 if (j - i) % 3 == 1 else -1.0  # even or odd permutation
    cb = np.hypot(m[..., i, i], m[..., j, i])
    b = np.arctan2(-s * m[..., k, i], cb)
    a = np.arctan2(s * m[..., k, j], m[..., k, k])
    c = np.arctan2(s * m[..., j, i], m[..., i, i])
    lock = cb < 1e-9
    if np.any(lock):
        a = np.where(lock, np.arctan2(-s * m[..., j, k], m[..., j, j]), a)
        c = np.where(lock, 0.0, c)
    out = np.empty(m.shape[:-2] + (3,))
    out[..., i], out[..., j], out[..., k] = a, b, c
    return out


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Quaternions ``[..., 4]`` (w, x, y, z; normalised here) -> ``[..., 3, 3]``."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), 1e-12)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Rotation matrices ``[..., 3, 3]`` -> unit quaternions ``[..., 4]`` (w, x, y, z), w >= 0."""
    m = np.asarray(m, dtype=np.float64)
    tr = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    cand = np.stack([
        np.stack([1 + tr, m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]], -1),
        np.stack([m[..., 2, 1] - m[..., 1, 2], 1 + 2 * m[..., 0, 0] - tr, m[..., 0, 1] + m[..., 1, 0],
                  m[..., 0, 2] + m[..., 2, 0]], -1),
        np.stack([m[..., 0, 2] - m[..., 2, 0], m[..., 0, 1] + m[..., 1, 0], 1 + 2 * m[..., 1, 1] - tr,
                  m[..., 1, 2] + m[..., 2, 1]], -1),
        np.stack([m[..., 1, 0] - m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1],
                  1 + 2 * m[..., 2, 2] - tr], -1),
    ], -2)  # (..., 4, 4): row r is 4 * q * q[r], well conditioned where q[r] is largest
    diag = np.stack([1 + tr, 1 + 2 * m[..., 0, 0] - tr, 1 + 2 * m[..., 1, 1] - tr, 1 + 2 * m[..., 2, 2] - tr], -1)
    best = np.argmax(diag, axis=-1)
    q = np.take_along_axis(cand, best[..., None, None], axis=-2)[..., 0, :]
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return q * np.where(q[..., :1] < 0, -1.0, 1.0)


def axis_angle_to_matrix(a: np.ndarray) -> np.ndarray:
    """Axis-angle ``[..., 4]`` (angle, x, y, z) -> ``[..., 3, 3]``."""
    a = np.asarray(a, dtype=np.float64)
    axis = a[..., 1:] / np.maximum(np.linalg.norm(a[..., 1:], axis=-1, keepdims=True), 1e-12)
    half = 0.5 * a[..., :1]
    return quat_to_matrix(np.concatenate([np.cos(half), np.sin(half) * axis], -1))


def quat_to_axis_angle(q: np.ndarray) -> np.ndarray:
    """Quaternions ``[..., 4]`` -> axis-angle ``[..., 4]`` (angle, x, y, z); identity -> (0, 0, 1, 0)."""
    q = np.asarray(q, dtype=np.float64)
    s = np.linalg.norm(q[..., 1:], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., :1])
    axis = np.where(s > 1e-12, q[..., 1:] / np.maximum(s, 1e-12), np.array([0.0, 1.0, 0.0]))
    return np.concatenate([angle, axis], -1)


def matrix_to_rotvec(m: np.ndarray) -> np.ndarray:
    """Rotation matrices ``[..., 3, 3]`` -> rotation vectors ``[..., 3]`` (axis * angle, the angle at most pi)."""
    a = quat_to_axis_angle(matrix_to_quat(m))
    return a[..., :1] * a[..., 1:]


def closing_turns(rot: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Rotations ``rot`` ``[F, ..., 3, 3]`` each turned by its share ``weights`` ``[F]`` of the turn that takes the
    last onto the first (applied on the left: in the frame they are given in), so that with a weight of 1 on the last
    they end where they began."""
    rot = np.asarray(rot, dtype=np.float64)
    miss = matrix_to_rotvec(rot[0] @ np.swapaxes(rot[-1], -1, -2))
    share = np.asarray(weights, dtype=np.float64).reshape((-1,) + (1,) * (rot.ndim - 2))
    return rotvec_to_matrix(share * miss) @ rot


def quat_continuous(q: np.ndarray, previous: np.ndarray | None = None) -> np.ndarray:
    """Flip signs along axis 0 of ``[F, ..., 4]`` so consecutive quaternions lie in the same
    hemisphere; ``previous`` ``[..., 4]`` is the key before frame 0 (for a seam)."""
    q = np.array(q, dtype=np.float64)
    ref = np.concatenate([q[:1] if previous is None else np.asarray(previous, np.float64)[None], q[:-1]])
    dots = np.sum(q * ref, axis=-1)
    sign = np.where(dots < 0, -1.0, 1.0)
    if previous is None:
        sign[0] = 1.0
    return q * np.cumprod(sign, axis=0)[..., None]


def _wrap_near(x: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Add multiples of 2 pi to ``x`` so it is within pi of ``ref``."""
    return x - 2 * np.pi * np.round((x - ref) / (2 * np.pi))


def euler_continuous(e: np.ndarray, order: str, previous: np.ndarray | None = None) -> np.ndarray:
    """Euler angles ``[F, ..., 3]`` made continuous along frames, like Blender's
    ``to_euler(order, compat)``: each frame takes whichever of its two equivalent angle
    triples, shifted by multiples of 2 pi, lies closest to the frame before.
    ``previous`` ``[..., 3]`` is the key before frame 0 (for a seam)."""
    e = np.array(e, dtype=np.float64)
    i, j, k = (_AXIS[a] for a in order)
    alt = e.copy()  # the same rotation: (a + pi, pi - b, c + pi)
    alt[..., i] += np.pi
    alt[..., j] = np.pi - e[..., j]
    alt[..., k] += np.pi
    ref = e[0] if previous is None else np.asarray(previous, np.float64)
    out = np.empty_like(e)
    for f in range(len(e)):
        a, b = _wrap_near(e[f], ref), _wrap_near(alt[f], ref)
        pick = np.sum((b - ref) ** 2, -1, keepdims=True) < np.sum((a - ref) ** 2, -1, keepdims=True)
        ref = out[f] = np.where(pick, b, a)
    return out
