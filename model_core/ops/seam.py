"""Seams: where new frames meet the frames they continue or replace, faded so nothing jumps.

Every seam length lives here. Three kinds of seam:

- a predicted window after its context (:meth:`Engine.predict`, ``training.rolled_context``):
  the decoder's offset on the last context frame is carried into the prediction, decaying as
  ``exp(-k / PREDICT_SEAM_FRAMES)`` (:func:`seam_fade`);
- new frames after a clip (:func:`extend.extend_positions`, :func:`follow.smooth_seam`): the jump
  from where the clip's last motion leads (:func:`seam_target`) fades out over :data:`SEAM_FRAMES`
  model frames on a half cosine (:func:`blend_seam`), and on motion the model does not know the
  clip's momentum eases into the model's over :data:`MOMENTUM_FRAMES` (:func:`momentum_share`); new
  frames held at the clip's last pose keep what the seam carried on through their window (``coast``);
- a replaced range inside a clip (Denoise on part of an action): the new frames are blended from
  the old ones over :data:`EDGE_FADE_S` seconds at each edge (:func:`fade_edges`).
"""

from __future__ import annotations

import numpy as np

from ..motion.conventions import CONTACT_JOINTS, UP_AXIS
from ..motion.noise import white_noise_variance

PREDICT_SEAM_FRAMES = 10.0  # decay (frames) of the engine's seam correction in predict(); chosen on validation
SEAM_FRAMES = 10  # model frames over which a jump at the start of an extension is faded out
EDGE_FADE_S = 0.2  # a partial Denoise range fades in and out over this long where it meets untouched frames
# The first new frame continues the clip's last velocity and this share of its last acceleration, as far as
# the acceleration stands out of the clip's jitter (seam_target); chosen on the validation split.
SEAM_ACCEL = 0.75
SEAM_NOISE_MARGIN = 3.0  # the acceleration counts against this many times the jitter it carries
ACCEL_FRAMES = 6  # recent second differences that measure how much the clip accelerates
D2_NOISE_GAIN2 = 6.0  # variance of the 2nd difference of unit white noise
# On motion the model does not know, its own velocity is worse than the clip's: there the clip's momentum
# carries on into the new frames, easing into the model's motion over MOMENTUM_FRAMES (an exponential
# time constant) and given back by MOMENTUM_FADE_FRAMES. How much: none while the clip reconstructs at
# most as badly as 90 % of the motion the model knows (familiarity ratio 1), in full from MOMENTUM_RATIO[1].
# Chosen on the held-out groups and the validation split (model card).
MOMENTUM_RATIO = (1.0, 1.5)
MOMENTUM_FRAMES = 4.0
MOMENTUM_FADE_FRAMES = 20


def seam_fade(n: int, frames: float = PREDICT_SEAM_FRAMES, xp=np, dtype=np.float32):
    """Weights ``[n]`` of the seam correction on predicted frames 1..n: ``exp(-k / frames)``.
    ``xp``: ``numpy`` or ``torch`` (with a torch ``dtype``), so the engine and training share it."""
    return xp.exp(-xp.arange(1, n + 1, dtype=dtype) / frames)


def seam_target(ctx: np.ndarray, accel: float = SEAM_ACCEL) -> np.ndarray:
    """Where the frame after a context ``[C, J, 3]`` should be: the last frame moved on by its velocity
    and by ``accel`` times its acceleration, the latter shrunk by how much of it could be jitter (a
    Wiener gain per joint and axis: the clip's recent acceleration against the noise measured on it;
    a clean take keeps it, noisy capture falls back to the velocity alone). A body that is slowing
    down or speeding up goes on doing so for a frame, which the velocity alone misses."""
    ctx = np.asarray(ctx, np.float64)
    target = 2 * ctx[-1] - ctx[-2]
    if len(ctx) < 8 or accel == 0.0:
        return target
    noise = D2_NOISE_GAIN2 * white_noise_variance(ctx)
    signal = np.maximum((np.diff(ctx[-ACCEL_FRAMES - 2:], n=2, axis=0) ** 2).mean(0) - noise, 0.0)
    total = signal + SEAM_NOISE_MARGIN * noise
    gain = np.divide(signal, total, out=np.zeros_like(total), where=total > 0)
    return target + accel * gain * (ctx[-1] - 2 * ctx[-2] + ctx[-3])


