"""Curve-driven synthesis on the NumPy engine (what Follow Curve runs) with the bundled model: the
length and progress of a walk, reaching the path's end, walking to a path that starts elsewhere,
scene units, and the evaluation paths."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.eval.metrics import bone_lengths_of as bone_lengths
from model_core.inference.steps import drive
from model_core.io.checkpoint import DEFAULT_MODEL
from model_core.motion.conventions import CONTACT_JOINTS, LAYOUT
from model_core.motion.features import heading
from model_core.motion.stance import PLANT_TRUST, planted_steps
from model_core.motion.synthetic import walking_skeleton
from model_core.ops import footlock as fl
from model_core.ops.follow import (
    ControlSettings,
    PathFollower,
    align_to_path,
    follow_curve_positions,
    follow_path,
    follow_path_steps,
    lead_in_radius,
    match_mean,
    with_lead_in,
)
from model_core.ops.paths import Path, evaluation_paths, path_errors_cm


@pytest.fixture(scope="module")
def bundled():
    return PathFollower.load(DEFAULT_MODEL)


def straight(length=10.0):
    return Path(np.stack([np.zeros(101), np.linspace(0, length, 101)], -1))


def test_follow_is_deterministic_and_has_the_asked_length(bundled):
    seed = walking_skeleton(40)
    a, fa = follow_path(bundled, seed, straight(), frames=45)
    b, _ = follow_path(bundled, seed, straight(), frames=45)
    assert a.shape == (45, 21, 3) and fa.shape == (45, LAYOUT.size)
    np.testing.assert_array_equal(a, b)
    assert np.isfinite(a).all()


def test_steps_report_each_window_and_give_the_same_walk(bundled):
    seed, fractions = walking_skeleton(40), []
    stepped = drive(follow_path_steps(bundled, seed, straight(), frames=45), fractions.append)
    windows = -(-45 // bundled.n)
    assert fractions == [min(k * bundled.n / 45, 1.0) for k in range(1, windows + 1)]  # after each n-frame window
    np.testing.assert_array_equal(stepped[0], follow_path(bundled, seed, straight(), frames=45)[0])


def test_a_windows_last_step_keeps_its_strides_pace_not_the_paths():
    """The root steps of a window follow its planted feet, scaled to the path's pace (:func:`match_mean`). Its last
    frame's step leads into the next window, whose feet are not known yet; it used to be the path's own step, scaled
    with the rest: a stride that the model walks at 10 cm a frame on a path that asks 14 put 1.4 x 14 cm into the
    last step, a pop of the hips at every seam (a runner's hand flung 1.3 x as hard as in the take, in Blender). It
    now repeats the step before it."""
    n = 20
    window = np.zeros((n, LAYOUT.size), np.float32)
    feet = window[:, LAYOUT.positions].reshape(n, -1, 3)
    for j in CONTACT_JOINTS:  # every heel and toe planted, sliding back 10 cm a frame under the root
        feet[:, j, 2] = -0.10 * np.arange(n)
    window[:, LAYOUT.positions] = feet.reshape(n, -1)
    window[:, LAYOUT.contacts] = 1.0
    control = np.tile([0.0, 0.14], (n, 1))
    steps = planted_steps(window, control)
    np.testing.assert_allclose(steps[:-1, 1], (4 * 0.10 + PLANT_TRUST * 0.14) / (4 + PLANT_TRUST), rtol=1e-6)
    assert steps[-1, 1] == pytest.approx(steps[-2, 1])
    paced = match_mean(steps, control)
    np.testing.assert_allclose(paced[:, 1], 0.14, rtol=1e-6)  # the path's pace, no jump into the next window


def test_the_seeds_window_is_decoded_and_later_ones_leave_the_decoder_out():
    """The first window reads the seed through the whole model; later windows, whose context is the walk's own,
    run without the backward decoder (:meth:`Engine.predict_next`) and stay within a centimetre of the walk
    decoded throughout, on the same path."""
    follower, seed = PathFollower.load(DEFAULT_MODEL), walking_skeleton(40)
    shipped, _ = follow_path(follower, seed, straight(), frames=90)
    follower.engine.decode_later_windows = True
    decoded, _ = follow_path(follower, seed, straight(), frames=90)
    n = follower.n
    np.testing.assert_array_equal(shipped[:n], decoded[:n])
    apart = np.linalg.norm(shipped[n:] - decoded[n:], axis=-1).mean(-1)
    assert 1e-5 < apart.max() and apart.mean() < 0.01


@pytest.mark.parametrize("speed", [None, 0.6, 2.0])
def test_with_no_frame_count_the_walk_reaches_the_end_of_the_path(speed):
    """Until the path ends, whatever the pace: the root ends within 25 cm of the end, having walked it."""
    f = PathFollower.load(DEFAULT_MODEL, ControlSettings(speed=speed))
    path = straight(5.0)
    pos, _ = follow_path(f, walking_skeleton(40), path)
    assert np.linalg.norm(pos[-1, 0, [0, 2]] - path.at(path.length)) < 0.25
    if speed:
        assert len(pos) == pytest.approx(5.0 / speed * 30, rel=0.1)


@pytest.mark.parametrize("name", ["circle", "s_curve", "figure_eight"])
def test_the_bundled_model_walks_the_evaluation_paths(bundled, name):
    walk = [i for i, n in enumerate(bundled.ckpt.seed_names) if "walk" in n] or [0]
    points, cyclic = evaluation_paths()[name]
    path = Path(points, cyclic)
    from model_core.motion.features import features_to_positions

    seed = features_to_positions(bundled.ckpt.seeds[walk[0]])
    pos, _ = follow_path(bundled, seed, path)
    mean, worst = path_errors_cm(pos[:, 0], path)
    locked = fl.foot_lock(pos, contacts=fl.detect_foot_contacts(pos))
    skate = fl.foot_skate_cm(locked, fl.detect_foot_contacts(pos))
    step = np.linalg.norm(np.diff(pos[:, 0, [0, 2]], axis=0), axis=-1).mean() * 30
    print(f"{name}: {len(pos)} frames, path error mean {mean:.1f} cm, max {worst:.1f}; skate locked {skate:.2f} "
          f"cm/frame; {step:.2f} m/s")
    assert np.isfinite(pos).all() and mean < 10.0 and worst < 30.0
    assert skate < 0.2 and step > 0.6  # planted feet after the lock; it keeps walking
    legs = pos[:, [7, 11], 2] - pos[:, [0], 2]  # both ankles fore-aft of the hips: they alternate
    assert (np.diff(legs, axis=1).std()) > 0.1


def test_a_path_that_starts_away_from_the_character_is_walked_to_and_then_from_its_start(bundled):
    """A clip that ends 2 m beside a curve's start walks to the start, then along the curve from there:
    it does not cut across to the curve's nearest point."""
    clip = walking_skeleton(30, fps=30.0)
    end = clip[-1, 0, [0, 2]]
    start = end + [2.0, 0.0]
    curve = np.stack([np.full(60, start[0]), np.zeros(60), start[1] + np.linspace(0.0, 6.0, 60)], -1)
    out = follow_curve_positions(bundled, curve, False, 30.0, context=clip)
    hips = out[:, 0, [0, 2]]
    to_start = np.linalg.norm(hips - start, axis=-1)
    arrive = int(to_start.argmin())
    assert to_start[arrive] < 0.2, "passes the curve's start"
    path = Path(curve[:, [0, 2]])
    mean, _ = path_errors_cm(hips[arrive:], path)
    assert mean < 10.0
    assert np.linalg.norm(hips[-1] - curve[-1, [0, 2]]) < 0.3, "walks on to the curve's end"
    for leave in (None, np.array([0.0, -1.0]), np.array([-1.0, 0.0])):  # towards it, away from it, turned round
        lead = with_lead_in(path, end, direction=leave)
        np.testing.assert_allclose(lead.points[0], end)
        seg = np.diff(lead.points, axis=0)
        yaw = np.unwrap(np.arctan2(seg[:, 0], seg[:, 1]))
        want = np.arctan2(*(start - end if leave is None else leave))
        assert abs((yaw[0] - want + np.pi) % (2 * np.pi) - np.pi) < 0.1, "leaves the way the character moves"
        turn = np.abs(np.diff(yaw)) / np.linalg.norm(seg[1:], axis=-1)  # radians per metre
        assert turn.max() < 1.05 / lead_in_radius(0.0), "no corner, where it meets the path either"
        assert abs(yaw[-1] - yaw[-2]) < 0.05 and abs(np.sin(yaw[-1])) < 0.05, "meets the path along it (+z)"
        assert lead.length > 2.0 + 6.0 - 1e-6
    assert with_lead_in(path, start + [0.1, 0.0]) is path  # already at the start: no lead-in


def test_curve_positions_continue_a_clip_in_scene_units(bundled):
    clip = walking_skeleton(30, fps=24.0) * 100.0  # centimetres at 24 fps
    curve = np.stack([np.linspace(0, 300, 50), np.zeros(50), np.linspace(0, 500, 50)], -1)
    out = follow_curve_positions(bundled, curve, False, 24.0, frames=40, context=clip)
    assert out.shape == (40, 21, 3) and np.isfinite(out).all()
    legs = lambda p: np.linalg.norm(p[:, 9] - p[:, 10], axis=-1).mean()  # noqa: E731 (r_upleg - r_knee)
    assert legs(out) == pytest.approx(legs(clip), rel=0.2)


def test_curve_positions_start_from_a_shipped_seed_on_the_curve(bundled):
    rest = walking_skeleton(1)[0] * 2.0  # a character twice the standard size
    curve = np.stack([np.full(20, 5.0), np.zeros(20), np.linspace(0, 4, 20)], -1)
    out = follow_curve_positions(bundled, curve, False, 30.0, rest=rest, speed=2.0)
    assert len(out) == pytest.approx(60, abs=6) and np.isfinite(out).all()  # 4 units at 2 per second, 30 fps
    assert np.linalg.norm(out[-1, 0, [0, 2]] - [5.0, 4.0]) < 0.5


def test_a_walk_from_the_shipped_seed_is_put_on_the_rigs_own_body_with_its_feet_as_high(bundled):
    """Without a clip to continue, Follow Curve walks the shipped seed's body scaled to the rig's legs. A rig whose
    pelvis and chest are other shapes (its thighs lower and wider under the hips, its shoulders high and wide of the
    neck, as an MMD model's) and whose bones are of other lengths gets the walk on its own bones, its pelvis and chest
    turned whole, each frame's lowest heel or toe as high as before, so that what Foot Lock and a Ground do to the
    feet is what the rig's solve then plays."""
    from model_core.motion.conventions import JOINT_INDEX
    from model_core.motion.features import body_lengths, lowest_foot, on_body_of, part_frames

    rest = walking_skeleton(1)[0].copy()
    for side in ("l", "r"):
        out_way = np.sign(rest[JOINT_INDEX[f"{side}_upleg"], 0] - rest[0, 0])
        legs = [JOINT_INDEX[f"{side}_{j}"] for j in ("upleg", "knee", "foot", "toe")]
        rest[legs] += [0.02 * out_way, -0.03, 0.0]  # the thighs 3 cm lower and 2 cm further out
        arms = [JOINT_INDEX[f"{side}_{j}"] for j in ("arm", "elbow", "wrist", "fingertip")]
        rest[arms] += [0.05 * out_way, 0.04, 0.0]  # the shoulders 4 cm higher and 5 cm further out
    rest[JOINT_INDEX["head"]] += [0.0, 0.05, 0.0]  # a longer neck
    curve = np.stack([np.zeros(20), np.zeros(20), np.linspace(0, 4, 20)], -1)
    walk = follow_curve_positions(bundled, curve, False, 30.0, frames=45, rest=rest)
    np.testing.assert_allclose(body_lengths(walk), body_lengths(rest[None]), atol=1e-6)
    def in_part(x, part, sides):  # the joints spanning a rigid part, from its joint, in the part's own frame
        offsets = x[:, [JOINT_INDEX[j] for j in sides]] - x[:, [JOINT_INDEX[part]]]
        return np.einsum("fji,fkj->fki", part_frames(x, part), offsets)

    for part, sides in (("hips", ("l_upleg", "r_upleg")), ("spine1", ("l_arm", "r_arm"))):
        np.testing.assert_allclose(in_part(walk, part, sides), np.repeat(in_part(rest[None], part, sides), 45, 0),
                                   atol=1e-6)
    seed_body = on_body_of(walk, walking_skeleton(1)[0])  # and back on the standard body: the feet as high
    np.testing.assert_allclose(lowest_foot(seed_body), lowest_foot(walk), atol=1e-9)


def test_align_to_path_puts_the_seed_on_the_start():
    path = Path(np.stack([np.linspace(3, 8, 20), np.full(20, -2.0)], -1))  # heading +X from (3, -2)
    seed = align_to_path(walking_skeleton(20), path)
    np.testing.assert_allclose(seed[-1, 0, [0, 2]], [3.0, -2.0], atol=1e-5)
    assert heading(seed)[-1] == pytest.approx(np.pi / 2, abs=1e-3)
    np.testing.assert_allclose(bone_lengths(seed), bone_lengths(walking_skeleton(20)), atol=1e-5)


def test_path_evaluation_section(bundled):
    from types import SimpleNamespace

    from model_core.eval.path_evaluation import evaluate_paths

    clips = [SimpleNamespace(name=f"walk_{i}", positions=walking_skeleton(60)) for i in range(2)]
    out = evaluate_paths(bundled, clips, seeds=1, log=lambda m: None)
    assert out["names"] == ["line", "circle", "s_curve", "figure_eight"]
    for key in ("mean_cm", "max_cm", "bone_error", "speed_ratio", "end_reached"):
        assert len(out[key]) == 4 and all(np.isfinite(out[key]))
    assert all(r > 0.95 for r in out["end_reached"]) and all(0.7 < r < 1.3 for r in out["speed_ratio"])
    assert len(out["foot_skate_cm"]["raw"]) == len(out["knee_pops"]["locked"]) == 4
    assert out["seed_clips"] == ["walk_0"] and out["frames_per_second"] > 0


def test_a_character_already_at_the_paths_end_gets_a_short_walk_not_an_error(bundled):
    seed = walking_skeleton(40)
    end = seed[-1, 0, [0, 2]]
    path = Path(np.stack([end - [0.0, 3.0], end], 0))  # ends where the seed ends
    pos, _ = follow_path(bundled, seed, path, align=False)
    assert 1 <= len(pos) <= bundled.n and np.isfinite(pos).all()
