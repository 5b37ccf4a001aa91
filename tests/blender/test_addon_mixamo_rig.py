"""A Mixamo character with the control rig Artell's Mixamo Rig add-on builds into its armature, made here bone for
bone as that add-on makes it (its names, parents and constraints): each ``mixamorig:`` bone copies a ``Ctrl_``
control (the hips through ``Hips_Free_Helper`` below ``Ctrl_Hips_Free``, the foot through ``Foot_FK_<side>`` below
``Ctrl_Foot_FK_<side>``), the limbs follow an IK chain, and their FK chain where the ``ik_fk_switch`` on
``Ctrl_Foot_IK_<side>`` / ``Ctrl_Hand_IK_<side>`` drives the FK constraints' influence to 1. The FK legs and arms
have rolls of their own, as the add-on's do. The shipped ``mixamo_rig`` preset fits it with no set-up: Extend keys
each limb where it is animated (the legs on their IK controls and poles, the arms on their FK controls) and keeps
the switches there, whatever namespace the character's bones have."""

from __future__ import annotations

import bpy
import numpy as np
import pytest
from scenes import (
    action_of,
    build_armature,
    evaluated_joints,
    fcurves_of,
    key_ik_walk,
    key_snapshot,
    mixamo_bones,
    same_keys,
    set_pole,
    switch_driver,
    switch_keys,
)

SIDES = ("Left", "Right")


def _copy(obj, bone: str, kind: str, target: str, name: str, switch: str = "") -> None:
    con = obj.pose.bones[bone].constraints.new(kind)
    con.name, con.target, con.subtarget = name, obj, target
    if switch:
        switch_driver(obj, con, switch)


