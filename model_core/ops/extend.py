"""Extend Clip's maths: continue a user's clip with the model, on the user's frames, scale and ground."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..inference import memory as clip_memory
from ..inference.memory import first_scale
from ..motion.conventions import (
    CONTACT_JOINTS,
    GROUND_AXES,
    JOINT_INDEX,
    MIN_MODEL_FRAMES,
    MODEL_FPS,
    ROOT,
    STANDARD_LEG_LENGTH,
    UP_AXIS,
)
from ..motion.features import floor_height, gaussian_smooth, positions_to_features
from ..motion.geometry import interpolate_frames
from ..rig.rigs import leg_length
from .familiarity import momentum_shares
from .normalise import fit_normalisation, model_frames_available, sample_at
from .seam import SEAM_FRAMES
from .skeleton import join_clip, sampled_on_bones

# Seconds of the clip before its end that Extend Clip reads as the clip's own motion, which long
# continuations lean on (inference/memory.py): several strides of a walk, without reading a long take whole.
MEMORY_S = 20.0
# Where the model does not know the motion (momentum share 1, :mod:`familiarity`) and the clip has come to rest,
# the continuation's first window keeps (speed / STILL_SPEED) ** STILL_POWER of its motion away from the last pose
# (all of it from STILL_SPEED on; speed: the joints' mean speed over the clip's last STILL_FRAMES model frames, in
# metres a model frame at the model's scale): a fighter paused at the cut is better left near the pause than
# given a move the model invents. The speed is the clip's most recent (0.13 s), so that a move that has just
# ended reads as the pause it is, not as the move before it. The later windows are the model's own from there.
# Chosen on the held-out groups (model card, "A clip at rest in motion the model does not know"). 0: off (and
# STILL_KNOWN_SPEED with it).
STILL_SPEED, STILL_POWER, STILL_FRAMES = 0.01, 2.0, 4
# Where the model knows the motion (momentum share 0) a clip reads as at rest only under STILL_KNOWN_SPEED (the
# same power): a raised hand held still, a bow paused at its lowest, a stance kept. The model's own move there is a
# guess at when the performer moves on, and it guesses early; held, the first window is nearer the take at 0.5 s
# more often (the held-out style: further than holding the pose in 78 of 617 windows, against 119). Between the two
# the held share is their mean weighed by the momentum share. Chosen on the held-out groups and the validation split
# (models/strnn_default/HISTORY.md, "a clip at rest in motion the model knows is held too"). 0: off.
STILL_KNOWN_SPEED = 0.003
# After a first window held near the last pose the next window is eased in (:func:`eased_after_hold`): where the
# window was held 70 % or more, the joints' mean speed jumped 0.65 cm a model frame (martial arts) from the held
# window's last frame to the next window's first, against 0.02 between other frames; eased, 0.13, every figure of the
# as-Extend rows the same to 0.01 cm (models/strnn_default/HISTORY.md, "a held first window coasts to a stop").
# False: off.
EASE_AFTER_HOLD = True
# The report says the first window was held near the last pose when it kept at most this share of its motion.
HELD_NOTE = 0.75
# A clip whose own floor (its lowest heel or toe, the lowest over FLOOR_RISE_S seconds about each frame) rises or
# falls by more than FLOOR_RISE_M metres (for a standard body) over what Extend reads walks up or down something:
# the model, which learnt flat floors, reads it with that rise taken out (floor_rise). 0.3 m: over the project's
# own takes (runs of up to 20 s ending every 2 s, runs/s62/floor_max.py), the Bandai actions read at most 0.015 m,
# salsa, martial arts, Indian dance and the cgspeed takes 0.07 to 0.12, the CMU playground's climbs up to 1.55.
FLOOR_RISE_S, FLOOR_RISE_M = 1.0, 0.30
FLOOR_STILL = 0.3  # metres a second (standard body): a heel or toe slower than this for FLOOR_STAND_S seconds
FLOOR_STAND_S = 0.15  # stands on the floor (a foot that only passes that slowly, as a body rises, does not)

# Seconds of the clip before its end whose floor (features.floor_height) the new frames' feet are kept out of
# (stance.ground): long enough to hold a step down even where the clip ends in a jump, short enough to be the floor
# where the clip ends when a capture's floor drifts over a take.
FLOOR_S = 3.0


# A clip that walks or runs in place (its hips kept over one spot on the ground while its feet step, as game cycles
# are made: Mixamo's "In Place"): over its last IN_PLACE_S seconds the hips' path over the ground, smoothed over a
# step, moves slower than IN_PLACE_SPEED (m/s on the standard body) while the feet move about the hips faster than
# STEPPING_SPEED. Its continuation is kept in place: the new frames' drift over the ground (their hips' path smoothed
# over IN_PLACE_SMOOTH_S seconds, a Gaussian's sigma) is taken off the whole body, their sway kept. The model learnt
# walks that travel, and without it an in-place walk crept 0.4 to 2.2 m in 20 s and a run 4.6 m
# (models/strnn_default/HISTORY.md, "A walk in place stays in place"). 0: off.
IN_PLACE_S, IN_PLACE_SPEED, STEPPING_SPEED, IN_PLACE_SMOOTH_S = 2.0, 0.02, 0.3, 0.5
# A clip that ends on a stalled frame: its last frame (nearly) repeats the one before while the body was moving (the
# joints' last step under STALL_SHARE x their mean step over the STALL_FRAMES steps before, which moved at STALL_SPEED
# m/s or more on the standard body, and the step before the last not stalled itself, so a hold of two frames or more
# is a hold). 30 of the 43 takes of the CMU conversion in data/mocap/cmu/iclone that end on the move end so; extended
# from that frame, the continuation starts from a body that stopped for a frame and the walk stumbles at the cut (the
# hips at 0.2 to 0.4 x their pace for the first tenth of a second, back to it only after 0.3 s). Extend Clip goes on
# from the frame before and, in the new action, puts the continuation's first frame in the stalled one's place
# (models/strnn_default/HISTORY.md, "a take that ends on a repeated frame stumbled at the cut"). 0: off.
STALL_SHARE, STALL_SPEED, STALL_FRAMES = 0.3, 0.1, 5
_GROUND = list(GROUND_AXES)
_FEET = [JOINT_INDEX["l_foot"], JOINT_INDEX["r_foot"]]


def in_place(clip: np.ndarray) -> bool:
    """Whether a clip ``[T, 21, 3]`` (model units and rate) steps in place over its last :data:`IN_PLACE_S`."""
    p = np.asarray(clip, np.float64)[-int(IN_PLACE_S * MODEL_FPS):]
    if IN_PLACE_SPEED <= 0.0 or len(p) < MODEL_FPS:
        return False
    hips = p[:, ROOT][:, _GROUND]
    path = gaussian_smooth(hips, IN_PLACE_SMOOTH_S * MODEL_FPS)
    travel = np.linalg.norm(np.diff(path, axis=0), axis=-1).mean() * MODEL_FPS
    feet = p[:, _FEET][:, :, _GROUND] - hips[:, None]
    stepping = np.linalg.norm(np.diff(feet, axis=0), axis=-1).mean() * MODEL_FPS
    return bool(travel < IN_PLACE_SPEED and stepping > STEPPING_SPEED)


def clip_in_place(clip: np.ndarray, fps: float) -> bool:
    """Whether a clip ``[F, 21, 3]`` (any units, ``fps``) steps in place (:func:`in_place`), as Extend reads it."""
    return _steps_in_place(_at_model_rate(clip, fps))


def _steps_in_place(clip: np.ndarray) -> bool:
    """:func:`in_place` of a clip ``[T, 21, 3]`` in any units at the model's rate, scaled as its last frames are."""
    return in_place(fit_normalisation(clip[-MIN_MODEL_FRAMES:]).to_model(clip))


