"""A character rigged with Auto-Rig Pro (Artell's add-on; its human rig), made here bone for bone after the add-on's
public source: ``c_pos`` > ``c_traj`` > ``c_root_master.x``, the body's root control, its head at the pelvis;
``c_root.x`` below it turns the hips about the waist (it points down, its head at the waist) and the deform
``root.x`` copies it; each limb has an FK chain of ``c_`` controls (``c_thigh_fk.l`` below ``c_thigh_b.l``,
``c_foot_fk.l`` lying along the ground, turned half a turn), an IK chain to ``c_foot_ik.l`` / ``c_hand_ik.l`` (the
IK foot below its control), and
bones that blend the two (``thigh.l``, ``leg.l``, ``foot.l``; ``arm.l``, ``forearm.l``, ``hand.l``) by the
``ik_fk_switch`` on the IK control (1 FK, 0 IK); twist and stretch bones split each segment in two and deform.
The shipped ``auto_rig_pro`` preset fits it with no set-up: Extend keys the FK controls and the switches."""

from __future__ import annotations

import bpy
import numpy as np
import pytest
from scenes import (
    _mid,
    _rest_joints,
    action_of,
    build_armature,
    evaluated_joints,
    fcurves_of,
    find_mocap,
    key_ik_walk,
    key_snapshot,
    same_keys,
    set_pole,
    skinned,
    switch_driver,
    switch_keys,
    through_fbx,
    world_bones,
)

SIDES = "lr"


def _follow(obj, bone: str, kind: str, target: str, switch: str = "") -> None:
    con = obj.pose.bones[bone].constraints.new(kind)
    con.target, con.subtarget = obj, target
    if switch:
        switch_driver(obj, con, switch)