def mixamo_rig(prefix: str = "mixamorig:", frames: int = 60):
    """The Mixamo Rig add-on's control rig on :func:`scenes.mixamo_bones`, legs in IK (switch 0) and arms in FK
    (switch 1), a walk keyed on Ctrl_Hips, the IK feet and the FK arms."""
    deform = [(prefix + n.split(":")[1], p and prefix + p.split(":")[1], h, t) for n, p, h, t in mixamo_bones()]
    rest = {n.split(":")[-1]: (np.asarray(h, float), np.asarray(t, float)) for n, _, h, t in deform}
    bones = list(deform)

    def copy_of(name, deform_name, parent):
        bones.append((name, parent, *rest[deform_name]))

    bones.append(("Ctrl_Master", None, np.zeros(3), np.array([0.0, -0.4, 0.0])))
    copy_of("Ctrl_Hips", "Hips", "Ctrl_Master")
    bones.append(("Ctrl_Hips_Free", "Ctrl_Hips", rest["Hips"][1], rest["Hips"][0]))  # pivots at the hips' tail
    copy_of("Hips_Free_Helper", "Hips", "Ctrl_Hips_Free")
    for name, parent in (("Spine", "Hips"), ("Spine1", "Spine"), ("Spine2", "Spine1"), ("Neck", "Spine2"),
                         ("Head", "Neck")):
        copy_of(f"Ctrl_{name}", name, f"Ctrl_{parent}")
    for side in SIDES:
        copy_of(f"Ctrl_Shoulder_{side}", f"{side}Shoulder", "Ctrl_Spine2")
        copy_of(f"Ctrl_Arm_FK_{side}", f"{side}Arm", "Ctrl_Spine2")
        copy_of(f"Ctrl_ForeArm_FK_{side}", f"{side}ForeArm", f"Ctrl_Arm_FK_{side}")
        copy_of(f"Ctrl_Hand_FK_{side}", f"{side}Hand", f"Ctrl_ForeArm_FK_{side}")
        copy_of(f"Ctrl_Hand_IK_{side}", f"{side}Hand", "Ctrl_Master")
        copy_of(f"Arm_IK_{side}", f"{side}Arm", f"Ctrl_Shoulder_{side}")
        copy_of(f"ForeArm_IK_{side}", f"{side}ForeArm", f"Arm_IK_{side}")
        copy_of(f"Ctrl_UpLeg_FK_{side}", f"{side}UpLeg", "Ctrl_Hips_Free")
        copy_of(f"Ctrl_Leg_FK_{side}", f"{side}Leg", f"Ctrl_UpLeg_FK_{side}")
        ankle, toe = rest[f"{side}Foot"]
        flat = np.array([toe[0], toe[1], ankle[2]])  # the add-on's foot controls lie flat, Z up
        bones.append((f"Ctrl_Foot_FK_{side}", f"Ctrl_Leg_FK_{side}", ankle, flat))
        copy_of(f"Foot_FK_{side}", f"{side}Foot", f"Ctrl_Foot_FK_{side}")
        copy_of(f"Ctrl_Toe_FK_{side}", f"{side}ToeBase", f"Foot_FK_{side}")
        bones.append((f"Ctrl_Foot_IK_{side}", "Ctrl_Master", ankle, flat))
        knee, elbow = rest[f"{side}Leg"][0], rest[f"{side}ForeArm"][0]
        # the poles go with the body here, so that the walk's knees point ahead as it walks on
        bones.append((f"Ctrl_LegPole_IK_{side}", "Ctrl_Hips", knee + [0, -0.5, 0], knee + [0, -0.5, 0.1]))
        bones.append((f"Ctrl_ArmPole_IK_{side}", "Ctrl_Hips", elbow + [0, 0.5, 0], elbow + [0, 0.5, 0.1]))
        copy_of(f"UpLeg_IK_{side}", f"{side}UpLeg", "Ctrl_Hips_Free")
        copy_of(f"Leg_IK_{side}", f"{side}Leg", f"UpLeg_IK_{side}")
        copy_of(f"Foot_IK_{side}", f"{side}Foot", f"Leg_IK_{side}")
        copy_of(f"Ctrl_Toe_IK_{side}", f"{side}ToeBase", f"Foot_IK_{side}")
    obj = build_armature("MixamoRig", bones, rotation_mode="XYZ")
    bpy.ops.object.mode_set(mode="EDIT")
    for side in SIDES:  # the FK limbs' rolls are the add-on's own, not the deform bones'
        for name in (f"Ctrl_Arm_FK_{side}", f"Ctrl_ForeArm_FK_{side}", f"Ctrl_UpLeg_FK_{side}", f"Ctrl_Leg_FK_{side}"):
            obj.data.edit_bones[name].roll += np.pi / 2 if side == "Left" else -np.pi / 2
    bpy.ops.object.mode_set(mode="OBJECT")
    for pb in obj.pose.bones:
        if pb.name.startswith(prefix) or not pb.name.startswith("Ctrl_"):
            pb.rotation_mode = "QUATERNION"
    d = prefix
    _copy(obj, d + "Hips", "COPY_TRANSFORMS", "Hips_Free_Helper", "Copy Transforms")
    for name in ("Spine", "Spine1", "Spine2", "Neck", "Head"):
        _copy(obj, d + name, "COPY_TRANSFORMS", f"Ctrl_{name}", "Copy Transforms")
    for side in SIDES:
        obj.pose.bones[f"Ctrl_Foot_IK_{side}"]["ik_fk_switch"] = 0.0
        obj.pose.bones[f"Ctrl_Hand_IK_{side}"]["ik_fk_switch"] = 1.0
        legs, hand = f"Ctrl_Foot_IK_{side}", f"Ctrl_Hand_IK_{side}"
        _copy(obj, d + f"{side}Shoulder", "COPY_TRANSFORMS", f"Ctrl_Shoulder_{side}", "Copy Transforms")
        arm_at = obj.pose.bones[f"Ctrl_Arm_FK_{side}"].constraints.new("COPY_LOCATION")
        arm_at.target, arm_at.subtarget, arm_at.head_tail = obj, f"Ctrl_Shoulder_{side}", 1.0
        ik = obj.pose.bones[f"ForeArm_IK_{side}"].constraints.new("IK")
        ik.target, ik.subtarget, ik.chain_count = obj, hand, 2
        set_pole(obj, ik, f"Ctrl_ArmPole_IK_{side}")
        ik = obj.pose.bones[f"Leg_IK_{side}"].constraints.new("IK")
        ik.target, ik.subtarget, ik.chain_count = obj, legs, 2
        set_pole(obj, ik, f"Ctrl_LegPole_IK_{side}")
        _copy(obj, f"Foot_IK_{side}", "COPY_ROTATION", legs, "Copy Rotation")
        for bone, ik_bone, fk_bone in ((f"{side}UpLeg", f"UpLeg_IK_{side}", f"Ctrl_UpLeg_FK_{side}"),
                                       (f"{side}Leg", f"Leg_IK_{side}", f"Ctrl_Leg_FK_{side}"),
                                       (f"{side}Foot", f"Foot_IK_{side}", f"Foot_FK_{side}")):
            _copy(obj, d + bone, "COPY_TRANSFORMS", ik_bone, "IK_follow")
            _copy(obj, d + bone, "COPY_TRANSFORMS", fk_bone, "FK_follow", switch=legs)
        _copy(obj, d + f"{side}ToeBase", "COPY_ROTATION", f"Ctrl_Toe_IK_{side}", "IK_Rot_follow")
        _copy(obj, d + f"{side}ToeBase", "COPY_ROTATION", f"Ctrl_Toe_FK_{side}", "FK_Rot_follow", switch=legs)
        for bone, ik_bone, fk_bone in ((f"{side}Arm", f"Arm_IK_{side}", f"Ctrl_Arm_FK_{side}"),
                                       (f"{side}ForeArm", f"ForeArm_IK_{side}", f"Ctrl_ForeArm_FK_{side}")):
            _copy(obj, d + bone, "COPY_TRANSFORMS", ik_bone, "IK_follow")
            _copy(obj, d + bone, "COPY_TRANSFORMS", fk_bone, "FK_Follow", switch=hand)
        _copy(obj, d + f"{side}Hand", "COPY_ROTATION", hand, "IK_follow")
        _copy(obj, d + f"{side}Hand", "COPY_ROTATION", f"Ctrl_Hand_FK_{side}", "FK_Follow", switch=hand)
    key_ik_walk(obj, frames, "Ctrl_Hips", ("Ctrl_Foot_IK_Left", "Ctrl_Foot_IK_Right"),
                ("Ctrl_Arm_FK_Left", "Ctrl_Arm_FK_Right"))
    return obj


