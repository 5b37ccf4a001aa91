"""Ground paths for curve-driven synthesis: arc-length parameterisation, the control
signal the model is steered by, the path-error metric, and the fixed evaluation paths.

NumPy only (no torch), so the Blender side can check a curve before any model runs.
Paths live on the ground plane of model space: ``(x, z)`` in metres, Y-up
(:data:`conventions.GROUND_AXES`). Headings are yaw angles about +Y that take +Z to
``(sin yaw, cos yaw)`` as in :func:`features.yaw_matrix`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..motion.conventions import GROUND_AXES

TANGENT_STEP = 0.1  # metres either side over which the heading of a path is measured


class PathError(ValueError):
    """A path that cannot be followed (too few points, zero length, not finite)."""


class Path:
    """A polyline on the ground parameterised by arc length ``s`` in metres.

    ``points`` ``[P, 2]`` ground ``(x, z)`` (or ``[P, 3]`` Y-up, height dropped); ``cyclic``
    joins the last point to the first and wraps ``s``."""

    def __init__(self, points: np.ndarray, cyclic: bool = False):
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] not in (2, 3):
            raise PathError(f"a path needs points [P, 2] or [P, 3], got {pts.shape}")
        pts = pts[:, list(GROUND_AXES)] if pts.shape[1] == 3 else pts
        if not np.isfinite(pts).all():
            raise PathError("the path has non-finite points")
        if cyclic:
            pts = np.concatenate([pts, pts[:1]])
        keep = np.r_[True, np.linalg.norm(np.diff(pts, axis=0), axis=-1) > 1e-9]
        self.points, self.cyclic = pts[keep], cyclic
        self.s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(self.points, axis=0), axis=-1))]
        if len(self.points) < 2 or self.length < 1e-6:
            raise PathError("the path has zero length on the ground")

    @property
    def length(self) -> float:
        return float(self.s[-1])

    def _wrap(self, s: np.ndarray) -> np.ndarray:
        s = np.asarray(s, dtype=np.float64)
        return np.mod(s, self.length) if self.cyclic else np.clip(s, 0.0, self.length)

    def at(self, s: np.ndarray) -> np.ndarray:
        """Points ``[..., 2]`` at arc lengths ``s`` ``[...]`` (clamped to the ends, or wrapped)."""
        s = self._wrap(s)
        return np.stack([np.interp(s, self.s, self.points[:, k]) for k in range(2)], -1)

    def tangent(self, s: np.ndarray) -> np.ndarray:
        """Unit tangents ``[..., 2]`` at ``s``, measured over :data:`TANGENT_STEP` either side."""
        h = min(TANGENT_STEP, 0.25 * self.length)
        s = np.asarray(s, dtype=np.float64)
        lo, hi = (s - h, s + h) if self.cyclic else (np.clip(s - h, 0, self.length - 2 * h),
                                                      np.clip(s + h, 2 * h, self.length))
        d = self.at(hi) - self.at(lo)
        return d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12)

    def heading(self, s: np.ndarray) -> np.ndarray:
        """Yaw ``[...]`` (radians) of the tangent at ``s``."""
        t = self.tangent(s)
        return np.arctan2(t[..., 0], t[..., 1])

    def project(self, p: np.ndarray, lo: float = -np.inf, hi: float = np.inf, tie: float = 1e-6) -> float:
        """Arc length of the point of the path nearest to ``p`` ``[2]`` among arc lengths in
        [lo, hi] (unwrapped: a cyclic path may be searched past its end); of points within
        ``tie`` of the nearest distance (a crossing), the earliest."""
        lo, hi = max(lo, -self.length if self.cyclic else 0.0), min(hi, 2 * self.length if self.cyclic
                                                                    else self.length)
        laps = np.arange(np.floor(lo / self.length), np.floor(hi / self.length) + 1) if self.cyclic else [0.0]
        a, b = self.points[:-1], self.points[1:]
        ab = b - a
        t = np.clip(np.sum((p - a) * ab, -1) / np.maximum(np.sum(ab * ab, -1), 1e-18), 0.0, 1.0)
        cand = np.concatenate([np.clip(self.s[:-1] + t * np.diff(self.s) + lap * self.length, lo, hi)
                               for lap in laps])
        d = np.linalg.norm(self.at(cand) - p, axis=-1)
        return float(cand[d <= d.min() + tie].min())


@dataclass
class Steering:
    """How the control signal returns a character that is off the path onto it."""

    return_frames: float = 10.0  # time constant (frames) of the return to the path and its heading


def control_signal(path: Path, position: np.ndarray, yaw: float, s0: float, speed: float, frames: int,
                   fps: float, steering: Steering | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Root channels ``[frames, 3]`` the next ``frames`` frames should have to walk the path.

    The character is at ground ``position`` ``[2]`` facing ``yaw``, at arc length ``s0`` (its
    projection). Frame k aims at ``path(s0 + k * speed / fps)`` plus the current offset, which
    decays over ``return_frames``; its heading turns from ``yaw`` to the tangent's the same way.
    Channels: velocity ``(x, z)`` in the root's frame (metres per frame) and yaw rate (radians
    per frame), as :data:`conventions.LAYOUT` lays them out. Also returns the aimed ground
    positions ``[frames + 1, 2]`` (k = 0 .. frames)."""
    tau = (steering or Steering()).return_frames
    k = np.arange(frames + 1, dtype=np.float64)
    s = s0 + k * speed / fps
    fade = np.exp(-k / max(tau, 1e-6))[:, None]
    aim = path.at(s) + fade * (np.asarray(position, np.float64) - path.at(s0))
    ahead = path.heading(s)
    turn = np.angle(np.exp(1j * (yaw - ahead[0])))  # wrapped to (-pi, pi]
    psi = np.unwrap(ahead) + turn * fade[:, 0]
    step = np.diff(aim, axis=0)  # (frames, 2) world (x, z)
    c, sn = np.cos(psi[:-1]), np.sin(psi[:-1])
    local = np.stack([c * step[:, 0] - sn * step[:, 1], sn * step[:, 0] + c * step[:, 1]], -1)
    return np.concatenate([local, np.diff(psi)[:, None]], -1), aim


