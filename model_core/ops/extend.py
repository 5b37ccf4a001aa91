"""Extend Clip's maths: continue a user's clip with the model, on the user's frames, scale and ground."""

from __future__ import annotations

import math

import numpy as np

from ..motion.conventions import MODEL_FPS
from .familiarity import momentum_shares
from .normalise import fit_normalisation, model_frames_available, sample_at
from .seam import blend_seam


def extend_positions(engine, pos: np.ndarray, fps: float, frames: int) -> np.ndarray:
    """Continue a clip ``[F, 21, 3]`` (Y-up, scene units, ``fps``) by ``frames`` scene frames.

    The context is resampled to the model's rate aligned on its LAST frame, so the new
    frames follow it at exactly 1 / fps. Returns ``[frames, 21, 3]`` in the same space.
    """
    duration = (len(pos) - 1) / fps
    n_ctx = model_frames_available(len(pos), fps)
    ctx_times = duration - np.arange(n_ctx)[::-1] / MODEL_FPS
    ctx = sample_at(pos, fps, ctx_times)
    norm = fit_normalisation(ctx)
    n_model = int(math.ceil(frames * MODEL_FPS / fps)) + 1
    new = np.asarray(engine.extend(norm.to_model(ctx), n_model), dtype=np.float64)
    momentum = momentum_shares(engine, norm.to_model(ctx)[None])[0]
    # model frame 0 is the last context frame
    seq = np.concatenate([ctx[-1:], blend_seam(ctx, norm.to_user(new), momentum=momentum)])
    return sample_at(seq, MODEL_FPS, np.arange(1, frames + 1) / fps)
