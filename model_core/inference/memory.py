"""The clip's own motion as a memory for long continuations (no torch needed).

Window after window, a continuation of motion the model has not seen settles into motion it knows: an
unseen actor's walk, extended by 20 s, turned into a two-footed hop or a stand within seconds. The clip
itself shows how this person moves. So each predicted window after the first leans on the clip: the
stretch of the clip whose last :data:`MATCH_FRAMES` frames are most like the continuation's last ones is
found (features normalised by the model's own spread), and the frames that followed it in the clip are
blended into the model's window by ``SHARE * exp(-distance / SCALE)``: much where the clip has been here
before (a walk's next step), nothing where it has not (a clip that ends in a pose it never held before).
The frames that followed are first moved to start where the continuation stands (their jump from it fades
out over :data:`ALIGN_FRAMES`) and, after the first window, to go on at its pace (:func:`aligned_offsets`), so no
window pops. The first window leans on the clip as well where Extend Clip asks it to (:func:`first_scale`): only
where the clip did just this before, and less where the model knows the motion. The features are the body's own
(root-local joints, the root's velocity in the body's frame, the turn rate), so a stretch of the clip fits wherever
the continuation has walked to. Chosen on the held-out groups (model card, "Extend follows the clip").
"""

from __future__ import annotations

from functools import cached_property

import numpy as np

from ..motion.conventions import LAYOUT, MODEL_FPS
from ..motion.stance import STANCE_SHARE

SHARE = 0.8  # the clip's share of a window where its frames match the continuation's exactly
SCALE = 1.0  # the mean squared normalised distance at which the share has fallen to SHARE / e
MATCH_FRAMES = 10  # how many of the continuation's last frames are compared with the clip's
ALIGN_FRAMES = 10  # over how many frames the followed stretch's jump from the continuation fades out
# Where a window after the first takes a stretch of the clip, its frames go on at the continuation's pace and turn to
# the stretch's over ALIGN_FRAMES (memory.aligned_offsets), instead of at once. False: the jump alone fades out.
ALIGN_VELOCITY = True
# The first window leans on the clip too, where the clip did just this before (a drill's next kick, a walk's
# next step): by exp(-distance / scale), the scale FIRST_SCALE where the model does not know the context's
# motion (momentum share 1) and FIRST_FAMILIAR x that where it does (0), so that familiar motion is left to
# the models unless the clip matches almost exactly. 0: the first window is the models' alone.
FIRST_SCALE, FIRST_FAMILIAR = 0.3, 0.1
# From the window LONG_FROM on (past the first second and a third, which the models predict well) a continuation
# leans harder on the clip: share LONG_SHARE, scale LONG_SCALE, so that it goes on doing what the clip did instead
# of settling, window by window, into the still idle the models fall back on (a wave extended by 20 s stopped
# waving within 5 s). There it also plays on: the stretch after the one it just followed is taken where it matches
# within PLAYHEAD_TIE of the best, and the one just followed (or a neighbour) is never taken again at once, so a
# clip that ends in a pause does not replay its pause for ever. Chosen on the held-out groups and the validation
# split (model card, "Long extensions play on"). LONG_FROM None: every window leans as the second does.
LONG_FROM, LONG_SHARE, LONG_SCALE, PLAYHEAD_TIE = 2, 0.9, 10.0, 0.1
# What the clip followed over the last RECENT windows (and their neighbours) is not taken again from LONG_FROM on,
# where a stretch elsewhere is left: a clip that ends in a pause neither replays its last window for ever nor
# ping-pongs between its last few (a fighter's closing guard looped in 1.3 s cycles for a minute); where the clip
# runs out, the continuation goes back to where it matches best outside them and plays on from there. Where that
# leaves under a window's worth of the clip (a clip of a cycle or two), the oldest are let go first. Chosen on the
# held-out groups and the validation split (models/strnn_default/HISTORY.md, "a long extension no longer loops the
# clip's last seconds"): 10 s. 1: only the stretch just followed.
RECENT = 15
# A clip too short to play on through (under play_frames: a raised hand of 1.5 s) offers no two stretches a window
# apart, so from LONG_FROM on a continuation following it kept repeating one window of it for ever (the arms pumping
# in a 0.67 s cycle at 0.2 to 0.8 x the take's speed). There the long windows follow the clip played on instead
# (played_on): back and forth where the clip stands (raised hands come down the way they went up, never faster than
# the clip moves them), round where it does not (a run goes on from a stride before its end, in step; played
# backwards, a run or a walk on the spot would step backwards). It stands where its root's mean ground speed is under
# TRAVEL_SPEED and every heel and toe is down in stance.STANCE_SHARE of its frames (459 of the data's 463 clips under
# 2 s stand, all raised hands; the 4 others run). Chosen on the validation split's 17 clips under 2 s
# (models/strnn_default/HISTORY.md, "a clip too short to play on is played back and forth").
TRAVEL_SPEED = 0.3  # m / s (the long horizon's locomotion threshold)
# A long continuation that travels does not go back to where the clip starts from a stand: its stretches before the
# root first reaches START_SHARE x the clip's cruising speed (smoothed over START_SMOOTH frames) are left out of the
# places it goes back to where the clip runs out (a 4.4 s walk from a stand, extended by 20 s, slowed to under half
# its pace every 3.3 s, each time it went back to its first steps). None: no stretch is left out.
START_SHARE, START_SMOOTH = 0.75, 5
# Where played_on turns back or goes round, the motion is eased over EASE_FRAMES either side (_eased): a raised hand
# cut while still rising turned back at once, a bounce up to 3.3 x as hard as any in its take; eased over 2 frames,
# 1.1 x, the hands as fast as before (over 4: every turn softer than the take's, the hands' fastest 10 % slower).
# Chosen on the validation split's 17 clips under 2 s (HISTORY.md, as above).
EASE_FRAMES = 2
# The channels compared: joint positions and root motion (contacts follow the motion, they are not matched).
_CHANNELS = np.r_[np.arange(LAYOUT.size)[LAYOUT.positions], np.arange(LAYOUT.size)[LAYOUT.root]]


