"""Run the model on a user's clip: frame rate, scale and ground in, the same out.

A user's clip is canonical joint positions ``[F, 21, 3]`` in Y-up scene units at the
scene's frame rate (any size of character, any unit). The model wants the standard
skeleton (:data:`conventions.STANDARD_LEG_LENGTH`), ground at y = 0 and
:data:`conventions.MODEL_FPS`. These helpers convert, call the engine, and convert back,
so the result lands on the user's frames, scale and ground.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .conventions import JOINT_INDEX, MODEL_FPS, STANDARD_LEG_LENGTH, UP_AXIS
from .rigs import leg_length
from .steps import drive

FEET = [JOINT_INDEX[j] for j in ("l_foot", "l_toe", "r_foot", "r_toe")]
SEAM_FRAMES = 10  # model frames over which a jump at the start of an extension is faded out


@dataclass
class Normalisation:
    """``model = (user - ground * up) * scale``: scale (model metres per scene unit), ground (scene units)."""

    scale: float
    ground: float

    def to_model(self, pos: np.ndarray) -> np.ndarray:
        out = np.array(pos, dtype=np.float64)
        out[..., UP_AXIS] -= self.ground
        return (out * self.scale).astype(np.float32)

    def to_user(self, pos: np.ndarray) -> np.ndarray:
        out = np.asarray(pos, dtype=np.float64) / self.scale
        out[..., UP_AXIS] += self.ground
        return out


def fit_normalisation(pos: np.ndarray) -> Normalisation:
    """Scale and ground of a clip ``[F, 21, 3]`` (Y-up): legs to the standard length, feet to y = 0."""
    legs = leg_length(pos)
    if not np.isfinite(legs) or legs <= 1e-9:
        raise ValueError("the mapped legs have zero length; check the hip, knee and foot bones of the bone map")
    ground = float(np.percentile(np.asarray(pos)[:, FEET, UP_AXIS].min(axis=1), 5))
    return Normalisation(STANDARD_LEG_LENGTH / legs, ground)


def sample_at(x: np.ndarray, fps: float, times: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``x`` ``[N, ...]`` (frame k at time k / fps) at ``times`` ``[M]``
    seconds, clamped at both ends -> ``[M, ...]``."""
    t = np.clip(np.asarray(times, dtype=np.float64) * fps, 0, len(x) - 1)
    i0 = np.minimum(np.floor(t + 1e-9).astype(int), len(x) - 1)
    i1 = np.minimum(i0 + 1, len(x) - 1)
    w = (t - i0).reshape((-1,) + (1,) * (np.ndim(x) - 1))
    return np.asarray(x, dtype=np.float64)[i0] * (1 - w) + np.asarray(x, dtype=np.float64)[i1] * w


def model_frames_available(frames: int, fps: float) -> int:
    """How many model-rate frames a clip of ``frames`` scene frames at ``fps`` spans."""
    return int(math.floor((frames - 1) * MODEL_FPS / fps + 1e-6)) + 1


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
    seq = np.concatenate([ctx[-1:], blend_seam(ctx, norm.to_user(new))])  # model frame 0 = the last context frame
    return sample_at(seq, MODEL_FPS, np.arange(1, frames + 1) / fps)


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


def denoise_positions(engine, pos: np.ndarray, fps: float, strength: float = 1.0) -> np.ndarray:
    """Denoised clip ``[F, 21, 3]`` (same space and frames as ``pos``), blended with the input by
    ``strength`` in [0, 1] (0: unchanged, 1: the model's output)."""
    return drive(denoise_positions_steps(engine, pos, fps, strength))


def denoise_positions_steps(engine, pos: np.ndarray, fps: float, strength: float = 1.0):
    """:func:`denoise_positions` as a step generator (:mod:`steps`): yields the fraction done."""
    duration = (len(pos) - 1) / fps
    n_model = model_frames_available(len(pos), fps)
    model_times = np.arange(n_model) / MODEL_FPS
    if model_times[-1] < duration - 1e-9:  # cover the last scene frame too
        model_times = np.append(model_times, duration)
    clip = sample_at(pos, fps, model_times)
    norm = fit_normalisation(clip)
    clean = norm.to_user((yield from engine.denoise_positions_steps(norm.to_model(clip))))
    delta = clean - clip  # resample the correction, not the motion: untouched input stays exact
    delta_scene = _sample_times(delta, model_times, np.arange(len(pos)) / fps)
    return np.asarray(pos, dtype=np.float64) + strength * delta_scene


def _sample_times(x: np.ndarray, src_times: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``x`` ``[N, ...]`` sampled at ``src_times`` ``[N]`` at ``times`` ``[M]``."""
    flat = x.reshape(len(x), -1)
    out = np.stack([np.interp(times, src_times, flat[:, k]) for k in range(flat.shape[1])], -1)
    return out.reshape((len(times),) + x.shape[1:])


