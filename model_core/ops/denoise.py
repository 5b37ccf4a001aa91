"""Denoise Action's maths: the model's reconstruction of a user's clip, weighed against the input."""

from __future__ import annotations

import math

import numpy as np

from ..inference.steps import drive
from ..motion.conventions import MODEL_FPS
from ..motion.features import gaussian_smooth, mirror_positions
from ..motion.geometry import cubic_frames
from . import fusion
from .familiarity import Familiarity, clip_familiarity
from .normalise import fit_normalisation, sample_at


def denoise_positions(engine, pos: np.ndarray, fps: float, strength: float = 1.0) -> np.ndarray:
    """Denoised clip ``[F, 21, 3]`` (same space and frames as ``pos``), blended with the input by
    ``strength`` in [0, 1] (0: unchanged, 1: the model's output)."""
    return drive(denoise_positions_steps(engine, pos, fps, strength))


def result_familiarity(engine, pos: np.ndarray, denoised: np.ndarray, fps: float,
                       strength: float) -> Familiarity | None:
    """How familiar the motion of a clip ``pos`` ``[F, 21, 3]`` (``fps``) is to ``engine``'s model (usually the
    main model, which is calibrated), judged on what Denoise made of it (``denoised``, blended by ``strength``;
    None for strength 0): the input's noise would read as unfamiliar motion (a validation take with 1 cm of
    jitter rebuilds 1.45 x worse than the usual), its denoised self reads as the clean take does, on the
    validation split and each held-out group (model card, "Familiarity")."""
    if strength <= 0.0:
        return None
    pos = np.asarray(pos, np.float64)
    return clip_familiarity(engine, pos + (np.asarray(denoised, np.float64) - pos) / strength, fps)  # the blend undone


def denoise_positions_steps(engine, pos: np.ndarray, fps: float, strength: float = 1.0):
    """:func:`denoise_positions` as a step generator (:mod:`steps`): yields the fraction done.

    Pops are found and the noise measured at the clip's own rate (:mod:`fusion`). The model reads
    the repaired clip at its own rate, once per phase of a faster clip (frames 0, 2, 4... and 1, 3,
    5... of a 60 fps clip), and, with the engine's ``mirrored_reading``, as its mirror image (left and
    right swapped, mirrored back after), and these reconstructions, brought back to the clip's
    frames, are averaged: each reading errs in its own way and the average less than either. That
    estimate, less its slow offset from the input (:func:`fusion.correct_bias`), is weighed against
    the input by how much each deserves (where the two sides disagree, the model is less sure:
    :func:`fusion.model_error2`): a clean take comes back nearly as it was."""
    duration = (len(pos) - 1) / fps
    fixed, found = fusion.assess(np.asarray(pos, np.float64))
    # Scale and ground from a smoothed clip: noise lengthens the legs and lowers the lowest foot.
    norm = fit_normalisation(gaussian_smooth(fixed, fps / 15.0) if len(fixed) > 1 else fixed)
    fixed = norm.to_model(fixed).astype(np.float64)
    found = fusion.Assessment(found.noise_m * norm.scale, found.pops)
    frames = np.arange(len(pos)) / fps
    phases = [k / fps for k in range(max(1, int(round(fps / MODEL_FPS))))]
    phases = [p for p in phases if len(_model_times(duration, p)) >= engine.m] or [0.0]
    sides = (False, True) if engine.mirrored_reading else (False,)  # the engine's one switch (Engine.predict)
    readings = [(phase, mirrored) for phase in phases for mirrored in sides]
    prior = np.zeros_like(fixed)
    spread2 = np.zeros(fixed.shape[:2]) if len(sides) == 2 else None  # where the two sides disagree
    plain = None  # each phase's plain reading, read just before its mirrored one
    for i, (phase, mirrored) in enumerate(readings):
        times = _model_times(duration, phase)
        flip = mirror_positions if mirrored else np.asarray
        seen = flip(sample_at(fixed, fps, times)).astype(np.float32)
        clean = yield from _scaled(engine.reconstruct_positions_steps(seen), i / len(readings), 1 / len(readings))
        reading = _sample_times(flip(np.asarray(clean, np.float64)), times, frames)
        prior += reading / len(readings)
        if mirrored:
            spread2 += (((plain - reading) / 2.0) ** 2).mean(-1) / len(phases)
        else:
            plain = reading
    prior = fusion.correct_bias(fixed, prior, found, fps)
    out = norm.to_user(fusion.keep_bone_lengths(fusion.fuse(fixed, prior, found, fps, spread2), found.joint_noise_m))
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
    try:
        while True:
            yield start + share * next(steps)
    except StopIteration as stop:
        return stop.value


def _sample_times(x: np.ndarray, src_times: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``x`` ``[N, ...]`` sampled at increasing ``src_times`` ``[N]``, at ``times`` ``[M]``: a Catmull-Rom cubic
    over the samples, so that a 60 fps take's frames between a reading's follow its arcs (a straight line
    between them cuts a fast hand's corner)."""
    return cubic_frames(x, np.interp(times, src_times, np.arange(len(src_times))))
