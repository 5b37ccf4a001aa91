"""Extend reads a clip on the body its model learnt and hands the new frames back on the clip's own body: a
walk on a rig of other proportions (a generated Rigify rig's spine and legs, as the bone map reads them)
walks on as it does on the training body."""

from __future__ import annotations

import numpy as np

from model_core.inference.engine import Engine, on_learnt_body
from model_core.io.checkpoint import walk_seed_index
from model_core.motion.features import body_lengths, features_to_positions, learnt_body, with_bone_lengths
from model_core.motion.synthetic import walking_skeleton


def test_bone_lengths_change_and_come_back_exactly():
    walk = walking_skeleton(60).astype(np.float64)
    other = with_bone_lengths(walk, body_lengths(walk) * np.linspace(0.7, 1.4, 21))
    np.testing.assert_allclose(body_lengths(other)[1:], (body_lengths(walk) * np.linspace(0.7, 1.4, 21))[1:], rtol=1e-9)
    np.testing.assert_allclose(other[:, 0], walk[:, 0])  # the hips stay where they are
    np.testing.assert_allclose(with_bone_lengths(other, body_lengths(walk)), walk, atol=1e-6)


def joint_speed(pos: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(pos - pos[:, :1], axis=0), axis=-1).mean())


def test_a_walk_on_other_proportions_walks_on_like_the_same_walk_on_the_learnt_body():
    engine = Engine.load()
    seed = np.concatenate([engine.seeds[walk_seed_index(engine.ckpt.seed_names)]] * 2)  # 40 frames of a real walk
    walk = with_bone_lengths(features_to_positions(seed), learnt_body(engine.seeds))  # on the learnt body exactly
    stretch = np.ones(21)
    stretch[[1, 2, 3, 6, 7, 10, 11]] = [0.8, 2.5, 0.8, 1.15, 0.85, 1.15, 0.85]  # spine, chest, neck, thighs, shins
    rig = with_bone_lengths(walk, learnt_body(engine.seeds) * stretch)
    ours, theirs = engine.extend(walk, 90), engine.extend(rig, 90)
    np.testing.assert_allclose(body_lengths(theirs), body_lengths(rig), atol=1e-4)  # back on the rig's own bones
    np.testing.assert_allclose(with_bone_lengths(theirs, body_lengths(ours)), ours, atol=1e-3)  # the same motion
    seen, _ = on_learnt_body(engine, rig)
    np.testing.assert_allclose(body_lengths(seen), learnt_body(engine.seeds), atol=1e-4)
    assert joint_speed(theirs[-30:]) > 0.5 * joint_speed(walk)


def test_a_body_near_the_learnt_one_is_read_as_it_is():
    """The training takes' own bodies (the Bandai actors', within 0.4 % of the learnt one) are read as they are."""
    engine = Engine.load()
    walk = features_to_positions(engine.seeds[walk_seed_index(engine.ckpt.seed_names)])
    near = with_bone_lengths(walk, body_lengths(walk) * 1.01)
    seen, back = on_learnt_body(engine, near)
    assert seen is near or np.array_equal(seen, near)
    np.testing.assert_array_equal(back(walk), walk)
