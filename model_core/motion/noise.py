"""Corruptions of motion as capture and hand-keying make them, for training the denoiser and for
scoring it: joint rotations with jitter (the BVH's or armature's own channels); and how much white
jitter a motion carries (:func:`white_noise_variance`), which Denoise and Extend's seam both measure."""

from __future__ import annotations

import numpy as np

from .conventions import PARENTS
from .rotations import euler_to_matrix

D4_NOISE_GAIN2 = 70.0  # variance of the 4th difference of unit white noise


def white_noise_variance(x: np.ndarray) -> np.ndarray:
    """Robust variance of white noise per channel ``[...]`` of ``[F, ...]`` (F >= 5) from the median absolute
    4th difference in time, which white noise dominates and smooth motion hardly reaches."""
    d4 = np.diff(np.asarray(x, np.float64), n=4, axis=0)
    mad = np.median(np.abs(d4 - np.median(d4, 0)), axis=0)
    return (1.4826 * mad) ** 2 / D4_NOISE_GAIN2


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