def kept_in_place(before: np.ndarray, new: np.ndarray) -> np.ndarray:
    """Frames ``new`` ``[N, 21, 3]`` that follow ``before`` ``[T, 21, 3]`` (any units, the model's rate) without
    their drift over the ground: the hips' path smoothed over :data:`IN_PLACE_SMOOTH_S` (across the seam), taken
    off the whole body from where it is at ``before``'s last frame, so the body sways but does not travel."""
    hips = np.concatenate([before[:, ROOT], new[:, ROOT]])[:, _GROUND]
    path = gaussian_smooth(hips, IN_PLACE_SMOOTH_S * MODEL_FPS)
    out = np.array(new, dtype=np.float64)
    out[:, :, _GROUND] -= (path[len(before):] - path[len(before) - 1])[:, None]
    return out


@dataclass(frozen=True)
class FirstWindow:
    """How much of its motion Extend's first window keeps (:func:`first_motion`) and how long it lasts."""
    motion: float  # 1: the model's own; 0: the last pose held
    seconds: float
    unknown: bool = True  # the model does not know the clip's motion (momentum share over a half)

    def note(self, back: bool = False) -> str:
        """A sentence for the operator's report; empty unless the first window was mostly held. ``back``: the
        frames were added before the clip's start (read backwards in time)."""
        if self.motion > HELD_NOTE:
            return ""
        where = " in motion the model does not know" if self.unknown else ""
        held = f"({1.0 - self.motion:.0%} of the model's move held back) rather than invent a move"
        if back:
            return (f"The clip starts at rest{where}, so the {self.seconds:.2f} s before it stay near its first pose "
                    f"{held}: if the performer had just moved, key it or extend from a frame where the clip moves")
        return (f"The clip has come to rest{where}, so its first {self.seconds:.2f} s stay near the last pose "
                f"{held}: if the performer was about to move, key it or extend from a frame where the clip still "
                "moves")