def arp_bones(spines: int = 3) -> list[tuple]:
    """(name, parent, head, tail) of an Auto-Rig Pro human rig on the canonical rest skeleton; ``spines``: 3 (the
    add-on's default) or 2 spine bones."""
    j = _rest_joints()
    up, fwd, back = np.array([0, 0, 0.1]), np.array([0, -0.06, 0]), np.array([0, -0.04, 0])
    chain = [j["spine"], _mid(j["spine"], j["spine1"]), j["spine1"], j["neck"]] if spines == 3 else [
        j["spine"], j["spine1"], j["neck"]]
    bones = [("c_pos", None, np.zeros(3), np.array([0, 0.4, 0])),
             ("c_traj", "c_pos", np.zeros(3), np.array([0, 0.3, 0])),
             ("c_root_master.x", "c_traj", j["hips"], j["spine"]),
             ("c_root.x", "c_root_master.x", j["spine"], j["hips"]), ("root.x", "c_traj", j["spine"], j["hips"])]
    control, deform = "c_root_master.x", "root.x"
    for k in range(spines):
        name = f"spine_0{k + 1}.x"
        bones += [("c_" + name, control, chain[k], chain[k + 1]), (name, deform, chain[k], chain[k + 1])]
        control, deform = "c_" + name, name
    top_c, top_d = control, deform
    bones += [("c_neck.x", top_c, j["neck"], j["head"]), ("neck.x", top_d, j["neck"], j["head"]),
              ("c_head.x", "c_neck.x", j["head"], j["head"] + 2 * up),
              ("head.x", "neck.x", j["head"], j["head"] + 2 * up)]
    for s in SIDES:
        hip, knee, ankle, toe = (j[f"{s}_{n}"] for n in ("upleg", "knee", "foot", "toe"))
        knee = knee + np.array([0, -0.03, 0])  # bent a little forward, as the add-on asks: the IK knees know their way
        arm, elbow, wrist = (j[f"{s}_{n}"] for n in ("arm", "elbow", "wrist"))
        elbow = elbow + np.array([0, 0.03, 0])  # and the elbows a little back: the IK arms know their way too
        hand_tip = _mid(wrist, j[f"{s}_fingertip"], 0.45)
        clavicle = _mid(j["neck"], arm, 0.3) - up
        S = "." + s
        bones += [
            ("c_shoulder" + S, top_c, clavicle, arm), ("shoulder" + S, top_d, clavicle, arm),
            ("c_arm_fk" + S, "c_shoulder" + S, arm, elbow), ("arm_fk" + S, "c_arm_fk" + S, arm, elbow),
            ("c_forearm_fk" + S, "c_arm_fk" + S, elbow, wrist), ("forearm_fk" + S, "c_forearm_fk" + S, elbow, wrist),
            ("c_hand_fk" + S, "c_forearm_fk" + S, wrist, hand_tip),
            ("c_hand_ik" + S, "c_traj", wrist, hand_tip),
            ("arm_ik" + S, "c_shoulder" + S, arm, elbow), ("forearm_ik" + S, "arm_ik" + S, elbow, wrist),
            ("arm" + S, "shoulder" + S, arm, elbow), ("forearm" + S, "arm" + S, elbow, wrist),
            ("hand" + S, "forearm" + S, wrist, hand_tip),
            ("c_arm_twist_offset" + S, "arm" + S, arm, _mid(arm, elbow)),
            ("arm_stretch" + S, "arm" + S, _mid(arm, elbow), elbow),
            ("forearm_stretch" + S, "forearm" + S, elbow, _mid(elbow, wrist)),
            ("forearm_twist" + S, "forearm" + S, _mid(elbow, wrist), wrist),
            ("c_thigh_b" + S, "c_root.x", hip - (knee - hip) / 7, hip),
            ("c_thigh_fk" + S, "c_thigh_b" + S, hip, knee), ("thigh_fk" + S, "c_thigh_fk" + S, hip, knee),
            ("c_leg_fk" + S, "c_thigh_fk" + S, knee, ankle), ("leg_fk" + S, "c_leg_fk" + S, knee, ankle),
            ("c_foot_fk" + S, "c_leg_fk" + S, ankle, ankle + back), ("foot_fk" + S, "c_foot_fk" + S, ankle, toe),
            ("c_toes_fk" + S, "foot_fk" + S, toe, toe + fwd),
            ("c_foot_ik" + S, "c_traj", ankle, ankle + back),
            ("c_leg_pole" + S, "c_root_master.x", knee + [0, -0.5, 0], knee + [0, -0.5, 0.1]),  # with the body
            ("c_arms_pole" + S, "c_root_master.x", elbow + [0, 0.5, 0], elbow + [0, 0.5, 0.1]),
            ("thigh_ik" + S, "c_thigh_b" + S, hip, knee), ("leg_ik" + S, "thigh_ik" + S, knee, ankle),
            ("foot_ik" + S, "c_foot_ik" + S, ankle, toe), ("c_toes_ik" + S, "foot_ik" + S, toe, toe + fwd),
            ("thigh" + S, "root.x", hip, knee), ("leg" + S, "thigh" + S, knee, ankle),
            ("foot" + S, "leg" + S, ankle, toe),
            ("toes_01" + S, "foot" + S, toe, toe + fwd / 3),
            ("thigh_twist" + S, "thigh" + S, hip, _mid(hip, knee)),
            ("thigh_stretch" + S, "thigh" + S, _mid(hip, knee), knee),
            ("leg_stretch" + S, "leg" + S, knee, _mid(knee, ankle)),
            ("leg_twist" + S, "leg" + S, _mid(knee, ankle), ankle)]
    return bones


