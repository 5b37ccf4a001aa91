"""A MikuMikuDance model as mmd_tools imports it, made here bone for bone after the add-on's public source (the
add-on itself cannot be installed in a test): Japanese bone names with left and right as ``.L`` / ``.R``;
``全ての親`` > ``センター`` > ``グルーブ``, from which the upper body (``上半身`` > ``上半身2`` > ``首`` > ``頭``, the
shoulders and arms) and the lower body (``下半身``, pointing down from the waist to the pelvis, and the legs ``足`` >
``ひざ`` > ``足首`` > ``つま先``) hang apart; the legs always in IK as the importer sets them: an IK constraint named
"IK" on the knee (two bones, to ``足ＩＫ``, the knee bending only about its X axis within its limits) and on the
ankle (one bone, to ``つま先ＩＫ``, which hangs from ``足ＩＫ``), and the deform copies of the legs (``足D``) turning
with them. The shipped ``mmd`` preset fits it with no set-up."""

from __future__ import annotations

import math

import bpy
import numpy as np
import pytest
from scenes import (
    _mid,
    _rest_joints,
    action_of,
    addon_module,
    build_armature,
    evaluated_joints,
    fcurves_of,
    find_mocap,
    skinned,
    through_fbx,
    world_bones,
)

SIDES = "LR"
# Canonical joint -> (bone, at its tail) of the model, as the bone map reads it.
LEG = ("足", "ひざ", "足首")


def mmd_bones() -> list[tuple]:
    """(name, parent, head, tail) of an MMD model's standard bones on the canonical rest skeleton."""
    j = _rest_joints()
    up, fwd = np.array([0, 0, 0.1]), np.array([0, -0.08, 0])
    centre = np.array([0.0, 0.0, 0.7 * j["hips"][2]])
    bones = [("全ての親", None, np.zeros(3), up), ("センター", "全ての親", centre, centre - up),
             ("グルーブ", "センター", centre + 0.2 * up, centre + up),
             ("下半身", "グルーブ", j["spine"], j["hips"]), ("上半身", "グルーブ", j["spine"], j["spine1"]),
             ("上半身2", "上半身", j["spine1"], j["neck"]), ("首", "上半身2", j["neck"], j["head"]),
             ("頭", "首", j["head"], j["head"] + 2 * up)]
    for s, S in (("l", "L"), ("r", "R")):
        hand = [_mid(j[f"{s}_wrist"], j[f"{s}_fingertip"], t) for t in (0.0, 0.45, 0.65, 0.85, 1.0)]
        bones += [(f"肩.{S}", "上半身2", _mid(j["neck"], j[f"{s}_arm"], 0.3) - up, j[f"{s}_arm"]),
                  (f"腕.{S}", f"肩.{S}", j[f"{s}_arm"], j[f"{s}_elbow"]),
                  (f"ひじ.{S}", f"腕.{S}", j[f"{s}_elbow"], j[f"{s}_wrist"]),
                  (f"手首.{S}", f"ひじ.{S}", hand[0], hand[1])]
        fingers = [f"手首.{S}"] + [f"中指{k}.{S}" for k in "１２３"]
        bones += [(fingers[n], fingers[n - 1], hand[n], hand[n + 1]) for n in (1, 2, 3)]
        bones += [(f"足.{S}", "下半身", j[f"{s}_upleg"], j[f"{s}_knee"]),
                  (f"ひざ.{S}", f"足.{S}", j[f"{s}_knee"], j[f"{s}_foot"]),
                  (f"足首.{S}", f"ひざ.{S}", j[f"{s}_foot"], j[f"{s}_toe"]),
                  (f"つま先.{S}", f"足首.{S}", j[f"{s}_toe"], j[f"{s}_toe"] - 0.3 * up),
                  (f"足ＩＫ.{S}", "全ての親", j[f"{s}_foot"], j[f"{s}_foot"] + fwd),
                  (f"つま先ＩＫ.{S}", f"足ＩＫ.{S}", j[f"{s}_toe"], j[f"{s}_toe"] - 0.3 * up),
                  (f"足D.{S}", "下半身", j[f"{s}_upleg"], j[f"{s}_knee"]),
                  (f"ひざD.{S}", f"足D.{S}", j[f"{s}_knee"], j[f"{s}_foot"]),
                  (f"足首D.{S}", f"ひざD.{S}", j[f"{s}_foot"], j[f"{s}_toe"])]
    return bones


