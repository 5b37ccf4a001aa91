"""Corruptions of motion as capture and hand-keying make them, for training the denoiser and for
scoring it: joint rotations with jitter (the BVH's or armature's own channels)."""

from __future__ import annotations

import numpy as np

from .conventions import PARENTS
from .rotations import euler_to_matrix


def add_rotation_jitter(pos: np.ndarray, deg: float, rng: np.random.Generator) -> np.ndarray:
    """``pos`` ``[F, 21, 3]`` as if every joint's three rotation channels had Gaussian jitter of ``deg``
    degrees, as a BVH's or an armature's do: from the hips down, each joint's subtree is turned about
    the joint by its own small random rotation, frame by frame."""
    out = np.array(pos, np.float64)
    below = [[k for k in range(len(PARENTS)) if _descends(k, j)] for j in range(len(PARENTS))]
    for j, sub in enumerate(below):
        if sub:
            turn = euler_to_matrix(rng.normal(0.0, np.radians(deg), (len(out), 3)), "ZXY")  # a BVH's usual order
            out[:, sub] = out[:, j:j + 1] + np.einsum("fij,fkj->fki", turn, out[:, sub] - out[:, j:j + 1])
    return out.astype(np.float32)


def _descends(k: int, j: int) -> bool:
    """Whether joint ``k`` lies below joint ``j`` in the canonical tree."""
    while PARENTS[k] >= 0:
        k = int(PARENTS[k])
        if k == j:
            return True
    return False
