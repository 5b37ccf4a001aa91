"""How sure a comparison of two rows of prediction errors is: a paired bootstrap that resamples whole takes.

Windows cut from one take share its actor, its action and its pace, and err together; resampling windows one by one
would read 105 windows of 14 takes as 105 independent trials and give intervals far too narrow. Each draw here picks
as many takes as there are, with replacement, and weighs every window by how often its take was picked."""

from __future__ import annotations

import numpy as np

DRAWS = 2000
LEVEL = 0.95


def paired_gap(ours: np.ndarray, theirs: np.ndarray, takes: np.ndarray, draws: int = DRAWS, level: float = LEVEL,
               seed: int = 0) -> dict:
    """``ours`` against ``theirs``, errors ``[W, H]`` over the same W windows (H horizons), ``takes`` ``[W]`` the
    take each window comes from. Returns per horizon the mean gap ``gap_cm`` (ours - theirs: under 0, ours is
    nearer), the ratio of the means ``ratio``, and each one's central ``level`` interval over ``draws`` resamplings
    of the takes (``gap_interval_cm``, ``ratio_interval``: ``[low, high]`` per horizon)."""
    ours, theirs = np.asarray(ours, np.float64), np.asarray(theirs, np.float64)
    if ours.shape != theirs.shape or ours.ndim != 2 or len(takes) != len(ours):
        raise ValueError(f"paired errors [W, H] over the same windows and a take per window are needed; got "
                         f"{ours.shape}, {theirs.shape} and {len(takes)} takes")
    _, first, index = np.unique(np.asarray(takes), return_index=True, return_inverse=True)
    count = len(first)
    index = np.argsort(np.argsort(first))[index.reshape(-1)]  # takes numbered as they first come, whatever their labels
    per_take = lambda e: np.stack([np.bincount(index, e[:, h], count) for h in range(e.shape[1])], 1)  # [T, H]
    windows = np.bincount(index, minlength=count).astype(np.float64)  # each take's window count
    rng = np.random.default_rng(seed)
    picked = np.stack([np.bincount(rng.integers(0, count, count), minlength=count) for _ in range(draws)])
    picked = picked.astype(np.float64)  # [draws, T]: how often each take is drawn; its windows weigh as much
    ours_drawn, theirs_drawn = picked @ per_take(ours), picked @ per_take(theirs)  # sums over the drawn windows
    gap = (ours_drawn - theirs_drawn) / (picked @ windows)[:, None]
    tails = [50 * (1 - level), 50 * (1 + level)]
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = ours_drawn / theirs_drawn
    return {"gap_cm": [float(v) for v in (ours - theirs).mean(0)],
            "gap_interval_cm": np.percentile(gap, tails, axis=0).T.round(4).tolist(),
            "ratio": [float(v) for v in ours.mean(0) / theirs.mean(0)],
            "ratio_interval": np.percentile(ratio, tails, axis=0).T.round(4).tolist()}
