"""Root motion: a game rig's root bone (the bone above the hips that carries the travel, as Unreal's ``root`` does)
carried on over new frames with the body.

A take made for a game engine moves its root bone over the ground under the body and turns it with the body, and
the engine moves the character by the root's motion. New frames that moved only the hips would leave the root where
the clip ends and the body walking away from it. Here the root is moved rigidly with the body's ground track and
heading, both smoothed (so that the pelvis' sway and the turn of each step stay in the hips, off the root), keeping
where it stood against them at the clip's last frame: no jump at the seam, and the root under the body as it was.
The root keeps its height (the engine's root moves over the ground).
"""

from __future__ import annotations

import numpy as np

from ..motion.features import gaussian_taps

SMOOTH_S = 0.5  # seconds: the body's ground track and heading smoothed over this (a stride's sway and turns)


def trend_smooth(x: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian filter along axis 0 that follows a steady trend to the ends: padded by reflecting the motion
    through its first and last frames (a walk at the end of the frames goes on, where padding with the last frame
    would hold it back by up to a second's travel)."""
    x = np.asarray(x, np.float64)
    taps = gaussian_taps(sigma)
    radius = min(len(taps) // 2, len(x) - 1)
    taps = taps[len(taps) // 2 - radius:len(taps) // 2 + radius + 1]
    taps = taps / taps.sum()
    if radius < 1:
        return x.copy()
    padded = np.concatenate([2 * x[:1] - x[radius:0:-1], x, 2 * x[-1:] - x[-2:-radius - 2:-1]])
    return sum(w * padded[k:k + len(x)] for k, w in enumerate(taps))


def _yaw(angle: np.ndarray, up: int) -> np.ndarray:
    """Rotations ``[F, 3, 3]`` by ``angle`` ``[F]`` (radians, counter-clockwise seen from above) about axis ``up``
    (a right-handed frame)."""
    a, b = [(1, 2), (2, 0), (0, 1)][up]
    out = np.zeros((len(angle), 3, 3))
    out[:, up, up] = 1.0
    c, s = np.cos(angle), np.sin(angle)
    out[:, a, a], out[:, a, b], out[:, b, a], out[:, b, b] = c, -s, s, c
    return out


def carried_root(root: np.ndarray, hips: np.ndarray, forward: np.ndarray, seam: int, fps: float, up: int = 2,
                 smooth_s: float = SMOOTH_S) -> np.ndarray:
    """World matrices ``[F - seam, 4, 4]`` of the root on frames ``seam`` on: ``root`` ``[4, 4]`` (its world matrix at
    frame ``seam - 1``, the clip's last) moved rigidly with the body, whose hips are at ``hips`` ``[F, 3]`` and which
    faces ``forward`` ``[F, 3]`` (any length) on every frame, the clip's and the new; turned about world axis ``up``
    only, its height kept."""
    hips, forward = np.asarray(hips, np.float64), np.asarray(forward, np.float64)
    ground = [k for k in range(3) if k != up]
    sigma = smooth_s * fps
    track = trend_smooth(hips, sigma)
    track[:, up] = 0.0
    angle = np.unwrap(np.arctan2(forward[:, ground[1]], forward[:, ground[0]]))
    if up == 1:  # (z, x) is the counter-clockwise pair about +Y
        angle = -angle
    angle = trend_smooth(angle, sigma)
    turn = _yaw(angle[seam:] - angle[seam - 1], up)  # [N, 3, 3]
    out = np.repeat(np.asarray(root, np.float64)[None], len(turn), 0)
    out[:, :3, :3] = turn @ out[:, :3, :3]
    offset = root[:3, 3] - track[seam - 1]
    out[:, :3, 3] = track[seam:] + np.einsum("fij,j->fi", turn, offset)
    return out
