"""Small geometry every layer shares, written once: unit vectors, rotation vectors, the
shortest-arc rotation, the nearest rotation to a matrix, turns about +Y on the ground, and linear
interpolation of frames.

NumPy; arrays broadcast over leading dimensions (``[..., 3]`` vectors, ``[..., 3, 3]``
matrices). :func:`rotate_ground` also runs on torch tensors (``xp=torch``), so the NumPy and
torch code paths share one formula.
"""

from __future__ import annotations

import numpy as np


def unit(v: np.ndarray) -> np.ndarray:
    """``v`` ``[..., 3]`` scaled to length 1 (zero vectors stay zero)."""
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def rotvec_to_matrix(w: np.ndarray) -> np.ndarray:
    """Rotation matrices ``[..., 3, 3]`` from rotation vectors ``[..., 3]`` (axis * angle, Rodrigues)."""
    theta = np.linalg.norm(w, axis=-1)[..., None, None]
    k = np.zeros(w.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -w[..., 2], w[..., 1], -w[..., 0]
    k = k - np.swapaxes(k, -1, -2)
    safe = np.maximum(theta, 1e-12)
    return np.eye(3) + np.sin(theta) / safe * k + (1 - np.cos(theta)) / safe ** 2 * (k @ k)


def closing_weights(n: int, blend: int) -> np.ndarray:
    """Weights ``[n]`` that close a cycle of ``n`` frames (its first frame to its seam) over its end: 0 up to its last
    ``blend`` frames (at least a tenth of the cycle), then rising by smoothstep to 1 on the seam."""
    span = max(int(blend), max(1, (n - 1) // 10))
    s = np.clip((np.arange(n) - (n - 1 - span)) / span, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def shortest_arc(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotations ``[..., 3, 3]`` taking directions ``a`` onto ``b`` ``[..., 3]`` (any length).

    Opposite directions turn half a circle about an axis perpendicular to ``a`` (``a`` x X, or
    ``a`` x Y when ``a`` lies near X)."""
    a, b = unit(a), unit(b)
    v = np.cross(a, b)
    c = np.sum(a * b, -1)
    perp = unit(np.cross(a, np.where(np.abs(a[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])))
    flip = c < -1 + 1e-9
    axis_angle = np.where(flip[..., None], perp * np.pi, unit(v) * np.arctan2(np.linalg.norm(v, axis=-1), c)[..., None])
    return rotvec_to_matrix(axis_angle)


def nearest_rotation(m: np.ndarray) -> np.ndarray:
    """The rotations ``[..., 3, 3]`` nearest to matrices ``m`` ``[..., 3, 3]`` (the polar factor, by SVD): a matrix
    that is a rotation up to rounding comes back one to the last bit, where a chain of them would grow the error
    bone by bone."""
    u, _, vt = np.linalg.svd(np.asarray(m, np.float64))
    d = np.sign(np.linalg.det(u @ vt))
    u = u * np.concatenate([np.ones(d.shape + (2,)), d[..., None]], -1)[..., None, :]
    return u @ vt


def rotate_ground(yaw, xz, xp=np):
    """Ground vectors ``[..., 2]`` (x, z) turned by ``yaw`` ``[...]`` radians about +Y, as
    :func:`features.yaw_matrix` turns (x, 0, z). ``xp``: ``numpy`` or ``torch`` (for tensors)."""
    c, s = xp.cos(yaw), xp.sin(yaw)
    return xp.stack([c * xz[..., 0] + s * xz[..., 1], -s * xz[..., 0] + c * xz[..., 1]], -1)


def cubic_frames(x: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``x`` ``[N, ...]`` (N >= 2) at fractional frame indices ``t`` ``[M]`` by a Catmull-Rom cubic, which
    passes every frame and follows the curve between them (a straight line cuts a fast arc's corner),
    clamped to the first and last frame -> ``float64 [M, ...]``."""
    x = np.asarray(x, np.float64)
    n = len(x)
    t = np.clip(np.asarray(t, np.float64), 0, n - 1)
    i = np.clip(np.floor(t + 1e-9).astype(int), 0, max(n - 2, 0))
    u = np.maximum(t - i, 0.0).reshape((-1,) + (1,) * (x.ndim - 1))
    p0, p1 = x[np.maximum(i - 1, 0)], x[i]
    p2, p3 = x[np.minimum(i + 1, n - 1)], x[np.minimum(i + 2, n - 1)]
    return 0.5 * (2 * p1 + (p2 - p0) * u + (2 * p0 - 5 * p1 + 4 * p2 - p3) * u ** 2
                  + (3 * p1 - p0 - 3 * p2 + p3) * u ** 3)


def interpolate_frames(x: np.ndarray, t: np.ndarray, snap: float = 1e-9) -> np.ndarray:
    """``x`` ``[N, ...]`` linearly interpolated at fractional frame indices ``t`` ``[M]``, clamped to
    the first and last frame -> ``float64 [M, ...]``. A ``t`` within ``snap`` below a whole frame
    counts as that frame."""
    n = len(x)
    t = np.clip(np.asarray(t, dtype=np.float64), 0, n - 1)
    i0 = np.minimum(np.floor(t + snap).astype(int), n - 1)
    i1 = np.minimum(i0 + 1, n - 1)
    w = np.maximum(t - i0, 0.0).reshape((-1,) + (1,) * (np.ndim(x) - 1))
    x = np.asarray(x, dtype=np.float64)
    return x[i0] * (1 - w) + x[i1] * w