def arp_rig(spines: int = 3, frames: int = 60):
    """The rig of :func:`arp_bones`, legs in IK (switch 0) and arms in FK (switch 1), a walk keyed on
    c_root_master.x, the IK feet and the FK arms."""
    bones = arp_bones(spines)
    obj = build_armature("ARP_rig", bones, rotation_mode="QUATERNION")
    bpy.ops.object.mode_set(mode="EDIT")
    for s in SIDES:  # the foot controls lie along the ground turned half a turn, the toes' too, as the add-on's
        for name in ("c_foot_fk", "c_foot_ik", "c_toes_fk"):
            obj.data.edit_bones[f"{name}.{s}"].roll = np.pi
    bpy.ops.object.mode_set(mode="OBJECT")
    for pb in obj.pose.bones:  # the limbs' FK controls turn by Euler angles, the rest by quaternions
        if pb.name.startswith(("c_arm_fk", "c_forearm_fk", "c_thigh_fk", "c_leg_fk")):
            pb.rotation_mode = "XYZ"
    _follow(obj, "root.x", "COPY_TRANSFORMS", "c_root.x")
    names = {b[0] for b in bones}
    for name in [n for n in names if n.endswith(".x") and "c_" + n in names]:
        _follow(obj, name, "COPY_TRANSFORMS", "c_" + name)
    for s in SIDES:
        S, legs, hands = "." + s, f"c_foot_ik.{s}", f"c_hand_ik.{s}"
        obj.pose.bones[legs]["ik_fk_switch"] = 0.0
        obj.pose.bones[hands]["ik_fk_switch"] = 1.0
        _follow(obj, "shoulder" + S, "COPY_TRANSFORMS", "c_shoulder" + S)
        for bone, target, pole in (("leg_ik" + S, legs, "c_leg_pole" + S),
                                   ("forearm_ik" + S, hands, "c_arms_pole" + S)):
            ik = obj.pose.bones[bone].constraints.new("IK")
            ik.target, ik.subtarget, ik.chain_count = obj, target, 2
            set_pole(obj, ik, pole)
        for bone, switch in (("thigh", legs), ("leg", legs), ("foot", legs), ("arm", hands), ("forearm", hands)):
            _follow(obj, bone + S, "COPY_TRANSFORMS", f"{bone}_ik{S}")
            _follow(obj, bone + S, "COPY_TRANSFORMS", f"{bone}_fk{S}", switch)
        _follow(obj, "toes_01" + S, "COPY_ROTATION", "c_toes_ik" + S)
        _follow(obj, "toes_01" + S, "COPY_ROTATION", "c_toes_fk" + S, legs)
        _follow(obj, "hand" + S, "COPY_ROTATION", hands)
        _follow(obj, "hand" + S, "COPY_ROTATION", "c_hand_fk" + S, hands)
    key_ik_walk(obj, frames, "c_root_master.x", ("c_foot_ik.l", "c_foot_ik.r"), ("c_arm_fk.l", "c_arm_fk.r"),
                speed=0.6, drop=0.06)  # knees bent: every foot within the legs' reach
    return obj


