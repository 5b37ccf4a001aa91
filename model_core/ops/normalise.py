"""A user's clip to the model's space and back: frame rate, scale and ground.

A user's clip is canonical joint positions ``[F, 21, 3]`` in Y-up scene units at the
scene's frame rate (any size of character, any unit). The model wants the standard
skeleton (:data:`conventions.STANDARD_LEG_LENGTH`), ground at y = 0 and
:data:`conventions.MODEL_FPS`. The operations (:mod:`.extend`, :mod:`.denoise`, :mod:`.follow`)
convert with these helpers, call the engine, and convert back, so the result lands on the
user's frames, scale and ground.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..motion.conventions import MODEL_FPS, STANDARD_LEG_LENGTH, UP_AXIS
from ..motion.features import floor_height
from ..motion.geometry import interpolate_frames
from ..rig.rigs import leg_length


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
    return Normalisation(STANDARD_LEG_LENGTH / legs, floor_height(pos))


def sample_at(x: np.ndarray, fps: float, times: np.ndarray) -> np.ndarray:
    """Linear interpolation of ``x`` ``[N, ...]`` (frame k at time k / fps) at ``times`` ``[M]``
    seconds, clamped at both ends -> ``[M, ...]``."""
    return interpolate_frames(x, np.asarray(times, dtype=np.float64) * fps)


def model_frames_available(frames: int, fps: float) -> int:
    """How many model-rate frames a clip of ``frames`` scene frames at ``fps`` spans."""
    return int(math.floor((frames - 1) * MODEL_FPS / fps + 1e-6)) + 1
