"""A Mixamo-style rig whose deform bones follow a control chain through COPY_TRANSFORMS
constraints (how many game and studio rigs are built): with no controls set, keys written on the
deform bones would not show, so the operators refuse and say what to set; with the controls set in
the Bone Map panel's Controls list, results are keyed on the controls and the deform bones follow."""

from __future__ import annotations

import bpy
import numpy as np
import pytest
from scenes import (
    action_of,
    build_armature,
    evaluated_joints,
    fcurves_of,
    import_bvh,
    key_snapshot,
    key_walk,
    mixamo_bones,
    mixamo_walk,
    same_keys,
    walk_bvh,
)

CTRL = "CTRL_"


def control_rig(frames: int = 60, rotation_mode: str = "QUATERNION"):
    """Deform bones (``mixamorig:``) copying the transforms of a parallel control chain (``CTRL_``),
    with a walk keyed on the controls (rotations in ``rotation_mode``)."""
    deform = mixamo_bones()
    controls = [(CTRL + n.split(":")[1], p and CTRL + p.split(":")[1], h, t) for n, p, h, t in deform]
    obj = build_armature("ControlRig", deform + controls, rotation_mode=rotation_mode)
    for name, *_ in deform:
        con = obj.pose.bones[name].constraints.new("COPY_TRANSFORMS")
        con.target, con.subtarget = obj, CTRL + name.split(":")[1]
    pair = lambda bone: (CTRL + "Left" + bone, CTRL + "Right" + bone)  # noqa: E731
    key_walk(obj, frames, CTRL + "Hips", pair("UpLeg"), pair("Leg"), pair("Arm"))
    return obj


def set_controls(obj) -> None:
    """Every mapped deform bone driven by its control, through the panel's operators."""
    assert bpy.ops.strnn.auto_map() == {"FINISHED"}
    mapped = {getattr(obj.strnn_map, j) for j in obj.strnn_map.bl_rna.properties.keys()
              if j not in ("rna_type", "name", "family") and not j.endswith("_tail")} - {""}
    bridges = {"mixamorig:LeftShoulder", "mixamorig:RightShoulder", "mixamorig:Spine1"}
    for bone in sorted(mapped | bridges):
        assert bpy.ops.strnn.control_add() == {"FINISHED"}
        item = obj.strnn_controls[obj.strnn_control_index]
        item.bone, item.drives, item.location = CTRL + bone.split(":")[1], bone, bone.endswith("Hips")


def test_without_controls_the_operators_say_what_to_set(addon):
    control_rig()
    obj = bpy.context.active_object
    before = key_snapshot(obj)
    with pytest.raises(RuntimeError, match="follows.*constraint.*Controls"):
        bpy.ops.strnn.extend_clip(frames=10)
    assert same_keys(before, key_snapshot(obj))


@pytest.mark.parametrize("channel", ["rotation_quaternion", "location"])
def test_a_bone_whose_keyed_channel_a_driver_sets_is_refused_and_nothing_changes(addon, channel):
    """A driver overrides a channel's keys: a knee whose rotation, or hips whose location, a driver sets would not
    show what an operator keys on it. The operator says which bone and channel, and changes nothing; a driver on a
    channel no operator keys (the knee's location) is left alone."""
    obj = mixamo_walk(40)
    bone = "mixamorig:Hips" if channel == "location" else "mixamorig:LeftLeg"
    fc = obj.pose.bones[bone].driver_add(channel, 1)
    fc.driver.expression = "0.0"
    before = key_snapshot(obj)
    with pytest.raises(RuntimeError, match=rf"Bone '{bone}' has a driver on {channel}\[1\].*remove the driver"):
        bpy.ops.strnn.extend_clip(frames=10)
    assert same_keys(before, key_snapshot(obj)) and action_of(obj).name == "MixamoAction"
    obj.animation_data.drivers.remove(fc)
    obj.pose.bones["mixamorig:LeftLeg"].driver_add("location", 0).driver.expression = "0.0"
    assert bpy.ops.strnn.extend_clip(frames=10) == {"FINISHED"}


