"""The clip's own motion as a memory for long continuations (model_core/inference/memory.py)."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.inference import memory as mem
from model_core.inference.engine import Engine
from model_core.inference.memory import ClipMemory
from model_core.motion.conventions import CONTACT_JOINTS, LAYOUT
from model_core.motion.features import positions_to_features
from model_core.motion.synthetic import walking_skeleton


def walk_features(frames: int = 200) -> np.ndarray:
    return positions_to_features(walking_skeleton(frames))[0]


def test_a_stretch_of_the_clip_is_followed_by_what_came_after_it():
    feats = walk_features()
    clip = ClipMemory(feats, 20, 20, np.ones(LAYOUT.size, np.float32))
    assert len(clip) == len(feats) - 20 - 20 + 1
    share, frames = clip.follow(feats[60:100])  # the continuation is back where the clip was at frames 90-99
    assert share == pytest.approx(mem.SHARE, rel=1e-5)
    np.testing.assert_allclose(frames, feats[100:120], atol=1e-5)


def test_the_followed_frames_start_where_the_continuation_stands():
    feats = walk_features()
    clip = ClipMemory(feats, 20, 20, np.ones(LAYOUT.size, np.float32))
    context = feats[60:100].copy()
    context[-2:, LAYOUT.positions] += 0.02  # the continuation's last frames are 2 cm from the clip's (at its pace)
    share, frames = clip.follow(context)
    assert 0 < share < mem.SHARE
    jump = frames - feats[100:120]
    t = 1 / mem.ALIGN_FRAMES  # faded out on a cubic that leaves the pace alone at the start
    np.testing.assert_allclose(jump[0, LAYOUT.positions], 0.02 * (2 * t ** 3 - 3 * t ** 2 + 1), atol=1e-5)
    assert np.abs(jump[mem.ALIGN_FRAMES - 1:]).max() < 1e-5  # faded out
    assert np.all(np.diff(jump[:mem.ALIGN_FRAMES, LAYOUT.positions][:, 0]) < 0)


def test_a_later_windows_stretch_goes_on_at_the_continuations_pace(monkeypatch):
    """After the first window, the followed frames start where the continuation stands and at its pace (here a step
    2 cm longer than the clip's into the matched frame), then turn to the clip's own frames and pace by
    ALIGN_FRAMES; with ALIGN_VELOCITY off (and in the first window, whose seam is the clip's) the jump alone fades
    out, and the first step keeps the clip's pace."""
    feats = walk_features()
    context = feats[60:100].copy()
    context[-1, LAYOUT.positions] += 0.02
    pos = LAYOUT.positions
    pace = context[-1, pos] - context[-2, pos]

    def first_step(**kw):
        _, frames = ClipMemory(feats, 20, 20, np.ones(LAYOUT.size, np.float32)).follow(context, **kw)
        return frames, np.abs(frames[0, pos] - context[-1, pos] - pace).mean()

    frames, off_pace = first_step(window=1)
    np.testing.assert_allclose(frames[mem.ALIGN_FRAMES - 1:], feats[100 + mem.ALIGN_FRAMES - 1:120], atol=1e-5)
    first, off_pace_first = first_step(first=True)
    np.testing.assert_allclose(first[0, pos] - feats[100, pos], 0.02 * (1 - 1 / mem.ALIGN_FRAMES), atol=1e-5)
    monkeypatch.setattr(mem, "ALIGN_VELOCITY", False)
    _, off_pace_before = first_step(window=1)
    assert off_pace < 0.5 * off_pace_before and off_pace_first == pytest.approx(off_pace_before)
    offsets = mem.aligned_offsets(20, np.ones(LAYOUT.size), np.zeros(LAYOUT.size))
    assert np.all(offsets[:, LAYOUT.contacts] == 0) and np.all(np.diff(offsets[:, 0]) <= 0)


def test_motion_the_clip_never_did_gets_no_share():
    feats = walk_features()
    clip = ClipMemory(feats, 20, 20, np.full(LAYOUT.size, 0.01, np.float32))
    far = feats[60:100] + 0.5  # half a metre off in every channel, a hundred spreads
    share, _ = clip.follow(far)
    assert share < 1e-6
    predicted = np.zeros((20, LAYOUT.size), np.float32)
    np.testing.assert_allclose(clip.lean(far, predicted), predicted, atol=1e-5)


def test_a_clip_too_short_to_lean_on_is_followed_only_played_on():
    """A clip one frame short of a context and a window offers no stretch: the windows before ``LONG_FROM`` are the
    model's alone; the later ones follow the clip played on (``memory.played_on``)."""
    engine = Engine.load()
    pos = walking_skeleton(39)
    clip = ClipMemory(positions_to_features(pos)[0], engine.m, engine.n, engine.std)
    assert len(clip) == 0 and clip.played_on is not None
    early = mem.LONG_FROM * engine.n
    np.testing.assert_allclose(engine.extend(pos, early, memory=pos), engine.extend(pos, early), atol=1e-6)
    later = engine.extend(pos, early + engine.n, memory=pos) - engine.extend(pos, early + engine.n)
    assert np.abs(later[early:]).max() > 0.01


def test_the_first_window_is_the_models_and_later_windows_lean_on_the_clip():
    engine = Engine.load()
    pos = walking_skeleton(150)
    plain, leaning = engine.extend(pos[-20:], 60), engine.extend(pos[-20:], 60, memory=pos)
    np.testing.assert_allclose(leaning[:engine.n], plain[:engine.n], atol=1e-6)
    assert np.abs(leaning[engine.n:] - plain[engine.n:]).max() > 0.01


def test_the_first_window_leans_on_the_clip_when_asked_as_far_as_the_model_does_not_know_the_motion():
    """With a first-window scale the first window leans on the clip too (Extend Clip passes it); the scale is
    FIRST_FAMILIAR x smaller where the model knows the motion (momentum share 0) than where it does not."""
    engine = Engine.load()
    walk = walking_skeleton(300, radius=4.0)
    clip, truth = walk[:200], walk[200:220]
    plain = engine.extend(clip[-20:], 20, memory=clip)
    leaning = engine.extend(clip[-20:], 20, memory=clip, first_scale=mem.first_scale(1.0))
    assert np.abs(leaning - plain).max() > 0.01
    error = lambda p: np.linalg.norm(p - truth, axis=-1).mean()
    assert error(leaning) < 0.7 * error(plain)  # the clip walked this very step before
    assert mem.first_scale(0.0) == pytest.approx(mem.FIRST_FAMILIAR * mem.first_scale(1.0))
    assert mem.first_scale(1.0) == mem.FIRST_SCALE > 0


def test_extend_clip_follows_the_clip_from_its_first_frame():
    """extend_positions (Extend Clip's maths) passes the first-window scale for the context's familiarity."""
    from model_core.ops.extend import extend_positions

    engine = Engine.load()
    walk = 100 * walking_skeleton(300, radius=4.0)  # centimetres, as a scene may be
    clip, truth = walk[:200], walk[200:230]
    followed = extend_positions(engine, clip[-20:], 30.0, 30, memory=clip)
    alone = extend_positions(engine, clip[-20:], 30.0, 30)
    error = lambda p: np.linalg.norm(p - truth, axis=-1).mean()
    assert error(followed) < 0.7 * error(alone)


def test_a_model_that_reads_more_than_the_context_reads_the_rest_from_the_clip(tmp_path):
    """extend_positions with a model that reads a longer context than the frames Extend hands it (a release
    trained with ``--encode-len``): the missing frames come from the clip (the memory) before the context, so
    it continues as from the longer context; without a clip, the short context is led in by its first frame."""
    from releases import random_release

    from model_core.ops.extend import extend_positions

    random_release(tmp_path / "r", m=30, n=10, seed=2)
    engine = Engine.load(tmp_path / "r")
    clip = walking_skeleton(200, radius=4.0)
    short = extend_positions(engine, clip[-20:], 30.0, 25, memory=clip)
    np.testing.assert_allclose(short, extend_positions(engine, clip[-30:], 30.0, 25, memory=clip), atol=1e-9)
    assert np.abs(short - extend_positions(engine, clip[-20:], 30.0, 25)).max() > 1e-4  # the clip was read
    assert np.isfinite(extend_positions(engine, clip[-20:], 30.0, 25)).all()


def test_an_unseen_actors_walk_extended_by_20_s_still_steps(mocap_root):
    """The held-out CMU subject's first walk (60 fps; a take the model never saw), its first 10 s extended by 20 s
    as Extend Clip does: without the memory its last 5 s are a two-footed hop (the feet side by side, both
    off the floor a fifth of the time); with it the feet still swing past each other and stay on the floor."""
    from model_core.eval.evaluation import _at_rate
    from model_core.eval.extend_evaluation import feet_lead
    from model_core.model.dataset import load_folder
    from model_core.ops.extend import extend_positions

    clips = [c for c in load_folder(mocap_root, progress=False).group("actor") if c.name.endswith("006_01.bvh")]
    pos = _at_rate(clips, 60.0, str(mocap_root))[0][0][:600]
    engine = Engine.load()
    new = extend_positions(engine, pos[-41:], 60.0, 1200, memory=pos)
    last = new[-300:]
    floor = np.percentile(pos[:, CONTACT_JOINTS, 1].min(1), 5)
    airborne = np.mean(last[:, CONTACT_JOINTS, 1].min(1) - floor > 0.05)
    assert airborne < 0.03
    assert feet_lead(last) > 0.4 * feet_lead(pos[-300:])
    speed = lambda p: np.linalg.norm(np.diff(p - p[:, :1], axis=0), axis=-1).mean()  # noqa: E731
    assert 0.5 < speed(last) / speed(pos) < 1.5


def test_later_windows_play_on_through_the_clip_and_never_replay_the_stretch_just_followed():
    """From ``LONG_FROM`` on a continuation plays on through the clip (the stretch after the one it followed) and
    does not take the same stretch again at once: a clip that ends in a pause does not replay its pause for ever.
    Earlier windows keep taking the nearest stretch."""
    walk = walk_features(200)
    feats = np.concatenate([walk, np.repeat(walk[-1:], 60, 0)])  # walks, then stands for 2 s at its end
    still = feats[-40:]
    clip = ClipMemory(feats, 20, 20, np.ones(LAYOUT.size, np.float32))
    share, _ = clip.follow(still, window=mem.LONG_FROM)
    assert share == pytest.approx(mem.LONG_SHARE, rel=1e-4)  # the pause matches exactly: the clip's long share
    before = clip.last
    clip.follow(still, window=mem.LONG_FROM + 1)
    assert abs(clip.last - before) >= 20  # a pause elsewhere, not the same stretch again
    nearest = ClipMemory(feats, 20, 20, np.ones(LAYOUT.size, np.float32))
    nearest.follow(still, window=1)
    first = nearest.last
    nearest.follow(still, window=1)
    assert nearest.last == first  # the second window takes the nearest, as it always has
    going = ClipMemory(feats, 20, 20, np.ones(LAYOUT.size, np.float32))
    going.follow(walk[40:80], window=mem.LONG_FROM)
    followed = going.last
    going.follow(walk[40:100], window=mem.LONG_FROM + 1)  # the continuation did what the clip did next
    assert going.last == followed + 20


def _followed(clip: ClipMemory, context: np.ndarray, windows: int) -> list[int]:
    """The stretches (their ends' frames) ``clip`` follows over ``windows`` long windows from one ``context``: of
    the clip played on where it is too short to play on through (``ClipMemory.played_on``)."""
    out, followed = [], clip.played_on or clip
    for w in range(mem.LONG_FROM, mem.LONG_FROM + windows):
        clip.follow(context, window=w)
        out.append(int(followed.ends[followed.last]))
    return out


def test_a_continuation_at_rest_does_not_loop_the_clips_last_pause(monkeypatch):
    """A clip that walks for 800 frames and ends in a 2 s pause, continued at rest: from ``LONG_FROM`` on nothing
    followed in the last ``RECENT`` windows (or within a window of it) is followed again but where the clip plays
    on (the stretch after the one just followed, or the clip's last), so once the pause has been played the
    continuation goes back into the walk instead of swinging between two stretches of the pause (what it did with
    only the stretch just followed ruled out: a fighter's closing guard looped for a minute)."""
    walk = walk_features(800)
    feats = np.concatenate([walk, np.repeat(walk[-1:], 60, 0)])
    still = feats[-40:]
    ends = _followed(ClipMemory(feats, 20, 20, np.ones(LAYOUT.size, np.float32)), still, 2 * mem.RECENT)
    for i, e in enumerate(ends[1:], start=1):
        plays_on = 0 < e - ends[i - 1] <= 20
        assert plays_on or all(abs(e - f) >= 20 for f in ends[max(0, i - mem.RECENT):i]), ends
    assert min(ends) < 800  # back into the walk
    monkeypatch.setattr(mem, "RECENT", 1)
    looped = _followed(ClipMemory(feats, 20, 20, np.ones(LAYOUT.size, np.float32)), still, 2 * mem.RECENT)
    assert min(looped) >= 800 and len(set(looped)) <= 3  # within the pause, back and forth


def test_a_clip_of_a_cycle_or_two_plays_its_cycle(monkeypatch):
    """Where the clip offers too few stretches to keep ``RECENT`` windows apart (82 frames, one stride and a bit),
    the oldest are let go first, as long as a window's worth of stretches is left: the continuation follows the
    same stretches as with only the stretch just followed ruled out, never that one twice running, and plays the
    clip to its last stretch."""
    feats = walk_features(82)
    clip = ClipMemory(feats, 20, 20, np.ones(LAYOUT.size, np.float32))
    walking = _followed(clip, feats[-40:], 12)
    assert all(a != b for a, b in zip(walking, walking[1:])) and clip.ends[-1] in walking, walking
    monkeypatch.setattr(mem, "RECENT", 1)
    assert walking == _followed(ClipMemory(feats, 20, 20, np.ones(LAYOUT.size, np.float32)), feats[-40:], 12)


@pytest.mark.parametrize("short", [True, False])
def test_a_clip_shorter_than_play_frames_is_followed_played_on(short, monkeypatch):
    """``memory.play_frames`` is where a clip starts to offer two stretches a window apart. One frame shorter, every
    long window followed the same stretch (the arms of a 1.5 s raised hand pumping in a 0.67 s cycle for ever): the
    long windows follow the clip played on (``memory.played_on``), playing on through it window after window; that
    long, the clip's own two stretches take turns, a window apart."""
    frames = mem.play_frames(20, 20) - (1 if short else 0)
    feats = walk_features(frames)
    clip = ClipMemory(feats, 20, 20, np.ones(LAYOUT.size, np.float32))
    assert (clip.played_on is not None) == short
    ends = _followed(clip, feats[-40:], 8)[2:]
    if short:
        assert len(set(ends)) >= 4 and any(b - a == 20 for a, b in zip(ends, ends[1:])), ends
        monkeypatch.setattr(mem, "play_frames", lambda m, n: 0)  # as it was: the clip's own stretches
        alone = ClipMemory(feats, 20, 20, np.ones(LAYOUT.size, np.float32))
        assert alone.played_on is None and len(set(_followed(alone, feats[-40:], 8)[2:])) == 1
    else:
        assert len(set(ends)) == 2 and abs(ends[0] - ends[1]) >= 20, ends


def test_a_clip_that_stands_is_played_back_and_forth_and_one_that_steps_round(monkeypatch):
    """``memory.played_on``: a clip that stands (raised hands: both feet down, the root all but still) goes on
    backwards from its last frame, the root's velocity and turn reversed, and forwards again from its first, so no
    frame jumps further than the clip's own frames do, and each turn is eased over ``EASE_FRAMES`` either side (a
    hand slows to its turn instead of bouncing off it); a walk (or a walk on the spot) goes round, walking forwards,
    each repeat going on in step from a gait cycle before the clip's end, moved to start where the last ended and its
    jump faded out over ``ALIGN_FRAMES``."""
    walk = walk_features(50)
    still = walk.copy()
    still[:, LAYOUT.root] = 0.0
    still[:, LAYOUT.velocity] = 0.002  # swaying 6 cm/s, both feet down: it stands
    still[:, LAYOUT.contacts] = 1.0
    assert mem.stands(still) and not mem.stands(walk)
    on_the_spot = walk.copy()
    on_the_spot[:, LAYOUT.root] = 0.0
    assert not mem.stands(on_the_spot)  # its feet step
    played, k = mem.played_on(still, 200), 2 * mem.EASE_FRAMES  # frames further than k from a turn are the clip's
    assert len(played) >= 200 and mem.EASE_FRAMES > 0
    np.testing.assert_array_equal(played[:50 - k], still[:50 - k])
    np.testing.assert_allclose(played[49 + k:99 - k, LAYOUT.positions], still[::-1][k:50 - k, LAYOUT.positions])
    np.testing.assert_allclose(played[49 + k:99 - k, LAYOUT.velocity], -0.002)
    np.testing.assert_allclose(played[98 + k:148 - k], still[k:50 - k])  # and forwards again
    step = lambda f: np.abs(np.diff(f[:, LAYOUT.positions], axis=0)).max()  # noqa: E731
    turn = lambda f: np.abs(np.diff(f[:, LAYOUT.positions], 2, axis=0)).max()  # noqa: E731
    assert step(played) <= step(still) + 1e-6
    round_ = mem.played_on(walk, 200)
    assert len(round_) >= 200 and np.all(round_[:, LAYOUT.velocity][:, 1] * walk[:, LAYOUT.velocity][:, 1].mean() > 0)
    assert step(round_) <= step(walk) + 1e-6  # the repeat goes on from where the clip ended, no frame jumping
    start = mem._most_like_the_end(walk)  # it goes on from a frame in step with its end: a gait cycle (33 frames) back
    assert abs((len(walk) - 1 - start) - 30.0 / 0.9) < 2 and mem.cycle_frames(walk) == len(walk) - 1 - start
    assert mem.cycle_frames(still) == 2 * (len(still) - 1)  # there and back
    again = round_[49 + mem.ALIGN_FRAMES:49 + (49 - start) - k]  # the clip itself once the repeat's jump has faded out
    np.testing.assert_allclose(again, walk[start + mem.ALIGN_FRAMES:49 - k], atol=1e-6)
    monkeypatch.setattr(mem, "EASE_FRAMES", 0)
    assert turn(played) < 0.75 * turn(mem.played_on(still, 200))  # turned sharply, not eased


def _from_a_stand(start: int = 60, walking: int = 140) -> np.ndarray:
    """Features of a clip that starts from a stand: ``start`` frames of the same steps at under half the pace
    (0.6 m/s), then the walk at 1.3 m/s."""
    slow = positions_to_features(walking_skeleton(start, speed=0.6))[0]
    return np.concatenate([slow, walk_features(walking)])


def test_a_travelling_continuation_does_not_go_back_to_the_clips_start_from_a_stand(monkeypatch):
    """A clip that starts from a stand and then walks: its stretches before the root first reaches ``START_SHARE``
    x its cruising speed are its start-up (here its 60 slow frames); a long continuation that walks goes back
    anywhere but there where the clip runs out (with the rule off it went back to the slow start, as a 4.4 s walk
    from a stand extended by 20 s slowed to under half its pace every 3.3 s), while a continuation that stands may
    still take the clip's stand."""
    feats = _from_a_stand()
    clip = ClipMemory(feats, 20, 20, np.ones(LAYOUT.size, np.float32))
    first_cruising = int(clip.ends[clip.start_up])
    assert 55 <= first_cruising <= 64, first_cruising
    ends = _followed(clip, feats[-40:], 24)
    assert min(ends) >= first_cruising and len(set(ends)) > 3, ends
    standing = ClipMemory(feats, 20, 20, np.ones(LAYOUT.size, np.float32))
    at_rest = feats[:40].copy()
    at_rest[:, LAYOUT.velocity] *= 0.3  # 0.18 m/s: under TRAVEL_SPEED
    _followed(standing, at_rest, 1)
    assert standing.ends[standing.last] < first_cruising  # at rest, the start is still where it matches
    monkeypatch.setattr(mem, "START_SHARE", None)
    before = ClipMemory(feats, 20, 20, np.ones(LAYOUT.size, np.float32))
    assert before.start_up == 0 and min(_followed(before, feats[-40:], 24)) < first_cruising


def test_a_clip_that_starts_on_the_move_or_never_travels_has_no_start_up():
    """Only a clip that starts slower than ``START_SHARE`` x its cruising speed and then travels for a window has a
    start-up to leave out: a walk throughout has none, and neither has a clip that stands throughout."""
    walk = walk_features(200)
    assert ClipMemory(walk, 20, 20, np.ones(LAYOUT.size, np.float32)).start_up == 0
    still = walk.copy()
    still[:, LAYOUT.velocity] = 0.002
    assert ClipMemory(still, 20, 20, np.ones(LAYOUT.size, np.float32)).start_up == 0


@pytest.mark.parametrize("fps", [60.0, 59.998798394426075])
def test_an_unseen_actors_walk_from_a_stand_extended_by_20_s_keeps_its_pace(fps, mocap_root):
    """The held-out CMU subject's 4.4 s walk that starts from a stand (006_03), extended by 20 s as Extend Clip does,
    read at 60 fps and at the rate Blender's BVH import gave it: the hips never slow to under 0.7 x the clip's
    cruising pace (the median of its walking part) in any 1/6 s, where going back to the clip's first steps each
    time it ran out slowed them to under half (at the second rate; at 60 fps the clip went back elsewhere)."""
    from model_core.ops.extend import clip_floor, extend_positions
    from model_core.rig.rigs import leg_length, load_clip

    take = mocap_root / "cmu" / "iclone" / "006_03.bvh"
    if not take.is_file():
        pytest.skip(f"{take} is not on this machine")
    clip = np.asarray(load_clip(str(take), rate=fps), np.float64)
    new = extend_positions(Engine.load(), clip[-40:], fps, 1200, memory=clip, floor=clip_floor(clip, fps))
    unit = leg_length(clip) / 0.87
    speed = lambda p: np.linalg.norm(p[10:, 0, [0, 2]] - p[:-10, 0, [0, 2]], axis=-1) * fps / 10 / unit  # noqa: E731
    cruise = float(np.median(speed(clip)[speed(clip) > 0.3]))
    assert speed(new)[120:].min() > 0.7 * cruise, (speed(new)[120:].min(), cruise)
