"""The shipped control presets (no Blender): which rigs they fit and how they spell the bones; what a baked control
rig carries."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from test_bonemap import _auto_rig_pro

from model_core.motion.geometry import rotvec_to_matrix
from model_core.rig.controls import (
    PRESETS,
    Row,
    SwitchRow,
    as_rows,
    carried_bones,
    closed_cycle,
    from_rows,
    keyed_followers,
    loose_bones,
    placed_on_targets,
    preset_for,
    rest_twins,
    visual_local,
)
from model_core.rig.rigs import MMD_SPELLINGS, mmd_name
from model_core.rig.solve import Rig, fk


def test_auto_rig_pro_fits_with_three_or_two_spine_bones():
    three = preset_for(_auto_rig_pro(3)[0])
    two = preset_for(_auto_rig_pro(2)[0])
    assert three.name == two.name == "auto_rig_pro"
    drives = {c.bone: c.drives for c in three.controls}
    assert drives["c_spine_03.x"] == "spine_03.x" and drives["c_thigh_fk.l"] == "thigh.l"
    assert [c.bone for c in three.controls if c.location] == ["c_root_master.x"]  # it alone carries the body
    assert {c.bone for c in three.controls} - {c.bone for c in two.controls} == {"c_spine_03.x"}
    assert {(s.bone, s.prop, s.value) for s in two.switches} == {
        (f"c_{limb}_ik.{s}", "ik_fk_switch", 1.0) for limb in ("foot", "hand") for s in "lr"}


def test_a_rig_without_a_bone_a_preset_needs_gets_no_preset():
    names = [n for n in _auto_rig_pro(3)[0] if n != "c_spine_02.x"]  # only spine_03 and the toes are optional
    assert preset_for(names) is None
    names = [n for n in _auto_rig_pro(3)[0] if n != "c_foot_ik.r"]  # a switch's bone
    assert preset_for(names) is None


def test_auto_rig_pro_without_toes_keys_the_rest():
    names = [n for n in _auto_rig_pro(3)[0] if not n.startswith(("c_toes", "toes"))]
    found = preset_for(names)
    assert found.name == "auto_rig_pro" and len(found.controls) == 20
    assert not any("toes" in c.bone for c in found.controls)


def test_rigify_limbs_animated_in_ik_are_keyed_on_their_ik_controls():
    rigify = PRESETS["rigify"]
    fk = rigify.keyed({("thigh_parent.L", "IK_FK"): 0.8})  # nearer FK: as before, switched to FK
    assert fk.controls == rigify.controls and fk.switches == rigify.switches and not fk.keyed_ik
    ik = rigify.keyed({("thigh_parent.L", "IK_FK"): 0.0, ("upper_arm_parent.R", "IK_FK"): 0.1})
    bones = {c.bone: c for c in ik.controls}
    assert {"foot_ik.L", "thigh_ik.L", "toe_ik.L", "hand_ik.R", "upper_arm_ik.R"} <= set(bones)
    assert not {"thigh_fk.L", "shin_fk.L", "foot_fk.L", "toe_fk.L", "upper_arm_fk.R", "hand_fk.R"} & set(bones)
    assert {"thigh_fk.R", "upper_arm_fk.L"} <= set(bones)  # the limbs animated in FK keep their FK controls
    assert bones["foot_ik.L"].location and bones["foot_ik.L"].end and bones["thigh_ik.L"].twist
    assert {(s.bone, s.value) for s in ik.switches} == {("thigh_parent.L", 0.0), ("upper_arm_parent.R", 0.0),
                                                        ("thigh_parent.R", 1.0), ("upper_arm_parent.L", 1.0)}
    assert ik.keyed_ik == ["thigh_parent.L", "upper_arm_parent.R"]
    pole = rigify.keyed({("thigh_parent.L", "IK_FK"): 0.0, ("thigh_parent.L", "pole_vector"): 1})
    bones = {c.bone: c for c in pole.controls}  # with its pole on, the knee follows the pole, not thigh_ik's turn
    assert bones["thigh_ik_target.L"].pole and "thigh_ik.L" not in bones and "foot_ik.L" in bones


def test_a_rig_without_a_limbs_ik_controls_keys_that_limb_on_fk():
    rigify = PRESETS["rigify"]
    names = {b for c in rigify.controls for b in (c.bone, c.drives)} | {s.bone for s in rigify.switches}
    found = rigify.on(names | {"foot_ik.L", "thigh_ik.L", "toe_ik.L", "thigh_ik_target.L"})
    assert [limb.switch.bone for limb in found.ik_limbs] == ["thigh_parent.L"]


def test_each_preset_as_an_edited_list_gives_the_preset_back():
    for preset in PRESETS.values():
        rows, switches = as_rows(preset)
        found, problems = from_rows(preset.name, rows, switches)
        assert not problems
        # a list names the bones of one rig, so nothing in it is optional
        assert found.controls == [replace(c, optional=False) for c in preset.controls]
        assert found.switches == preset.switches and found.ik_limbs == preset.ik_limbs
        assert len(rows) == len(preset.controls) + sum(len(limb.ik) + (limb.pole is not None)
                                                       for limb in preset.ik_limbs)


def test_an_edited_list_still_keys_a_limb_animated_in_ik_on_its_ik_controls():
    rows, switches = as_rows(PRESETS["rigify"])
    rows = [r for r in rows if r.bone != "toe_ik.L"]  # an animator who keys the toe on FK only
    found, problems = from_rows("custom", rows, switches)
    assert not problems
    ik = found.keyed({("thigh_parent.L", "IK_FK"): 0.0})
    bones = {c.bone for c in ik.controls}
    assert {"foot_ik.L", "thigh_ik.L"} <= bones and not {"thigh_fk.L", "toe_fk.L", "toe_ik.L"} & bones
    assert ik.keyed_ik == ["thigh_parent.L"]


def test_an_edited_list_says_what_is_wrong_with_it():
    rows = [Row("torso", "ORG-spine", True), Row("foot_ik.L", "ORG-foot.L", True, "IK_END"),
            Row("thigh_ik.L", "ORG-thigh.L", False, "IK_BASE", "thigh_parent.L"),
            Row("hand_fk.R", "ORG-hand.R", False, "FK", "upper_arm_parent.R")]
    found, problems = from_rows("custom", rows, [SwitchRow("thigh_parent.L", "IK_FK", 1.0)])
    assert len(problems) == 2, problems
    assert "'hand_fk.R'" in problems[0] and "'upper_arm_parent.R'" in problems[0]  # a switch the list lacks
    assert "no IK End" in problems[1]  # thigh_parent.L's limb: its end names no switch
    assert not found.ik_limbs and [c.bone for c in found.controls] == ["torso", "foot_ik.L", "hand_fk.R"]
    assert found.controls[1].end and found.controls[1].location  # an IK End of no switch: keyed always
    two_poles = rows[:1] + [Row("foot_ik.L", "ORG-foot.L", True, "IK_END", "thigh_parent.L"),
                            Row("p1", "ORG-shin.L", True, "POLE", "thigh_parent.L"),
                            Row("p2", "ORG-shin.L", True, "POLE", "thigh_parent.L")]
    found, problems = from_rows("custom", two_poles, [SwitchRow("thigh_parent.L", "IK_FK", 1.0)])
    assert problems == ["The limb of the switch on 'thigh_parent.L' has 2 Pole controls (p1, p2): keep one and "
                        "remove the others"]


MMD_NAMES = ["全ての親", "センター", "グルーブ", "上半身", "上半身2", "首", "頭", "下半身"] + [
    f"{w}.{S}" for S in "LR"
    for w in ("肩", "腕", "ひじ", "手首", "足", "ひざ", "足首", "つま先", "足ＩＫ", "つま先ＩＫ", "足D")]


def test_an_mmd_model_is_keyed_on_its_centre_its_fk_bones_and_its_leg_ik():
    found = preset_for(MMD_NAMES)
    assert found is not None and found.name == "mmd" and not found.switches and not found.ik_limbs
    by_bone = {c.bone: c for c in found.controls}
    # the centre only moves (as MMD animators key it), the lower body turns the hips
    assert by_bone["センター"].drives == "下半身" and by_bone["センター"].location and not by_bone["センター"].turns
    assert by_bone["下半身"].turns and not by_bone["下半身"].location
    for side in "LR":  # the foot IK puts the ankle where it goes; the leg's own bones start each IK from the solve
        ik = by_bone[f"足ＩＫ.{side}"]
        assert ik.drives == f"足首.{side}" and ik.end and ik.location
        assert {f"足.{side}", f"ひざ.{side}", f"足首.{side}"} <= set(by_bone)
    assert not {"つま先ＩＫ.L", "足D.L", "グルーブ", "全ての親"} & set(by_bone)
    rows, switches = as_rows(found)  # as an edited list: the foot IK an IK End of no switch, and back again
    assert [r.role for r in rows if r.bone.startswith("足ＩＫ")] == ["IK_END", "IK_END"] and not switches
    assert [r.role for r in rows if r.bone == "センター"] == ["MOVE"]
    again, problems = from_rows("mmd", rows, switches)
    assert not problems and again.controls == [replace(c, optional=False) for c in found.controls]
    assert preset_for([n for n in MMD_NAMES if n != "上半身2"]) is not None  # a model without the second upper body
    for spelling in MMD_SPELLINGS:  # however the model's bones are named
        names = [mmd_name(w, None, spelling) for w in ("センター", "下半身", "上半身", "首", "頭")] + [
            mmd_name(w, S, spelling) for S in "LR"
            for w in ("肩", "腕", "ひじ", "手首", "足", "ひざ", "足首", "足ＩＫ")]
        spelt = preset_for(names)
        assert spelt is not None and spelt.name == "mmd" and {c.bone for c in spelt.controls} == set(names)
    assert preset_for([n for n in MMD_NAMES if n != "足ＩＫ.L"]) is None  # nor one without its leg IK


def test_a_limb_always_in_ik_with_its_ik_off_is_keyed_on_fk():
    found = preset_for(MMD_NAMES)
    off = found.ik_off({"足ＩＫ.L"}, {"ひざ.L", "足.L", "下半身"})
    bones = {c.bone: c for c in off.controls}
    assert "足ＩＫ.L" not in bones and "足ＩＫ.R" in bones  # the right leg's IK is still on
    assert not bones["足.L"].twist and bones["足.R"].twist  # the left thigh keyed whole, the right about its axis
    assert found.ik_off(set(), {"足.L"}) is found


def _baked_rig():
    """A control rig as an exporter leaves it: the deform bones (DEF-) hang from a mechanism bone (ORG-spine), the
    face from the mechanism's head (ORG-head > MCH-lid > DEF-lid, connected; ORG-head > DEF-nose), no constraint
    anywhere."""
    bones = [("root", -1, (0, 0, 0), False), ("ORG-spine", 0, (0, 0, 1.0), False),
             ("DEF-spine", 0, (0, 0, 1.0), False), ("DEF-thigh", 1, (0.1, 0, 0.95), False),
             ("DEF-shin", 3, (0.1, 0, 0.5), True), ("ORG-head", 1, (0, 0, 1.56), False),
             ("MCH-lid", 5, (0.03, -0.1, 1.65), False), ("DEF-lid", 6, (0.03, -0.1, 1.66), True),
             ("DEF-nose", 5, (0, -0.12, 1.6), False), ("DEF-pelvis", 1, (0.02, 0, 1.05), False),
             ("DEF-head", 2, (0, 0, 1.55), False), ("DEF-toe", 4, (0.1, -0.1, 0.02), False)]
    rest = np.repeat(np.eye(4)[None], len(bones), axis=0)
    rest[:, :3, 3] = [b[2] for b in bones]
    rest[:, :3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # each bone's +Y up the body
    return Rig([b[0] for b in bones], [b[1] for b in bones], rest, np.full(len(bones), 0.2),
               np.array([b[3] for b in bones]))


WRITTEN = ["DEF-spine", "DEF-head", "DEF-thigh", "DEF-shin"]
SKIN = {"DEF-spine", "DEF-thigh", "DEF-shin", "DEF-head", "DEF-lid", "DEF-nose", "DEF-pelvis", "DEF-toe"}


def _take(rig: Rig, rigid: dict[str, str], frames: int = 12) -> np.ndarray:
    """Poses ``[S, B, 4, 4]`` where each bone turns and moves its own way, but the bones of ``rigid`` {bone: written
    bone} go rigidly with theirs."""
    rng = np.random.default_rng(3)
    index = {n: b for b, n in enumerate(rig.names)}
    pose = np.repeat(rig.rest[None], frames, axis=0)
    turn = rotvec_to_matrix(rng.normal(0.0, 0.3, (frames, len(rig.names), 3)))
    pose[..., :3, :3] = turn @ rig.rest[:, :3, :3]
    pose[..., :3, 3] += rng.normal(0.0, 0.05, (frames, len(rig.names), 3))
    for bone, carrier in rigid.items():
        pose[:, index[bone]] = pose[:, index[carrier]] @ np.linalg.inv(rig.rest[index[carrier]]) @ rig.rest[index[bone]]
    return pose


def named(rig: Rig, found: dict[int, int]) -> dict[str, str]:
    return {rig.names[c]: rig.names[w] for c, w in found.items()}


def test_a_baked_control_rigs_face_is_carried_by_the_bone_above_it_that_moved_with_the_head():
    """Keys on the deform bones alone would leave behind the skin that hangs from mechanism bones. The face (the lid,
    the nose) moved with the head in the take and the pelvis with the hips, though all hang from ORG-spine: the face
    is carried by the mechanism's head above it, which moved with the head too (the highest such bone with no
    written bone below it: not ORG-spine, above the thigh), the pelvis by itself; the toe follows the shin. The
    written bones that hang from no written bone get their place keyed too."""
    rig = _baked_rig()
    face = {"ORG-head": "DEF-head", "MCH-lid": "DEF-head", "DEF-lid": "DEF-head", "DEF-nose": "DEF-head",
            "DEF-pelvis": "DEF-spine"}
    pose = _take(rig, face)
    assert named(rig, carried_bones(rig, WRITTEN, SKIN, pose, 0.9)) == {"ORG-head": "DEF-head",
                                                                        "DEF-pelvis": "DEF-spine"}
    assert loose_bones(rig, WRITTEN) == ["DEF-spine", "DEF-thigh"]
    assert carried_bones(rig, WRITTEN, {"DEF-spine", "DEF-toe"}, pose, 0.9) == {}
    # a take that holds still: each goes with the written bone whose rest segment it lies on
    still = np.repeat(rig.rest[None], 12, axis=0)
    assert named(rig, carried_bones(rig, WRITTEN, SKIN, still, 0.9)) == {"ORG-head": "DEF-head",
                                                                         "DEF-pelvis": "DEF-spine"}


def test_a_face_bone_that_moved_its_own_way_is_carried_apart_and_a_connected_one_by_its_parent():
    """Where the nose moved with another bone than the head in the take (the hips), the lid is carried without it:
    by MCH-lid, which it is connected to (Blender keeps a connected bone's head on its parent's tail), and the nose
    by itself, with the hips."""
    rig = _baked_rig()
    pose = _take(rig, {"ORG-head": "DEF-head", "MCH-lid": "DEF-head", "DEF-lid": "DEF-head",
                       "DEF-nose": "DEF-spine", "DEF-pelvis": "DEF-spine"})
    assert named(rig, carried_bones(rig, WRITTEN, SKIN, pose, 0.9)) == {
        "MCH-lid": "DEF-head", "DEF-nose": "DEF-spine", "DEF-pelvis": "DEF-spine"}


def test_a_skin_chain_beside_the_written_chain_is_carried_bone_by_bone():
    """A deform chain that hangs beside the written one, not from it (a rig whose mapped bones are its mechanism's,
    its skin a parallel chain: DEF-a > DEF-b beside ORG-a > ORG-b): DEF-b hangs from DEF-a, which is carried with
    ORG-a, but moved with ORG-b, which bends against ORG-a; it is carried too, with ORG-b, not left rigid on
    DEF-a."""
    bones = [("root", -1, (0, 0, 0)), ("ORG-a", 0, (0, 0, 1.0)), ("ORG-b", 1, (0, 0, 1.3)),
             ("DEF-a", 0, (0, 0, 1.0)), ("DEF-b", 3, (0, 0, 1.3))]
    rest = np.repeat(np.eye(4)[None], len(bones), axis=0)
    rest[:, :3, 3] = [b[2] for b in bones]
    rest[:, :3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    rig = Rig([b[0] for b in bones], [b[1] for b in bones], rest, np.full(len(bones), 0.3))
    pose = _take(rig, {"DEF-a": "ORG-a", "DEF-b": "ORG-b"})
    assert named(rig, carried_bones(rig, ["ORG-a", "ORG-b"], {"DEF-a", "DEF-b"}, pose, 0.9)) == {
        "DEF-a": "ORG-a", "DEF-b": "ORG-b"}


def test_a_carried_bone_connected_to_its_parent_has_that_parent_carried_with_the_bone_it_moved_with():
    """Blender keeps a connected bone's head on its parent's tail, whatever its place is keyed: the face's mechanism
    head (ORG-head), connected to the mechanism neck (ORG-neck, as a Rigify rig baked in Blender has them), is
    carried with the head, and the neck it sits on with the neck it moved with."""
    bones = [("root", -1, (0, 0, 0), False), ("DEF-spine", 0, (0, 0, 1.0), False),
             ("DEF-neck", 1, (0, 0, 1.45), False), ("DEF-head", 2, (0, 0, 1.55), False),
             ("ORG-neck", 0, (0, 0, 1.45), False), ("ORG-head", 4, (0, 0, 1.55), True),
             ("DEF-face", 5, (0, -0.1, 1.6), False)]
    rest = np.repeat(np.eye(4)[None], len(bones), axis=0)
    rest[:, :3, 3] = [b[2] for b in bones]
    rest[:, :3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]
    rig = Rig([b[0] for b in bones], [b[1] for b in bones], rest, np.full(len(bones), 0.1),
              np.array([b[3] for b in bones]))
    pose = _take(rig, {"ORG-neck": "DEF-neck", "ORG-head": "DEF-head", "DEF-face": "DEF-head"})
    assert named(rig, carried_bones(rig, ["DEF-spine", "DEF-neck", "DEF-head"], {"DEF-face"}, pose, 0.9)) == {
        "ORG-neck": "DEF-neck", "ORG-head": "DEF-head"}


def test_a_cycle_on_a_baked_control_rig_ends_where_it_began_carried_by_its_travel():
    """Make Loop on a baked control rig: the written bones hold the cycle (their seam their first pose carried by the
    travel), but the mechanism bones they hang from (ORG-spine, ORG-head) lean and travel as the take did. Closed,
    every bone ends the cycle on its first pose carried by the travel, and every local transform below a bone that
    moves repeats as it is, so that repeating each location with its offset carries the whole rig by the travel
    alone; the written bones and the root that stays put keep their poses, and the first frame is as it was."""
    rig = _baked_rig()
    index = {n: b for b, n in enumerate(rig.names)}
    pose = _take(rig, {}, frames=21)
    pose[:, index["root"]] = rig.rest[index["root"]]  # it stays put
    travel = np.array([0.0, -0.6, 0.02])
    kept = np.isin(rig.names, WRITTEN)
    pose[-1, kept] = pose[0, kept]
    pose[-1, kept, :3, 3] += travel
    lid, mch = index["DEF-lid"], index["MCH-lid"]  # connected: its head where its parent holds it
    pose[:, lid, :3, 3] = (pose[:, mch] @ np.linalg.inv(rig.rest[mch]) @ rig.rest[lid])[:, :3, 3]
    turned = np.ones(len(rig.names), bool)
    placed = ~rig.connected
    out = closed_cycle(rig, pose, travel, 4, kept, turned, placed, 1.0)
    assert np.allclose(out[:, kept], pose[:, kept]) and np.allclose(out[:, index["root"]], pose[:, index["root"]])
    assert np.allclose(out[0], pose[0])
    assert np.allclose(out[-1, :, :3, :3], out[0, :, :3, :3], atol=1e-9)
    assert np.allclose(out[-1, :, :3, 3], out[0, :, :3, 3] + travel * (np.arange(len(rig.names)) != 0)[:, None])
    loc, rot = visual_local(rig, out)
    below = rig.parents > 0  # under a bone that moves: its local transform repeats as it is
    assert np.allclose(loc[-1, below], loc[0, below], atol=1e-9) and np.allclose(rot[-1], rot[0], atol=1e-9)
    # the turn is eased in over the end: untouched before the last frames; the place's miss spread over the cycle
    spine = index["ORG-spine"]
    assert np.allclose(out[:15, spine, :3, :3], pose[:15, spine, :3, :3])
    miss = pose[0, spine, :3, 3] + travel - pose[-1, spine, :3, 3]
    assert np.allclose(out[10, spine, :3, 3] - pose[10, spine, :3, 3], 0.5 * miss)


def test_skin_below_a_written_bone_through_a_bone_of_no_skin_is_carried_with_the_bone_it_moved_with():
    """A baked MMD model: its FK ankle (no skin) hangs from the legs that hang from the written lower body, and the
    toe below it (skin) moved with the written deform ankle beside it, as the IK turned both. Hanging from the lower
    body through a bone of no skin, it does not follow it: the FK ankle carries it with the deform ankle (and the FK
    knee, which the connected ankle's head stays on, with the deform knee)."""
    bones = [("下半身", -1, (0, 0, 1.0), False), ("足", 0, (0.1, 0, 0.9), False), ("ひざ", 1, (0.1, 0, 0.5), True),
             ("足首", 2, (0.1, 0, 0.1), True), ("つま先", 3, (0.1, -0.12, 0.02), True),
             ("足D", 0, (0.1, 0, 0.9), False), ("ひざD", 5, (0.1, 0, 0.5), True), ("足首D", 6, (0.1, 0, 0.1), True)]
    rest = np.repeat(np.eye(4)[None], len(bones), axis=0)
    rest[:, :3, 3] = [b[2] for b in bones]
    rig = Rig([b[0] for b in bones], [b[1] for b in bones], rest, np.full(len(bones), 0.2),
              np.array([b[3] for b in bones]))
    written = ["下半身", "足D", "ひざD", "足首D"]
    pose = _take(rig, {"足首": "足首D", "つま先": "足首D", "足": "足D", "ひざ": "ひざD"})
    found = named(rig, carried_bones(rig, written, set(written) | {"つま先"}, pose, 1.0))
    assert found == {"足首": "足首D", "ひざ": "ひざD"}, found


def test_keyed_bones_that_kept_to_a_written_bone_they_do_not_hang_from_follow_it():
    """An Unreal rig: its IK bones hang from the root and were keyed onto the feet and the hand (the hand's with its
    still finger too: the hand it lies on carries it); a prop keyed its own way, a bone keyed still, the root above the
    written bones and a finger that hangs from its written hand are not followers."""
    bones = [("root", -1, (0, 0, 0.0), False), ("pelvis", 0, (0, 0, 1.0), False),
             ("thigh_l", 1, (0.1, 0, 0.9), False), ("calf_l", 2, (0.1, 0, 0.5), True),
             ("foot_l", 3, (0.1, 0, 0.1), True), ("hand_l", 1, (0.4, 0, 1.0), False),
             ("middle_01_l", 5, (0.45, 0, 1.0), True), ("nail_l", 6, (0.5, 0, 1.0), True),
             ("ik_foot_root", 0, (0, 0, 0.0), False), ("ik_foot_l", 8, (0.1, 0, 0.1), False),
             ("ik_hand_l", 0, (0.4, 0, 1.0), False), ("prop", 0, (0.3, 0.3, 0.0), False),
             ("still", 0, (0, 1, 0.0), False)]
    rest = np.repeat(np.eye(4)[None], len(bones), axis=0)
    rest[:, :3, 3] = [b[2] for b in bones]
    rig = Rig([b[0] for b in bones], [b[1] for b in bones], rest, np.full(len(bones), 0.05),
              np.array([b[3] for b in bones]))
    written = ["pelvis", "thigh_l", "calf_l", "foot_l", "hand_l", "middle_01_l"]
    pose = _take(rig, {"ik_foot_l": "foot_l", "ik_hand_l": "hand_l", "middle_01_l": "hand_l", "nail_l": "middle_01_l",
                       "ik_foot_root": "root"})
    pose[:, rig.names.index("still")] = rig.rest[rig.names.index("still")]
    keyed = {"root", "ik_foot_root", "ik_foot_l", "ik_hand_l", "prop", "still", "nail_l"}
    found = named(rig, keyed_followers(rig, written, keyed, pose, 1.0))
    assert found == {"ik_foot_l": "foot_l", "ik_hand_l": "hand_l"}, found
    # kept to its foot only loosely (2 cm off and on): not a follower
    loose = pose.copy()
    loose[::2, rig.names.index("ik_foot_l"), 0, 3] += 0.04
    assert "ik_foot_l" not in named(rig, keyed_followers(rig, written, keyed, loose, 1.0))


def test_bones_that_rest_on_a_written_bone_without_hanging_from_it_are_its_twins():
    """With no take to read: an IK bone hanging from the root and resting where the foot rests, axes and all, is the
    foot's twin; one resting there turned, one a millimetre off, a bone below the foot and the root are not."""
    bones = [("root", -1, (0, 0, 0.0)), ("pelvis", 0, (0, 0, 1.0)), ("thigh_l", 1, (0.1, 0, 0.9)),
             ("calf_l", 2, (0.1, 0, 0.5)), ("foot_l", 3, (0.1, 0, 0.1)), ("ball_l", 4, (0.1, -0.1, 0.02)),
             ("ik_foot_root", 0, (0, 0, 0.0)), ("ik_foot_l", 6, (0.1, 0, 0.1)), ("ik_turned", 6, (0.1, 0, 0.1)),
             ("ik_off", 6, (0.1, 0.001, 0.1)), ("heel_l", 4, (0.1, 0, 0.1))]
    rest = np.repeat(np.eye(4)[None], len(bones), axis=0)
    rest[:, :3, 3] = [b[2] for b in bones]
    rest[8, :3, :3] = rotvec_to_matrix(np.array([0.0, 0.0, 0.1]))
    rig = Rig([b[0] for b in bones], [b[1] for b in bones], rest, np.full(len(bones), 0.05))
    found = named(rig, rest_twins(rig, ["pelvis", "thigh_l", "calf_l", "foot_l", "ball_l"], 0.9))
    assert found == {"ik_foot_l": "foot_l"}, found


def test_the_bake_in_closed_form_puts_each_bone_on_its_target_parents_first():
    """On a rig that follows nothing but its parents (a rig an exporter baked): targets made from a pose are met by
    the locals of that pose, the chosen bones' (the hips moved and turned, the thigh and the shin turned, the shin
    connected) found below the others that keep theirs (the mechanism bone above the thigh, moved off its place);
    a place asked of a bone only turned is missed, and by as much as the error says."""
    rig = _baked_rig()
    index = {n: b for b, n in enumerate(rig.names)}
    rng = np.random.default_rng(7)
    frames, n = 5, len(rig.names)
    loc = rng.normal(0.0, 0.05, (frames, n, 3))
    rot = rotvec_to_matrix(rng.normal(0.0, 0.4, (frames, n, 3)))
    scale = np.ones((frames, n, 3))
    pose = fk(rig, loc, rot)
    chosen = [index[b] for b in ("DEF-spine", "DEF-thigh", "DEF-shin")]
    targets = pose[:, chosen]
    kept = loc.copy(), rot.copy()
    loc[:, chosen[0]], rot[:, chosen] = 0.0, np.eye(3)  # what they had before: anything (the turned keep their place)
    got_loc, got_rot, error = placed_on_targets(rig, loc, rot, scale, chosen, [True, False, False], targets)
    assert error < 1e-9
    np.testing.assert_allclose(got_rot, kept[1][:, chosen], atol=1e-9)
    np.testing.assert_allclose(got_loc[:, 0], kept[0][:, chosen[0]], atol=1e-9)  # the hips' place, asked
    np.testing.assert_allclose(got_loc[:, 1:], kept[0][:, chosen[1:]])  # the others keep theirs
    # the thigh only turned, but asked 5 cm off: missed by that
    moved = targets.copy()
    moved[:, 1, :3, 3] += [0.05, 0.0, 0.0]
    _, _, error = placed_on_targets(rig, loc, rot, scale, chosen, [True, False, False], moved)
    assert abs(error - 0.05) < 1e-6
