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

from . import familiarity as _familiarity, fusion
from .conventions import JOINT_INDEX, MODEL_FPS, STANDARD_LEG_LENGTH, UP_AXIS
from .features import gaussian_smooth
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


def familiarity(engine, pos: np.ndarray, fps: float) -> _familiarity.Familiarity:
    """How familiar a clip ``[F, 21, 3]`` (Y-up, scene units, ``fps``; at least the model's context)
    is to the model (:mod:`familiarity`), read at the model's rate and scale as Extend reads it."""
    n = model_frames_available(len(pos), fps)
    clip = sample_at(pos, fps, (len(pos) - 1) / fps - np.arange(n)[::-1] / MODEL_FPS)
    return _familiarity.assess(engine, fit_normalisation(clip).to_model(clip))


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
    """:func:`denoise_positions` as a step generator (:mod:`steps`): yields the fraction done.

    Pops are found and the noise measured at the clip's own rate (:mod:`fusion`). The model reads
    the repaired clip at its own rate, once per phase of a faster clip (frames 0, 2, 4... and 1, 3,
    5... of a 60 fps clip), and the phases' reconstructions, brought back to the clip's frames, are
    averaged. That estimate is weighed against the input by how much each deserves: a clean take
    comes back nearly as it was."""
    duration = (len(pos) - 1) / fps
    fixed, found = fusion.assess(np.asarray(pos, np.float64))
    # Scale and ground from a smoothed clip: noise lengthens the legs and lowers the lowest foot.
    norm = fit_normalisation(gaussian_smooth(fixed, fps / 15.0) if len(fixed) > 1 else fixed)
    x, fixed = norm.to_model(pos).astype(np.float64), norm.to_model(fixed).astype(np.float64)
    found = fusion.Assessment(found.noise_m * norm.scale, found.pops)
    frames = np.arange(len(pos)) / fps
    phases = [k / fps for k in range(max(1, int(round(fps / MODEL_FPS))))]
    phases = [p for p in phases if len(_model_times(duration, p)) >= engine.m] or [0.0]
    prior = np.zeros_like(x)
    for i, phase in enumerate(phases):
        times = _model_times(duration, phase)
        clean = yield from _scaled(engine.denoise_positions_steps(sample_at(fixed, fps, times).astype(np.float32)),
                                   i / len(phases), 1 / len(phases))
        prior += _sample_times(np.asarray(clean, np.float64), times, frames) / len(phases)
    out = norm.to_user(fusion.fuse(fixed, prior, found, fps))
    user = np.asarray(pos, dtype=np.float64)
    return user + strength * (out - user)


def _model_times(duration: float, phase: float) -> np.ndarray:
    """Times (s) at the model's rate from ``phase`` on, the clip's start and end included."""
    times = phase + np.arange(int(math.floor((duration - phase) * MODEL_FPS + 1e-6)) + 1) / MODEL_FPS
    if phase > 1e-9:
        times = np.r_[0.0, times]
    if times[-1] < duration - 1e-9:
        times = np.append(times, duration)
    return times


def _scaled(steps, start: float, share: float):
    """Re-yield a step generator's fractions as ``start + share * fraction``; return its value."""
    value = yield from ((start + share * f) for f in ())  # keeps this a generator when steps is empty
    try:
        while True:
            yield start + share * next(steps)
    except StopIteration as stop:
        value = stop.value
    return value


def _sample_times(x: np.ndarray, src_times: np.ndarray, times: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``x`` ``[N, ...]`` sampled at ``src_times`` ``[N]`` at ``times`` ``[M]``."""
    flat = x.reshape(len(x), -1)
    out = np.stack([np.interp(times, src_times, flat[:, k]) for k in range(flat.shape[1])], -1)
    return out.reshape((len(times),) + x.shape[1:])