@dataclass(frozen=True)
class Following:
    """What *Follow the Clip* has to follow in a long extension (:func:`following`)."""
    seconds: float  # the clip it reads, in seconds
    needed_s: float  # the least that lets a long continuation play on through the clip (memory.play_frames)
    from_s: float  # from when the continuation plays on through the clip (memory.LONG_FROM windows)
    stands: bool  # the clip stands where it is (memory.stands): a clip too short to play on is played back and forth
    cycle_s: float  # how often such a clip comes round again as it is played on (memory.cycle_frames; 0: long enough)

    @property
    def plays(self) -> str:
        """How a clip too short to play on through is played on (:func:`memory.played_on`): "back and forth" where
        it stands, else "round"; empty where the clip is long enough."""
        if self.seconds >= self.needed_s:
            return ""
        return "back and forth" if self.stands else "round"

    def note(self) -> str:
        """A sentence for the operator's report; empty unless the clip is too short to play on through."""
        if not self.plays:
            return ""
        return (f"The action gives Follow the Clip {self.seconds:.2f} s to follow, under the {self.needed_s:.2g} s "
                f"it needs to play on through, so after the first {self.from_s:.1f} s the new frames play it "
                f"{self.plays}, over and over (every {self.cycle_s:.1f} s): extend a longer action for a continuation "
                "that plays on, or turn Follow the Clip off for the model's own continuation")


def following(engine, memory: np.ndarray, fps: float, frames: int) -> Following | None:
    """What :func:`extend_positions` has to follow in ``memory`` ``[M, 21, 3]`` at ``fps`` for an extension of
    ``frames`` scene frames, for the operator's report; None where the extension ends before it plays on through the
    clip (:data:`memory.LONG_FROM`), so the clip's length does not matter."""
    window_s, long_from = engine.n / MODEL_FPS, clip_memory.LONG_FROM
    if long_from is None or frames / fps <= long_from * window_s:
        return None
    available = model_frames_available(len(memory), fps)
    stands, cycle = False, 0
    if available < clip_memory.play_frames(engine.m, engine.n):  # where it matters: at the model's rate and scale
        clip = _at_model_rate(memory, fps)  # (the engine reads it on the body it learnt where the rig is unlike it)
        feats = positions_to_features(fit_normalisation(clip).to_model(clip))[0]
        stands, cycle = clip_memory.stands(feats), clip_memory.cycle_frames(feats)
    return Following(available / MODEL_FPS, clip_memory.play_frames(engine.m, engine.n) / MODEL_FPS,
                     long_from * window_s, stands, cycle / MODEL_FPS)