def with_semi_standard(bones: list[tuple]) -> list[tuple]:
    """``bones`` with the semi-standard bones most models have (PMX Editor's plug-in adds them): the waist (``腰``)
    above both bodies, the shoulder's parent and child (``肩P``, ``肩C``), the arm's and the wrist's twist bones
    (``腕捩``, ``手捩``) between the arm's joints, the waist cancel (``腰キャンセル``) above each leg, the leg IK's
    parent (``足IK親``) and the toe of the deform chain (``足先EX``); and a third upper body (``上半身3``), from which
    the neck and shoulders hang, as newer models have."""
    by_name = {b[0]: b for b in bones}
    out, parent_of = [], {}
    j = _rest_joints()
    up = np.array([0, 0, 0.1])
    waist = by_name["下半身"][2]
    out.append(("腰", "グルーブ", waist - 0.5 * up, waist))
    chest = by_name["上半身2"]
    out.append(("上半身3", "上半身2", _mid(chest[2], chest[3], 0.5), chest[3]))
    parent_of.update({"上半身": "腰", "下半身": "腰", "首": "上半身3"})
    for s, S in (("l", "L"), ("r", "R")):
        shoulder, arm, elbow = (by_name[f"{b}.{S}"] for b in ("肩", "腕", "ひじ"))
        out += [(f"肩P.{S}", "上半身3", shoulder[2], shoulder[3]),
                (f"肩C.{S}", f"肩.{S}", arm[2], _mid(arm[2], arm[3], 0.1)),
                (f"腕捩.{S}", f"腕.{S}", _mid(arm[2], arm[3], 0.6), arm[3]),
                (f"手捩.{S}", f"ひじ.{S}", _mid(elbow[2], elbow[3], 0.6), elbow[3]),
                (f"腰キャンセル.{S}", "下半身", j[f"{s}_upleg"], j[f"{s}_upleg"] + 0.3 * up),
                (f"足IK親.{S}", "全ての親", j[f"{s}_foot"] * [1, 1, 0], j[f"{s}_foot"] * [1, 1, 0] + up),
                (f"足先EX.{S}", f"足首D.{S}", _mid(j[f"{s}_foot"], j[f"{s}_toe"], 0.7), j[f"{s}_toe"])]
        parent_of.update({f"肩.{S}": f"肩P.{S}", f"腕.{S}": f"肩C.{S}", f"ひじ.{S}": f"腕捩.{S}",
                          f"手首.{S}": f"手捩.{S}", f"足.{S}": f"腰キャンセル.{S}", f"足D.{S}": f"腰キャンセル.{S}",
                          f"足ＩＫ.{S}": f"足IK親.{S}"})
    result, after = [], {b[0]: b[1] for b in out}  # each new bone right after its parent

    def place(entry):
        result.append(entry)
        for b in out:
            if after[b[0]] == entry[0]:
                place(b)

    for name, parent, head, tail in bones:
        place((name, parent_of.get(name, parent), head, tail))
    return result


def _constrain(obj, bone: str, kind: str, target: str, name: str):
    con = obj.pose.bones[bone].constraints.new(kind)
    con.name, con.target, con.subtarget = name, obj, target
    return con


