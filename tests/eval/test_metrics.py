"""Long-horizon judgement of a rollout (DESIGN.md metrics): explosion, freeze, speed ratio, D_1nn."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.eval.metrics import (
    airborne_fraction,
    feet_report,
    joint_speed,
    pose_vectors,
    rollout_report,
    segments,
)
from model_core.motion.conventions import JOINT_INDEX, PARENTS, UP_AXIS
from model_core.motion.features import floor_height, positions_to_features
from model_core.motion.noise import add_rotation_jitter
from model_core.motion.synthetic import walking_skeleton


def _walk(frames: int = 2000):
    pos = walking_skeleton(frames)
    feats, _ = positions_to_features(pos)
    return pos, feats


def test_a_real_like_walk_is_neither_exploded_nor_frozen():
    pos, feats = _walk()
    speed = float(joint_speed(pos).mean())
    ref = segments(pose_vectors(feats[:400]))
    report = rollout_report(feats, pos[:20], speed, ref)
    assert not report.exploded and not report.frozen
    assert abs(report.speed_ratio_last_1000 - 1.0) < 0.05
    assert len(report.d1nn_per_block) == 2 and max(report.d1nn_per_block) < 1e-3  # the same gait as the reference


def test_a_held_pose_is_a_freeze_and_a_grown_skeleton_an_explosion():
    pos, feats = _walk()
    speed = float(joint_speed(pos).mean())
    ref = segments(pose_vectors(feats[:400]))
    still = np.repeat(feats[:1], 200, 0)
    still[:, 63:66] = 0.0  # no root motion
    held = rollout_report(still, pos[:20], speed, ref, block=100)
    assert held.frozen and held.speed_ratio_last_1000 < 0.01
    grown = feats.copy()
    grown[:, :63] *= 1.2  # every bone 20 % longer than the seed's
    assert rollout_report(grown, pos[:20], speed, ref).exploded
    broken = feats.copy()
    broken[500, 3] = np.nan
    report = rollout_report(broken, pos[:20], speed, ref)
    assert report.exploded and np.isnan(report.speed_ratio_last_1000)


def test_a_rollout_is_frozen_only_where_it_holds_still_longer_than_its_take_ever_does():
    """The long horizon's ``frozen`` (evaluation._judge_rollouts): a rollout that stands still for 79 frames is
    frozen after a take that never stands still (a walk), not after one that holds a pose for 100 frames; both
    runs are given seed by seed (``still_frames``, ``take_still_frames``)."""
    from model_core.eval.evaluation import _judge_rollouts

    pos, feats = _walk(400)
    speed = float(joint_speed(pos).mean())
    ref = segments(pose_vectors(feats[:200]))
    rollout = feats[:300].copy()
    rollout[100:180] = feats[100]  # 80 frames alike: 79 frames of no motion
    rollout[100:180, 63:66] = 0.0  # and no root motion
    holds = np.concatenate([pos[:150], np.repeat(pos[150:151], 100, 0), pos[151:300] - pos[151] + pos[150]])
    takes = {"walk": pos, "holds": holds}
    judged = _judge_rollouts([rollout, rollout], [("walk", pos[:20]), ("holds", holds[:20])], [0.0, 0.0], takes,
                             speed, speed, ref)
    assert judged["still_frames"] == [79, 79] and judged["take_still_frames"][0] == 0
    assert judged["take_still_frames"][1] >= 99
    assert judged["frozen"] == 1  # after the walk only
    assert rollout_report(rollout, pos[:20], speed, ref, block=100).frozen  # the report itself: 2 s or more


def test_freeze_threshold_is_a_tenth_of_the_median_speed():
    pos, feats = _walk(400)
    speed = float(joint_speed(pos).mean())
    ref = segments(pose_vectors(feats[:200]))
    slow = features_slowed(feats, 0.08)  # moves at 8 % of the walk's speed
    assert rollout_report(slow, pos[:20], speed, ref, block=100).frozen  # by the mean (the default)
    assert not rollout_report(slow, pos[:20], speed, ref, block=100, median_speed=0.5 * speed).frozen


def features_slowed(feats: np.ndarray, factor: float) -> np.ndarray:
    """The same motion played ``factor`` times as fast (linear interpolation of the frames)."""
    t = np.arange(len(feats)) * factor
    i = np.floor(t).astype(int)
    w = (t - i)[:, None]
    out = feats[i] * (1 - w) + feats[np.minimum(i + 1, len(feats) - 1)] * w
    out[:, 63:66] = feats[i, 63:66] * factor  # root steps scale with the playback speed
    return out.astype(np.float32)


def test_prediction_errors_also_score_the_extend_seam_blend():
    """Extend's seam blend starts the continuation where the context's last velocity leads: for a
    stand-in that freezes the last pose (gliding on at the root's speed) it brings the first
    frames of a walk closer to the truth."""
    from model_core.eval.metrics import prediction_errors

    class Freeze:
        def extrapolate(self, feats, frames):
            return np.repeat(np.asarray(feats)[:, -1:], frames, 1)

    errors, windows = prediction_errors(Freeze(), [walking_skeleton(120, speed=1.2)])
    assert windows > 0 and set(errors) == {"strnn", "zero_velocity", "constant_velocity", "strnn_seam_blend"}
    assert errors["strnn_seam_blend"][0] < errors["strnn"][0]


def test_feet_report_sees_hovering_sinking_and_gliding():
    pos = walking_skeleton(300)
    floor = floor_height(pos)
    real = feet_report(pos, floor)
    assert real.touch_fraction == 1.0 and abs(real.floor_offset_cm) < 3 and real.sink_cm < 1
    lifted = pos.copy()
    lifted[..., UP_AXIS] += 0.12  # the whole body 12 cm above the floor
    hover = feet_report(lifted, floor)
    assert hover.touch_fraction == 0.0 and hover.floor_offset_cm > 9
    sunk = pos.copy()
    sunk[..., UP_AXIS] -= 0.07
    assert feet_report(sunk, floor).sink_cm > 6
    glide = np.repeat(pos[:1], 300, 0)  # one pose pushed along the ground at 1 m/s, feet in the air
    glide[..., UP_AXIS] += 0.1
    glide[..., 2] += np.arange(300)[:, None] / 30.0
    assert feet_report(glide, floor).touch_fraction == 0.0
    still = feet_report(np.repeat(pos[:1], 60, 0), floor)
    assert np.isnan(still.touch_fraction)  # no locomotion: nothing to judge


def test_feet_report_sees_a_stance_that_glides_with_its_feet_down():
    """The failure the long-horizon check missed: a stance whose feet are down (its contact channels say so, and
    they stand on the floor) while the whole body glides at 0.23 m/s. It touches the floor and is too slow to
    count as locomotion; the slide of the feet that are down shows it. Standing in place, they do not slide."""
    pos = np.repeat(walking_skeleton(60)[:1], 300, 0)
    floor = floor_height(pos)
    down = np.ones((300, 4), np.float32)
    glide = pos.copy()
    glide[..., 2] += 0.23 * np.arange(300)[:, None] / 30.0
    gliding = feet_report(glide, floor, contacts=down)
    assert np.isnan(gliding.touch_fraction) and abs(gliding.floor_offset_cm) < 3  # on the floor, not locomotion
    assert gliding.skate_cm == pytest.approx(23.0 / 30.0, rel=1e-3)
    assert feet_report(pos, floor, contacts=down).skate_cm == 0.0
    assert feet_report(glide, floor, contacts=np.zeros((300, 4))).skate_cm == 0.0  # feet it says are up
    assert np.isnan(feet_report(glide, floor).skate_cm)  # no contact channels: not judged


def test_a_walk_turned_into_hops_is_in_the_air_where_the_walk_never_is():
    """Both feet leave the floor together for a third of each hop: the speed and the once-a-second floor
    contact look like a walk's, the share of frames in the air does not."""
    pos = walking_skeleton(300)
    floor = floor_height(pos)
    walk = feet_report(pos, floor).airborne_fraction
    hops = pos.copy()
    t = np.arange(300)
    hops[..., UP_AXIS] += (0.15 * np.clip(np.sin(2 * np.pi * t / 20), 0, None))[:, None]  # 1.5 hops a second
    report = feet_report(hops, floor)
    assert report.touch_fraction == 1.0 and report.airborne_fraction > walk + 0.2
    assert airborne_fraction(pos, floor - 1.0) == 1.0 and airborne_fraction(pos, floor + 1.0) == 0.0


def test_rollout_report_judges_the_feet_of_the_last_block():
    pos, feats = _walk(1200)
    speed = float(joint_speed(pos).mean())
    report = rollout_report(feats, pos[:20], speed, segments(pose_vectors(feats[:400])), floor=floor_height(pos))
    assert report.feet.touch_fraction == 1.0 and report.feet.sink_cm < 1
    assert rollout_report(feats, pos[:20], speed, segments(pose_vectors(feats[:400]))).feet is None


def test_rotation_jitter_turns_joints_and_keeps_bones():
    """Jitter on rotation channels moves joints (more the further from the hips) but never stretches a
    bone, as jitter in a BVH's or an armature's channels does."""
    walk = walking_skeleton(60)
    out = add_rotation_jitter(walk, 1.5, np.random.default_rng(0))
    lengths = [np.linalg.norm(p[:, 1:] - p[:, PARENTS[1:]], axis=-1) for p in (walk, out)]
    np.testing.assert_allclose(lengths[1], lengths[0], atol=1e-5)
    moved = np.linalg.norm(out - walk, axis=-1).mean(0)
    assert moved[0] < 1e-6 and 0.005 < moved.mean() < 0.1
    assert moved[JOINT_INDEX["l_fingertip"]] > moved[JOINT_INDEX["spine"]]


def test_a_model_that_reads_more_frames_gets_the_take_before_each_window():
    """reading_contexts: the same windows as prediction_windows (their last 20 frames the same contexts), each with
    the take's frames before it as far as the model reads, a window near the take's start led in by its first."""
    from model_core.eval.metrics import prediction_windows, reading_contexts

    clips = [walking_skeleton(150, speed=1.2), walking_skeleton(90, speed=0.8)]
    ctx, _ = prediction_windows(clips, 20)
    np.testing.assert_array_equal(reading_contexts(clips, 20, 20), ctx)
    longer = reading_contexts(clips, 20, 50)
    assert longer.shape == (len(ctx), 50) + ctx.shape[2:]
    np.testing.assert_array_equal(longer[:, -20:], ctx)
    np.testing.assert_array_equal(longer[0, :30], np.repeat(clips[0][:1], 30, 0))  # the take's first window
    np.testing.assert_array_equal(longer[3], clips[0][15:65])  # starts at frame 45: 50 frames of take before
