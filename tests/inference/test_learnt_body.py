"""Extend reads a clip on the body its model learnt and hands the new frames back on the clip's own body: a
walk on a rig of other proportions (a generated Rigify rig's spine and legs, as the bone map reads them)
walks on as it does on the training body."""

from __future__ import annotations

import numpy as np

from model_core.inference.engine import Engine, on_learnt_body
from model_core.io.checkpoint import walk_seed_index
from model_core.motion.conventions import JOINT_INDEX, PARENTS
from model_core.motion.features import (
    body_lengths,
    features_to_positions,
    learnt_body,
    part_frames,
    with_bone_lengths,
)
from model_core.motion.synthetic import walking_skeleton


def test_bone_lengths_change_and_come_back_exactly():
    walk = walking_skeleton(60).astype(np.float64)
    other = with_bone_lengths(walk, body_lengths(walk) * np.linspace(0.7, 1.4, 21))
    np.testing.assert_allclose(body_lengths(other)[1:], (body_lengths(walk) * np.linspace(0.7, 1.4, 21))[1:], rtol=1e-9)
    np.testing.assert_allclose(other[:, 0], walk[:, 0])  # the hips stay where they are
    np.testing.assert_allclose(with_bone_lengths(other, body_lengths(walk)), walk, atol=1e-6)


def directions(pos: np.ndarray) -> np.ndarray:
    """Each bone's direction ``[F, 21, 3]`` (joint from its parent; the hips' row 0)."""
    bones = pos - pos[:, PARENTS]
    return bones / np.maximum(np.linalg.norm(bones, axis=-1, keepdims=True), 1e-12)


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
    # back on the rig's own bones, its pelvis and chest turned whole as the rig's last frame holds them
    np.testing.assert_allclose(body_lengths(theirs), body_lengths(rig), atol=1e-6)
    for part, (left, right) in (("hips", ("l_upleg", "r_upleg")), ("spine1", ("l_arm", "r_arm"))):
        spans = [JOINT_INDEX[left], JOINT_INDEX[right]]

        def in_part(x, part=part, spans=spans):  # the joints spanning the part, from its joint, in its own frame
            return np.einsum("fji,fkj->fki", part_frames(x, part), x[:, spans] - x[:, [JOINT_INDEX[part]]])

        np.testing.assert_allclose(in_part(theirs), np.repeat(in_part(rig[-1:]), len(theirs), 0), atol=1e-6)
    rigid = [JOINT_INDEX[j] for j in ("l_upleg", "r_upleg", "l_arm", "r_arm")]
    others = [j for j in range(1, 21) if j not in rigid]
    np.testing.assert_allclose(directions(theirs)[:, others], directions(ours)[:, others], atol=2e-3)  # the same motion
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


def test_a_rigs_pelvis_comes_back_as_the_rig_holds_it_and_its_feet_stay_on_the_floor():
    """A generated Rigify rig's thighs sit above its hips joint (7 cm as the bone map reads it); read on the body
    the model learnt, whose thighs hang below, the continuation came back with the thighs where the model put them,
    which the rig's rigid pelvis cannot follow: the solved legs came out 11 cm high and the feet floated. The frames
    come back with the clip's own pelvis turned whole, the legs hanging from it and the body as high as keeps each
    frame's lowest foot where it was, on the floor."""
    engine = Engine.load()
    seed = np.concatenate([engine.seeds[walk_seed_index(engine.ckpt.seed_names)]] * 2)
    walk = features_to_positions(seed)
    lengths = body_lengths(walk)
    rig = walk.copy()
    for side in ("l", "r"):  # the thighs' heads 7 cm above the hips, as far out to the side
        j = JOINT_INDEX[f"{side}_upleg"]
        lift = np.array([0.0, 0.07 + (walk[:, 0, 1] - walk[:, j, 1]).mean(), 0.0])
        rig[:, j:j + 4] += lift  # the thigh's head and the leg below it (upleg, knee, foot, toe)
    feet = [7, 8, 11, 12]
    rig[..., 1] -= np.percentile(rig[:, feet, 1].min(1), 5) - np.percentile(walk[:, feet, 1].min(1), 5)
    rig = with_bone_lengths(rig, body_lengths(rig) * np.where(np.arange(21) == 1, 2.0, 1.0))  # a long lower spine
    assert np.abs(body_lengths(rig) - lengths).sum() > 0.05 * lengths.sum()  # read on the learnt body
    new = engine.extend(rig, 90)
    thighs = lambda p: (p[:, [JOINT_INDEX["l_upleg"], JOINT_INDEX["r_upleg"]], 1] - p[:, :1, 1]).mean()  # noqa: E731
    assert abs(thighs(new) - thighs(rig)) < 0.005  # the rig's pelvis
    floor = np.percentile(rig[:, [7, 8, 11, 12], 1].min(1), 5)
    assert abs(np.median(new[:, [7, 8, 11, 12], 1].min(1)) - floor) < 0.02  # the feet on the floor, not over it