def extend_positions(engine, pos: np.ndarray, fps: float, frames: int, memory: np.ndarray | None = None,
                     floor: float | None = None) -> np.ndarray:
    """Continue a clip ``[F, 21, 3]`` (Y-up, scene units, ``fps``) by ``frames`` scene frames.

    The context is resampled to the model's rate aligned on its LAST frame, so the new
    frames follow it at exactly 1 / fps. ``memory`` ``[M, 21, 3]`` (the same space and rate, ending on the
    same frame as ``pos``; usually more of the clip before it): the clip's own motion, which each predicted
    window leans on where the continuation comes back to something the clip did (the first only as far as the
    model does not know the context's motion: :func:`inference.memory.first_scale`). Where the model does not
    know the motion and the clip has come to rest, the first window stays near the last pose (:func:`first_motion`),
    the window after it eased in (:func:`eased_after_hold`),
    and as far as it does not know it, the first two windows lean on the release's regularised model
    (:meth:`Engine.extrapolate`'s ``unfamiliar``).
    A long continuation that settles into a stance stands where it is (:func:`stance.settle_stances`), and no
    new frame's feet go under the floor the clip stands on (:func:`stance.ground`): ``floor`` (a height in the same
    space), by default :func:`clip_floor` of ``memory`` (else of ``pos``). Every new frame is on the clip's bones
    (:func:`skeleton.join_clip`), which the seam, moving each joint by its own offset, would stretch, and so is
    every frame between the model's at another rate than its (:func:`skeleton.sampled_on_bones`).
    Returns ``[frames, 21, 3]`` in the same space.
    """
    ctx, norm, model_ctx, momentum = _reading(engine, pos, fps, memory)
    n_model = int(math.ceil(frames * MODEL_FPS / fps)) + 1
    looked = ctx if memory is None else _at_model_rate(memory, fps)  # the clip at the model's rate
    kw = {} if memory is None else {"memory": norm.to_model(looked), "first_scale": first_scale(momentum)}
    still = first_motion(model_ctx, momentum)
    if still < 1.0:
        kw["first_motion"] = still
    if momentum > 0:  # the first windows lean on the release's regularised model as far as the motion is unfamiliar
        kw["unfamiliar"] = momentum
    if floor is None:
        floor = clip_floor(pos if memory is None else memory, fps)
    kw["floor"] = (floor - norm.ground) * norm.scale  # in the model's units, as Normalisation.to_model puts it
    new = np.asarray(engine.extend(model_ctx, n_model, settle=True, **kw), dtype=np.float64)
    if still < 1.0 and EASE_AFTER_HOLD:
        new = eased_after_hold(new, engine.n)
    # model frame 0 is the last context frame; a first window held near the last pose coasts to a stop from the
    # clip's last motion as far as it is held (seam.blend_seam's coast), rather than carrying it on and coming back
    coast = {"coast": 1.0 - still, "coast_frames": engine.n} if still < 1.0 else {}
    joined = join_clip(ctx, norm.to_user(new), momentum, **coast)
    if _steps_in_place(looked):  # a walk in place goes on in place
        joined = np.concatenate([joined[:1], kept_in_place(looked, joined[1:])])
    return sampled_on_bones(joined, np.arange(1, frames + 1) * (MODEL_FPS / fps))  # at the scene's rate


