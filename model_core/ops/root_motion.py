"""Root motion: a game rig's root bone (the bone above the hips that carries the travel, as Unreal's ``root`` does)
carried on over new frames with the body.

A take made for a game engine moves its root bone over the ground under the body and turns it with the body, and
the engine moves the character by the root's motion. New frames that moved only the hips would leave the root where
the clip ends and the body walking away from it. Here the root is moved rigidly with the body's ground track and
heading, both smoothed (so that the pelvis' sway and the turn of each step stay in the hips, off the root), keeping
where it stood against them at the clip's last frame: no jump at the seam, and the root under the body as it was.
The root keeps its height (the engine's root moves over the ground), or, where the body is carried over a ground
that is not flat, goes up and down by as much as the body is carried.
"""

from __future__ import annotations

import numpy as np

from ..motion.features import gaussian_smooth
from ..motion.geometry import rotvec_to_matrix

SMOOTH_S = 0.5  # seconds: the body's ground track and heading smoothed over this (a stride's sway and turns)


def carried_root(root: np.ndarray, hips: np.ndarray, forward: np.ndarray, seam: int, fps: float, up: int = 2,
                 smooth_s: float = SMOOTH_S, lift: np.ndarray | None = None) -> np.ndarray:
    """World matrices ``[F - seam, 4, 4]`` of the root on frames ``seam`` on: ``root`` ``[4, 4]`` (its world matrix at
    frame ``seam - 1``, the clip's last) moved rigidly with the body, whose hips are at ``hips`` ``[F, 3]`` and which
    faces ``forward`` ``[F, 3]`` (any length) on every frame, the clip's and the new; turned about world axis ``up``
    only, its height kept, or raised by as much as ``lift`` ``[F]`` (how far the body is carried up over a ground,
    frame by frame) rises from frame ``seam - 1``."""
    hips, forward = np.asarray(hips, np.float64), np.asarray(forward, np.float64)
    a, b = (up + 1) % 3, (up + 2) % 3  # a turn about +up takes axis a towards axis b
    sigma = smooth_s * fps
    track = gaussian_smooth(hips, sigma, ends="trend")
    track[:, up] = 0.0
    angle = gaussian_smooth(np.unwrap(np.arctan2(forward[:, b], forward[:, a])), sigma, ends="trend")
    turn = rotvec_to_matrix(np.outer(angle[seam:] - angle[seam - 1], np.eye(3)[up]))  # [N, 3, 3]
    out = np.repeat(np.asarray(root, np.float64)[None], len(turn), 0)
    out[:, :3, :3] = turn @ out[:, :3, :3]
    offset = root[:3, 3] - track[seam - 1]
    out[:, :3, 3] = track[seam:] + np.einsum("fij,j->fi", turn, offset)
    if lift is not None:
        out[:, up, 3] += np.asarray(lift, np.float64)[seam:] - float(lift[seam - 1])
    return out