class ClipMemory:
    """What a clip ``[F, C]`` (raw features at the model's rate) did after each of its stretches, for a model
    that reads ``m`` frames and predicts ``n`` (``std``: its features' spread, ``[C]``)."""

    def __init__(self, feats: np.ndarray, m: int, n: int, std: np.ndarray, first_scale: float | None = None):
        self.feats = np.asarray(feats, np.float32)
        self.m, self.n, self.std = m, n, std
        self.first_scale = first_scale  # the first window's scale (:func:`first_scale`; None: not leant on)
        self.scale = np.asarray(std, np.float32)[_CHANNELS]
        self.recent: list[int] = []  # the stretches followed in the last RECENT windows (index into ends), oldest first
        self.playhead = None  # the stretch that follows it, where the clip goes on
        first = max(m, MATCH_FRAMES)  # a stretch ends at frame e - 1 and is followed by frames e .. e + n - 1
        self.ends = np.arange(first, len(self.feats) - n + 1)
        self.keys = np.stack([self.feats[e - MATCH_FRAMES:e, _CHANNELS] for e in self.ends]) / self.scale \
            if len(self.ends) else np.zeros((0, MATCH_FRAMES, len(_CHANNELS)), np.float32)

    @cached_property
    def played_on(self) -> ClipMemory | None:
        """What the long windows of a clip too short to play on through follow (:func:`played_on`; None: the clip
        itself), made the first time a long window asks: an extension that ends before :data:`LONG_FROM` never
        makes it."""
        if not MATCH_FRAMES < len(self.feats) < play_frames(self.m, self.n):
            return None
        long_enough = max(play_frames(self.m, self.n), (RECENT + 3) * self.n)  # never short of what the rule leaves
        return ClipMemory(played_on(self.feats, long_enough), self.m, self.n, self.std)

    @property
    def last(self) -> int | None:
        """The stretch last followed (index into ends; None before the first window)."""
        return self.recent[-1] if self.recent else None

    def __len__(self) -> int:
        """How many stretches the clip offers (0: too short to lean on)."""
        return len(self.ends)

    def follow(self, context: np.ndarray, first: bool = False, window: int = 1) -> tuple[float, np.ndarray]:
        """(the clip's share, the ``n`` frames ``[n, C]`` that followed its stretch nearest ``context`` ``[T, C]``,
        moved to start where ``context`` ends); share 0 (and the context's last frame held) without stretches.
        ``window``: the rollout's window this is for (0 the first; from :data:`LONG_FROM` on the clip plays on,
        a clip too short for that :func:`played_on`)."""
        long = not first and LONG_FROM is not None and window >= LONG_FROM
        if long and self.played_on is not None:
            return self.played_on.follow(context, first, window)
        last = np.asarray(context[-1], np.float32)
        if not len(self.ends):
            return 0.0, np.repeat(last[None], self.n, 0)
        probe = np.asarray(context[-MATCH_FRAMES:, _CHANNELS], np.float32) / self.scale
        distance = ((self.keys - probe) ** 2).mean((1, 2))
        pool = self._past_start_up(distance) if long and _travels(context) else distance
        allowed = self._unfollowed(pool) if long and self.recent else pool  # not what was just followed
        best = int(np.argmin(allowed))
        # the playhead goes forward only, so it never loops: it is exempt from the rule above
        if long and self.playhead is not None and distance[self.playhead] <= distance[best] + PLAYHEAD_TIE:
            best = self.playhead
        self.recent = (self.recent + [best])[-max(1, RECENT):]
        # where the clip goes on: the stretch a window on, or its last where it ends sooner (its last frames are played)
        self.playhead = min(best + self.n, len(self.ends) - 1) if best < len(self.ends) - 1 else None
        end = self.ends[best]
        frames = self.feats[end:end + self.n].copy()
        frames += aligned_offsets(self.n, last - self.feats[end - 1],
                                  None if first or not ALIGN_VELOCITY else _turn(context, self.feats[end - 2:end]))
        if first:
            return float(np.exp(-distance[best] / self.first_scale)) if self.first_scale else 0.0, frames
        share, scale = (LONG_SHARE, LONG_SCALE) if long else (SHARE, SCALE)
        return float(share * np.exp(-distance[best] / scale)), frames

    @cached_property
    def start_up(self) -> int:
        """How many of the clip's first stretches are followed by its start from a stand: those that end before
        its root's ground speed (over :data:`START_SMOOTH` frames) first reaches :data:`START_SHARE` x its cruising
        speed (the median where it travels, over :data:`TRAVEL_SPEED`). 0 where the clip starts on the move or
        travels for under a window."""
        if START_SHARE is None or not len(self.ends):
            return 0
        speed = _ground_speed(self.feats)
        k = min(START_SMOOTH, len(speed))
        speed = np.convolve(speed, np.ones(k) / k, mode="valid")
        moving = speed >= TRAVEL_SPEED
        if moving.sum() < self.n:
            return 0
        cruising = np.flatnonzero(speed >= START_SHARE * float(np.median(speed[moving])))
        return int(np.searchsorted(self.ends, cruising[0])) if len(cruising) else 0

    def _past_start_up(self, distance: np.ndarray) -> np.ndarray:
        """``distance`` with the stretches of the clip's :attr:`start_up` ruled out, where any other is left."""
        if not 0 < self.start_up < len(distance):
            return distance
        out = distance.copy()
        out[:self.start_up] = np.inf
        return out

    def _unfollowed(self, distance: np.ndarray) -> np.ndarray:
        """``distance`` with the stretches followed in the last :data:`RECENT` windows and their neighbours ruled out;
        where that leaves under a window's worth of stretches (a short clip) the oldest are let go first, so that a
        clip of a cycle or two plays its cycle, and the one just followed stays ruled out while anything is left."""
        for k in range(len(self.recent), 0, -1):
            out = self._without(distance, self.recent[-k:])
            left = np.isfinite(out).sum()
            if left >= self.n or (k == 1 and left):
                return out
        out = np.full_like(distance, np.inf)  # a clip too short for anything else: the stretch just followed
        out[self.last] = distance[self.last]
        return out

    def _without(self, distance: np.ndarray, followed: list[int]) -> np.ndarray:
        """``distance`` with each stretch of ``followed`` and those within a window of it ruled out (infinite)."""
        out = distance.copy()
        for r in followed:
            out[max(0, r - self.n + 1):r + self.n] = np.inf
        return out

    def lean(self, context: np.ndarray, predicted: np.ndarray, first: bool = False, window: int = 1) -> np.ndarray:
        """``predicted`` ``[n, C]`` (the model's window after ``context`` ``[T, C]``; ``first``: the rollout's
        first) blended with what followed the clip's nearest stretch by its share (:meth:`follow`)."""
        share, frames = self.follow(context, first, window)
        return predicted + share * (frames[:len(predicted)] - predicted) if share > 0 else predicted