def test_with_controls_extend_keys_them_and_the_deform_bones_follow(addon, model_calls):
    obj = control_rig()
    set_controls(obj)
    original = evaluated_joints(addon, obj, np.arange(1, 61))
    old = action_of(obj)
    before = key_snapshot(obj)
    assert bpy.ops.strnn.extend_clip(frames=30) == {"FINISHED"}
    new = action_of(obj)
    assert new is not old and same_keys(before, key_snapshot(obj, old))
    assert np.abs(evaluated_joints(addon, obj, np.arange(1, 61)) - original).max() < 1e-5
    paths = {fc.data_path for fc in fcurves_of(obj, new)}
    assert not [p for p in paths if "mixamorig:" in p], paths  # nothing keyed on the deform bones
    pos = evaluated_joints(addon, obj, np.arange(61, 91))
    err = np.linalg.norm(pos - model_calls.extended(), axis=-1)  # the deform bones follow the model
    assert err.max() < 0.01, err.max()
    assert new["strnn"]["controls"]["set"] == "custom"


@pytest.mark.parametrize("mode", ["AXIS_ANGLE", "ZXY"])
def test_controls_turned_by_axis_angle_or_euler_are_baked_and_nothing_is_left_behind(addon, model_calls, mode):
    """The bake sets the controls through a stand-in action while Blender evaluates the rig: controls in any rotation
    mode are keyed where the deform bones follow the model; afterwards the file holds the take and the new action
    alone, the take as it was and still holding its keys, and the controls not keyed by the take (the spine, the
    feet) as they were."""
    obj = control_rig(rotation_mode=mode)
    set_controls(obj)
    old = action_of(obj)
    unkeyed = {pb.name: pb.matrix_basis.copy() for pb in obj.pose.bones
               if pb.name.startswith(CTRL) and not any(pb.name in fc.data_path for fc in fcurves_of(obj, old))}
    assert unkeyed
    before = key_snapshot(obj)
    actions = set(bpy.data.actions)
    assert bpy.ops.strnn.extend_clip(frames=30) == {"FINISHED"}
    new = action_of(obj)
    assert set(bpy.data.actions) == actions | {new}
    assert same_keys(before, key_snapshot(obj, old))
    assert all(np.allclose(obj.pose.bones[n].matrix_basis, m) for n, m in unkeyed.items())
    err = np.linalg.norm(evaluated_joints(addon, obj, np.arange(61, 91)) - model_calls.extended(), axis=-1)
    assert err.max() < 0.01, err.max()
    rot = {fc.data_path.rsplit(".", 1)[1] for fc in fcurves_of(obj, new) if "rotation" in fc.data_path}
    assert rot == {"rotation_axis_angle" if mode == "AXIS_ANGLE" else "rotation_euler"}


def test_transfer_onto_a_control_rig_with_no_animation_data_bakes_its_controls_and_leaves_no_trace(addon, tmp_path):
    """A control rig that was never animated (no animation data at all) gets the motion baked on its controls
    through the stand-in action; afterwards it holds the new action alone and the file no other action but the
    source's."""
    obj = control_rig()
    set_controls(obj)
    bpy.data.actions.remove(action_of(obj))
    obj.animation_data_clear()
    source = import_bvh(walk_bvh(tmp_path, frames=60))
    for other in bpy.context.view_layer.objects:
        other.select_set(other in (source, obj))
    bpy.context.view_layer.objects.active = obj
    assert bpy.ops.strnn.transfer_motion() == {"FINISHED"}
    new = action_of(obj)
    assert set(bpy.data.actions) == {new, action_of(source)}
    assert not obj.animation_data.drivers and new["strnn"]["controls"]["set"] == "custom"
    paths = {fc.data_path for fc in fcurves_of(obj, new)}
    assert paths and all(CTRL in p for p in paths), paths