def mmd_model(semi_standard: bool = False):
    """The model of :func:`mmd_bones` (with ``semi_standard``, :func:`with_semi_standard`'s too, the shoulder's child
    and each waist cancel undoing their parent's turn) with its leg IK and deform copies set as mmd_tools sets them,
    no action."""
    bones = mmd_bones()
    obj = build_armature("MMD_model", with_semi_standard(bones) if semi_standard else bones,
                         rotation_mode="QUATERNION")
    if semi_standard:
        for bone, source in [(f"肩C.{S}", f"肩P.{S}") for S in SIDES] + [(f"腰キャンセル.{S}", "腰") for S in SIDES]:
            undo = _constrain(obj, bone, "COPY_ROTATION", source, "mmd_additional_rotation")
            undo.owner_space = undo.target_space = "LOCAL"
            undo.invert_x = undo.invert_y = undo.invert_z = True
            undo.mix_mode = "ADD"
    bones = obj.pose.bones
    for S in SIDES:
        knee = bones[f"ひざ.{S}"]
        ik = _constrain(obj, knee.name, "IK", f"足ＩＫ.{S}", "IK")
        ik.chain_count, ik.iterations = 2, 40
        # the knee bends only about its X axis, forwards never (the importer turns MMD's limits into these)
        bend = _bend_sign(obj, knee)
        knee.use_ik_limit_x = knee.use_ik_limit_y = knee.use_ik_limit_z = True
        knee.ik_min_x, knee.ik_max_x = sorted((bend * math.radians(0.5), bend * math.radians(180)))
        knee.ik_min_y = knee.ik_max_y = knee.ik_min_z = knee.ik_max_z = 0.0
        limit = knee.constraints.new("LIMIT_ROTATION")
        limit.name, limit.owner_space, limit.mute = "mmd_ik_limit_override", "LOCAL", False
        limit.use_limit_x = False  # as the importer leaves it where its limits match the IK's
        ankle = _constrain(obj, f"足首.{S}", "IK", f"つま先ＩＫ.{S}", "IK")
        ankle.chain_count, ankle.iterations = 1, 3
        for target, link in ((f"足首.{S}", knee.name), (f"つま先.{S}", f"足首.{S}")):
            track = _constrain(obj, target, "DAMPED_TRACK", link, "mmd_ik_target_override")
            track.mute, track.influence = True, 0.0
        for bone in LEG:  # the deform copies turn with the leg (mmd_tools' additional rotation)
            copy = _constrain(obj, f"{bone}D.{S}", "COPY_ROTATION", f"{bone}.{S}", "mmd_additional_rotation")
            copy.owner_space = copy.target_space = "LOCAL"
    return obj


def _bend_sign(obj, knee) -> float:
    """+1 where turning the knee about its X axis by a positive angle swings the ankle backwards (+Y), else -1."""
    m = np.array(knee.bone.matrix_local)
    x, y = m[:3, 0], m[:3, 1]
    return 1.0 if np.cross(x, y)[1] > 0 or (np.cross(x, y)[1] == 0 and y[1] > 0) else -1.0


def in_english(obj) -> None:
    """Rename ``obj``'s MMD bones to the PMX format's standard English names (``leg_L``), as mmd_tools can."""
    from model_core.rig.rigs import MMD_ENGLISH, mmd_name

    for pb in obj.pose.bones:
        word, _, side = pb.name.partition(".")
        if word in MMD_ENGLISH:
            pb.name = mmd_name(word, side or None, "english")


def moved_walk(addon, folder, variant: str = "standard"):
    """The model (:func:`mmd_model`; ``variant``: "standard", "semi_standard" or "english", its bones renamed by
    :func:`in_english`) given a walk (real motion capture when unpacked) by Transfer Motion with its feet locked:
    (model, source, new action, the floor it stands on)."""
    from test_addon_rigify import import_walk

    obj = mmd_model(variant == "semi_standard")
    if variant == "english":
        in_english(obj)
    floor = evaluated_joints(addon, obj, [1])[0, [7, 8, 11, 12], 2].min()
    source = import_walk(folder)
    for o in bpy.context.view_layer.objects:
        o.select_set(o in (source, obj))
    bpy.context.view_layer.objects.active = obj
    assert bpy.ops.strnn.transfer_motion(foot_lock=True) == {"FINISHED"}
    return obj, source, action_of(obj), floor