def aligned_offsets(n: int, jump: np.ndarray, turn: np.ndarray | None = None, over: int = ALIGN_FRAMES) -> np.ndarray:
    """What is added ``[n, C]`` to the ``n`` frames that followed a stretch of the clip so that they go on from where
    the continuation stands: its ``jump`` ``[C]`` (the continuation's last frame less the stretch's; contacts are
    left alone) faded out over ``over`` frames, linearly where ``turn`` is None (a window's first, whose seam the
    clip's own joins), else on a cubic Hermite that also takes out ``turn`` ``[C]``, the difference in the joints'
    velocity (:func:`_turn`), so that the motion goes on at the continuation's pace and turns to the stretch's
    over those frames instead of at once. On martial arts the joints' acceleration on the last frame of the second
    to fifth windows went 1.55 / 0.90 / 1.19 / 1.52 -> 0.90 / 0.76 / 0.85 / 1.14 cm a frame squared (0.60 between
    other frames), for no change at 1 s (models/strnn_default/HISTORY.md, "a stretch of the clip taken at the
    continuation's pace")."""
    jump = np.array(jump, np.float32)
    jump[LAYOUT.contacts] = 0.0
    k = np.arange(1, n + 1, dtype=np.float32)[:, None]
    if turn is None:
        return np.clip(1.0 - k / over, 0.0, 1.0) * jump
    t = np.minimum(k / over, 1.0)
    return (2 * t ** 3 - 3 * t ** 2 + 1) * jump + (t ** 3 - 2 * t ** 2 + t) * over * turn


