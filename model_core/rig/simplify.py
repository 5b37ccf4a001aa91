"""Sparser keys for a baked pose (no bpy): which frames to keep so that the joints stay within a
tolerance of the bake, in the spirit of Blender's Clean Curves but measured on the joints.

Every channel is keyed on the same frames. The caller measures the joints' error of a choice of
frames with the curves as they will play (Blender's own Bezier curves through the kept keys), and
:func:`refine` adds, in each span between kept frames where a joint strays too far, the frame that
strays furthest, until none does.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def refine(frames: int, error_of: Callable[[np.ndarray], np.ndarray], tolerance: float, start_every: int = 6,
           rounds: int = 50) -> tuple[np.ndarray, np.ndarray]:
    """(sorted indices ``[K]`` of the frames to key, the joints' error ``[frames]`` with them).

    ``error_of(kept [K]) -> [frames]``: the largest joint error at each frame when only ``kept`` are
    keyed. Starts from every ``start_every``-th frame (first and last always) and gives up after
    ``rounds`` (then every frame still over the tolerance is keyed)."""
    keep = set(range(0, frames, max(1, start_every))) | {0, frames - 1}
    for _ in range(rounds):
        kept = np.array(sorted(keep))
        err = error_of(kept)
        if not (err > tolerance).any():
            return kept, err
        span = np.searchsorted(kept, np.arange(frames), side="right")  # frames between the same two keys
        for s in np.unique(span[err > tolerance]):
            inside = np.flatnonzero(span == s)
            keep.add(int(inside[np.argmax(err[inside])]))
    keep.update(np.flatnonzero(error_of(np.array(sorted(keep))) > tolerance).tolist())
    kept = np.array(sorted(keep))
    return kept, error_of(kept)
