"""In-betweening: the frames between a context and a target, from the motion model.

The model continues the context across the gap as Extend would. Its continuation is then
bent onto the target with corrections that grow smoothly over the gap, from nothing at the
context (where the motion already continues it) to exactly what is missing at the target:

- the body's heading and ground position (the root), so that it arrives where and facing how
  the target stands: the continuation's path is turned and stretched about the gap's start so
  that it ends at the target (its shape kept), the body turning with it and then onto the
  target's heading; what stretching within limits cannot reach is shifted;
- the pose in the body's own frame (root-local joints), so that it arrives in the target pose.

Before that, the continuation's jump from the context is faded out as Extend fades it
(:func:`seam.blend_seam`), so the gap leaves the context without a pop.

Each correction follows a cubic Hermite curve with zero slope at the start; with two or more
target frames its slope at the end also matches the target's own velocity, so the motion
leaves the gap as the target moves on (no pop after it). Positions are ``[F, 21, 3]`` metres,
Y-up, at the model's rate; :func:`inbetween_positions` takes a user's clip at any rate and unit.
"""

from __future__ import annotations

import numpy as np

from ..motion.conventions import MODEL_FPS
from ..motion.features import root_and_local, wrap_angle, yaw_matrix
from . import gap_memory
from .extend import MEMORY_S
from .familiarity import momentum_shares
from .normalise import fit_normalisation, model_frames_available, sample_at
from .seam import blend_seam
from .skeleton import knee_side, on_skeleton, sampled_on_bones
from .transfer import bone_lengths

# How many of the continuation's windows are the average of the release and its companion
# (Engine.extrapolate's paired_windows; None: every window of the gap).
PAIRED_WINDOWS = None
MAX_GAP_S = 4.0  # longest gap the model is asked to bridge (its continuation drifts beyond a few seconds)