@pytest.mark.parametrize("spines", [3, 2])
def test_extend_keys_auto_rig_pro_legs_in_ik_on_their_ik_controls_and_arms_in_fk_on_fk(addon, model_calls, spines):
    obj = arp_rig(spines)
    original = evaluated_joints(addon, obj, np.arange(1, 61))
    assert np.ptp(original[:, 0, 1]) > 1.1  # the body walks 1.2 m
    assert np.ptp(original[:, 7, 1]) > 0.5  # the left ankle (IK) steps
    knee = original[:, 5:7] - original[:, 6:8]  # the legs reach their feet: hip-knee and knee-ankle keep their length
    assert np.ptp(np.linalg.norm(knee, axis=-1), axis=0).max() < 1e-3
    old = action_of(obj)
    before = key_snapshot(obj)
    assert bpy.ops.strnn.extend_clip(frames=30) == {"FINISHED"}
    new = action_of(obj)
    assert new is not old and same_keys(before, key_snapshot(obj, old))
    assert new["strnn"]["controls"]["set"] == "auto_rig_pro"
    assert new["strnn"]["controls"]["max_error_cm"] < 0.5
    np.testing.assert_allclose(evaluated_joints(addon, obj, np.arange(1, 61)), original, atol=1e-5)
    keyed = {fc.data_path.split('"')[1] for fc in fcurves_of(obj, new) if fc.data_path.startswith("pose.bones")}
    assert all(b.startswith("c_") for b in keyed), sorted(keyed)
    assert {"c_root_master.x", "c_foot_ik.l", "c_leg_pole.r", "c_toes_ik.l", "c_arm_fk.r", "c_hand_fk.l",
            "c_spine_02.x"} <= keyed
    assert ("c_spine_03.x" in keyed) == (spines == 3)
    moved = {b for b in keyed if any(fc.data_path.startswith(f'pose.bones["{b}"].') for fc in fcurves_of(obj, new))}
    assert not moved & {"c_thigh_fk.l", "c_leg_fk.r", "c_foot_fk.l", "c_hand_ik.r", "c_arms_pole.l"}
    assert new["strnn"]["controls"]["ik"] == ["c_foot_ik.l", "c_foot_ik.r"]
    assert all(v == 0.0 for v in switch_keys(obj, new, "c_foot_ik.l").values())  # the legs stay in IK
    assert all(v == 1.0 for v in switch_keys(obj, new, "c_hand_ik.r").values())
    # the blending and deform bones put the joints where the model put them (the legs on their IK chains)
    pos = evaluated_joints(addon, obj, np.arange(61, 91))
    assert np.linalg.norm(pos - model_calls.extended(), axis=-1).max() < 0.01


def test_the_bone_map_reads_auto_rig_pro_at_the_pelvis_and_the_bones_that_blend_fk_and_ik(addon):
    obj = arp_rig(frames=10)
    assert bpy.ops.strnn.auto_map() == {"FINISHED"}
    m = obj.strnn_map
    assert m.family == "auto_rig_pro"
    assert (m.hips, m.spine, m.spine1, m.l_upleg, m.r_knee, m.l_toe, m.r_arm, m.l_wrist) == (
        "c_root_master.x", "spine_01.x", "spine_03.x", "thigh.l", "leg.r", "toes_01.l", "arm.r", "hand.l")


def test_controls_from_preset_fills_the_auto_rig_pro_controls(addon):
    obj = arp_rig(spines=2, frames=10)
    assert bpy.ops.strnn.controls_from_preset() == {"FINISHED"}
    listed = {c.bone: c.drives for c in obj.strnn_controls if c.role == "FK"}
    assert listed["c_root_master.x"] == "c_root_master.x" and listed["c_toes_fk.r"] == "toes_01.r"
    assert len(listed) == 21 and "c_spine_03.x" not in listed  # a rig with two spine bones
    assert {s.bone for s in obj.strnn_switches} == {f"c_{limb}_ik.{s}" for limb in ("foot", "hand") for s in SIDES}
    ik = {c.bone: (c.role, c.switch) for c in obj.strnn_controls if c.role != "FK"}  # kept for limbs in IK
    assert ik == {**{f"c_foot_ik.{s}": ("IK_END", f"c_foot_ik.{s}") for s in SIDES},
                  **{f"c_toes_ik.{s}": ("IK", f"c_foot_ik.{s}") for s in SIDES},
                  **{f"c_leg_pole.{s}": ("POLE", f"c_foot_ik.{s}") for s in SIDES},
                  **{f"c_hand_ik.{s}": ("IK_END", f"c_hand_ik.{s}") for s in SIDES},
                  **{f"c_arms_pole.{s}": ("POLE", f"c_hand_ik.{s}") for s in SIDES}}
    assert {(s.bone, s.value, s.ik_value) for s in obj.strnn_switches} == {
        (f"c_{limb}_ik.{s}", 1.0, 0.0) for limb in ("foot", "hand") for s in SIDES}