def keyed_bones(obj, action) -> set[str]:
    return {fc.data_path.split('"')[1] for fc in fcurves_of(obj, action) if fc.data_path.startswith("pose.bones")}


def test_the_bone_map_reads_an_mmd_model_with_its_hips_at_the_lower_bodys_tail(addon):
    obj = mmd_model()
    assert bpy.ops.strnn.auto_map() == {"FINISHED"}
    m = obj.strnn_map
    assert m.family == "mmd"
    assert (m.hips, m.spine, m.spine1, m.neck, m.l_upleg, m.r_knee, m.l_foot, m.r_arm, m.l_wrist) == (
        "下半身", "上半身", "上半身2", "首", "足.L", "ひざ.R", "足首.L", "腕.R", "手首.L")
    assert m.hips_tail  # kept as found (it was not: every operation after Auto Map put the hips at the waist)
    assert addon_module(addon, "strnn_addon.scene.mapping").stored_map(obj)["hips"] == ("下半身", True)


def test_controls_from_preset_fills_the_mmd_controls_with_the_leg_ik_keyed_always(addon):
    from test_addon_ui import panel_labels

    obj = mmd_model()
    assert ("Always in IK, keyed on: 足ＩＫ.L, 足ＩＫ.R", "CON_KINEMATIC") in panel_labels("STRNN_PT_controls",
                                                                                       bpy.context)
    assert bpy.ops.strnn.controls_from_preset() == {"FINISHED"}
    listed = {c.bone: (c.drives, c.role, c.switch) for c in obj.strnn_controls}
    assert listed["センター"] == ("下半身", "MOVE", "") and listed["下半身"] == ("下半身", "FK", "")
    assert listed["腕.L"] == ("腕.L", "FK", "")
    for S in SIDES:  # no switch: an MMD model's legs never leave IK
        assert listed[f"足ＩＫ.{S}"] == (f"足首.{S}", "IK_END", "")
        assert listed[f"足.{S}"] == (f"足.{S}", "IK_BASE", "")
    assert len(listed) == 22 and not len(obj.strnn_switches)


