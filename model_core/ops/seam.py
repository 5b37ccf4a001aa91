"""Seams: where new frames meet the frames they continue or replace, faded so nothing jumps.

Every seam length lives here. Three kinds of seam:

- a predicted window after its context (:meth:`Engine.predict`, ``training.rolled_context``):
  the decoder's offset on the last context frame is carried into the prediction, decaying as
  ``exp(-k / PREDICT_SEAM_FRAMES)`` (:func:`seam_fade`);
- new frames after a clip (:func:`extend.extend_positions`, :func:`follow.smooth_seam`): the jump
  from where the clip's last velocity leads fades out over :data:`SEAM_FRAMES` model frames on a
  half cosine (:func:`blend_seam`);
- a replaced range inside a clip (Denoise on part of an action): the new frames are blended from
  the old ones over :data:`EDGE_FADE_S` seconds at each edge (:func:`fade_edges`).
"""

from __future__ import annotations

import numpy as np

PREDICT_SEAM_FRAMES = 10.0  # decay (frames) of the engine's seam correction in predict(); chosen on validation
SEAM_FRAMES = 10  # model frames over which a jump at the start of an extension is faded out
EDGE_FADE_S = 0.2  # a partial Denoise range fades in and out over this long where it meets untouched frames


def seam_fade(n: int, frames: float = PREDICT_SEAM_FRAMES, xp=np, dtype=np.float32):
    """Weights ``[n]`` of the seam correction on predicted frames 1..n: ``exp(-k / frames)``.
    ``xp``: ``numpy`` or ``torch`` (with a torch ``dtype``), so the engine and training share it."""
    return xp.exp(-xp.arange(1, n + 1, dtype=dtype) / frames)


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


def fade_edges(before: np.ndarray, after: np.ndarray, fps: float, fade_in: bool, fade_out: bool,
               seconds: float = EDGE_FADE_S) -> np.ndarray:
    """``after`` ``[F, 21, 3]`` blended from ``before`` over ``seconds`` at the start (``fade_in``) and
    end (``fade_out``) of a range at ``fps``, so it meets the frames around it without a pop."""
    n = len(after)
    k = min(int(round(seconds * fps)), n // 4)
    weight = np.ones(n)
    ramp = np.arange(1, k + 1) / (k + 1)
    if k and fade_in:
        weight[:k] = np.minimum(weight[:k], ramp)
    if k and fade_out:
        weight[n - k:] = np.minimum(weight[n - k:], ramp[::-1])
    return before + weight[:, None, None] * (after - before)