def moved_walk(addon, folder, hands_ik: bool = False):
    """The character (no action, in its rest pose; its arms in FK, or in IK with ``hands_ik``) given a walk (real
    motion capture when unpacked) by Transfer Motion with its feet locked: (character, source, new action, the floor
    it stands on)."""
    from test_addon_rigify import import_walk, transfer

    obj = arp_rig(frames=1)
    obj.animation_data.action = None
    for pb in obj.pose.bones:
        pb.matrix_basis.identity()
    for side in SIDES:
        obj.pose.bones[f"c_hand_ik.{side}"]["ik_fk_switch"] = 0.0 if hands_ik else 1.0
    floor = evaluated_joints(addon, obj, [1])[0, [7, 8, 11, 12], 2].min()  # where it stands: its toes, 3 cm down
    source = import_walk(folder)
    _, moved = transfer(source, obj, foot_lock=True)
    return obj, source, moved, floor


def test_a_walk_moved_onto_the_rig_is_keyed_on_its_controls_and_stands_on_its_floor(addon, tmp_path):
    from test_addon_rigify import knee_bend_forward

    obj, source, moved, floor = moved_walk(addon, tmp_path)
    assert moved["strnn"]["controls"]["set"] == "auto_rig_pro"
    frames = np.arange(int(moved.frame_range[0]), int(moved.frame_range[1]) + 1)
    got, src = evaluated_joints(addon, obj, frames), evaluated_joints(addon, source, frames)
    for side in SIDES:  # each knee bends the way the source's does
        bent = np.abs(knee_bend_forward(src, side)) > 0.02
        assert bent.any() and (np.sign(knee_bend_forward(got, side)[bent]) ==
                               np.sign(knee_bend_forward(src, side)[bent])).all()
    real = find_mocap() is not None  # the procedural walk's knees bend backwards: its poles go behind them
    for k, side in ((6, "l"), (10, "r")) if real else ():  # each knee's pole stays in front of it, never behind
        poles = []
        for f in frames:
            bpy.context.scene.frame_set(int(f))
            poles.append(np.array(obj.matrix_world @ obj.pose.bones[f"c_leg_pole.{side}"].head))
        across = got[:, 5] - got[:, 9]
        forward = np.cross(across, [0.0, 0.0, 1.0])
        assert (np.einsum("fi,fi->f", np.array(poles) - got[:, k], forward) > 0).all()
    feet = got[:, [7, 8, 11, 12], 2].min(1) - floor  # the lowest heel or toe stands on the floor, not in it
    assert np.percentile(feet, 5) > -0.03 and np.percentile(feet, 50) < 0.05, np.percentile(feet, [5, 50])
    assert np.linalg.norm(got[-1, 0, :2] - got[0, 0, :2]) > 1.0  # it walks


def test_arms_animated_in_ik_are_keyed_on_their_ik_controls_and_poles(addon, tmp_path):
    obj, _, moved, _ = moved_walk(addon, tmp_path, hands_ik=True)
    controls = moved["strnn"]["controls"]
    assert controls["ik"] == ["c_foot_ik.l", "c_foot_ik.r", "c_hand_ik.l", "c_hand_ik.r"]
    assert controls["max_error_cm"] < 1.0, controls
    paths = {fc.data_path for fc in fcurves_of(obj, moved)}
    keyed = {p.split('"')[1] for p in paths if p.startswith("pose.bones") and '"][' not in p}
    assert {"c_hand_ik.l", "c_hand_ik.r", "c_arms_pole.l", "c_arms_pole.r", "c_shoulder.l"} <= keyed
    assert not keyed & {"c_arm_fk.l", "c_forearm_fk.r", "c_hand_fk.l"}