@pytest.mark.parametrize("prefix", ["mixamorig:", "mixamorig1:", ""])
def test_extend_keys_the_mixamo_rig_legs_in_ik_on_their_ik_controls_and_the_arms_in_fk_on_fk(addon, model_calls,
                                                                                             prefix):
    obj = mixamo_rig(prefix)
    original = evaluated_joints(addon, obj, np.arange(1, 61))
    assert np.ptp(original[:, 0, 1]) > 2.0  # the body walks 2.4 m
    old = action_of(obj)
    before = key_snapshot(obj)
    assert bpy.ops.strnn.extend_clip(frames=30) == {"FINISHED"}
    new = action_of(obj)
    assert new is not old and same_keys(before, key_snapshot(obj, old))
    assert new["strnn"]["controls"]["set"] == "mixamo_rig"
    assert new["strnn"]["controls"]["max_error_cm"] < 0.5
    np.testing.assert_allclose(evaluated_joints(addon, obj, np.arange(1, 61)), original, atol=1e-5)
    keyed = {fc.data_path.split('"')[1] for fc in fcurves_of(obj, new) if fc.data_path.startswith("pose.bones")}
    assert all(b.startswith("Ctrl_") for b in keyed), sorted(keyed)
    assert {"Ctrl_Hips", "Ctrl_Foot_IK_Left", "Ctrl_LegPole_IK_Right", "Ctrl_Toe_IK_Left", "Ctrl_Arm_FK_Right",
            "Ctrl_Hand_FK_Left"} <= keyed
    moved = {b for b in keyed if any(fc.data_path.startswith(f'pose.bones["{b}"].') for fc in fcurves_of(obj, new))}
    assert not moved & {"Ctrl_UpLeg_FK_Left", "Ctrl_Leg_FK_Right", "Ctrl_Foot_FK_Left", "Ctrl_Hand_IK_Right",
                        "Ctrl_ArmPole_IK_Left"}
    assert new["strnn"]["controls"]["ik"] == ["Ctrl_Foot_IK_Left", "Ctrl_Foot_IK_Right"]
    assert all(v == 0.0 for v in switch_keys(obj, new, "Ctrl_Foot_IK_Left").values())  # the legs stay in IK
    assert all(v == 1.0 for v in switch_keys(obj, new, "Ctrl_Hand_IK_Right").values())
    # the deform bones put the joints where the model put them
    pos = evaluated_joints(addon, obj, np.arange(61, 91))
    assert np.linalg.norm(pos - model_calls.extended(), axis=-1).max() < 0.01


def test_controls_from_preset_fills_the_mixamo_rig_controls(addon):
    obj = mixamo_rig("mixamorig1:", frames=10)
    assert bpy.ops.strnn.controls_from_preset() == {"FINISHED"}
    listed = {c.bone: c.drives for c in obj.strnn_controls}
    assert listed["Ctrl_Hips"] == "mixamorig1:Hips" and listed["Ctrl_Toe_FK_Right"] == "mixamorig1:RightToeBase"
    assert {s.bone for s in obj.strnn_switches} == {
        f"Ctrl_{limb}_IK_{side}" for limb in ("Foot", "Hand") for side in SIDES}
    roles = {c.bone: (c.role, c.switch) for c in obj.strnn_controls}  # 22 FK controls, 10 for the limbs in IK
    assert len(roles) == 32 and sum(role == "FK" for role, _ in roles.values()) == 22
    assert roles["Ctrl_Hips"] == ("FK", "") and roles["Ctrl_UpLeg_FK_Left"] == ("FK", "Ctrl_Foot_IK_Left")
    assert roles["Ctrl_Foot_IK_Left"] == ("IK_END", "Ctrl_Foot_IK_Left")
    assert roles["Ctrl_ArmPole_IK_Right"] == ("POLE", "Ctrl_Hand_IK_Right")

