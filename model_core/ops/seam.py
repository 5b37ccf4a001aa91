"""Seams: where new frames meet the frames they continue or replace, faded so nothing jumps."""

from __future__ import annotations

import numpy as np

SEAM_FRAMES = 10  # model frames over which a jump at the start of an extension is faded out


def blend_seam(ctx: np.ndarray, new: np.ndarray, frames: int = SEAM_FRAMES) -> np.ndarray:
    """Fade out the jump between a context ``[C, 21, 3]`` and its continuation ``[N, 21, 3]``
    (same rate): the first new frame is moved to where the context's last velocity leads,
    and that correction decays smoothly to zero over ``frames`` frames."""
    if len(ctx) < 2 or len(new) == 0:
        return new
    offset = (2 * ctx[-1] - ctx[-2]) - new[0]  # (21, 3)
    k = np.arange(len(new), dtype=np.float64)
    weight = np.where(k < frames, 0.5 * (1 + np.cos(np.pi * k / frames)), 0.0)  # 1 -> 0, flat at both ends
    return new + weight[:, None, None] * offset
