"""Whether a take's keys play at the pace it was captured at, read from its stride.

A take imported at another rate than it was captured (a 60 fps capture keyed one frame per frame
of a 24 fps scene) plays 2.5 x too slow, and the model, which reads seconds, continues a motion
that slow. The stride gives it away: people walk and run at a stride (two steps) of about 0.5 to
1.6 s, whatever their speed, while a take read at the wrong rate has its strides stretched or
squeezed by the ratio of the rates. The stride is the period of the feet's alternation: how far
the left foot is ahead of the right along the body's facing direction, which swings from about
+0.5 m to -0.5 m once per stride in walking and running, and barely moves in standing motion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..motion.conventions import JOINT_INDEX, LAYOUT, NUM_JOINTS
from ..motion.features import positions_to_features
from .normalise import fit_normalisation

STRIDE_S = (0.45, 1.6)  # seconds per stride people take, from a sprint to a slow walk
TYPICAL_STRIDE_S = 1.0
RATES = (24.0, 25.0, 30.0, 50.0, 60.0, 120.0)  # capture and scene rates a take may come from
MIN_SWING_M = 0.12  # standard deviation of the feet's fore-aft offset (legs of 0.87 m) that counts as stepping
MIN_CORRELATION = 0.5  # how alike one stride is to the next for the motion to count as periodic
MIN_STRIDES = 2.0  # the stretch read must hold at least this many strides
RATE_TOLERANCE = 1e-3  # a rate read from a BVH's rounded Frame Time (0.00833333 s: 120.000048 fps) is that rate


@dataclass
class Pace:
    stride_s: float  # seconds per stride with the keys read at ``fps``
    fps: float  # the keys per second the take was read at

    @property
    def plausible(self) -> bool:
        return STRIDE_S[0] <= self.stride_s <= STRIDE_S[1]

    def suggested_rate(self) -> float:
        """The rate of :data:`RATES` at which the stride is closest to a typical one (in ratio)."""
        frames = self.stride_s * self.fps
        return min(RATES, key=lambda r: abs(np.log(frames / r / TYPICAL_STRIDE_S)))

    def note(self) -> str:
        """A sentence for an operator's report; empty when the pace is plausible, or when no other rate
        would make it so (the rate read at is already the nearest: stepping that slow or fast is the
        motion's own, as in a martial arts stance shifting its feet every few seconds)."""
        rate = self.suggested_rate()
        if self.plausible or abs(rate / self.fps - 1.0) < RATE_TOLERANCE:
            return ""
        pace = "slower" if self.stride_s > STRIDE_S[1] else "faster"
        return (f"Its strides take {self.stride_s:.2f} s at {self.fps:g} keys per second, {pace} than people move "
                f"({STRIDE_S[0]:g} to {STRIDE_S[1]:g} s): the take may have been captured at {rate:g} fps. If so, "
                f"set Keys per Second to {rate:g} (STRNN sidebar) so that the result keeps its pace")


def feet_offset(pos: np.ndarray, fps: float) -> np.ndarray:
    """How far ``[F]`` the left ankle is ahead of the right along the body's facing direction, in
    standard-leg metres, for positions ``[F, 21, 3]`` (Y-up) read at ``fps``."""
    model = fit_normalisation(pos).to_model(pos)
    local = positions_to_features(model, fps)[0][:, LAYOUT.positions].reshape(len(pos), NUM_JOINTS, 3)
    return local[:, JOINT_INDEX["l_foot"], 2] - local[:, JOINT_INDEX["r_foot"], 2]


def stride_period(pos: np.ndarray, fps: float) -> float | None:
    """Seconds per stride of positions ``[F, 21, 3]`` read at ``fps``: the lag of the first clear peak of
    the feet's alternation's autocorrelation; None when the feet do not alternate (standing motion) or the
    stretch is too short to hold two strides."""
    offset = feet_offset(pos, fps).astype(np.float64)
    offset -= offset.mean()
    if len(offset) < 8 or offset.std() < MIN_SWING_M:
        return None
    n = len(offset)
    spectrum = np.fft.rfft(offset, 2 * n)
    corr = np.fft.irfft(spectrum * np.conj(spectrum))[:n]
    corr /= corr[0] * (n - np.arange(n)) / n  # unbiased: each lag over the overlap it has
    usable = int(n / MIN_STRIDES)
    for lag in range(2, usable):
        if corr[lag] >= MIN_CORRELATION and corr[lag] >= corr[lag - 1] and corr[lag] >= corr[lag + 1]:
            before = corr[2:lag]
            if len(before) and before.min() < 0.0:  # past the alternation's trough: a whole stride
                return lag / fps
    return None


def take_pace(pos: np.ndarray, fps: float) -> Pace | None:
    """The :class:`Pace` of positions ``[F, 21, 3]`` read at ``fps``; None when they show no stride."""
    period = stride_period(pos, fps)
    return None if period is None else Pace(period, float(fps))