def stalled_end(pos: np.ndarray, fps: float) -> bool:
    """Whether a clip ``[F, 21, 3]`` (scene units, ``fps``; in the order it is read, so the end is where it is
    continued) ends on a stalled frame (:data:`STALL_SHARE`): its last frame nearly repeats the one before while the
    body was moving. False for a clip of under ``STALL_FRAMES + 2`` frames."""
    pos = np.asarray(pos, dtype=np.float64)
    if STALL_SHARE <= 0 or len(pos) < STALL_FRAMES + 2:
        return False
    unit = leg_length(pos) / STANDARD_LEG_LENGTH
    step = np.linalg.norm(np.diff(pos[-STALL_FRAMES - 2:], axis=0), axis=-1).mean(1) * fps / unit  # m/s, standard body
    before = float(step[:-1].mean())
    return before >= STALL_SPEED and step[-1] < STALL_SHARE * before and step[-2] >= 0.5 * float(step[:-2].mean())


def eased_after_hold(new: np.ndarray, n: int, frames: int = SEAM_FRAMES) -> np.ndarray:
    """A continuation ``[N, 21, 3]`` whose first ``n`` frames were held near the last pose, with the window after them
    eased in: the model reads the held window as a body at rest and starts its next window at its own pace at once,
    a jump into motion. Its first ``frames`` frames are retimed along the model's path (a cubic time warp) so that
    the body leaves the held window at the pace it had there and meets the model's own frames, at their pace,
    ``frames`` frames on. A next window no faster than the held one is left as it is."""
    k = min(frames, len(new) - n)
    if k < 2 or n < 2:
        return new
    out = np.array(new, dtype=np.float64)
    pace = lambda a, b: float(np.linalg.norm(out[b] - out[a], axis=-1).mean())  # noqa: E731
    held, next_ = pace(n - 2, n - 1), pace(n - 1, n)
    if next_ <= held:
        return new
    start = held / next_  # the warp's pace at its start, as a share of the model's
    u = np.arange(k + 1) / k
    when = k * (-2 * u ** 3 + 3 * u ** 2 + start * (u ** 3 - 2 * u ** 2 + u) + u ** 3 - u ** 2)  # Hermite, 0 .. k
    out[n - 1:n + k] = interpolate_frames(out[n - 1:n + k], when)  # along the held window's last frame and the next k
    return out


def floor_rise(clip: np.ndarray, fps: float) -> np.ndarray | None:
    """How much higher ``[F]`` than at its last frame the floor under a clip ``[F, 21, 3]`` (Y-up, any units, ``fps``)
    is at each frame, where it rises or falls by more than :data:`FLOOR_RISE_M` (a walk up stairs or a slope, read
    from the clip alone); None where the floor is flat, or where the feet seldom stand still (a body that rises or
    falls as a whole, a flight, is no floor that does). The floor: the lowest heel or toe standing still (slower
    than :data:`FLOOR_STILL` in any direction for :data:`FLOOR_STAND_S` or more), its lowest over
    :data:`FLOOR_RISE_S` about each frame, smoothed over a quarter second."""
    clip = np.asarray(clip, np.float64)
    unit = leg_length(clip) / STANDARD_LEG_LENGTH
    feet = clip[:, CONTACT_JOINTS]  # [F, 4, 3]
    speed = np.zeros(feet.shape[:2])
    if len(clip) > 1:
        step = np.linalg.norm(np.diff(feet, axis=0), axis=-1) * fps / unit
        speed[1:], speed[0] = step, step[0]
    standing = _long_runs(speed < FLOOR_STILL, max(2, int(np.ceil(FLOOR_STAND_S * fps))))
    still = np.where(standing, feet[..., UP_AXIS], np.inf).min(axis=1)
    found = np.isfinite(still)
    if found.mean() < 0.25:
        return None
    frames = np.arange(len(clip))
    low = np.interp(frames, frames[found], still[found])
    half = max(1, int(round(FLOOR_RISE_S * fps / 2)))
    running = np.lib.stride_tricks.sliding_window_view(np.pad(low, half, mode="edge"), 2 * half + 1).min(-1)
    profile = gaussian_smooth(running, 0.25 * fps)
    rise = profile - profile[-1]
    return rise if np.abs(rise).max() > FLOOR_RISE_M * unit else None