def test_a_walk_moved_onto_the_rig_and_extended_still_walks(addon, real_model, tmp_path):
    """An animator's day: a real walk moved onto the character, then extended by 5 s with the bundled model: keyed
    on the controls, and still walking in its last 2 s."""
    from test_addon_rigify import joint_speed

    if find_mocap() is None:
        pytest.skip("needs a real walk (../shared/mocap unpacked): the procedural walk is not motion the model learnt")
    obj, _, moved, _ = moved_walk(addon, tmp_path)
    last = int(moved.frame_range[1])
    fps = bpy.context.scene.render.fps
    assert bpy.ops.strnn.extend_clip(frames=5 * fps) == {"FINISHED"}
    new = action_of(obj)
    assert new["strnn"]["controls"]["set"] == "auto_rig_pro" and new["strnn"]["controls"]["max_error_cm"] < 1.0
    keyed = {fc.data_path.split('"')[1] for fc in fcurves_of(obj, new) if fc.data_path.startswith("pose.bones")}
    assert all(b.startswith("c_") for b in keyed), sorted(keyed)
    before = joint_speed(evaluated_joints(addon, obj, np.arange(last - 2 * fps + 1, last + 1)))
    after = joint_speed(evaluated_joints(addon, obj, np.arange(last + 3 * fps + 1, last + 5 * fps + 1)))
    print(f"auto-rig-pro walk extended: joint speed {after / before:.2f} x the clip's in its last 2 s")
    assert 0.5 < after / before < 2.0, (before, after)


def test_root_motion_goes_on_c_traj_and_extend_carries_it_on(addon, model_calls, tmp_path):
    """Transfer Motion with Root Motion keys the travel on ``c_traj`` (the rig's root-motion control), under the body
    on the floor, and the body's controls against it; Extend then carries ``c_traj`` on with the body."""
    from test_addon_rigify import import_walk, transfer

    obj = arp_rig(frames=1)
    obj.animation_data.action = None
    for pb in obj.pose.bones:
        pb.matrix_basis.identity()
    source = import_walk(tmp_path)
    _, moved = transfer(source, obj, foot_lock=True, root_motion=True)
    assert moved["strnn"]["root_motion"].to_dict() == {"bone": "c_traj"}
    frames = np.arange(int(moved.frame_range[0]), int(moved.frame_range[1]) + 1)

    def traj(frames):
        out = []
        for f in frames:
            bpy.context.scene.frame_set(int(f))
            out.append(np.array(obj.matrix_world @ obj.pose.bones["c_traj"].head))
        return np.array(out)

    joints, roots = evaluated_joints(addon, obj, frames), traj(frames)
    assert np.linalg.norm(roots[-1, :2] - roots[0, :2]) > 1.0  # it carries the walk
    assert np.linalg.norm(roots[:, :2] - joints[:, 0, :2], axis=-1).max() < 0.15  # under the body
    assert np.abs(roots[:, 2] - roots[0, 2]).max() < 1e-5  # on the floor
    for o in bpy.context.view_layer.objects:
        o.select_set(o is obj)
    bpy.context.view_layer.objects.active = obj
    last = int(frames[-1])
    assert bpy.ops.strnn.extend_clip(frames=30) == {"FINISHED"}
    new = action_of(obj)
    assert new["strnn"]["root_motion"]["bone"] == "c_traj" and new["strnn"]["controls"]["max_error_cm"] < 1.0
    more = np.arange(last, last + 31)
    joints, roots = evaluated_joints(addon, obj, more), traj(more)
    assert np.linalg.norm(roots[-1, :2] - roots[0, :2]) > 0.3  # on with the body
    assert np.linalg.norm(roots[:, :2] - joints[:, 0, :2], axis=-1).max() < 0.15


# The bones of the rig above that deform a mesh in the add-on's rigs: the deform root and spine, the clavicles, the
# hands, feet and toes, and the twist and stretch halves of each limb's segments.
ARP_DEFORM = {"root", "spine_01", "spine_02", "spine_03", "neck", "head", "shoulder", "hand", "foot", "toes_01",
              "thigh_twist", "thigh_stretch", "leg_stretch", "leg_twist", "arm_stretch", "forearm_stretch",
              "forearm_twist"}