def momentum_share(ratio: float | None) -> float:
    """How much of the clip's momentum a continuation keeps (0 to 1) for a context whose familiarity ratio
    (:func:`familiarity.context_ratios`) is ``ratio``; 0 where it is unknown."""
    if ratio is None or not np.isfinite(ratio):
        return 0.0
    lo, hi = MOMENTUM_RATIO
    return float(np.clip((ratio - lo) / (hi - lo), 0.0, 1.0))


def _cosine_fade(n: int, frames: int) -> np.ndarray:
    k = np.arange(n, dtype=np.float64)
    return np.where(k < frames, 0.5 * (1 + np.cos(np.pi * k / frames)), 0.0)  # 1 -> 0, flat at both ends


def blend_seam(ctx: np.ndarray, new: np.ndarray, frames: int = SEAM_FRAMES, accel: float = SEAM_ACCEL,
               momentum: float = 0.0, land: bool = True, coast: float = 0.0, coast_frames: int = 0) -> np.ndarray:
    """Fade out the jump between a context ``[C, 21, 3]`` and its continuation ``[N, 21, 3]``
    (same rate): the first new frame is moved to where the context's last motion leads
    (:func:`seam_target`), and that correction decays smoothly to zero over ``frames`` frames.

    With ``momentum`` (0 to 1, :func:`momentum_share`), that share of the difference between the clip's
    last velocity and the continuation's first carries on, decaying over :data:`MOMENTUM_FRAMES`, and
    what it moved is given back over :data:`MOMENTUM_FADE_FRAMES`: the motion eases from the clip's
    momentum into the model's instead of turning at once.

    With ``land``, a heel or toe coming down at the context's end lands on its floor (:func:`_landed`):
    for the seam after a user's clip; Follow Curve's seams between its own windows leave it off.

    With ``coast`` (0 to 1), that share of what the seam carries on (the jump and the momentum's drift) is not given
    back through the first ``coast_frames`` new frames, and is given back over as many again on a half cosine: for new
    frames held at the context's last pose (Extend's first window after a clip at rest, held that share), where the
    body coasts to a stop from its last motion rather than carrying it on and coming back to the pose."""
    if len(ctx) < 2 or len(new) == 0:
        return new
    target = seam_target(ctx, accel)
    kept = _kept(len(new), coast, coast_frames)
    out = new + kept(_cosine_fade(len(new), frames))[:, None, None] * (target - new[0])
    if momentum > 0.0 and len(new) > 1:
        dv = (target - np.asarray(ctx[-1], np.float64)) - (new[1] - new[0])  # (21, 3) per frame
        k = np.arange(len(new), dtype=np.float64)
        carried = np.cumsum(np.exp(-k / MOMENTUM_FRAMES)) - 1.0  # 0 at the first new frame
        out = out + momentum * (carried * kept(_cosine_fade(len(new), MOMENTUM_FADE_FRAMES)))[:, None, None] * dv
    return _landed(ctx, new, out) if land else out


def _kept(n: int, coast: float, frames: int):
    """A function of a seam's fade ``[n]`` (1 -> 0) that keeps ``coast`` of its full weight through ``frames``
    frames and gives it back over as many again (:func:`blend_seam`); the fade as it is without ``coast``."""
    share = float(np.clip(coast, 0.0, 1.0))
    if share == 0.0 or frames <= 0:
        return lambda fade: fade
    hold = np.concatenate([np.ones(frames), _cosine_fade(max(n - frames, 0), frames)])[:n]  # 1, then 1 -> 0
    return lambda fade: fade + share * np.maximum(hold - fade, 0.0)


def _landed(ctx: np.ndarray, new: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``out`` with no heel or toe carried by the seam below the floor it stood on in the context: a foot
    coming down fast at the end of a clip lands, where its velocity (and acceleration) alone would carry it
    on through the floor. Each contact joint is kept at least as high as the lower of its lowest height in
    the context and the model's own continuation; nothing else changes."""
    up = (slice(None), CONTACT_JOINTS, UP_AXIS)
    floor = np.minimum(np.asarray(ctx, np.float64)[up].min(0), np.asarray(new, np.float64)[up])
    out = np.array(out, copy=True)
    out[up] = np.maximum(out[up], floor)
    return out


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
