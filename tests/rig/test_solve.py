"""Positions-to-rotations solve on a BVH-like rig: exact round trips, bone lengths, unmapped bones."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.io.bvh import local_transforms, read_bvh
from model_core.io.bvh_export import write_bvh
from model_core.motion import rotations
from model_core.motion.conventions import JOINT_INDEX, JOINTS
from model_core.motion.geometry import rotvec_to_matrix
from model_core.motion.synthetic import walking_skeleton
from model_core.rig.controls import joint_rig
from model_core.rig.rigs import detect_rig
from model_core.rig.solve import (
    FOOT_DROP,
    FOOT_FORWARD,
    HAND_TO_FOREARM,
    Anchors,
    Rig,
    SolveError,
    anchor_positions,
    facing_and_up,
    fk,
    solve,
    solved_bones,
    tips_along_the_limb,
)


@pytest.fixture(scope="module")
def rig_and_motion(tmp_path_factory):
    """A rig built from a BVH file (rest frames aligned with the world) and its local motion."""
    path = write_bvh(tmp_path_factory.mktemp("bvh") / "walk.bvh", walking_skeleton(60))
    bvh = read_bvh(path)
    keep = [i for i in range(len(bvh.names)) if not bvh.is_end[i]]
    parents = [keep.index(bvh.parents[i]) if bvh.parents[i] >= 0 else -1 for i in keep]
    heads = np.zeros((len(keep), 3))
    for b, p in enumerate(parents):
        heads[b] = bvh.offsets[keep[b]] + (heads[p] if p >= 0 else 0)
    rest = np.tile(np.eye(4), (len(keep), 1, 1))
    rest[:, :3, 3] = heads
    rig = Rig([bvh.names[i] for i in keep], np.array(parents), rest, np.full(len(keep), 0.1))
    rot, trans = local_transforms(bvh)
    loc = trans[:, keep] - bvh.offsets[keep][None]
    sources = detect_rig(bvh.names).sources
    mapping = {j: (sources[j], False) if sources[j] else (sources[j.replace("fingertip", "wrist")], True)
               for j in JOINTS}
    return rig, Anchors.from_map(rig, mapping), loc, rot[:, keep]


def test_own_motion_from_own_pose_is_exact(rig_and_motion):
    rig, anchors, loc, rot = rig_and_motion
    targets = anchor_positions(rig, anchors, fk(rig, loc, rot))
    loc2, rot2 = solve(rig, anchors, targets, loc, rot)
    assert np.allclose(rot2, rot, atol=1e-8) and np.allclose(loc2, loc, atol=1e-8)


def test_own_motion_from_a_held_pose_reproduces_the_joints(rig_and_motion):
    rig, anchors, loc, rot = rig_and_motion
    targets = anchor_positions(rig, anchors, fk(rig, loc, rot))
    n = len(targets)
    loc2, rot2 = solve(rig, anchors, targets, np.repeat(loc[:1], n, 0), np.repeat(rot[:1], n, 0))
    got = anchor_positions(rig, anchors, fk(rig, loc2, rot2))
    assert np.linalg.norm(got - targets, axis=-1).mean() < 1e-4  # metres
    assert np.allclose(np.linalg.det(rot2), 1.0)


def test_bone_lengths_kept_and_unmapped_bones_hold(rig_and_motion):
    rig, anchors, loc, rot = rig_and_motion
    targets = anchor_positions(rig, anchors, fk(rig, loc, rot)) * 1.2  # a bigger body: cannot be reached
    loc2, rot2 = solve(rig, anchors, targets, loc, rot)
    pose = fk(rig, loc2, rot2)
    heads = pose[:, :, :3, 3]
    for b, p in enumerate(rig.parents):
        if p >= 0:
            rest = np.linalg.norm(rig.rest[b, :3, 3] - rig.rest[p, :3, 3])
            assert np.allclose(np.linalg.norm(heads[:, b] - heads[:, p], axis=-1), rest, atol=1e-9)
    solved = set(solved_bones(rig, anchors))
    held = [b for b in range(len(rig.names)) if b not in solved]
    assert np.allclose(rot2[:, held], rot[:, held])


def test_rotations_encode_in_every_mode(rig_and_motion):
    _, _, _, rot = rig_and_motion
    m = rot[:, 3]
    for order in rotations.EULER_ORDERS:
        e = rotations.euler_continuous(rotations.matrix_to_euler(m, order), order)
        assert np.allclose(rotations.euler_to_matrix(e, order), m, atol=1e-9)


def test_map_that_does_not_fit_the_hierarchy_is_refused(rig_and_motion):
    rig, anchors, _, _ = rig_and_motion
    mapping = {j: (rig.names[b], bool(t)) for j, b, t in zip(JOINTS, anchors.bone, anchors.tail)}
    mapping["l_knee"] = mapping["r_knee"]  # the left leg's chain jumps to the right leg
    with pytest.raises(SolveError, match="l_knee"):
        Anchors.from_map(rig, mapping)
    del mapping["head"]
    with pytest.raises(SolveError, match="head"):
        Anchors.from_map(rig, mapping)


def _without(rig: Rig, drop: list[str]) -> Rig:
    """``rig`` without the bones ``drop``, their children hanging from their parents (rest matrices kept)."""
    keep = [b for b, n in enumerate(rig.names) if n not in drop]

    def parent(b):
        p = int(rig.parents[b])
        while p >= 0 and rig.names[p] in drop:
            p = int(rig.parents[p])
        return keep.index(p) if p >= 0 else -1

    return Rig([rig.names[b] for b in keep], np.array([parent(b) for b in keep]), rig.rest[keep], rig.lengths[keep])


@pytest.mark.parametrize("drop", [("spine1",), ("neck",), ("spine1", "neck")], ids=["one_spine", "no_neck", "both"])
def test_a_rig_without_a_chest_or_neck_bone_places_them_and_is_solved_exactly(rig_and_motion, drop):
    """A rig with one spine bone (no chest of its own) or whose head sits on its chest (no neck bone): the joint is
    placed between its neighbours, and the bone below it turns to carry what it would have carried, twist too."""
    rig, anchors, _, _ = rig_and_motion
    mapping = {j: (rig.names[b], bool(t)) for j, b, t in zip(JOINTS, anchors.bone, anchors.tail)}
    small = _without(rig, [mapping[j][0] for j in drop] + ["LeftShoulder", "RightShoulder"])  # no clavicles either
    for j in drop:
        del mapping[j]
    placed = Anchors.from_map(small, mapping)
    assert sorted(JOINTS[j] for j in placed.between) == sorted(drop)
    rng = np.random.default_rng(0)
    n, b = 40, len(small.names)
    turns = rng.normal(0.0, 0.4, (n, b, 3))  # every bone at a joint turns; the ones between (clavicles) rest
    turns[:, [x not in placed.on_bones() for x in range(b)]] = 0.0
    rot = rotvec_to_matrix(turns)
    loc = np.zeros((n, b, 3))
    loc[:, 0] = rng.normal(0.0, 0.3, (n, 3))
    targets = anchor_positions(small, placed, fk(small, loc, rot))
    for j, (below, above, share) in placed.between.items():  # on the line between its neighbours
        assert 0.0 < share < 1.0
        assert np.allclose(targets[:, j], (1 - share) * targets[:, below] + share * targets[:, above])
    held_loc, held_rot = np.repeat(loc[:1], n, 0), np.repeat(rot[:1], n, 0)
    loc2, rot2 = solve(small, placed, targets, held_loc, held_rot)
    got = anchor_positions(small, placed, fk(small, loc2, rot2))
    assert np.abs(got - targets).max() < 1e-6  # every joint, the arms and the head on the one bone below too
    with pytest.raises(SolveError, match="head"):  # the joints around a placed one are still needed
        Anchors.from_map(small, {j: m for j, m in mapping.items() if j != "head"})
    skeleton = joint_rig(small, mapping)  # the skeleton a control rig or a visual bake is solved on
    assert set(skeleton.names) == set(small.names)  # every bone here carries a joint or lies between two
    on_skeleton = Anchors.from_map(skeleton, mapping)
    assert on_skeleton.between == placed.between


def test_hips_at_the_tail_of_a_bone_pointing_down_from_the_waist_are_solved_exactly(rig_and_motion):
    """An MMD model has no bone at the pelvis: its lower body points down from the waist, the hips at its tail, and
    the legs and the spine hang from it. The solve turns that bone about the hips and puts its head where that sets
    its tail on them."""
    rig, anchors, _, _ = rig_and_motion
    mapping = {j: (rig.names[b], bool(t)) for j, b, t in zip(JOINTS, anchors.bone, anchors.tail)}
    hips = rig.names.index(mapping["hips"][0])
    down = np.eye(4)
    down[:3, :3] = np.diag([1.0, -1.0, -1.0])  # its +Y along the bone points down
    down[:3, 3] = rig.rest[hips, :3, 3] + [0.0, 0.1, 0.0]  # its head 10 cm over the pelvis, at the waist
    lower = Rig(["Lower"] + rig.names, np.r_[-1, np.where(rig.parents < 0, 0, rig.parents + 1)],
                np.concatenate([down[None], rig.rest]), np.r_[0.1, rig.lengths])
    lower = _without(lower, [mapping["hips"][0]])  # the pelvis bone gone: the legs and spine hang from Lower
    mapping["hips"] = ("Lower", True)
    at_tail = Anchors.from_map(lower, mapping)
    rng = np.random.default_rng(1)
    n, b = 40, len(lower.names)
    turns = rng.normal(0.0, 0.4, (n, b, 3))
    turns[:, [x not in at_tail.on_bones() for x in range(b)]] = 0.0
    rot = rotvec_to_matrix(turns)
    loc = np.zeros((n, b, 3))
    loc[:, 0] = rng.normal(0.0, 0.3, (n, 3))
    targets = anchor_positions(lower, at_tail, fk(lower, loc, rot))
    loc2, rot2 = solve(lower, at_tail, targets, np.zeros_like(loc), np.repeat(np.eye(3)[None, None], n, 0).repeat(b, 1))
    got = anchor_positions(lower, at_tail, fk(lower, loc2, rot2))
    assert np.abs(got - targets).max() < 1e-6
    assert np.allclose(loc2[:, 0], loc[:, 0]) and np.allclose(rot2[:, 0], rot[:, 0])  # the same pose, not another


def test_hips_connected_to_a_root_bone_are_placed_by_moving_the_root(rig_and_motion):
    """A BVH whose root is a bone on the floor with the hips its only child (Character Creator's ``RL_BoneRoot``)
    imports with the hips bone connected to it, and Blender leaves a connected bone's location out: the hips stayed
    on the root's tail, so the whole body played up to 4 cm from the model's. The solve puts the hips' place on the
    root (turned and tilted in its rest and in the held pose) and leaves the hips bone's location at zero."""
    rig, anchors, loc, rot = rig_and_motion
    mapping = {j: (rig.names[b], bool(t)) for j, b, t in zip(JOINTS, anchors.bone, anchors.tail)}
    hips = rig.names.index(mapping["hips"][0])
    floor = np.eye(4)
    floor[:3, :3] = rotvec_to_matrix(np.array([0.2, 0.7, 0.0]))
    floor[:3, 3] = rig.rest[hips, :3, 3] * [1.0, 0.0, 1.0]  # on the floor under the hips
    names = ["Root"] + rig.names
    parents = np.r_[-1, np.where(rig.parents < 0, 0, rig.parents + 1)]
    connected = np.arange(len(names)) == hips + 1  # the hips bone, on the root's tail
    rooted = Rig(names, parents, np.concatenate([floor[None], rig.rest]), np.r_[0.5, rig.lengths], connected)
    targets = anchor_positions(rig, anchors, fk(rig, loc, rot))
    n = len(targets)
    held_loc = np.concatenate([np.zeros((n, 1, 3)), np.repeat(loc[:1], n, 0)], 1)
    held_rot = np.concatenate([np.repeat(rotvec_to_matrix(np.array([0.0, 0.4, 0.1]))[None, None], n, 0),
                               np.repeat(rot[:1], n, 0)], 1)
    on_root = Anchors.from_map(rooted, mapping)
    loc2, rot2 = solve(rooted, on_root, targets, held_loc, held_rot)
    got = anchor_positions(rooted, on_root, fk(rooted, loc2, rot2))
    assert np.linalg.norm(got - targets, axis=-1).max() < 1e-6
    assert np.abs(loc2[:, hips + 1]).max() == 0.0  # nothing keyed where Blender would leave it out
    assert np.allclose(rot2[:, 0], held_rot[:, 0])  # the root moves, and keeps its turn
    unconnected = Rig(names, parents, rooted.rest, rooted.lengths)
    assert np.abs(solve(unconnected, on_root, targets, held_loc, held_rot)[0][:, 0]).max() == 0.0  # else the hips


def test_a_limb_from_a_joint_the_rig_puts_elsewhere_still_reaches_its_end(rig_and_motion):
    """Motion whose legs hang 1 cm lower from the pelvis than the rig's (a CMU take's pelvis bones, shaped unlike
    the motion's): the rig's hips joints stay where its pelvis has them, and the thigh used to aim at the knee's
    target from there, so the foot missed by about as far (1 cm). Now the knee bends to reach the ankle, moving at
    most twice as far as the ankle would have missed: where the knee bends 30 degrees or more, the ankle lands within
    3 mm, and over the walk it misses 0.6 as far on average; the arms, untouched, are exact."""
    from model_core.motion.conventions import JOINT_INDEX

    rig, anchors, loc, rot = rig_and_motion
    played = anchor_positions(rig, anchors, fk(rig, loc, rot))
    low = played.copy()
    legs = [[JOINT_INDEX[f"{side}_{j}"] for j in ("upleg", "knee", "foot", "toe")] for side in "lr"]
    for leg in legs:
        low[:, leg, 1] -= 0.01
    solved = anchor_positions(rig, anchors, fk(rig, *solve(rig, anchors, low, loc, rot)))
    ankles = [leg[2] for leg in legs]
    miss = np.linalg.norm(solved[:, ankles] - low[:, ankles], axis=-1)  # [F, 2]
    thigh, shin = (np.stack([low[:, leg[k + 1]] - low[:, leg[k]] for leg in legs], 1) for k in (0, 1))
    cos = np.sum(thigh * shin, -1) / np.linalg.norm(thigh, axis=-1) / np.linalg.norm(shin, axis=-1)
    bent = cos < np.cos(np.radians(30.0))
    assert bent.sum() > 20 and miss[bent].max() < 0.003
    assert miss.mean() < 0.6 * 0.01
    knees = [leg[1] for leg in legs]
    assert np.linalg.norm(solved[:, knees] - low[:, knees], axis=-1).max() < 0.01 + 2 * 0.01
    arms = [JOINT_INDEX[j] for j in ("l_elbow", "l_wrist", "r_elbow", "r_wrist")]
    assert np.abs(solved[:, arms] - low[:, arms]).max() < 1e-6


def test_a_knee_moved_with_its_ankle_kept_still_lands_the_ankle(rig_and_motion):
    """Each knee moved a fifth further out of its hip-ankle line, the ankles kept (as Denoise may move a clean take's
    knee and not its foot): the motion's legs are no longer the rig's lengths, and the thigh aimed at the knee's
    target took the ankle up to 1.75 cm off (0.66 on average), a clean take's foot moved in playback. The knee now
    bends to reach the ankle: within 2 mm, 0.5 mm on average."""
    from model_core.motion.conventions import JOINT_INDEX

    rig, anchors, loc, rot = rig_and_motion
    moved = anchor_positions(rig, anchors, fk(rig, loc, rot))
    ankles = []
    for side in "lr":
        hip, knee, ankle = (JOINT_INDEX[f"{side}_{j}"] for j in ("upleg", "knee", "foot"))
        moved[:, knee] += 0.2 * (moved[:, knee] - 0.5 * (moved[:, hip] + moved[:, ankle]))
        ankles.append(ankle)
    solved = anchor_positions(rig, anchors, fk(rig, *solve(rig, anchors, moved, loc, rot)))
    miss = np.linalg.norm(solved[:, ankles] - moved[:, ankles], axis=-1)
    assert miss.max() < 0.002 and miss.mean() < 0.0006


def test_rest_matrices_that_are_rotations_only_to_rounding_solve_without_growing_down_a_chain(rig_and_motion):
    """Blender gives a bone pointing straight down (a leg, an MMD model's lower body) a rest matrix that is a rotation
    only to about 1e-4. Each bone's turn is read from its parent's, so such an error used to grow about three times a
    bone down a chain: an MMD model's wrist, below shoulder, twist and finger bones, came 1.2 cm off its solve. The
    rig's rest rotations are the rotations nearest its matrices, and every solved turn is a rotation."""
    rig, anchors, loc, rot = rig_and_motion
    rng = np.random.default_rng(3)
    skewed = rig.rest.copy()
    skewed[:, :3, :3] = skewed[:, :3, :3] @ (np.eye(3) + 1e-4 * rng.normal(size=(len(skewed), 3, 3)))
    rounded = Rig(rig.names, rig.parents, skewed, rig.lengths)
    targets = anchor_positions(rig, anchors, fk(rig, loc, rot))
    n = len(targets)
    loc2, rot2 = solve(rounded, anchors, targets, np.repeat(loc[:1], n, 0), np.repeat(rot[:1], n, 0))
    assert np.abs(np.swapaxes(rot2, -1, -2) @ rot2 - np.eye(3)).max() < 1e-9
    got = anchor_positions(rounded, anchors, fk(rounded, loc2, rot2))
    assert np.linalg.norm(got - targets, axis=-1).max() < 1e-3  # metres: the rounding's own size, not grown


def _with_bone_above(rig: Rig, name: str, child: str, head: np.ndarray) -> Rig:
    """``rig`` with an unmapped bone ``name`` (head at ``head``, the rest turn of the bone above ``child``) inserted
    between ``child`` and its parent."""
    c = rig.names.index(child)
    rest = np.eye(4)
    rest[:3, :3], rest[:3, 3] = rig.rest[int(rig.parents[c]), :3, :3], head
    names = rig.names[:c] + [name] + rig.names[c:]
    shift = lambda p: p + 1 if p >= c else p  # noqa: E731 (an index past the new bone)
    parents = [shift(int(p)) if p >= 0 else -1 for p in rig.parents[:c]] + [int(rig.parents[c])] + \
        [c] + [shift(int(p)) if p >= 0 else -1 for p in rig.parents[c + 1:]]
    return Rig(names, np.array(parents), np.concatenate([rig.rest[:c], rest[None], rig.rest[c:]]),
               np.r_[rig.lengths[:c], 0.1, rig.lengths[c:]])


def test_a_twist_bone_in_line_and_a_bone_at_its_joint_keep_their_pose_however_near_the_target(rig_and_motion):
    """An arm's twist bone (part way along the upper arm, in line with it) and an MMD model's shoulder cancel bone
    (its head at the shoulder) carry joints but turn nothing the bone above does not: the solve leaves them in their
    reference pose. A twist bone aimed again from part way along used to turn half a circle where the elbow asked
    for was nearer the shoulder than itself (an MMD model's forearm came 22 cm off)."""
    rig, anchors, loc, rot = rig_and_motion
    mapping = {j: (rig.names[b], bool(t)) for j, b, t in zip(JOINTS, anchors.bone, anchors.tail)}
    arm, elbow = mapping["l_arm"][0], mapping["l_elbow"][0]
    shoulder, at_elbow = (rig.rest[rig.names.index(n), :3, 3] for n in (arm, elbow))
    twisted = _with_bone_above(rig, "ArmTwist", elbow, shoulder + 0.6 * (at_elbow - shoulder))
    twisted = _with_bone_above(twisted, "ShoulderCancel", arm, shoulder)
    on_it = Anchors.from_map(twisted, mapping)
    n, b = 20, len(twisted.names)
    ref_loc, ref_rot = np.zeros((n, b, 3)), np.repeat(np.eye(3)[None, None], n, 0).repeat(b, 1)
    targets = anchor_positions(twisted, on_it, fk(twisted, ref_loc, ref_rot))
    j_arm, j_elbow = JOINTS.index("l_arm"), JOINTS.index("l_elbow")
    swing = rotvec_to_matrix(np.linspace(0.0, 1.2, n)[:, None] * np.array([1.0, 0.0, 0.0]))
    reach = np.linspace(1.0, 0.3, n)[:, None]  # down to 0.3 of the upper arm: nearer than the twist bone's head
    targets[:, j_elbow] = targets[:, j_arm] + reach * np.einsum("fij,j->fi", swing, at_elbow - shoulder)
    _, rot2 = solve(twisted, on_it, targets, ref_loc, ref_rot)
    for bone in ("ArmTwist", "ShoulderCancel"):
        np.testing.assert_allclose(rot2[:, twisted.names.index(bone)], ref_rot[:, 0], atol=1e-9)
    got = anchor_positions(twisted, on_it, fk(twisted, ref_loc, rot2))
    way = lambda p: (p[:, j_elbow] - p[:, j_arm]) / np.linalg.norm(p[:, j_elbow] - p[:, j_arm], axis=-1)[:, None]  # noqa: E731
    assert np.abs(got[:, j_arm] - targets[:, j_arm]).max() < 1e-6
    np.testing.assert_allclose(way(got), way(targets), atol=1e-6)  # the elbow on the way to its target, never behind


def test_ik_chains_are_put_on_joints_from_legs_played_shorter_than_their_bones(rig_and_motion):
    """Legs Blender's IK plays 2 % shorter than their bones (a chain that may stretch), and motion made on them: the
    solve keeps the bones, so its ankles land further along the legs (more than 1 cm off); the IK chains put on the
    joints (:func:`controls.chains_on_joints`) have each hip, knee, ankle and toe where the motion has it and each
    bone of the chain pointing at the next joint, the bones below the ankle carried with the foot. Motion on legs
    as long as the bones (an IK that does not stretch) is left as the solve has it."""
    from model_core.motion.conventions import JOINT_INDEX
    from model_core.rig.controls import chains_on_joints

    rig, anchors, loc, rot = rig_and_motion
    played = anchor_positions(rig, anchors, fk(rig, loc, rot))
    legs = {side: [JOINT_INDEX[f"{side}_{j}"] for j in ("upleg", "knee", "foot", "toe")] for side in "lr"}
    short = played.copy()
    for hip, knee, ankle, toe in legs.values():  # the legs 2 % shorter from the hip down, the toes carried
        for j, parent in ((knee, hip), (ankle, knee)):
            short[:, j] = short[:, parent] + 0.98 * (played[:, j] - played[:, parent]) \
                + (short[:, parent] - played[:, parent])
        short[:, toe] = short[:, ankle] + played[:, toe] - played[:, ankle]
    pose = fk(rig, *solve(rig, anchors, short, loc, rot))
    solved = anchor_positions(rig, anchors, pose)
    ankles = [legs[s][2] for s in "lr"]
    assert np.linalg.norm(solved[:, ankles] - short[:, ankles], axis=-1).max() > 0.01
    ends = [int(anchors.bone[j]) for j in ankles]
    assert chains_on_joints(rig, anchors, fk(rig, loc, rot), ends, played) == {}
    placed = chains_on_joints(rig, anchors, pose, ends, short)
    for hip, knee, ankle, toe in legs.values():
        chain = [int(anchors.bone[j]) for j in (hip, knee, ankle)]
        assert set(chain) <= set(placed)
        for b, joint, toward in zip(chain, (hip, knee, ankle), (knee, ankle, toe)):
            np.testing.assert_allclose(placed[b][:, :3, 3], short[:, joint], atol=1e-9)
            aim = short[:, toward] - short[:, joint]
            cos = np.sum(placed[b][:, :3, 1] * aim, -1) / np.linalg.norm(aim, axis=-1)
            assert cos.min() > 1 - 1e-9
        below = [b for b in range(len(rig.parents)) if b != chain[2] and rig.is_ancestor(chain[2], b)]
        for b in below:  # carried with the foot: the same transform relative to it as in the solve
            np.testing.assert_allclose(np.linalg.inv(placed[chain[2]]) @ placed[b],
                                       np.linalg.inv(pose[:, chain[2]]) @ pose[:, b], atol=1e-9)


def test_a_finger_tip_at_a_hand_tail_across_the_forearm_is_taken_along_the_forearm(rig_and_motion):
    """A finger tip at the hand's tail, which points up, across the arms held out to the sides (as Blender's BVH
    importer stands a bone that ends in a zero-length End Site): the finger tip goes along the
    forearm's line, HAND_TO_FOREARM of its length past the wrist, and turns with the hand; the solve is as exact
    with it; a tail along the forearm is left as it is."""
    rig, anchors, loc, rot = rig_and_motion
    mapping = {j: (rig.names[b], bool(t)) for j, b, t in zip(JOINTS, anchors.bone, anchors.tail)}
    for side in "lr":  # the finger tips at the hands' tails, which point up (the rest frames are the world's)
        mapping[f"{side}_fingertip"] = (mapping[f"{side}_wrist"][0], True)
    anchors = Anchors.from_map(rig, mapping)
    moved = tips_along_the_limb(rig, anchors)
    at_rest = anchor_positions(moved, anchors, fk(moved, np.zeros_like(loc[:1]), np.eye(3)[None, None].repeat(
        len(rig.names), 1)))[0]
    for side in "lr":
        tip, wrist, elbow = (at_rest[JOINT_INDEX[f"{side}_{k}"]] for k in ("fingertip", "wrist", "elbow"))
        np.testing.assert_allclose(tip - wrist, (wrist - elbow) * HAND_TO_FOREARM, atol=1e-9)
    targets = anchor_positions(moved, anchors, fk(moved, loc, rot))
    assert not np.allclose(targets, anchor_positions(rig, anchors, fk(rig, loc, rot)))  # the tips moved
    loc2, rot2 = solve(moved, anchors, targets, loc, rot)
    assert np.allclose(rot2, rot, atol=1e-8) and np.allclose(loc2, loc, atol=1e-8)
    assert tips_along_the_limb(moved, anchors) is moved


def test_a_toe_at_a_foot_tail_across_the_way_the_body_faces_is_placed_forward_of_the_ankle(rig_and_motion):
    """A toe at the foot's tail, which points up (the rest frames are the world's; a foot with no toe bone, imported
    without Automatic Bone Orientation): the toe goes FOOT_FORWARD of the shin's length forward of the ankle, the way
    the body faces (+Z in the model's axes, from the legs and the spine), and FOOT_DROP down, and turns with the
    foot; the solve is as exact with it. A foot's tail pointing forward is left as it is."""
    rig, anchors, loc, rot = rig_and_motion
    mapping = {j: (rig.names[b], bool(t)) for j, b, t in zip(JOINTS, anchors.bone, anchors.tail)}
    for side in "lr":
        mapping[f"{side}_toe"] = (mapping[f"{side}_foot"][0], True)
    anchors = Anchors.from_map(rig, mapping)
    moved = tips_along_the_limb(rig, anchors)
    still = np.zeros_like(loc[:1]), np.eye(3)[None, None].repeat(len(rig.names), 1)
    at_rest = anchor_positions(moved, anchors, fk(moved, *still))[0]
    forward, up = facing_and_up(dict(zip(JOINTS, at_rest)))
    np.testing.assert_allclose(forward, [0.0, 0.0, 1.0], atol=1e-9)
    for side in "lr":
        toe, ankle, knee = (at_rest[JOINT_INDEX[f"{side}_{k}"]] for k in ("toe", "foot", "knee"))
        shin = np.linalg.norm(ankle - knee)
        np.testing.assert_allclose(toe - ankle, (forward * FOOT_FORWARD - up * FOOT_DROP) * shin, atol=1e-9)
    targets = anchor_positions(moved, anchors, fk(moved, loc, rot))
    loc2, rot2 = solve(moved, anchors, targets, loc, rot)
    assert np.allclose(rot2, rot, atol=1e-8) and np.allclose(loc2, loc, atol=1e-8)
    assert tips_along_the_limb(moved, anchors) is moved  # the tails now point forward: left as they are


def test_a_toe_at_a_foot_tail_an_importer_guessed_is_placed_forward_of_the_ankle(rig_and_motion):
    """A foot with no toe bone at the end of the skeleton, through glTF or an FBX without leaf bones: the importer
    gives it its shin's length and points it on (forward, not across), and its tail is no toe: the toe goes to the
    ball of the foot as for a tail across. A foot shorter than its shin keeps its tail."""
    rig, anchors, loc, rot = rig_and_motion
    mapping = {j: (rig.names[b], bool(t)) for j, b, t in zip(JOINTS, anchors.bone, anchors.tail)}
    for side in "lr":
        mapping[f"{side}_toe"] = (mapping[f"{side}_foot"][0], True)
    anchors = Anchors.from_map(rig, mapping)

    def with_feet(share: float) -> Rig:
        lengths, tails = rig.lengths.copy(), rig.tails.copy()
        for side in "lr":
            foot, shin = (int(anchors.bone[JOINT_INDEX[f"{side}_{k}"]]) for k in ("foot", "knee"))
            lengths[foot] = share * lengths[shin]
            tails[foot] = rig.rest[foot, :3, :3].T @ np.array([0.0, -0.3, 1.0]) / np.hypot(0.3, 1.0) * lengths[foot]
        return Rig(rig.names, rig.parents, rig.rest, lengths, rig.connected, tails)

    guessed = with_feet(1.0)
    moved = tips_along_the_limb(guessed, anchors)
    at_rest = anchor_positions(moved, anchors, moved.rest[None])[0]
    forward, up = facing_and_up(dict(zip(JOINTS, at_rest)))
    for side in "lr":
        toe, ankle, knee = (at_rest[JOINT_INDEX[f"{side}_{k}"]] for k in ("toe", "foot", "knee"))
        shin = np.linalg.norm(ankle - knee)
        np.testing.assert_allclose(toe - ankle, (forward * FOOT_FORWARD - up * FOOT_DROP) * shin, atol=1e-9)
    real = with_feet(0.4)
    assert tips_along_the_limb(real, anchors) is real


def test_the_way_a_body_faces_is_read_from_its_legs_and_spine():
    """Across the legs crossed with up the spine: Blender's -Y for a character made facing the front view, also where
    both thighs start at the middle of the hips (the knees and ankles apart); none without legs apart or a spine."""
    at = {"hips": np.array([0.0, 0.0, 1.0]), "head": np.array([0.0, 0.0, 1.7])}
    for s, x in (("l", 0.1), ("r", -0.1)):
        at |= {f"{s}_upleg": np.array([0.0, 0.0, 0.95]), f"{s}_knee": np.array([x, 0.0, 0.5]),
               f"{s}_foot": np.array([x, 0.0, 0.1])}
    forward, up = facing_and_up(at)
    np.testing.assert_allclose(forward, [0.0, -1.0, 0.0], atol=1e-9)
    assert abs(float(np.dot(forward, up))) < 1e-12 and up[2] > 0.99
    assert facing_and_up({j: p for j, p in at.items() if j != "head"}) is None
    assert facing_and_up({j: p for j, p in at.items() if not j.endswith(("knee", "foot"))}) is None