def arp_through_fbx(folder):
    """The rig walking (:func:`arp_rig`), a mesh weighted to its deform bones, through Blender's FBX exporter and
    importer with every bone (baked, the constraints dropped), active."""
    obj = arp_rig()
    bpy.context.scene.frame_start, bpy.context.scene.frame_end = 1, 60
    skinned(obj, [bone.name for bone in obj.data.bones if bone.name.split(".")[0] in ARP_DEFORM])
    return through_fbx(obj, folder / "arp_baked.fbx")


def test_an_auto_rig_pro_rig_an_exporter_baked_walks_on_with_its_deform_bones(addon, model_calls, tmp_path):
    """The rig walking, a mesh weighted to its deform bones, through Blender's FBX exporter and importer with every
    bone (baked, the constraints dropped): its controls drive nothing, and its deform root (``root.x``) hangs from
    ``c_traj``, not from the body's root control the bone map reads the hips on. Extend keys the mapped bones, the
    hips' place on ``c_root_master.x``, and carries the deform bones that hang from none of them with the one they
    moved with (the deform root with the root control, the deform spine set below it): the deform skeleton takes the
    walk on where the model put the joints."""
    from test_addon_rigify import addon_joint_index

    baked = arp_through_fbx(tmp_path)
    assert baked.data.bones["c_root_master.x"].parent.name == "c_traj" == baked.data.bones["root.x"].parent.name
    last = int(action_of(baked).frame_range[1])
    assert bpy.ops.strnn.extend_clip(frames=30) == {"FINISHED"}
    new = action_of(baked)
    assert new["strnn"]["controls"]["set"] == "baked bones" and new["strnn"]["controls"]["max_error_cm"] < 0.5
    joints = addon_joint_index()
    model = model_calls.extended()
    world = np.array(baked.matrix_world)
    on = {"spine": ("root.x", "head"), "spine1": ("spine_03.x", "head"), "head": ("head.x", "head")}
    for s in SIDES:
        on.update({f"{s}_upleg": (f"thigh_twist.{s}", "head"), f"{s}_knee": (f"leg_stretch.{s}", "head"),
                   f"{s}_foot": (f"foot.{s}", "head"), f"{s}_toe": (f"toes_01.{s}", "head"),
                   f"{s}_elbow": (f"arm_stretch.{s}", "tail"), f"{s}_wrist": (f"hand.{s}", "head")})
    got = {j: [] for j in on}
    for f in range(last + 1, last + 31):
        bpy.context.scene.frame_set(f)
        for j, (bone, end) in on.items():
            got[j].append((world @ np.r_[getattr(baked.pose.bones[bone], end), 1.0])[:3])
    far = {j: float(np.linalg.norm(np.array(p) - model[:, joints[j]], axis=-1).max()) for j, p in got.items()}
    assert max(far.values()) < 0.01, far


def test_a_loop_made_on_an_auto_rig_pro_rig_an_exporter_baked_plays_on_whole(addon, tmp_path):
    """Make Loop on the rig an exporter baked (:func:`arp_through_fbx`), played three cycles as Blender repeats it:
    every deform bone in each cycle where it was in the first, carried by the deform root's travel."""
    baked = arp_through_fbx(tmp_path)
    skin = sorted(g.name for g in next(o for o in bpy.data.objects if o.type == "MESH").vertex_groups)
    assert bpy.ops.strnn.make_loop() == {"FINISHED"}
    cycle = action_of(baked)["strnn"]["cycle"]
    first, length = cycle["first"], cycle["frames"]
    mats = world_bones(baked, skin, range(first, first + 3 * length + 1))
    root = skin.index("root.x")
    travel = mats[length, root, :3, 3] - mats[0, root, :3, 3]
    assert np.linalg.norm(travel[:2]) > 0.2  # it walks
    for k in (1, 2):
        again = mats[k * length:(k + 1) * length + 1].copy()
        again[..., :3, 3] -= k * travel
        assert np.linalg.norm(again[..., :3, 3] - mats[:length + 1, :, :3, 3], axis=-1).max() < 2e-3
        assert np.abs(again[..., :3, :3] - mats[:length + 1, :, :3, :3]).max() < 1e-2