@pytest.mark.parametrize("variant", ["standard", "semi_standard", "english"])
def test_a_walk_moved_onto_the_model_is_keyed_on_its_centre_and_leg_ik_and_its_legs_follow(addon, tmp_path, variant):
    """Transfer Motion keys the centre, the upper body, the arms, each foot's IK and the leg bones each IK starts
    from; the knees' IK then lands them where the solve put them, the deform copies follow, and the feet stand on the
    model's floor; so too on a model with the semi-standard bones between them (waist, twist, shoulder and waist
    cancel bones, the leg IK's parent), which keep their keys, and on one whose bones have their English names."""
    from test_addon_rigify import knee_bend_forward

    from model_core.rig.rigs import mmd_name

    obj, source, moved, floor = moved_walk(addon, tmp_path, variant)
    reach = 1.0  # cm, the semi-standard bones too (a chain of twist bones no longer grows the solve's rounding)
    if variant == "english":  # the same keys under the bones' English names
        record = moved["strnn"]["controls"].to_dict()
        assert record["set"] == "mmd" and record["max_error_cm"] < reach, record
        assert {mmd_name(w, s, "english") for w, s in (("センター", None), ("下半身", None), ("足ＩＫ", "L"),
                                                        ("足", "R"))} <= keyed_bones(obj, moved)
        return
    record = moved["strnn"]["controls"].to_dict()
    assert record["set"] == "mmd" and record["max_error_cm"] < reach, record
    keyed = keyed_bones(obj, moved)
    assert {"センター", "下半身", "上半身", "頭", "腕.L", "足ＩＫ.L", "足ＩＫ.R", "足.L", "ひざ.R"} <= keyed
    if variant == "semi_standard":  # the chest the arms hang from is keyed, as the model's animator keys it
        assert "上半身3" in keyed
    assert not keyed & {"グルーブ", "全ての親", "つま先ＩＫ.L", "足D.L", "ひざD.R", "つま先.L", "腰", "肩P.L", "肩C.R",
                        "腕捩.L", "手捩.R", "腰キャンセル.L", "足IK親.R", "足先EX.L"}, keyed
    centre = [fc for fc in fcurves_of(obj, moved) if fc.data_path == 'pose.bones["センター"].rotation_quaternion']
    for fc in centre:  # the centre carries the body without turning: the lower and upper bodies turn it
        values = [k.co[1] for k in fc.keyframe_points]
        assert max(values) - min(values) < 1e-6, (fc.array_index, min(values), max(values))
    frames = np.arange(int(moved.frame_range[0]), int(moved.frame_range[1]) + 1)
    got, src = evaluated_joints(addon, obj, frames), evaluated_joints(addon, source, frames)
    for side in "lr":  # each knee bends the way the source's does
        bent = np.abs(knee_bend_forward(src, side)) > 0.02
        assert bent.any() and (np.sign(knee_bend_forward(got, side)[bent]) ==
                               np.sign(knee_bend_forward(src, side)[bent])).all()
    bones = obj.pose.bones
    for f in frames[::15]:
        bpy.context.scene.frame_set(int(f))
        for S in SIDES:  # each IK reaches its target, and the deform copies turn with the leg
            assert np.linalg.norm(np.array(bones[f"ひざ.{S}"].tail - bones[f"足ＩＫ.{S}"].head)) < 1e-3
            assert np.linalg.norm(np.array(bones[f"足首.{S}"].tail - bones[f"つま先ＩＫ.{S}"].head)) < 1e-3
            for bone in LEG:
                copy, leg = (np.array(bones[f"{bone}{d}.{S}"].matrix) for d in ("D", ""))
                assert np.abs(copy - leg).max() < 1e-3
    feet = got[:, [7, 8, 11, 12], 2].min(1) - floor  # the lowest heel or toe stands on the floor, not in it
    assert np.percentile(feet, 5) > -0.03 and np.percentile(feet, 50) < 0.05, np.percentile(feet, [5, 50])
    assert np.linalg.norm(got[-1, 0, :2] - got[0, 0, :2]) > 1.0  # it walks


@pytest.mark.parametrize("variant", ["standard", "semi_standard"])
def test_a_walk_moved_onto_the_model_and_extended_still_walks(addon, real_model, tmp_path, variant):
    """A real walk moved onto the model, then extended by 5 s with the bundled model: keyed where the animator keys
    an MMD model, within 1 cm of the solve, and still walking in its last 2 s."""
    from test_addon_rigify import joint_speed

    if find_mocap() is None:
        pytest.skip("needs a real walk (../shared/mocap unpacked): the procedural walk is not motion the model learnt")
    obj, _, moved, floor = moved_walk(addon, tmp_path, variant)
    reach = 1.0  # cm, the semi-standard bones too (a chain of twist bones no longer grows the solve's rounding)
    last = int(moved.frame_range[1])
    fps = bpy.context.scene.render.fps
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    assert bpy.ops.strnn.extend_clip(frames=5 * fps) == {"FINISHED"}
    new = action_of(obj)
    record = new["strnn"]["controls"].to_dict()
    assert record["set"] == "mmd" and record["max_error_cm"] < reach, record
    assert keyed_bones(obj, new) == keyed_bones(obj, moved)
    before = joint_speed(evaluated_joints(addon, obj, np.arange(last - 2 * fps + 1, last + 1)))
    joints = evaluated_joints(addon, obj, np.arange(last + 3 * fps + 1, last + 5 * fps + 1))
    after = joint_speed(joints)
    print(f"mmd walk extended ({variant}): joint speed {after / before:.2f} x the clip's in its last 2 s, "
          f"{record['max_error_cm']} cm from the solve (the transfer "
          f"{moved['strnn']['controls'].to_dict()['max_error_cm']} cm)")
    assert 0.5 < after / before < 2.0, (before, after)
    assert np.percentile(joints[:, [7, 8, 11, 12], 2].min(1) - floor, 5) > -0.03


