"""Pictures of motion: a stick-figure contact sheet with a top-down root trajectory.

Uses matplotlib's Agg canvas directly (no pyplot, no window, no global backend
switch), so it runs headless and inside other programs. Input is canonical
positions ``[frames, 21, 3]`` in metres, Y-up.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from ..io.files import write_atomic
from ..motion.conventions import GROUND_AXES, JOINT_INDEX, JOINTS, MODEL_FPS, PARENTS, UP_AXIS
from ..motion.features import heading, yaw_matrix

_VIEW_ANGLE = np.radians(30.0)  # camera turned this far from the body's side, so left and right separate
SIDE_COLOURS = {"l": "tab:blue", "r": "tab:red", "c": "0.2"}  # left, right, centre: every picture of a body


def joint_colour(joint: str) -> str:
    """The colour of a canonical joint's bone (to its parent): by its side of the body."""
    return SIDE_COLOURS[joint[0] if joint[:2] in ("l_", "r_") else "c"]


def frame_indices(frames: int, count: int) -> np.ndarray:
    """``count`` frame indices ``int [count]`` spread evenly over ``[0, frames)``, first and last included."""
    count = max(1, min(count, frames))
    return np.unique(np.round(np.linspace(0, frames - 1, count)).astype(int))


def body_view(pos: np.ndarray) -> np.ndarray:
    """Project poses ``[F, 21, 3]`` to 2-D ``[F, 21, 2]`` (metres): each pose seen from its own side,
    hips at horizontal 0, ground at vertical 0."""
    root = pos[:, JOINT_INDEX["hips"]].copy()
    root[:, UP_AXIS] = 0.0
    local = np.einsum("fij,fkj->fki", yaw_matrix(-heading(pos)), pos - root[:, None])  # body faces +Z
    across = local[..., 2] * np.cos(_VIEW_ANGLE) + local[..., 0] * np.sin(_VIEW_ANGLE)
    return np.stack([across, local[..., UP_AXIS]], axis=-1)


def _draw_strip(ax, pos: np.ndarray, idx: np.ndarray, fps: float, spacing: float = 1.1):
    flat = body_view(pos[idx])
    for k, (f, pose) in enumerate(zip(idx, flat)):
        x0 = k * spacing
        for j in range(1, len(JOINTS)):
            p = PARENTS[j]
            ax.plot([pose[p, 0] + x0, pose[j, 0] + x0], [pose[p, 1], pose[j, 1]],
                    color=joint_colour(JOINTS[j]), lw=1.6, solid_capstyle="round")
        ax.text(x0, -0.12, f"{f / fps:.1f} s", ha="center", va="top", fontsize=7)
    ax.axhline(0.0, color="0.6", lw=0.8)
    ax.set_aspect("equal")
    ax.set_xlim(-0.6 * spacing, (len(idx) - 0.4) * spacing)
    top = max(2.0, float(flat[..., 1].max()) + 0.1)
    ax.set_ylim(-0.3, top)
    ax.axis("off")


def _draw_trajectory(ax, pos: np.ndarray, idx: np.ndarray):
    g0, g1 = GROUND_AXES
    root = pos[:, JOINT_INDEX["hips"]]
    ax.plot(root[:, g0], root[:, g1], color="0.3", lw=1.0)
    ax.scatter(root[idx, g0], root[idx, g1], s=10, color="tab:orange", zorder=3, label="shown frames")
    ax.scatter(root[:1, g0], root[:1, g1], s=30, marker="o", color="tab:green", zorder=4, label="start")
    ax.scatter(root[-1:, g0], root[-1:, g1], s=30, marker="s", color="k", zorder=4, label="end")
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.set_title("root path, top view", fontsize=9)
    ax.legend(fontsize=7, loc="best")
    ax.grid(alpha=0.3)


def contact_sheet(path: str | Path, positions: np.ndarray, count: int = 10, fps: float = MODEL_FPS,
                  title: str | None = None) -> Path:
    """Write a PNG of ``count`` stick figures side by side plus the top-down root path.

    ``positions``: canonical ``[F, 21, 3]`` (metres, Y-up). Written atomically; returns the path.
    Left limbs blue, right limbs red.
    """
    pos = np.asarray(positions, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[1:] != (len(JOINTS), 3) or len(pos) == 0:
        raise ValueError(f"{path}: expected positions [frames, {len(JOINTS)}, 3], got {list(pos.shape)}")
    idx = frame_indices(len(pos), count)
    fig = Figure(figsize=(max(8.0, 1.1 * len(idx) + 3.5), 3.4), dpi=110)
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(1, 2, width_ratios=[max(len(idx), 1), 3.2], wspace=0.18)
    _draw_strip(fig.add_subplot(grid[0]), pos, idx, fps)
    _draw_trajectory(fig.add_subplot(grid[1]), pos, idx)
    fig.suptitle(title or f"{len(pos)} frames at {fps:g} fps ({len(pos) / fps:.1f} s)", fontsize=10)
    return write_atomic(path, lambda tmp: fig.savefig(tmp, format="png", bbox_inches="tight"))