def _left(d: np.ndarray) -> np.ndarray:
    return np.array([-d[1], d[0]])


def _angle(d: np.ndarray) -> float:
    return float(np.arctan2(d[1], d[0]))


def _arc(p: np.ndarray, centre: np.ndarray, turn: float, sign: float, step: float) -> np.ndarray:
    """Points ``[K, 2]`` from ``p`` (excluded) along the circle about ``centre``, ``turn`` radians, counter-
    clockwise in ``(x, z)`` for ``sign`` 1, clockwise for -1."""
    radius = float(np.linalg.norm(p - centre))
    count = max(int(np.ceil(radius * turn / step)), 1)
    phi = sign * turn * np.arange(1, count + 1) / count
    r = p - centre
    c, s = np.cos(phi)[:, None], np.sin(phi)[:, None]
    return centre + c * r + s * _left(r)


def turning_path(start: np.ndarray, leave: np.ndarray, end: np.ndarray, arrive: np.ndarray, radius: float,
                 step: float = 0.05) -> np.ndarray:
    """Points ``[K, 2]`` (every ``step`` metres or closer) of the shortest way from ``start`` ``[2]``, moving
    along ``leave`` ``[2]``, to ``end`` ``[2]``, moving along ``arrive`` ``[2]``, that turns no tighter than
    ``radius``: an arc, a straight line and an arc (Dubins' curve of kind CSC). The first point is
    ``start``, the last ``end``."""
    start, end = np.asarray(start, np.float64), np.asarray(end, np.float64)
    d0, d1 = (np.asarray(d, np.float64) / max(float(np.linalg.norm(d)), 1e-12) for d in (leave, arrive))
    best = None
    for s0 in (1.0, -1.0):  # 1: the first arc turns counter-clockwise (its centre on the left), -1: clockwise
        for s1 in (1.0, -1.0):
            c0, c1 = start + s0 * radius * _left(d0), end + s1 * radius * _left(d1)
            v = c1 - c0
            dist = float(np.linalg.norm(v))
            if s0 == s1:
                if dist < 1e-9:
                    continue
                straight, u = dist, v / dist
            else:
                if dist < 2 * radius:
                    continue
                straight = float(np.sqrt(dist ** 2 - 4 * radius ** 2))
                a = _angle(v) + s0 * np.arctan2(2 * radius, straight)
                u = np.array([np.cos(a), np.sin(a)])
            t0, t1 = c0 - s0 * radius * _left(u), c1 - s1 * radius * _left(u)
            turn0 = (s0 * (_angle(u) - _angle(d0))) % (2 * np.pi)
            turn1 = (s1 * (_angle(d1) - _angle(u))) % (2 * np.pi)
            total = radius * (turn0 + turn1) + straight
            if best is None or total < best[0]:
                best = (total, s0, s1, c0, c1, t0, t1, turn0, turn1, straight)
    if best is None:  # start and end on one circle, facing round it: go straight, the path turns the rest
        return np.stack([start, end])
    _, s0, s1, c0, c1, t0, t1, turn0, turn1, straight = best
    first = _arc(start, c0, turn0, s0, step) if turn0 > 1e-9 else np.empty((0, 2))
    count = max(int(np.ceil(straight / step)), 1)
    line = t0 + (t1 - t0) * (np.arange(1, count + 1) / count)[:, None]
    second = _arc(t1, c1, turn1, s1, step) if turn1 > 1e-9 else np.empty((0, 2))
    out = np.concatenate([start[None], first, line, second])
    out[-1] = end
    return out