def _turn(context: np.ndarray, stretch_end: np.ndarray) -> np.ndarray | None:
    """The continuation's last step (``context`` ``[T, C]``) less the clip's into the last frame of the stretch it
    matched (``stretch_end``: the stretch's last two frames ``[2, C]``), on the joints' positions only (zero
    elsewhere): none where the continuation moves as the clip did there. None for a context of one frame."""
    if len(context) < 2:
        return None
    turn = np.zeros(context.shape[-1], np.float32)
    step = np.asarray(context[-1], np.float32) - np.asarray(context[-2], np.float32)
    turn[LAYOUT.positions] = (step - (stretch_end[1] - stretch_end[0]))[LAYOUT.positions]
    return turn


def _ground_speed(feats: np.ndarray) -> np.ndarray:
    """The root's ground speed ``[F]`` (m / s on the learnt body) of raw features ``[F, C]``."""
    return np.linalg.norm(np.asarray(feats)[:, LAYOUT.velocity], axis=-1) * MODEL_FPS


def _travels(context: np.ndarray) -> bool:
    """Whether a continuation ``[T, C]`` travels: its root's mean ground speed over its last :data:`MATCH_FRAMES`
    frames at least :data:`TRAVEL_SPEED`."""
    return float(_ground_speed(context[-MATCH_FRAMES:]).mean()) >= TRAVEL_SPEED


def play_frames(m: int, n: int) -> int:
    """The fewest frames (the model's rate) a clip needs for a long continuation to play on through it, for a model
    that reads ``m`` frames and predicts ``n``: two of its stretches a window apart. In a shorter clip every long
    window would follow the same stretch, repeating its ``n`` frames; they follow the clip :func:`played_on`."""
    return max(m, MATCH_FRAMES) + 2 * n


def stands(feats: np.ndarray) -> bool:
    """Whether a clip ``[F, C]`` (raw features at the model's rate) stands where it is: its root's mean ground speed
    under :data:`TRAVEL_SPEED` and every heel and toe down in ``STANCE_SHARE`` of its frames (raised or waving
    hands, a bow). Such a clip too short to play on through is played back and forth, any other round
    (:func:`played_on`)."""
    feats = np.asarray(feats)
    speed = float(_ground_speed(feats).mean())
    return speed < TRAVEL_SPEED and float((feats[:, LAYOUT.contacts] > 0.5).all(-1).mean()) >= STANCE_SHARE