def _long_runs(mask: np.ndarray, frames: int) -> np.ndarray:
    """``mask`` ``[F, K]`` with each column's runs of on-frames shorter than ``frames`` switched off."""
    out = np.zeros(mask.shape, bool)
    for k in range(mask.shape[1]):
        edges = np.flatnonzero(np.diff(np.r_[0, mask[:, k].astype(np.int8), 0]))
        for start, stop in zip(edges[::2], edges[1::2]):
            if stop - start >= frames:
                out[start:stop, k] = True
    return out


def clip_floor(clip: np.ndarray, fps: float) -> float:
    """The floor (:func:`features.floor_height`) of the last :data:`FLOOR_S` seconds of a clip ``[F, 21, 3]`` at
    ``fps``: the ground the new frames' feet are kept out of."""
    return floor_height(clip[-max(2, int(round(FLOOR_S * fps))):])


def first_window(engine, pos: np.ndarray, fps: float, memory: np.ndarray | None = None) -> FirstWindow:
    """What :func:`extend_positions` does with the first window after the clip ``pos`` (same arguments): how
    much of its motion it keeps, for the operator's report."""
    _, _, model_ctx, momentum = _reading(engine, pos, fps, memory)
    return FirstWindow(first_motion(model_ctx, momentum), engine.n / MODEL_FPS, bool(momentum > 0.5))


def _reading(engine, pos: np.ndarray, fps: float, memory: np.ndarray | None):
    """The context Extend reads of the clip ``pos`` (and ``memory``, for a model that reads more than the clip's
    context): (context at the model's rate ``[T, 21, 3]``, its normalisation, the context in model units, the
    context's momentum share)."""
    ctx = _at_model_rate(pos, fps)
    if memory is not None and len(ctx) < engine.m:  # a model that reads more than the clip's context: more of it
        longer = _at_model_rate(memory, fps)
        ctx = longer[-engine.m:] if len(longer) > len(ctx) else ctx
    norm = fit_normalisation(ctx)
    model_ctx = norm.to_model(ctx)
    return ctx, norm, model_ctx, momentum_shares(engine, model_ctx[None])[0]


def first_motion(ctx: np.ndarray, momentum: float) -> float:
    """How much of its motion the first window after a context ``[T, 21, 3]`` (model units and rate) keeps: less
    the more the clip has come to rest, under :data:`STILL_SPEED` where the model does not know the motion (momentum
    share 1) and under :data:`STILL_KNOWN_SPEED` where it does (0). :data:`STILL_SPEED` 0 turns both off."""
    if STILL_SPEED <= 0.0 or len(ctx) < 2:
        return 1.0
    speed = float(np.linalg.norm(np.diff(ctx[-STILL_FRAMES - 1:], axis=0), axis=-1).mean())
    unknown = float(np.clip(momentum, 0.0, 1.0))
    return 1.0 - unknown * _rest(speed, STILL_SPEED) - (1.0 - unknown) * _rest(speed, STILL_KNOWN_SPEED)


def _rest(speed: float, threshold: float) -> float:
    """How far a clip whose joints move ``speed`` a model frame is at rest, under ``threshold`` (0: never)."""
    return 1.0 - min(1.0, speed / threshold) ** STILL_POWER if threshold > 0.0 else 0.0


def _at_model_rate(pos: np.ndarray, fps: float) -> np.ndarray:
    """A clip ``[F, 21, 3]`` at ``fps`` resampled to the model's rate, aligned on its last frame."""
    duration = (len(pos) - 1) / fps
    return sample_at(pos, fps, duration - np.arange(model_frames_available(len(pos), fps))[::-1] / MODEL_FPS)