PRESET_BONES = {"センター", "下半身", "上半身", "上半身2", "首", "頭"} | {
    f"{b}.{S}" for S in SIDES for b in ("肩", "腕", "ひじ", "手首", "足", "ひざ", "足首", "足ＩＫ")}


@pytest.mark.parametrize("op, kw", [("denoise_action", {}), ("foot_lock", {}), ("make_loop", {}),
                                    ("inbetween", {"use_range": True, "frame_start": 25, "frame_end": 40}),
                                    ("follow_curve", {"frames": 60})],
                         ids=["denoise", "foot_lock", "make_loop", "fill_gap", "follow_curve"])
def test_each_operation_keys_the_model_where_the_animator_keys_it(addon, real_model, tmp_path, op, kw):
    """Every operation on a walking MMD model writes a new action keyed on the preset's bones alone (never the lower
    body, the deform copies or the IK targets), each driven bone within 1 cm of the solve; the original is kept."""
    obj, source, moved, _ = moved_walk(addon, tmp_path)
    bpy.data.objects.remove(source)
    if op == "follow_curve":
        bpy.ops.curve.primitive_nurbs_path_add()
        kw = {**kw, "curve": bpy.context.active_object.name}
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    assert getattr(bpy.ops.strnn, op)(**kw) == {"FINISHED"}
    new = action_of(obj)
    assert new is not moved and moved.use_fake_user
    record = new["strnn"]["controls"].to_dict()
    assert record["set"] == "mmd" and record["max_error_cm"] < 1.0, record
    assert keyed_bones(obj, new) <= PRESET_BONES, keyed_bones(obj, new) - PRESET_BONES


def test_with_its_leg_ik_off_the_legs_are_keyed_on_fk(addon, tmp_path):
    """An MMD model posed with its leg IK toggled off (mmd_tools sets the IK constraints' influence to 0): keys on
    the foot IK would not show and the thigh's turn about its own axis alone would leave the leg straight, so the
    legs are keyed on their own bones, whole, within 1 cm of the solve; the panel no longer says they are in IK."""
    from test_addon_ui import panel_labels

    obj = mmd_model()
    for S in SIDES:
        for bone in (f"ひざ.{S}", f"足首.{S}"):
            obj.pose.bones[bone].constraints["IK"].influence = 0.0
    assert not [t for t, _ in panel_labels("STRNN_PT_controls", bpy.context) if t.startswith("Always in IK")]
    source = __import__("test_addon_rigify").import_walk(tmp_path)
    for o in bpy.context.view_layer.objects:
        o.select_set(o in (source, obj))
    bpy.context.view_layer.objects.active = obj
    assert bpy.ops.strnn.transfer_motion(foot_lock=True) == {"FINISHED"}
    moved = action_of(obj)
    record = moved["strnn"]["controls"].to_dict()
    assert record["max_error_cm"] < 1.0, record
    keyed = keyed_bones(obj, moved)
    assert {"足.L", "ひざ.L", "足首.R"} <= keyed and not keyed & {"足ＩＫ.L", "足ＩＫ.R"}, keyed