def _hermite(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cubic Hermite weights of the end value and the end slope at ``s`` in [0, 1] (zero value and
    slope at the start)."""
    return 3 * s ** 2 - 2 * s ** 3, s ** 3 - s ** 2


# The path is stretched at most this much either way to reach the target; the rest is shifted.
MAX_PATH_SCALE = 1.5
# Paths (the continuation's, and the one to the target) shorter than the first length are shifted
# only (the body stands or shuffles, and a short path's direction says little); from the second on
# they are turned and stretched in full, and in between partly.
PATH_M = (0.3, 0.8)


def _chord_fit(reach: np.ndarray, want: np.ndarray) -> tuple[float, float]:
    """(yaw angle, scale) that turn and stretch the ground vector ``reach`` onto ``want`` (both ``[3]``)."""
    a, b = np.hypot(reach[0], reach[2]), np.hypot(want[0], want[2])
    lo, hi = PATH_M
    weight = float(np.clip((min(a, b) - lo) / max(hi - lo, 1e-9), 0.0, 1.0))
    if weight == 0.0:
        return 0.0, 1.0
    angle = wrap_angle(np.arctan2(want[0], want[2]) - np.arctan2(reach[0], reach[2]))
    scale = np.clip(b / a, 1 / MAX_PATH_SCALE, MAX_PATH_SCALE)
    return float(weight * angle), float(1 + weight * (scale - 1))


def _arrive(q: np.ndarray, end, step, h_end: np.ndarray, h_slope: np.ndarray) -> np.ndarray:
    """``q`` ``[N + 1, ...]`` corrected along the Hermite curves so that its last frame is ``end`` and, where
    ``step`` is given, its last frame-to-frame change is exactly ``step`` (the target's own motion)."""
    shape = (-1,) + (1,) * (q.ndim - 1)
    out = q + h_end.reshape(shape) * (end - q[-1])
    if step is not None and len(q) > 1:  # h_slope is 0 at the end: only the last step changes
        out = out + h_slope.reshape(shape) * (((out[-1] - out[-2]) - step) / h_slope[-2])
    return out


def bend_onto(pred: np.ndarray, start: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The continuation ``pred`` ``[N + 1, J, 3]`` (its last frame where the target's first should be)
    bent onto ``target`` ``[T, J, 3]`` (T >= 1); ``start`` ``[J, 3]`` is the context's last frame.
    Returns the ``N`` gap frames and the frame where the target is, ``[N + 1, J, 3]``."""
    n1 = len(pred)
    s = np.arange(1, n1 + 1) / n1
    h_end, h_slope = _hermite(s)
    p_root, p_yaw, p_local = root_and_local(pred)
    t_root, t_yaw, t_local = root_and_local(target)
    origin = root_and_local(start[None])[0][0]
    moves_on = len(target) > 1  # arrive moving (and turning) as the target moves on
    # The path: turned and scaled about the gap's start so that it ends where the target stands, the turn
    # and the scale growing smoothly over the gap (no kink at its start). It keeps its shape and its pace
    # evens out, where a shift alone would drag the body sideways or hurry it at the end.
    chord, scale = _chord_fit(p_root[-1] - origin, t_root[0] - origin)
    path_angle = chord * h_end
    stretch = 1 + (scale - 1) * h_end
    root = origin + np.einsum("fij,fj->fi", yaw_matrix(path_angle), (p_root - origin) * stretch[:, None])
    # Heading: the body turns with its path, then onto the target's heading.
    p_yaw = p_yaw + path_angle
    yaw = _arrive(p_yaw, p_yaw[-1] + wrap_angle(t_yaw[0] - p_yaw[-1]),
                  wrap_angle(t_yaw[1] - t_yaw[0]) if moves_on else None, h_end, h_slope)
    # Ground position: what is still missing at the target shifted in.
    root = _arrive(root, t_root[0], t_root[1] - t_root[0] if moves_on else None, h_end, h_slope)
    # Pose in the body's frame.
    local = _arrive(p_local, t_local[0], t_local[1] - t_local[0] if moves_on else None, h_end, h_slope)
    out = np.einsum("fij,fkj->fki", yaw_matrix(yaw), local) + root[:, None]
    return out.astype(np.float32)


def inbetween(engine, context: np.ndarray, target: np.ndarray, frames: int,
              memory: list[np.ndarray] | None = None) -> np.ndarray:
    """``frames`` frames ``[frames, J, 3]`` between ``context`` ``[C, J, 3]`` (C >= 1; up to the model's
    ``m`` last frames are read, fewer are padded by holding the first) and ``target`` ``[T, J, 3]``
    (T >= 1), all at the model's rate and scale. ``memory``: the rest of the take, as runs of frames outside
    the gap (:func:`with_take`)."""
    context, target = np.asarray(context, np.float64), np.asarray(target, np.float64)
    given = context
    if len(context) < engine.m:
        context = np.concatenate([np.repeat(context[:1], engine.m - len(context), 0), context])
    pred = np.asarray(engine.extend(context[-engine.m:].astype(np.float32), frames + 1,
                                    paired_windows=PAIRED_WINDOWS), np.float64)
    momentum = momentum_shares(engine, context[None, -engine.m:])[0]
    filled = with_gap_model(engine, context, target, fill_from(context, pred, target, momentum), momentum)
    return with_take(given, target, filled, memory, momentum)[:-1]


def with_take(context: np.ndarray, target: np.ndarray, filled: np.ndarray, memory: list[np.ndarray] | None,
              momentum: float = 0.0) -> np.ndarray:
    """``filled`` ``[N + 1, J, 3]`` (a gap and the target's frame) blended with the stretch of the take
    (``memory``: runs of frames ``[S, J, 3]`` outside the gap) that best fits the gap's two ends
    (:func:`gap_memory.best_stretch`), bent onto ``target`` as the model's continuation is, by the fit's
    :func:`gap_memory.share`; unchanged without a memory or a stretch that fits. Both reach the target, and so
    does the blend."""
    if not memory:
        return filled
    distance, stretch = gap_memory.best_stretch(memory, context, target, len(filled) - 1)
    weight = gap_memory.share(distance, len(filled) - 1, momentum)
    if stretch is None or weight < 1e-3:
        return filled
    lengths, end_lengths, side = bone_lengths(context), bone_lengths(target[:1]), knee_side(context)
    followed = on_skeleton(bend_onto(blend_seam(context, stretch, momentum=momentum), context[-1], target),
                           lengths, end_lengths, side)
    return on_skeleton(filled + weight * (followed - filled), lengths, end_lengths, side)


# How far Fill Gap goes from the STRNN's bent continuation towards the gap model's in-between, where the
# release has one: two guesses that err apart, whose blend is nearer the truth than either. The gap model is
# the better guess the longer the gap, and the STRNN's continuation the better one where the model does not
# know the context's motion (model card, "In-betweening"): the share at gaps of 15, 30 and 60 frames at
# 30 fps (held in between and beyond), less by half the context's momentum share (familiarity).
GAP_MODEL_SHARE = ((15, 30, 60), (0.35, 0.6, 0.8))


def gap_model_share(frames: int, momentum: float) -> float:
    """The gap model's share of a gap of ``frames`` frames at the model's rate (:data:`GAP_MODEL_SHARE`)."""
    return float(np.interp(frames, *GAP_MODEL_SHARE)) * (1.0 - 0.5 * float(np.clip(momentum, 0.0, 1.0)))


def with_gap_model(engine, context: np.ndarray, target: np.ndarray, filled: np.ndarray,
                   momentum: float = 0.0) -> np.ndarray:
    """``filled`` ``[N + 1, J, 3]`` (a gap and the target's frame, :func:`fill_from` of a context whose momentum
    share is ``momentum``) blended with the release's gap model's in-between (:func:`gap_fill`) by
    :func:`gap_model_share` and put back on the body's bones; unchanged where the release has no gap model.
    Both reach the target, and so does the blend."""
    if getattr(engine, "gap", None) is None:
        return filled
    other = gap_fill(engine.gap, context, target, len(filled) - 1)
    mixed = filled + gap_model_share(len(filled) - 1, momentum) * (other - filled)
    return on_skeleton(mixed, bone_lengths(context), bone_lengths(target[:1]), knee_side(context))


def gap_fill(model, context: np.ndarray, target: np.ndarray, frames: int) -> np.ndarray:
    """The release's gap model's in-between (:class:`gap_engine.GapModel`) of ``frames`` frames from ``context``
    ``[C, J, 3]`` to ``target`` ``[T, J, 3]``, put on the body's bones (:func:`on_skeleton`): the ``N`` gap frames
    and the target's frame."""
    seq = np.concatenate([model.fill(context, target, frames), target[:1]])
    return on_skeleton(seq, bone_lengths(context), bone_lengths(target[:1]), knee_side(context))


def fill_from(context: np.ndarray, pred: np.ndarray, target: np.ndarray, momentum: float = 0.0) -> np.ndarray:
    """The model's continuation ``pred`` ``[N + 1, J, 3]`` of ``context`` ``[C, J, 3]``, its seam faded as
    Extend fades it (``momentum``: :func:`seam.blend_seam`) and bent onto ``target`` ``[T, J, 3]``: the ``N``
    gap frames and the target's frame. The gap then leans a little on the interpolation from the context to
    the target, and more where the model does not know the context's motion (``momentum``, the familiarity
    share of :func:`familiarity.momentum_shares`): :func:`lean_on_interpolation`."""
    bent = bend_onto(blend_seam(context, pred, momentum=momentum), context[-1], target)
    leaned = lean_on_interpolation(bent, context[-1], target[0], lean_weights(len(bent), momentum))
    return on_skeleton(leaned, bone_lengths(context), bone_lengths(target[:1]), knee_side(context))


# A continuation and the interpolation are two guesses that err apart, and an average of them is nearer
# the truth than either (model card, "In-betweening"). Where the model does not know the motion, the gap
# leans on the interpolation up to half-way, most at mid-gap; everywhere, by up to a tenth two thirds of the
# way through the gap, where the bent continuation is furthest from the truth. Neither at either end.
INTERPOLATION_LEAN = 0.5
LATE_LEAN = 0.1


def lean_weights(frames: int, share: float) -> np.ndarray:
    """How far each of ``frames`` frames (a gap and the frame after it) leans on the interpolation, for a
    context whose momentum share is ``share``: ``max(0.5 share 4 s (1 - s), 0.1 x 27/4 s^2 (1 - s))`` at
    the fraction ``s`` of the way, 0 at both ends and flat at the start."""
    s = np.arange(1, frames + 1) / frames
    return np.maximum(INTERPOLATION_LEAN * share * 4 * s * (1 - s), LATE_LEAN * 6.75 * s ** 2 * (1 - s))


def interpolation(start: np.ndarray, end: np.ndarray, frames: int) -> np.ndarray:
    """The ``frames`` frames ``[frames, J, 3]`` between poses ``start`` and ``end`` ``[J, 3]``, interpolated in
    the body's own terms: its ground position along the straight line, its heading the short way round, the
    pose in the body's frame joint by joint."""
    s = np.arange(1, frames + 1) / (frames + 1)
    (a_root, a_yaw, a_local), (b_root, b_yaw, b_local) = (root_and_local(p[None]) for p in (start, end))
    root = a_root + s[:, None] * (b_root - a_root)
    yaw = a_yaw[0] + s * wrap_angle(b_yaw[0] - a_yaw[0])
    local = a_local + s[:, None, None] * (b_local - a_local)
    return np.einsum("fij,fkj->fki", yaw_matrix(yaw), local) + root[:, None]


def lean_on_interpolation(frames: np.ndarray, start: np.ndarray, end: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``frames`` ``[N + 1, J, 3]`` (a gap and the pose ``end`` after it) pulled towards :func:`interpolation`
    from ``start`` to ``end`` by ``weights`` ``[N + 1]`` (:func:`lean_weights`, which are 0 at both ends and
    so keep the motion's speed where it leaves the context and where it arrives). The pull is in the body's
    own terms (ground position, heading, pose), so a body turning in the gap keeps its build. Zero weights
    return ``frames`` unchanged."""
    w = np.asarray(weights, np.float64)
    if not np.any(w > 0.0):
        return frames
    f_root, f_yaw, f_local = root_and_local(frames)
    i_root, i_yaw, i_local = root_and_local(np.concatenate([interpolation(start, end, len(frames) - 1), end[None]]))
    root = f_root + w[:, None] * (i_root - f_root)
    yaw = f_yaw + w * wrap_angle(i_yaw - f_yaw)
    local = f_local + w[:, None, None] * (i_local - f_local)
    return (np.einsum("fij,fkj->fki", yaw_matrix(yaw), local) + root[:, None]).astype(frames.dtype)


def inbetween_positions(engine, before: np.ndarray, after: np.ndarray, fps: float, frames: int,
                        follow_take: bool = True) -> np.ndarray:
    """Fill a gap of ``frames`` scene frames between ``before`` ``[B, 21, 3]`` (the frames up to the gap)
    and ``after`` ``[A, 21, 3]`` (the frames from its end on), Y-up scene units at ``fps``.

    Both sides are read at the model's rate, aligned on the gap's edges; the model's in-between is
    brought back to the scene's frames. With ``follow_take`` the gap leans on the rest of the take where it
    did what the gap must (:func:`with_take`): all of ``before`` and ``after``, up to
    :data:`extend.MEMORY_S` seconds of each, is looked through. Returns ``[frames, 21, 3]`` in the same
    space."""
    if frames < 1:
        raise ValueError("the gap has no frame to fill")
    if not len(before) or not len(after):
        raise ValueError("the gap needs at least one frame before it and one after it: key a pose on each side")
    gap_s = (frames + 1) / fps
    if gap_s > MAX_GAP_S:
        raise ValueError(f"the gap of {frames} frames ({gap_s:.1f} s) is longer than the {MAX_GAP_S:g} s the model "
                         "can bridge: key a pose inside it and fill the two shorter gaps")
    n_before = model_frames_available(len(before), fps)
    ctx = sample_at(before, fps, (len(before) - 1) / fps - np.arange(min(n_before, engine.m))[::-1] / MODEL_FPS)
    n_after = min(model_frames_available(len(after), fps), 2)
    tgt = sample_at(after, fps, np.arange(n_after) / MODEL_FPS)
    norm = fit_normalisation(np.concatenate([ctx, tgt]))
    n_model = max(int(round(gap_s * MODEL_FPS)) - 1, 1)
    memory = None
    if follow_take:  # the take either side of the gap, aligned on its edges, as far back and on as it is followed
        most = int(MEMORY_S * MODEL_FPS)
        back, on = min(n_before, most), min(model_frames_available(len(after), fps), most)
        memory = [norm.to_model(sample_at(before, fps, (len(before) - 1) / fps - np.arange(back)[::-1] / MODEL_FPS)),
                  norm.to_model(sample_at(after, fps, np.arange(on) / MODEL_FPS))]
    inner = inbetween(engine, norm.to_model(ctx), norm.to_model(tgt), n_model, memory)
    seq = np.concatenate([ctx[-1:], norm.to_user(inner), tgt[:1]])  # model frames 0 .. n_model + 1
    # the model's frames are spread evenly over the gap's duration, a little stretched to fit it
    return sampled_on_bones(seq, np.arange(1, frames + 1) / fps * (n_model + 1) / gap_s)  # on the bones between
