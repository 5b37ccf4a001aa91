"""Planted feet, stances that stand and feet kept out of the floor: :mod:`model_core.motion.stance`, on made-up
windows and on the shipped model's own open-loop rollouts."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.inference.engine import Engine
from model_core.io.checkpoint import DEFAULT_MODEL
from model_core.motion.conventions import CONTACT_JOINTS, JOINT_INDEX, LAYOUT, MODEL_FPS
from model_core.motion.features import (
    body_lengths,
    features_to_positions,
    floor_height,
    lowest_foot,
    positions_to_features,
    with_bone_lengths,
)
from model_core.motion.stance import GROUND_EASE, SETTLE_FROM, ground, planted_steps, settle_stances
from model_core.motion.synthetic import walking_skeleton
from model_core.ops.footlock import LEGS


def gliding(frames: int, down: bool = True, step: float = 0.008) -> np.ndarray:
    """Raw features ``[frames, C]`` of a body that stands still in its root's frame, feet down (or not), while its
    root steps ``step`` metres a frame forward: a stance that glides."""
    rng = np.random.default_rng(0)
    feats = np.zeros((frames, LAYOUT.size), np.float32)
    pose = rng.normal(0.0, 0.3, (LAYOUT.positions.stop - LAYOUT.positions.start,))
    feats[:, LAYOUT.positions] = pose
    feats[:, LAYOUT.velocity] = [0.0, step]
    feats[:, LAYOUT.contacts] = 1.0 if down else 0.0
    return feats


def test_a_planted_foot_that_slides_back_under_the_root_walks_it_forward():
    feats = gliding(10, step=0.0)
    local = feats[:, LAYOUT.positions].reshape(10, -1, 3)
    local[:, CONTACT_JOINTS, 2] -= 0.05 * np.arange(10)[:, None]  # every heel and toe slides back 5 cm a frame
    feats[:, LAYOUT.positions] = local.reshape(10, -1)
    steps = planted_steps(feats, feats[:, LAYOUT.velocity], trust=0.0)
    np.testing.assert_allclose(steps, np.tile([0.0, 0.05], (10, 1)), atol=1e-6)


def test_a_gliding_stance_stands_from_the_settled_windows_on_and_nothing_else_changes():
    n = 20
    feats = gliding(6 * n)
    feats[4 * n:5 * n, LAYOUT.contacts] = 0.0  # a window in the air: not a stance
    out = settle_stances(feats, n)
    speed = np.linalg.norm(out[:, LAYOUT.velocity], axis=-1)
    np.testing.assert_array_equal(out[:SETTLE_FROM * n], feats[:SETTLE_FROM * n])  # the clip's continuation
    assert speed[SETTLE_FROM * n:4 * n].max() < 0.1 * 0.008  # the feet hold the root (the model's step trusted 0.25)
    np.testing.assert_array_equal(out[4 * n:5 * n], feats[4 * n:5 * n])
    assert speed[5 * n:].max() < 0.1 * 0.008
    others = np.ones(LAYOUT.size, bool)
    others[LAYOUT.velocity] = False
    np.testing.assert_array_equal(out[:, others], feats[:, others])
    batched = settle_stances(np.stack([feats, gliding(6 * n, down=False)]), n)
    np.testing.assert_array_equal(batched[0], out)
    np.testing.assert_array_equal(batched[1], gliding(6 * n, down=False))  # feet up: a glide it cannot judge


def test_a_window_with_a_foot_lifted_keeps_the_models_steps():
    n = 20
    feats = gliding(4 * n)
    feats[::3, LAYOUT.contacts.start] = 0.0  # the left heel up in a third of the frames: a step, not a stance
    np.testing.assert_array_equal(settle_stances(feats, n), feats)


@pytest.fixture(scope="module")
def engine():
    return Engine.load(DEFAULT_MODEL)


def test_the_shipped_models_standing_rollout_stands_where_its_root_used_to_glide(engine):
    """The shipped model, open loop from its standing seed (a test-split take that raises both hands): after a few
    seconds it settles into an idle whose root glides on at about 0.2 m/s with both feet down (model card, "A stance
    stands"). Settled, the root keeps still; the body's motion and the first windows are the model's own."""
    names = list(engine.ckpt.seed_names)
    standing = next(i for i, name in enumerate(names) if "raise-up-both-hands" in name)
    seed = engine.seeds[standing]
    raw = engine.extrapolate(seed, 1500)
    settled = engine.extrapolate(seed, 1500, settle=True)
    glide = np.linalg.norm(raw[-600:, LAYOUT.velocity], axis=-1).mean() * MODEL_FPS
    stands = np.linalg.norm(settled[-600:, LAYOUT.velocity], axis=-1).mean() * MODEL_FPS
    assert glide > 0.1 and stands < 0.5 * glide
    np.testing.assert_array_equal(settled[:SETTLE_FROM * engine.n], raw[:SETTLE_FROM * engine.n])
    others = np.ones(LAYOUT.size, bool)
    others[LAYOUT.velocity] = False
    np.testing.assert_array_equal(settled[:, others], raw[:, others])


def test_ground_lifts_only_the_frames_that_go_under_the_floor_and_eases_the_lift():
    walk = walking_skeleton(60)
    floor = lowest_foot(walk).min()
    sunk = walk.copy()
    sunk[20:30, :, 1] -= 0.05  # ten frames 5 cm into the floor
    sunk[45:50, :, 1] += 0.2  # a hop: five frames in the air
    out = ground(sunk, floor)
    assert lowest_foot(out).min() >= floor - 1e-9  # no frame under the floor
    np.testing.assert_array_equal(out[:10], sunk[:10])  # far from the dip: as it was
    np.testing.assert_array_equal(out[45:50], sunk[45:50])  # nothing pushed down: the hop stays a hop
    lift = out[:, 0, 1] - sunk[:, 0, 1]
    np.testing.assert_allclose(out - sunk, np.broadcast_to(lift[:, None, None] * [0, 1, 0], out.shape), atol=1e-6)
    assert np.abs(np.diff(lift)).max() < 0.05  # it eases in and out rather than jumping by the dip
    both = ground(np.stack([sunk, sunk]), np.array([floor, np.nan]))
    np.testing.assert_array_equal(both[0], out)
    np.testing.assert_array_equal(both[1], sunk)  # no floor known: left as it is


def test_the_open_loop_on_a_longer_legged_body_keeps_its_feet_out_of_the_floor(engine):
    """The shipped model, open loop from its walking seed put on legs 8 % longer: the model places the hips for the
    bodies it learnt, so that, put back on the seed's bones window after window, the feet sink about 9 cm into the
    floor (model card, "Feet out of the floor"). With the seed's floor given, no frame goes under it and the feet
    still touch it: from the third window the body is lifted as a whole (only heights change once the lift has
    eased in over that window); in the first two the legs alone raise the feet, the hips and upper body as before."""
    names = list(engine.ckpt.seed_names)
    seed = features_to_positions(engine.seeds[next(i for i, name in enumerate(names) if "walk_active" in name)])
    lengths = body_lengths(seed)
    legs = [JOINT_INDEX[name] for name in ("l_knee", "l_foot", "r_knee", "r_foot")]
    lengths[legs] *= 1.08
    long_legs = with_bone_lengths(seed, lengths)
    long_legs[..., 1] -= floor_height(long_legs) - floor_height(seed)
    feats, floor = positions_to_features(long_legs)[0], floor_height(long_legs)
    raw = engine.extrapolate(feats, 600, settle=True)
    grounded = engine.extrapolate(feats, 600, settle=True, floor=floor)

    def lowest(out):
        return lowest_foot(out[:, LAYOUT.positions].reshape(len(out), -1, 3)) - floor

    assert np.percentile(lowest(raw)[-300:], 1) < -0.05  # it sinks
    held, first = (SETTLE_FROM + 1) * engine.n, SETTLE_FROM * engine.n
    assert lowest(raw)[:first].min() < -0.01  # the first two windows dip too
    assert lowest(grounded).min() > -1e-3 and np.median(lowest(grounded)[-300:]) < 0.02  # out of it, on it
    leg_channels = np.zeros(LAYOUT.size, bool)
    for j in [j for leg in LEGS for j in leg[1:]]:  # knees, ankles, toes
        leg_channels[LAYOUT.positions.start + 3 * j:LAYOUT.positions.start + 3 * j + 3] = True
    np.testing.assert_array_equal(grounded[:first, ~leg_channels], raw[:first, ~leg_channels])
    others = np.ones(LAYOUT.size, bool)
    others[LAYOUT.positions.start + 1:LAYOUT.positions.stop:3] = False  # the joints' heights
    later = held + 2 * GROUND_EASE  # past the legs' own lift of the ramp's last frames, eased as the body's is
    np.testing.assert_array_equal(grounded[later:, others], raw[later:, others])