def test_root_motion_goes_on_the_models_parent_of_all(addon, tmp_path):
    """Transfer Motion's Root Motion keys the travel on the bone above the centre, the model's ``全ての親`` (the
    parent of all, which MMD motions move to place a character), under the body on the floor; the centre moves
    against it."""
    from test_addon_rigify import import_walk

    obj = mmd_model()
    source = import_walk(tmp_path)
    for o in bpy.context.view_layer.objects:
        o.select_set(o in (source, obj))
    bpy.context.view_layer.objects.active = obj
    assert bpy.ops.strnn.transfer_motion(foot_lock=True, root_motion=True) == {"FINISHED"}
    moved = action_of(obj)
    assert moved["strnn"]["controls"]["max_error_cm"] < 1.0
    assert "全ての親" in keyed_bones(obj, moved)
    frames = np.arange(int(moved.frame_range[0]), int(moved.frame_range[1]) + 1)
    got = evaluated_joints(addon, obj, frames)
    root = []
    for f in frames:
        bpy.context.scene.frame_set(int(f))
        root.append(np.array(obj.matrix_world @ obj.pose.bones["全ての親"].head))
    root = np.array(root)
    assert np.linalg.norm(root[-1, :2] - root[0, :2]) > 1.0  # the root travels
    assert np.abs(root[:, 2] - root[0, 2]).max() < 1e-3  # on the floor
    assert np.linalg.norm(root[:, :2] - got[:, 0, :2], axis=1).max() < 0.15  # under the body


def test_follow_curve_from_the_models_rest_pose_keeps_its_shoulders(addon, real_model):
    """With no action, Follow Curve walks the shipped seed's body put on the model's own: its shoulders hang high and
    wide of the neck, and its chest is turned whole, as Transfer Motion does. Put on the model's bone lengths alone,
    the walk's shoulders were 18 cm from where the model's chest carries them and each upper arm's twist bone turned
    half a circle to reach an elbow closer than itself: the bake missed the solve by 22.4 cm."""
    from scenes import follow_from_rest

    new, _, lowest = follow_from_rest(addon, mmd_model(semi_standard=True), 90)
    record = new["strnn"]["controls"].to_dict()
    assert record["set"] == "mmd" and record["max_error_cm"] < 1.0, record
    assert abs(np.median(lowest)) < 0.01 and lowest.min() > -0.03, np.percentile(lowest, [0, 50])


def test_follow_curve_after_a_walk_keeps_the_models_chest_and_twist_bones(addon, real_model, tmp_path, monkeypatch):
    """Follow Curve continuing a walk on a model with the semi-standard bones: the walk the model makes comes back on
    the model's own body with its chest turned whole (its shoulders high and wide of its neck), so the solve puts
    every joint where the walk has it; on the clip's bone lengths alone the chest was turned to fit shoulders 18 cm
    from where it carries them, and each upper arm's twist bone, aimed again at an elbow nearer than itself, turned
    half a circle (the bake 22.4 cm off the solve)."""
    from scenes import addon_module

    stage = addon_module(addon, "strnn_addon.stages.follow")
    solve_module = addon_module(addon, "model_core.rig.solve")
    off = []

    def solve_and_measure(rig, anchors, targets, ref_loc, ref_rot, solve=stage.solve):
        loc, rot = solve(rig, anchors, targets, ref_loc, ref_rot)
        got = solve_module.anchor_positions(rig, anchors, solve_module.fk(rig, loc, rot))
        off.append(float(np.linalg.norm(got - targets, axis=-1).max()))
        return loc, rot

    monkeypatch.setattr(stage, "solve", solve_and_measure)
    obj, source, _, _ = moved_walk(addon, tmp_path, "semi_standard")
    source.select_set(False)
    bpy.ops.curve.primitive_nurbs_path_add()
    path = bpy.context.active_object
    path.scale = (3.0, 3.0, 3.0)
    path.select_set(False)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    assert bpy.ops.strnn.follow_curve(curve=path.name, frames=150) == {"FINISHED"}
    record = action_of(obj)["strnn"]["controls"].to_dict()
    assert record["max_error_cm"] < 1.0, record
    assert off and max(off) < 0.01, off  # metres: every joint where the walk has it