def played_on(feats: np.ndarray, frames: int) -> np.ndarray:
    """A clip ``[F, C]`` (raw features at the model's rate) played on to at least ``frames`` frames: back and forth
    where it :func:`stands` (played backwards, the root's velocity and turn reversed), round where it does not (each
    repeat going on from the frame most like the clip's end, :func:`_most_like_the_end`, so a run's next stride is in
    step, moved to start where the last ended, the jump fading out over :data:`ALIGN_FRAMES` as a followed stretch's
    does). Each part starts on the frame the last ended on, the motion eased there (:data:`EASE_FRAMES`)."""
    feats = np.asarray(feats, np.float32)
    if stands(feats):
        back = feats[::-1].copy()
        back[:, LAYOUT.root] *= -1.0
        cycle = [back[1:], feats[1:]]
    else:
        start = _most_like_the_end(feats)
        again = feats[start:].copy()
        jump = feats[-1] - feats[start]
        jump[LAYOUT.contacts] = 0.0
        again += np.clip(1.0 - np.arange(len(again)) / ALIGN_FRAMES, 0.0, 1.0)[:, None] * jump
        cycle = [again[1:]]
    parts, total, joins = [feats], len(feats), []
    while total < frames:
        part = cycle[(len(parts) - 1) % len(cycle)]
        parts.append(part)
        joins.append(total - 1)
        total += len(part)
    return _eased(np.concatenate(parts), joins, EASE_FRAMES)


def cycle_frames(feats: np.ndarray) -> int:
    """How many frames a clip ``[F, C]`` too short to play on through takes to come round again as
    :func:`played_on` plays it: there and back where it :func:`stands`, else from its end's look-alike to its end."""
    feats = np.asarray(feats)
    return 2 * (len(feats) - 1) if stands(feats) else len(feats) - 1 - _most_like_the_end(feats)


def _most_like_the_end(feats: np.ndarray, frames: int = 5) -> int:
    """The frame of a clip ``[F, C]`` whose last ``frames`` frames are most like the clip's last ones, at least
    :data:`ALIGN_FRAMES` before its end (a repeat's jump fades out before it repeats again): where a stepping clip
    goes on from, in step (0 for a clip too short to tell)."""
    k = max(1, min(frames, len(feats) // 4))
    last = feats[len(feats) - k:, _CHANNELS]
    candidates = np.arange(k - 1, len(feats) - 1 - ALIGN_FRAMES)
    if not len(candidates):
        return 0
    distance = [float(((feats[i - k + 1:i + 1, _CHANNELS] - last) ** 2).mean()) for i in candidates]
    return int(candidates[int(np.argmin(distance))])


def _eased(feats: np.ndarray, joins: list[int], k: int) -> np.ndarray:
    """``feats`` ``[F, C]`` with the motion around each of the frames ``joins`` eased: within ``k`` frames of it the
    frame is the mean of the ``2k + 1`` around it, the share of the mean fading to nothing over ``k`` more frames,
    so a hand that turns back there slows to its turn instead of bouncing off it. Contacts are left as they are."""
    if k <= 0 or not joins:
        return feats
    padded = np.concatenate([np.repeat(feats[:1], k, 0), feats, np.repeat(feats[-1:], k, 0)])
    sums = np.concatenate([np.zeros((1, feats.shape[1]), feats.dtype), np.cumsum(padded, 0, dtype=np.float64)])
    mean = (sums[2 * k + 1:] - sums[:-2 * k - 1]) / (2 * k + 1)
    off = np.abs(np.arange(len(feats))[:, None] - np.asarray(joins)[None]).min(1)
    share = np.clip(2.0 - off / k, 0.0, 1.0)[:, None]
    out = (feats + share * (mean - feats)).astype(feats.dtype)
    out[:, LAYOUT.contacts] = feats[:, LAYOUT.contacts]
    return out


def first_scale(momentum: float) -> float | None:
    """The first window's scale for a context whose momentum share is ``momentum`` (:data:`FIRST_SCALE`)."""
    if FIRST_SCALE <= 0.0:
        return None
    return FIRST_SCALE * (FIRST_FAMILIAR + (1.0 - FIRST_FAMILIAR) * float(np.clip(momentum, 0.0, 1.0)))
