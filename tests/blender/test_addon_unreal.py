"""An Unreal Engine mannequin (a plain rig): its IK bones, which hang from the root and which Unreal's animations key
onto the feet and hands, go on with them in the frames the operators write, as a game reading them expects."""

from __future__ import annotations

import bpy
import numpy as np
import pytest
from scenes import (
    across,
    action_of,
    build_armature,
    find_mocap,
    import_bvh,
    key_snapshot,
    open_rig,
    same_keys,
    unreal_bones,
    walk_bvh,
)

WALK = "bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh"  # a real take where the data is unpacked
# each IK bone and the bone Unreal keys it onto
FOLLOWERS = {"ik_foot_l": "foot_l", "ik_foot_r": "foot_r", "ik_hand_gun": "hand_r", "ik_hand_l": "hand_l",
             "ik_hand_r": "hand_r"}


def key_ik_bones(obj, frames) -> None:
    """Key each IK bone of ``obj`` on its bone (:data:`FOLLOWERS`) at ``frames``, as Unreal's animations have them."""
    scene, bones = bpy.context.scene, obj.pose.bones
    for f in frames:
        scene.frame_set(int(f))
        for ik, on in FOLLOWERS.items():  # parents first: ik_hand_gun before the hands below it
            bones[ik].matrix = bones[on].matrix.copy()
            bpy.context.view_layer.update()
            bones[ik].keyframe_insert("location", frame=int(f))
            bones[ik].keyframe_insert("rotation_quaternion", frame=int(f))


def walked_mannequin(folder):
    """The mannequin as an FBX from Unreal comes in (centimetres, the tails across the bones), with no action, and a
    walk moved onto it by Transfer Motion; (the mannequin, the source)."""
    mocap = find_mocap()
    path = mocap / WALK if mocap is not None and (mocap / WALK).exists() else walk_bvh(folder, frames=120)
    source = import_bvh(path, update_scene_fps=True, update_scene_duration=True)
    source.location.x = -2.0
    rig = build_armature("SK_Mannequin", across(unreal_bones()))
    rig.scale = (0.01, 0.01, 0.01)
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in (source, rig))
    bpy.context.view_layer.objects.active = rig
    assert bpy.ops.strnn.transfer_motion() == {"FINISHED"}
    return rig, source


@pytest.fixture(scope="module")
def unreal_file(addon, tmp_path_factory):
    """The mannequin walking, its IK bones keyed on its feet and hands on every frame (as Unreal's animations have
    them; Transfer Motion keys them so already, and here they are keyed again by Blender)."""
    folder = tmp_path_factory.mktemp("unreal")
    bpy.ops.wm.read_homefile(use_empty=True)
    rig, source = walked_mannequin(folder)
    bpy.data.objects.remove(source)
    first, last = (int(f) for f in action_of(rig).frame_range)
    key_ik_bones(rig, range(first, last + 1))
    out = folder / "mannequin.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(out))
    return out


@pytest.fixture
def mannequin(unreal_file):
    return open_rig(unreal_file, "SK_Mannequin")


def off_their_bones(obj, frames) -> np.ndarray:
    """``[F, len(FOLLOWERS)]``: how far (m) each IK bone's head is from its bone's at ``frames``, as Blender plays the
    armature's action, plus how far its axes are turned from its bone's (the matrices' largest difference, metres a
    metre: the IK bones are keyed with their bones' matrices)."""
    scene, bones, out = bpy.context.scene, obj.pose.bones, []
    for f in frames:
        scene.frame_set(int(f))
        out.append([(bones[ik].head - bones[on].head).length * obj.matrix_world.to_scale()[0]
                    + np.abs(np.array(bones[ik].matrix.to_3x3()) - np.array(bones[on].matrix.to_3x3())).max()
                    for ik, on in FOLLOWERS.items()])
    return np.array(out)


def test_extend_keys_the_ik_bones_on_the_feet_and_hands_they_were_keyed_on(mannequin, real_model, capfd):
    obj = mannequin
    old = action_of(obj)
    before = key_snapshot(obj)
    last = int(old.frame_range[1])
    assert bpy.ops.strnn.extend_clip(frames=60) == {"FINISHED"}
    new = action_of(obj)
    assert new is not old and same_keys(before, key_snapshot(obj, old))
    assert new["strnn"]["followers"]["bones"].to_dict() == FOLLOWERS
    assert ("5 keyed bones outside the bone map followed bones it writes over the take (ik_foot_l on foot_l, "
            "ik_foot_r on foot_r, ik_hand_gun on hand_r, ik_hand_l on hand_l, ...) and go on with them"
            in capfd.readouterr().out)
    new_frames = np.arange(last + 1, last + 61)
    off = off_their_bones(obj, new_frames)
    assert off.max() < 1e-3, dict(zip(FOLLOWERS, off.max(0)))
    # the feet walk on, and the IK bones with them
    scene, bones = bpy.context.scene, obj.pose.bones
    heads = []
    for f in (last, last + 60):
        scene.frame_set(f)
        heads.append(np.array(bones["ik_foot_l"].head))
    assert np.linalg.norm(heads[1] - heads[0]) * obj.matrix_world.to_scale()[0] > 0.5
    assert off_their_bones(obj, np.arange(1, last + 1, 20)).max() < 1e-3  # the take's frames as they were