@pytest.mark.parametrize("leaf_bones", [True, False], ids=["leaf_bones", "no_leaf_bones"])
def test_a_model_an_exporter_baked_walks_on_with_its_deform_legs(addon, tmp_path, capfd, leaf_bones):
    """A walking model with a mesh skinned as MMD models are (the legs on their deform copies ``足D``, not on the
    legs the IK turns), through Blender's FBX exporter and importer, which bakes every bone and drops the
    constraints: the copies no longer follow the legs, and the upper and lower bodies hang side by side from the
    groove. It was refused (the bone map did not fit the hierarchy); then, keyed on its deform bones, it was read
    without the centre that carries it (its joints walked in place, and the new frames stood at the origin). Now
    Extend walks on with all its skin, the centre carrying the travel, the feet on its floor; so too exported
    without the exporter's leaf bones, where the importer gives the deform ankle, at the end of the skeleton, its
    shin's length for a tail (the toe was read there, and sank 4 cm)."""
    obj, source, moved, floor = moved_walk(addon, tmp_path)
    bpy.data.objects.remove(source)
    bpy.context.scene.frame_start, bpy.context.scene.frame_end = 1, int(moved.frame_range[1])
    unskinned = {"全ての親", "センター", "グルーブ"}
    unskinned |= {f"{b}.{S}" for b in LEG + ("足ＩＫ", "つま先ＩＫ") for S in SIDES}
    skinned(obj, [bone.name for bone in obj.data.bones if bone.name not in unskinned])
    # the exporter's leaf bones keep the tails of the bones at the ends
    baked = through_fbx(obj, tmp_path / "baked.fbx", leaf_bones=leaf_bones)
    ankle, shin = baked.data.bones["足首D.L"], baked.data.bones["ひざD.L"]
    assert ("足首D.L_end" in baked.data.bones) == leaf_bones
    assert (abs(ankle.length - shin.length) < 1e-4) != leaf_bones  # without them, a tail the importer guessed
    capfd.readouterr()
    assert bpy.ops.strnn.auto_map() == {"FINISHED"}
    assert "(mmd_deform rig); it is a control rig an exporter baked" in capfd.readouterr().out
    last = int(action_of(baked).frame_range[1])
    skin = sorted(g.name for g in next(o for o in bpy.data.objects if o.type == "MESH").vertex_groups)
    hips = skin.index("下半身")
    took = world_bones(baked, skin, range(last - 40, last + 1))
    assert bpy.ops.strnn.extend_clip(frames=40) == {"FINISHED"}
    new = action_of(baked)
    record = new["strnn"].to_dict()
    assert record["controls"]["set"] == "baked bones" and record["root_motion"] == {"bone": "センター"}
    got = world_bones(baked, skin, range(last, last + 41))
    travel = np.linalg.norm(got[-1, :, :2, 3] - got[0, :, :2, 3], axis=-1)
    take = np.linalg.norm(took[-1, hips, :2, 3] - took[0, hips, :2, 3])  # over as many frames
    assert 0.5 * take < travel[hips] < 2.0 * take, (travel[hips], take)  # it walks on, from where it was
    assert np.linalg.norm(got[0, hips, :2, 3] - took[-1, hips, :2, 3]) < 0.05
    left = {n: round(float(t), 3) for n, t in zip(skin, travel) if t < 0.6 * travel[hips]}
    assert not left, f"left behind: {left}"
    for S in SIDES:  # the deform thighs stay on the lower body
        gap = np.linalg.norm(got[:, skin.index(f"足D.{S}"), :3, 3] - got[:, hips, :3, 3], axis=-1)
        assert np.ptp(gap) < 0.01
    def feet(mats):  # the lowest ankle or toe
        return np.array([mats[:, skin.index(f"{b}.{S}"), 2, 3] for b in ("足首D", "つま先") for S in SIDES]).min(0)

    assert np.percentile(feet(got), 5) > np.percentile(feet(took), 5) - 0.02 and feet(got).min() < floor + 0.05