def path_errors_cm(root: np.ndarray, path: Path, window: float = 1.0) -> tuple[float, float]:
    """(mean, max) horizontal distance in cm between a root trajectory ``[F, 2]`` or ``[F, 3]``
    (Y-up) and the path, each frame matched to the path by arc length: its nearest point
    among arc lengths within ``window`` metres ahead of the previous frame's match
    (so a figure-eight's crossing cannot be matched to the wrong branch)."""
    pts = np.asarray(root, np.float64)
    pts = pts[:, list(GROUND_AXES)] if pts.shape[1] == 3 else pts
    s, dists = path.project(pts[0], 0.0, window), []
    for p in pts:
        s = path.project(p, s - 0.05, s + window)
        dists.append(np.linalg.norm(path.at(s) - p))
    d = 100.0 * np.array(dists)
    return float(d.mean()), float(d.max())


def evaluation_paths(samples_per_metre: int = 20) -> dict[str, tuple[np.ndarray, bool]]:
    """The fixed evaluation set: {name: (points ``[P, 2]`` ground (x, z) metres, cyclic)}, each
    starting at the origin heading +Z: straight line 10 m, circle of radius 2 m, S-curve (1 m to
    either side over 8 m), figure-eight (two loops of radius 2 m)."""
    def n(length):
        return int(length * samples_per_metre) + 1

    z = np.linspace(0, 10, n(10))
    line = np.stack([0 * z, z], -1)
    a = np.linspace(0, 2 * np.pi, n(4 * np.pi), endpoint=False)
    circle = np.stack([2 * (1 - np.cos(a)), 2 * np.sin(a)], -1)  # turning left, back to the start
    z = np.linspace(0, 8, n(10))
    s_curve = np.stack([1.0 * np.sin(2 * np.pi * z / 8), z], -1)
    eight = np.concatenate([circle, circle * [-1, 1]])  # the circle, then its mirror image: radius 2 m loops
    return {"line": (line, False), "circle": (circle, True), "s_curve": (s_curve, False),
            "figure_eight": (eight, True)}