@pytest.mark.parametrize("op, kw", [("foot_lock", {}), ("make_loop", {})], ids=["foot_lock", "make_loop"])
def test_the_ik_bones_stay_on_the_feet_and_hands_the_other_operations_move(mannequin, real_model, op, kw):
    obj = mannequin
    assert getattr(bpy.ops.strnn, op)(**kw) == {"FINISHED"}
    new = action_of(obj)
    assert new["strnn"]["followers"]["bones"].to_dict() == FOLLOWERS
    first, last = (int(f) for f in new.frame_range)
    frames = np.arange(first, last + 1 + (2 * (last - first) if op == "make_loop" else 0), 3)  # a loop played on
    off = off_their_bones(obj, frames)
    assert off.max() < 2e-3, dict(zip(FOLLOWERS, off.max(0)))


def test_a_bone_keyed_apart_from_the_body_is_left_as_it_was(mannequin, real_model):
    """A keyed bone that moved on its own over the take (a prop swung about, not held) is not a follower: Extend leaves
    its keys as they were."""
    obj = mannequin
    prop = obj.pose.bones["ik_hand_gun"]
    first, last = (int(f) for f in action_of(obj).frame_range)
    for f in range(first, last + 1, 5):
        prop.location = (0.3 * np.sin(f / 7.0), 0.2 * np.cos(f / 5.0), 0.1 * f / last)
        prop.keyframe_insert("location", frame=f)
    assert bpy.ops.strnn.extend_clip(frames=20) == {"FINISHED"}
    assert "ik_hand_gun" not in action_of(obj)["strnn"]["followers"]["bones"].to_dict()


def test_transfer_onto_the_mannequin_keys_its_ik_bones_on_the_feet_and_hands_they_rest_on(real_model, tmp_path):
    """With no action to read, the IK bones that rest where the feet and hands rest (hanging from the root, not from
    them) are their twins: Transfer Motion keys them on those bones, as Unreal's own animations have them."""
    rig, _ = walked_mannequin(tmp_path)
    new = action_of(rig)
    assert new["strnn"]["followers"]["bones"].to_dict() == FOLLOWERS
    assert new["strnn"]["followers"]["note"].startswith("5 bones outside the bone map rest on bones it writes")
    first, last = (int(f) for f in new.frame_range)
    off = off_their_bones(rig, np.arange(first, last + 1, 7))
    assert off.max() < 1e-3, dict(zip(FOLLOWERS, off.max(0)))


def test_with_only_the_left_leg_selected_only_the_left_foots_ik_bone_is_keyed_again(mannequin, real_model):
    """Foot Lock with Only Selected Bones on the left leg: of the IK bones only `ik_foot_l`, which follows the left
    foot, gets new keys (on the locked foot); the others keep theirs as they were."""
    obj = mannequin
    left = {"thigh_l", "calf_l", "foot_l", "ball_l"}
    for pb in obj.pose.bones:
        if hasattr(pb, "select"):  # Blender 5 keeps pose selection on the pose bone, 4.x on the bone
            pb.select = pb.name in left
        else:
            pb.bone.select = pb.name in left
    old = action_of(obj)
    before = key_snapshot(obj, old)
    assert bpy.ops.strnn.foot_lock(only_selected=True) == {"FINISHED"}
    after = key_snapshot(obj, action_of(obj))
    changed = {key[0].split('"')[1] for key, co in before.items() if not np.array_equal(co, after[key])}
    assert "ik_foot_l" in changed and not changed & (set(FOLLOWERS) - {"ik_foot_l"}), changed
    first, last = (int(f) for f in old.frame_range)
    assert off_their_bones(obj, np.arange(first, last + 1, 3)).max() < 2e-3


def test_with_its_twist_bones_constrained_the_ik_bones_still_follow(mannequin, real_model):
    """A game rig set up in Blender turns its twist bones by constraints (half the turn of the bone below about the
    limb, as Unreal's own rigs do): the IK bones and the bones they follow have none, so they are still read and
    keyed in closed form, and go on with the feet and hands; the constrained twist bones are left to their
    constraints."""
    obj = mannequin
    for bone, source in (("lowerarm_twist_01_l", "hand_l"), ("lowerarm_twist_01_r", "hand_r"),
                         ("thigh_twist_01_l", "calf_l"), ("thigh_twist_01_r", "calf_r")):
        con = obj.pose.bones[bone].constraints.new("COPY_ROTATION")
        con.target, con.subtarget, con.use_x, con.use_z = obj, source, False, False
        con.target_space = con.owner_space = "LOCAL"
        con.influence = 0.5
    last = int(action_of(obj).frame_range[1])
    assert bpy.ops.strnn.extend_clip(frames=60) == {"FINISHED"}
    assert action_of(obj)["strnn"]["followers"]["bones"].to_dict() == FOLLOWERS
    off = off_their_bones(obj, np.arange(last + 1, last + 61))
    assert off.max() < 1e-3, dict(zip(FOLLOWERS, off.max(0)))
