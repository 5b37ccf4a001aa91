"""Bone auto-mapping (no Blender): families, the left/right heuristic, the hierarchy fallback."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.motion.conventions import JOINTS
from model_core.rig.bonemap import auto_map, heads_where_tails_point_across, missing, placed, split_side, tails_across
from model_core.rig.names import bare_names, shared_prefix, shared_suffix
from model_core.rig.rigs import MMD_ENGLISH, MMD_SPELLINGS, mmd_name


@pytest.mark.parametrize("name, want", [
    ("thigh.L", ("l", "thigh")), ("DEF-upper_arm.R.001", ("r", "upperarm")), ("CC_Base_L_Thigh", ("l", "thigh")),
    ("LeftUpLeg", ("l", "upleg")), ("mixamorig:RightHand", ("r", "hand")), ("lThigh", ("l", "thigh")),
    ("LHipJoint", ("l", "hipjoint")), ("upperarm_l", ("l", "upperarm")), ("L_Foot", ("l", "foot")),
    ("Root", (None, "root")), ("spine_01", (None, "spine01")), ("ball_r", ("r", "ball")),
    ("J_Bip_C_Neck", (None, "neck")), ("J_Bip_L_UpperLeg", ("l", "upperleg")), ("neck.x", (None, "neck")),
    ("upperleg01.L", ("l", "upperleg01")), ("LUArm", ("l", "uarm")), ("RFArm", ("r", "farm")),
    ("LShoulder", ("l", "shoulder")), ("Reference", (None, "reference")), ("HipLeft", ("l", "hip")),
    ("mShoulderRight", ("r", "mshoulder")), ("Left knee", ("l", "knee")), ("mHandMiddle3Left", ("l", "mhandmiddle3")),
])
def test_split_side(name, want):
    assert split_side(name) == want


def chain(*names):
    return list(names), [-1] + list(range(len(names) - 1))


def test_generic_names_map_by_words_and_hierarchy():
    names = ["root", "pelvis", "spine_a", "spine_b", "chest", "neck_01", "head"]
    parents = [-1, 0, 1, 2, 3, 4, 5]
    for s in "lr":
        for bone, parent in (("clavicle", "chest"), ("upperarm", "clavicle"), ("lowerarm", "upperarm"),
                             ("hand", "lowerarm"), ("thigh", "pelvis"), ("calf", "thigh"), ("foot", "calf")):
            names.append(f"{bone}.{s.upper()}")
            parents.append(names.index(parent if parent in ("chest", "pelvis") else f"{parent}.{s.upper()}"))
    family, mapping = auto_map(names, parents)
    assert family == "generic" and not missing(mapping)
    assert mapping["spine1"] == ("chest", False) and mapping["spine"] == ("spine_a", False)
    assert mapping["l_toe"] == ("foot.L", True) and mapping["r_fingertip"] == ("hand.R", True)


def test_of_two_families_a_rig_names_in_full_the_one_its_skin_follows_is_preferred():
    """A Rigify rig has its ORG- and its DEF- bones, each a family in full: the ORG- bones where nothing says
    otherwise (what a generated rig's controls drive), the DEF- bones where they are the ones the skin is weighted to
    (a rig an exporter baked)."""
    from model_core.rig.rigs import RIG_FAMILIES

    org = [c[0] for c in RIG_FAMILIES["rigify"].values()]
    deform = [c[0] for c in RIG_FAMILIES["rigify_deform"].values()]
    names = org + deform
    parents = [-1] * len(names)
    assert auto_map(names, parents)[0] == "rigify"
    family, mapping = auto_map(names, parents, prefer=set(deform))
    assert family == "rigify_deform" and mapping["l_upleg"] == ("DEF-thigh.L", False)
    assert auto_map(names, parents, prefer={"ORG-spine"})[0] == "rigify"


def test_end_site_candidates_become_tails():
    names = ["CC_Base_Hip", "CC_Base_Waist", "CC_Base_Spine02", "CC_Base_NeckTwist01", "CC_Base_Head"]
    names += [f"CC_Base_{s}_{b}" for s in "LR" for b in ("Thigh", "Calf", "Foot", "ToeBase", "Upperarm",
                                                           "Forearm", "Hand", "Mid3")]
    family, mapping = auto_map(names, [-1] * len(names))
    assert family == "iclone_cc_base" and mapping["l_fingertip"] == ("CC_Base_L_Mid3", True)


def test_missing_joints_are_listed():
    _, mapping = auto_map(*chain("a", "b", "c"))
    assert set(missing(mapping)) == set(JOINTS) - set(mapping) - {"spine1", "neck"}  # those two can be placed
    assert "l_knee" in missing(mapping) and "spine" in missing(mapping) and "head" in missing(mapping)


SMPL = [("Pelvis", None), ("L_Hip", "Pelvis"), ("R_Hip", "Pelvis"), ("Spine1", "Pelvis"), ("L_Knee", "L_Hip"),
        ("R_Knee", "R_Hip"), ("Spine2", "Spine1"), ("L_Ankle", "L_Knee"), ("R_Ankle", "R_Knee"), ("Spine3", "Spine2"),
        ("L_Foot", "L_Ankle"), ("R_Foot", "R_Ankle"), ("Neck", "Spine3"), ("L_Collar", "Spine3"),
        ("R_Collar", "Spine3"), ("Head", "Neck"), ("L_Shoulder", "L_Collar"), ("R_Shoulder", "R_Collar"),
        ("L_Elbow", "L_Shoulder"), ("R_Elbow", "R_Shoulder"), ("L_Wrist", "L_Elbow"), ("R_Wrist", "R_Elbow"),
        ("L_Hand", "L_Wrist"), ("R_Hand", "R_Wrist")]


@pytest.mark.parametrize("spell", [str, lambda n: n.lower().replace("l_", "left_").replace("r_", "right_")],
                         ids=["amass", "smplx_addon"])
def test_smpl_joints_map_the_ankle_wrist_and_chest_not_the_next_joint_down(spell):
    """SMPL (AMASS, the SMPL-X add-on) names the ball of the foot L_Foot below L_Ankle, the knuckles L_Hand below
    L_Wrist, and hangs the arms from Spine3 (a Mixamo chest name, Spine2, sits lower)."""
    names = [spell(n) for n, _ in SMPL]
    parents = [[n for n, _ in SMPL].index(p) if p else -1 for _, p in SMPL]
    family, mapping = auto_map(names, parents)
    got = mapping
    want = {"hips": "Pelvis", "spine": "Spine1", "spine1": "Spine3", "neck": "Neck", "head": "Head",
            "l_upleg": "L_Hip", "l_knee": "L_Knee", "l_foot": "L_Ankle", "l_toe": "L_Foot",
            "r_arm": "R_Shoulder", "r_elbow": "R_Elbow", "r_wrist": "R_Wrist"}
    assert family == "generic" and not missing(mapping)
    assert {j: got[j] for j in want} == {j: (spell(b), False) for j, b in want.items()}
    assert got["l_fingertip"] == (spell("L_Hand"), True)


def _tree(pairs: list[tuple[str, str | None]]) -> tuple[list[str], list[int]]:
    names = [n for n, _ in pairs]
    return names, [names.index(p) if p else -1 for _, p in pairs]


def _sided(pairs, sides):
    return [(n.format(S=s), p and p.format(S=s)) for s in sides for n, p in pairs]


VROID = [("J_Bip_C_Hips", None), ("J_Bip_C_Spine", "J_Bip_C_Hips"), ("J_Bip_C_Chest", "J_Bip_C_Spine"),
         ("J_Bip_C_UpperChest", "J_Bip_C_Chest"), ("J_Bip_C_Neck", "J_Bip_C_UpperChest"),
         ("J_Bip_C_Head", "J_Bip_C_Neck")] + _sided(
    [("J_Bip_{S}_UpperLeg", "J_Bip_C_Hips"), ("J_Bip_{S}_LowerLeg", "J_Bip_{S}_UpperLeg"),
     ("J_Bip_{S}_Foot", "J_Bip_{S}_LowerLeg"), ("J_Bip_{S}_ToeBase", "J_Bip_{S}_Foot"),
     ("J_Bip_{S}_Shoulder", "J_Bip_C_UpperChest"), ("J_Bip_{S}_UpperArm", "J_Bip_{S}_Shoulder"),
     ("J_Bip_{S}_LowerArm", "J_Bip_{S}_UpperArm"), ("J_Bip_{S}_Hand", "J_Bip_{S}_LowerArm")], "LR")
GENESIS8 = [("hip", None), ("pelvis", "hip"), ("abdomenLower", "hip"), ("abdomenUpper", "abdomenLower"),
            ("chestLower", "abdomenUpper"), ("chestUpper", "chestLower"), ("neckLower", "chestUpper"),
            ("neckUpper", "neckLower"), ("head", "neckUpper")] + _sided(
    [("{S}ThighBend", "pelvis"), ("{S}ThighTwist", "{S}ThighBend"), ("{S}Shin", "{S}ThighTwist"),
     ("{S}Foot", "{S}Shin"), ("{S}Toe", "{S}Foot"), ("{S}Collar", "chestUpper"), ("{S}ShldrBend", "{S}Collar"),
     ("{S}ShldrTwist", "{S}ShldrBend"), ("{S}ForearmBend", "{S}ShldrTwist"), ("{S}ForearmTwist", "{S}ForearmBend"),
     ("{S}Hand", "{S}ForearmTwist")], "lr")


# 3ds Max's Biped, as a BVH names it once its spaces are joined: the thighs hang from Spine, the clavicles from Neck.
BIPED = [("Bip01", None), ("Bip01_Pelvis", "Bip01"), ("Bip01_Spine", "Bip01_Pelvis"),
         ("Bip01_Spine1", "Bip01_Spine"), ("Bip01_Spine2", "Bip01_Spine1"), ("Bip01_Neck", "Bip01_Spine2"),
         ("Bip01_Head", "Bip01_Neck")] + _sided(
    [("Bip01_{S}_Clavicle", "Bip01_Neck"), ("Bip01_{S}_UpperArm", "Bip01_{S}_Clavicle"),
     ("Bip01_{S}_Forearm", "Bip01_{S}_UpperArm"), ("Bip01_{S}_Hand", "Bip01_{S}_Forearm"),
     ("Bip01_{S}_Thigh", "Bip01_Spine"), ("Bip01_{S}_Calf", "Bip01_{S}_Thigh"), ("Bip01_{S}_Foot", "Bip01_{S}_Calf"),
     ("Bip01_{S}_Toe0", "Bip01_{S}_Foot")], "LR")


@pytest.mark.parametrize("tree, want", [
    (BIPED, {"hips": "Bip01_Pelvis", "spine": "Bip01_Spine", "spine1": "Bip01_Spine2", "neck": "Bip01_Neck",
             "l_upleg": "Bip01_L_Thigh", "l_knee": "Bip01_L_Calf", "l_toe": "Bip01_L_Toe0",
             "r_arm": "Bip01_R_UpperArm"}),
    (VROID, {"hips": "J_Bip_C_Hips", "spine": "J_Bip_C_Spine", "spine1": "J_Bip_C_UpperChest",
             "neck": "J_Bip_C_Neck", "head": "J_Bip_C_Head", "l_knee": "J_Bip_L_LowerLeg",
             "r_arm": "J_Bip_R_UpperArm"}),
    (GENESIS8, {"hips": "hip", "spine": "abdomenLower", "spine1": "chestUpper", "neck": "neckLower",
                "l_upleg": "lThighBend", "l_knee": "lShin", "r_arm": "rShldrBend", "r_elbow": "rForearmBend"}),
], ids=["biped", "vroid", "genesis8"])
def test_centre_markers_and_bend_twist_limbs_map_fully(tree, want):
    """VRoid marks the body's middle with _C_ (J_Bip_C_Neck); Daz's Genesis 3 and 8 split each limb into a Bend and
    a Twist bone, the joint at the Bend's head; 3ds Max's Biped hangs its arms from the neck."""
    _, mapping = auto_map(*_tree(tree))
    assert not missing(mapping)
    assert {j: mapping[j][0] for j in want} == want


ROBLOX_R15 = [("HumanoidRootPart", None), ("LowerTorso", "HumanoidRootPart"), ("UpperTorso", "LowerTorso"),
              ("Head", "UpperTorso")] + _sided(
    [("{S}UpperArm", "UpperTorso"), ("{S}LowerArm", "{S}UpperArm"), ("{S}Hand", "{S}LowerArm"),
     ("{S}UpperLeg", "LowerTorso"), ("{S}LowerLeg", "{S}UpperLeg"), ("{S}Foot", "{S}LowerLeg")], ("Left", "Right"))
QUATERNIUS = [("Root", None), ("Hips", "Root"), ("Abdomen", "Hips"), ("Torso", "Abdomen"), ("Neck", "Torso"),
              ("Head", "Neck")] + _sided(
    [("Shoulder.{S}", "Torso"), ("UpperArm.{S}", "Shoulder.{S}"), ("LowerArm.{S}", "UpperArm.{S}"),
     ("Fist.{S}", "LowerArm.{S}"), ("UpperLeg.{S}", "Hips"), ("LowerLeg.{S}", "UpperLeg.{S}"),
     ("Foot.{S}", "LowerLeg.{S}"), ("Toes.{S}", "Foot.{S}")], "LR")


def test_a_rig_with_two_torso_bones_and_no_neck_maps_its_torso_as_one_spine_bone():
    """Roblox's R15 (LowerTorso, UpperTorso, Head; no neck, no toes): the upper torso is the one spine bone from
    the waist, the chest and the neck are placed between it and the head."""
    family, mapping = auto_map(*_tree(ROBLOX_R15))
    assert family == "generic" and not missing(mapping) and placed(mapping).keys() == {"spine1", "neck"}
    assert {j: mapping[j][0] for j in ("hips", "spine", "head", "l_wrist", "r_knee")} == {
        "hips": "LowerTorso", "spine": "UpperTorso", "head": "Head", "l_wrist": "LeftHand", "r_knee": "RightLowerLeg"}
    assert mapping["l_toe"] == ("LeftFoot", True)


def test_a_hand_named_fist_is_the_wrist():
    family, mapping = auto_map(*_tree(QUATERNIUS))
    assert not missing(mapping) and not placed(mapping)
    assert (mapping["l_wrist"], mapping["r_fingertip"]) == (("Fist.L", False), ("Fist.R", True))
    assert (mapping["spine"][0], mapping["spine1"][0]) == ("Abdomen", "Torso")


ADVANCED_SKELETON = [("Root_M", None), ("Spine1_M", "Root_M"), ("Spine2_M", "Spine1_M"), ("Chest_M", "Spine2_M"),
                     ("Neck_M", "Chest_M"), ("Head_M", "Neck_M")] + _sided(
    [("Hip_{S}", "Root_M"), ("Knee_{S}", "Hip_{S}"), ("Ankle_{S}", "Knee_{S}"), ("Toes_{S}", "Ankle_{S}"),
     ("Scapula_{S}", "Chest_M"), ("Shoulder_{S}", "Scapula_{S}"), ("Elbow_{S}", "Shoulder_{S}"),
     ("Wrist_{S}", "Elbow_{S}")], "LR")


def test_a_middle_marked_with_m_maps_its_neck_and_head():
    """Maya's AdvancedSkeleton marks the middle with ``_M`` (``Neck_M``, ``Head_M``) and calls the thigh ``Hip``."""
    _, mapping = auto_map(*_tree(ADVANCED_SKELETON))
    assert not missing(mapping) and not placed(mapping)
    assert {j: mapping[j][0] for j in ("hips", "spine", "spine1", "neck", "head", "l_upleg", "r_arm")} == {
        "hips": "Root_M", "spine": "Spine1_M", "spine1": "Chest_M", "neck": "Neck_M", "head": "Head_M",
        "l_upleg": "Hip_L", "r_arm": "Shoulder_R"}


XPS = [("root hips", None), ("spine lower", "root hips"), ("spine middle", "spine lower"),
       ("spine upper", "spine middle"), ("head neck lower", "spine upper"), ("head neck upper", "head neck lower"),
       ("head", "head neck upper")] + _sided(
    [("arm {S} shoulder 1", "spine upper"), ("arm {S} shoulder 2", "arm {S} shoulder 1"),
     ("arm {S} elbow", "arm {S} shoulder 2"), ("arm {S} wrist", "arm {S} elbow"), ("leg {S} thigh", "root hips"),
     ("leg {S} knee", "leg {S} thigh"), ("leg {S} ankle", "leg {S} knee"), ("leg {S} toes", "leg {S} ankle")],
    ("left", "right"))


def test_numbered_shoulder_segments_map_the_arm_at_the_one_the_elbow_hangs_from():
    """XPS / XNALara name the clavicle ``arm left shoulder 1`` and the upper arm ``arm left shoulder 2``: the arm is
    the segment the elbow hangs from (MakeHuman's ``upperarm01`` / ``upperarm02`` stay at the first, as before)."""
    _, mapping = auto_map(*_tree(XPS))
    assert not missing(mapping)
    assert (mapping["l_arm"][0], mapping["r_arm"][0]) == ("arm left shoulder 2", "arm right shoulder 2")
    assert (mapping["l_upleg"][0], mapping["spine1"][0], mapping["neck"][0]) == (
        "leg left thigh", "spine upper", "head neck lower")


def _auto_rig_pro(spines: int = 3) -> tuple[list[str], list[int]]:
    """Auto-Rig Pro's human rig as its bones hang (controls, the bones that blend FK and IK, twist and stretch
    bones that deform), parents by name."""
    tree = [("c_pos", None), ("c_traj", "c_pos"), ("c_root_master.x", "c_traj"), ("c_root.x", "c_root_master.x"),
            ("root.x", "c_traj")]
    top = ("c_root_master.x", "root.x")
    for k in range(1, spines + 1):
        tree += [(f"c_spine_0{k}.x", top[0]), (f"spine_0{k}.x", top[1])]
        top = (f"c_spine_0{k}.x", f"spine_0{k}.x")
    tree += [("c_neck.x", top[0]), ("neck.x", top[1]), ("c_head.x", "c_neck.x"), ("head.x", "neck.x")]
    for s in "lr":
        tree += [(n.format(S="." + s), p and p.format(S="." + s)) for n, p in [
            ("c_shoulder{S}", top[0]), ("shoulder{S}", top[1]), ("c_arm_fk{S}", "c_shoulder{S}"),
            ("c_forearm_fk{S}", "c_arm_fk{S}"), ("c_hand_fk{S}", "c_forearm_fk{S}"), ("c_hand_ik{S}", "c_traj"),
            ("arm{S}", "shoulder{S}"), ("forearm{S}", "arm{S}"), ("hand{S}", "forearm{S}"),
            ("arm_stretch{S}", "arm{S}"), ("forearm_stretch{S}", "forearm{S}"), ("forearm_twist{S}", "forearm{S}"),
            ("c_thigh_b{S}", "c_root.x"), ("c_thigh_fk{S}", "c_thigh_b{S}"), ("c_leg_fk{S}", "c_thigh_fk{S}"),
            ("c_foot_fk{S}", "c_leg_fk{S}"), ("c_toes_fk{S}", "c_foot_fk{S}"), ("c_foot_ik{S}", "c_traj"),
            ("thigh{S}", "root.x"), ("leg{S}", "thigh{S}"), ("foot{S}", "leg{S}"), ("toes_01{S}", "foot{S}"),
            ("thigh_twist{S}", "thigh{S}"), ("thigh_stretch{S}", "thigh{S}"), ("leg_stretch{S}", "leg{S}"),
            ("leg_twist{S}", "leg{S}")]]
    names = [n for n, _ in tree]
    return names, [names.index(p) if p else -1 for _, p in tree]


@pytest.mark.parametrize("spines, chest", [(3, "spine_03.x"), (2, "spine_02.x")])
def test_auto_rig_pro_maps_its_pelvis_control_and_the_bones_that_blend_fk_and_ik(spines, chest):
    """The body's root control has its head at the pelvis (the deform root.x points from the waist down); each
    limb's joint is the head of the bone that follows its FK and IK chains whole, not a twist or stretch bone that
    holds half a segment."""
    family, mapping = auto_map(*_auto_rig_pro(spines))
    assert family == "auto_rig_pro" and not missing(mapping)
    got = {j: b for j, (b, _) in mapping.items()}
    assert got["hips"] == "c_root_master.x" and got["spine"] == "spine_01.x" and got["spine1"] == chest
    assert (got["l_upleg"], got["r_knee"], got["l_foot"], got["r_toe"]) == ("thigh.l", "leg.r", "foot.l", "toes_01.r")
    assert (got["l_arm"], got["r_elbow"], got["l_wrist"]) == ("arm.l", "forearm.r", "hand.l")


def test_a_rig_with_some_auto_rig_pro_names_is_not_read_as_one():
    """thigh.L, leg.L and foot.L are common words: a rig that has them but not Auto-Rig Pro's whole body is mapped
    by its own words and hierarchy."""
    names, parents = chain("root", "hips", "spine", "chest", "neck", "head")
    for s in "LR":
        for n, p in (("thigh", "hips"), ("leg", "thigh"), ("foot", "leg"), ("toe", "foot"), ("shoulder", "chest"),
                     ("arm", "shoulder"), ("forearm", "arm"), ("hand", "forearm")):
            names.append(f"{n}.{s}")
            parents.append(names.index(f"{p}.{s}" if f"{p}.{s}" in names else p))
    family, mapping = auto_map(names, parents)
    assert family != "auto_rig_pro" and not missing(mapping)
    assert mapping["hips"][0] == "hips" and mapping["l_upleg"][0] == "thigh.L"


@pytest.mark.parametrize("spelling", MMD_SPELLINGS)
def test_an_mmd_model_maps_its_names_with_the_hips_at_the_lower_bodys_tail(spelling):
    """As mmd_tools imports it (left and right as ``.L``, as ``_L``, as the model spells them, ``左足``, or the PMX
    standard English names, ``leg_L``): the lower body points down from the waist to the pelvis, the ankle to the toe
    tip; the deform copies (``足D``) and the IK bones are not joints."""
    def sided(word, side):
        if spelling == "english" and word not in MMD_ENGLISH:
            return f"{word}_{side}"  # a bone of no standard English name keeps its own
        return mmd_name(word, side, spelling)

    names = [sided(w, None) if w in MMD_ENGLISH or spelling != "english" else w
             for w in ("全ての親", "センター", "グルーブ", "下半身", "上半身", "上半身2", "首", "頭")]
    names = [n if not n.endswith("_None") else n[:-5] for n in names]
    parents = [-1, 0, 1, 2, 2, 4, 5, 6]
    centre = dict(zip(("全ての親", "センター", "グルーブ", "下半身", "上半身", "上半身2", "首", "頭"), names))
    for s in "LR":
        for word, parent in (("足", "下半身"), ("ひざ", "足"), ("足首", "ひざ"), ("つま先", "足首"),
                             ("足D", "下半身"), ("足ＩＫ", "全ての親"), ("つま先ＩＫ", "足ＩＫ"), ("肩", "上半身2"),
                             ("腕", "肩"), ("ひじ", "腕"), ("手首", "ひじ"), ("中指１", "手首"), ("中指２", "中指１"),
                             ("中指３", "中指２")):
            names.append(sided(word, s))
            parents.append(names.index(centre.get(parent) or sided(parent, s)))
    family, mapping = auto_map(names, parents)
    assert family == ("mmd_english" if spelling == "english" else "mmd") and not missing(mapping), mapping
    assert mapping["hips"] == (centre["下半身"], True) and mapping["spine"] == (centre["上半身"], False)
    assert mapping["l_upleg"] == (sided("足", "L"), False) and mapping["r_knee"] == (sided("ひざ", "R"), False)
    assert mapping["l_toe"] == (sided("足首", "L"), True)
    assert mapping["r_fingertip"] == (sided("中指３" if spelling != "english" else "手首", "R"), True)


def test_a_baked_mmd_model_whose_skin_is_on_the_deform_legs_is_mapped_on_them():
    """An MMD model an exporter baked has no constraints: its deform copies of the legs (``足D``, with the
    semi-standard toe ``足先EX`` where it has one), on which its skin is weighted, no longer follow the legs the IK
    turned. Told the skin, the map takes them; told nothing (a model as mmd_tools imports it), the legs."""
    names = ["全ての親", "センター", "グルーブ", "下半身", "上半身", "上半身2", "首", "頭"]
    parents = [-1, 0, 1, 2, 2, 4, 5, 6]
    for s in "LR":
        for word, parent in (("足", "下半身"), ("ひざ", "足"), ("足首", "ひざ"), ("つま先", "足首"),
                             ("足D", "下半身"), ("ひざD", "足D"), ("足首D", "ひざD"), ("足先EX", "足首D"),
                             ("肩", "上半身2"), ("腕", "肩"), ("ひじ", "腕"), ("手首", "ひじ")):
            names.append(f"{word}.{s}")
            parents.append(names.index(parent if parent in names else f"{parent}.{s}"))
    skin = {n for n in names if n not in ("全ての親", "センター", "グルーブ") and not n.startswith(("足.", "ひざ.",
                                                                                            "足首.", "つま先."))}
    family, mapping = auto_map(names, parents, skin)
    assert family == "mmd_deform" and not missing(mapping), mapping
    assert [mapping[j] for j in ("hips", "l_upleg", "r_knee", "l_foot", "r_toe")] == [
        ("下半身", True), ("足D.L", False), ("ひざD.R", False), ("足首D.L", False), ("足先EX.R", False)]
    family, mapping = auto_map(names, parents)
    assert family == "mmd" and mapping["l_upleg"] == ("足.L", False) and mapping["r_toe"] == ("足首.R", True)


def test_a_rig_whose_leg_is_its_shin_is_not_read_as_an_mmd_model():
    """``leg_L`` is an MMD model's thigh but many rigs' shin: without the rest of an MMD model's English names the
    bone map reads it by words, as the shin."""
    names = ["hips", "spine", "chest", "neck", "head"] + [f"{w}_{s}" for s in "LR" for w in (
        "upleg", "leg", "foot", "toe", "arm", "elbow", "wrist")]
    parents = [-1, 0, 1, 2, 3] + [p for k in range(2) for p in (0, 5 + 7 * k, 6 + 7 * k, 7 + 7 * k, 2, 9 + 7 * k,
                                                                   10 + 7 * k)]
    family, mapping = auto_map(names, parents)
    assert family != "mmd_english" and mapping["l_knee"] == ("leg_L", False)


def test_an_mmd_model_without_a_second_upper_body_places_the_chest_and_keeps_the_hips_at_the_lower_bodys_tail():
    names, parents = ["全ての親", "センター", "グルーブ", "下半身", "上半身", "首", "頭"], [-1, 0, 1, 2, 2, 4, 5]
    for s in "LR":
        for word, parent in (("足", "下半身"), ("ひざ", "足"), ("足首", "ひざ"), ("肩", "上半身"), ("腕", "肩"),
                             ("ひじ", "腕"), ("手首", "ひじ")):
            names.append(f"{word}.{s}")
            parents.append(names.index(parent if parent in names else f"{parent}.{s}"))
    _, mapping = auto_map(names, parents)
    assert not missing(mapping) and "spine1" not in mapping  # placed between the spine and the neck
    assert mapping["hips"] == ("下半身", True) and mapping["spine"] == ("上半身", False)


# OptiTrack Motive's skeleton: Hip, Ab, Chest; the clavicle LShoulder, the upper and fore arm LUArm and LFArm.
MOTIVE = [("Hip", None), ("Ab", "Hip"), ("Chest", "Ab"), ("Neck", "Chest"), ("Head", "Neck")] + _sided(
    [("{S}Shoulder", "Chest"), ("{S}UArm", "{S}Shoulder"), ("{S}FArm", "{S}UArm"), ("{S}Hand", "{S}FArm"),
     ("{S}Thigh", "Hip"), ("{S}Shin", "{S}Thigh"), ("{S}Foot", "{S}Shin"), ("{S}Toe", "{S}Foot")], "LR")
MIXAMO_PLAIN = [("Hips", None), ("Spine", "Hips"), ("Spine1", "Spine"), ("Spine2", "Spine1"), ("Neck", "Spine2"),
                ("Head", "Neck")] + _sided(
    [("{S}Shoulder", "Spine2"), ("{S}Arm", "{S}Shoulder"), ("{S}ForeArm", "{S}Arm"), ("{S}Hand", "{S}ForeArm"),
     ("{S}UpLeg", "Hips"), ("{S}Leg", "{S}UpLeg"), ("{S}Foot", "{S}Leg"), ("{S}ToeBase", "{S}Foot")],
    ("Left", "Right"))


UNREAL_NAMES = [("pelvis", None), ("spine_01", "pelvis"), ("spine_02", "spine_01"), ("spine_03", "spine_02"),
                ("neck_01", "spine_03"), ("head", "neck_01")] + [
    (f"{bone}_{s}", parent.format(s=s)) for s in "lr" for bone, parent in (
        ("clavicle", "spine_03"), ("upperarm", "clavicle_{s}"), ("lowerarm", "upperarm_{s}"),
        ("hand", "lowerarm_{s}"), ("thigh", "pelvis"), ("calf", "thigh_{s}"), ("foot", "calf_{s}"),
        ("ball", "foot_{s}"))]


# Auto-Rig Pro's exported skeleton: the pelvis root.x, the limbs' deforming *_stretch bones beside their *_twist ones.
ARP_EXPORT = [("root.x", None), ("spine_01.x", "root.x"), ("spine_02.x", "spine_01.x"), ("spine_03.x", "spine_02.x"),
              ("neck.x", "spine_03.x"), ("head.x", "neck.x")] + [
    (bone.format(s=s), parent and parent.format(s=s)) for s in "lr" for bone, parent in (
        ("shoulder.{s}", "spine_03.x"), ("arm_stretch.{s}", "shoulder.{s}"), ("arm_twist.{s}", "shoulder.{s}"),
        ("forearm_stretch.{s}", "arm_stretch.{s}"), ("forearm_twist.{s}", "forearm_stretch.{s}"),
        ("hand.{s}", "forearm_stretch.{s}"), ("thigh_stretch.{s}", "root.x"), ("thigh_twist.{s}", "root.x"),
        ("leg_stretch.{s}", "thigh_stretch.{s}"), ("leg_twist.{s}", "thigh_stretch.{s}"),
        ("foot.{s}", "leg_stretch.{s}"), ("toes_01.{s}", "foot.{s}"))]
# Unreal's Manny: twist bones beside each limb bone, IK bones under the root, fingers from metacarpals.
UE5_MANNY = [("root", None), ("pelvis", "root"), ("spine_01", "pelvis"), ("spine_02", "spine_01"),
             ("spine_03", "spine_02"), ("spine_04", "spine_03"), ("spine_05", "spine_04"), ("neck_01", "spine_05"),
             ("neck_02", "neck_01"), ("head", "neck_02"), ("ik_foot_root", "root"), ("ik_foot_l", "ik_foot_root"),
             ("ik_foot_r", "ik_foot_root"), ("ik_hand_root", "root"), ("ik_hand_gun", "ik_hand_root"),
             ("ik_hand_l", "ik_hand_gun"), ("ik_hand_r", "ik_hand_gun")] + [
    (bone.format(s=s), parent.format(s=s)) for s in "lr" for bone, parent in (
        ("clavicle_{s}", "spine_05"), ("upperarm_{s}", "clavicle_{s}"), ("upperarm_twist_01_{s}", "upperarm_{s}"),
        ("lowerarm_{s}", "upperarm_{s}"), ("lowerarm_twist_01_{s}", "lowerarm_{s}"), ("hand_{s}", "lowerarm_{s}"),
        ("middle_metacarpal_{s}", "hand_{s}"), ("middle_01_{s}", "middle_metacarpal_{s}"),
        ("thigh_{s}", "pelvis"), ("thigh_twist_01_{s}", "thigh_{s}"), ("calf_{s}", "thigh_{s}"),
        ("calf_twist_01_{s}", "calf_{s}"), ("foot_{s}", "calf_{s}"), ("ball_{s}", "foot_{s}"))]


# Synty's POLYGON characters: the clavicle, then Shoulder_L (the upper arm) and Elbow_L; Ankle_L, Ball_L, Toes_L.
SYNTY = [("Root", None), ("Hips", "Root"), ("Spine_01", "Hips"), ("Spine_02", "Spine_01"), ("Spine_03", "Spine_02"),
         ("Neck", "Spine_03"), ("Head", "Neck")] + _sided(
    [("Clavicle_{S}", "Spine_03"), ("Shoulder_{S}", "Clavicle_{S}"), ("Elbow_{S}", "Shoulder_{S}"),
     ("Hand_{S}", "Elbow_{S}"), ("UpperLeg_{S}", "Hips"), ("LowerLeg_{S}", "UpperLeg_{S}"),
     ("Ankle_{S}", "LowerLeg_{S}"), ("Ball_{S}", "Ankle_{S}"), ("Toes_{S}", "Ball_{S}")], "LR")


# The Second Life avatar skeleton with Bento's extra spine and finger bones: the side a word glued after the bone's
# (mHipLeft), the ball of the foot mFootLeft above the toe's tip mToeLeft. Avastar's control bones drop the m.
BENTO = [("mPelvis", None), ("mSpine1", "mPelvis"), ("mSpine2", "mSpine1"), ("mTorso", "mSpine2"),
         ("mSpine3", "mTorso"), ("mSpine4", "mSpine3"), ("mChest", "mSpine4"), ("mNeck", "mChest"),
         ("mHead", "mNeck")] + _sided(
    [("mCollar{S}", "mChest"), ("mShoulder{S}", "mCollar{S}"), ("mElbow{S}", "mShoulder{S}"),
     ("mWrist{S}", "mElbow{S}"), ("mHandMiddle1{S}", "mWrist{S}"), ("mHandMiddle2{S}", "mHandMiddle1{S}"),
     ("mHandMiddle3{S}", "mHandMiddle2{S}"), ("mHip{S}", "mPelvis"), ("mKnee{S}", "mHip{S}"),
     ("mAnkle{S}", "mKnee{S}"), ("mFoot{S}", "mAnkle{S}"), ("mToe{S}", "mFoot{S}")], ("Left", "Right"))
AVASTAR = [("COG", None), ("Pelvis", "COG"), ("Torso", "Pelvis"), ("Chest", "Torso"), ("Neck", "Chest"),
           ("Head", "Neck")] + _sided(
    [("Collar{S}", "Chest"), ("Shoulder{S}", "Collar{S}"), ("Elbow{S}", "Shoulder{S}"), ("Wrist{S}", "Elbow{S}"),
     ("Hip{S}", "Pelvis"), ("Knee{S}", "Hip{S}"), ("Ankle{S}", "Knee{S}"), ("Foot{S}", "Ankle{S}"),
     ("Toe{S}", "Foot{S}")], ("Left", "Right"))
# A VRChat avatar as the Cats plugin names it (MMD's words in English, the side first): "Left leg" is the thigh.
CATS = [("Hips", None), ("Spine", "Hips"), ("Chest", "Spine"), ("Upper Chest", "Chest"), ("Neck", "Upper Chest"),
        ("Head", "Neck")] + _sided(
    [("{S} shoulder", "Upper Chest"), ("{S} arm", "{S} shoulder"), ("{S} elbow", "{S} arm"),
     ("{S} wrist", "{S} elbow"), ("{S} leg", "Hips"), ("{S} knee", "{S} leg"), ("{S} ankle", "{S} knee"),
     ("{S} toe", "{S} ankle")], ("Left", "Right"))
# Daz Genesis 8: the foot, then the metatarsals, then the toes' bone at the ball of the foot.
GENESIS8 = [("hip", None), ("pelvis", "hip"), ("abdomenLower", "hip"), ("abdomenUpper", "abdomenLower"),
            ("chestLower", "abdomenUpper"), ("chestUpper", "chestLower"), ("neckLower", "chestUpper"),
            ("neckUpper", "neckLower"), ("head", "neckUpper")] + _sided(
    [("{S}Collar", "chestUpper"), ("{S}ShldrBend", "{S}Collar"), ("{S}ShldrTwist", "{S}ShldrBend"),
     ("{S}ForearmBend", "{S}ShldrTwist"), ("{S}ForearmTwist", "{S}ForearmBend"), ("{S}Hand", "{S}ForearmTwist"),
     ("{S}ThighBend", "pelvis"), ("{S}ThighTwist", "{S}ThighBend"), ("{S}Shin", "{S}ThighTwist"),
     ("{S}Foot", "{S}Shin"), ("{S}Metatarsals", "{S}Foot"), ("{S}Toe", "{S}Metatarsals")], "lr")


def _prefixed(tree, prefix, unprefixed=()):
    return [(n if n in unprefixed else prefix + n, p and (p if p in unprefixed else prefix + p)) for n, p in tree]


@pytest.mark.parametrize("tree, want", [
    (MOTIVE, {"hips": "Hip", "spine": "Ab", "spine1": "Chest", "l_arm": "LUArm", "l_elbow": "LFArm",
              "r_wrist": "RHand", "l_upleg": "LThigh", "r_knee": "RShin", "l_toe": "LToe"}),
    (_prefixed(MOTIVE, "Skeleton_"), {"hips": "Skeleton_Hip", "l_arm": "Skeleton_LUArm",
                                      "r_elbow": "Skeleton_RFArm", "l_upleg": "Skeleton_LThigh"}),
    (_prefixed(MIXAMO_PLAIN, "Character1_"), {"hips": "Character1_Hips", "spine1": "Character1_Spine2",
                                              "l_arm": "Character1_LeftArm", "r_toe": "Character1_RightToeBase"}),
    # a reference bone under the hips' chain added without the character's name
    ([("Reference", None)] + _prefixed([(n, p or "Reference") for n, p in MIXAMO_PLAIN], "Character1_",
                                       ("Reference",)),
     {"hips": "Character1_Hips", "l_knee": "Character1_LeftLeg"}),
    ([(n + "_jnt", p and p + "_jnt") for n, p in UNREAL_NAMES],
     {"hips": "pelvis_jnt", "l_upleg": "thigh_l_jnt", "r_arm": "upperarm_r_jnt", "l_toe": "ball_l_jnt"}),
    ([(f"rig:{n}_JNT", p and f"rig:{p}_JNT") for n, p in MIXAMO_PLAIN],
     {"hips": "rig:Hips_JNT", "l_knee": "rig:LeftLeg_JNT"}),
    (ARP_EXPORT, {"hips": "root.x", "spine": "spine_01.x", "spine1": "spine_03.x", "l_upleg": "thigh_stretch.l",
                  "r_knee": "leg_stretch.r", "l_arm": "arm_stretch.l", "r_elbow": "forearm_stretch.r",
                  "l_toe": "toes_01.l"}),
    (UE5_MANNY, {"hips": "pelvis", "spine1": "spine_05", "l_upleg": "thigh_l", "r_knee": "calf_r", "l_foot": "foot_l",
                 "r_arm": "upperarm_r", "l_elbow": "lowerarm_l", "r_wrist": "hand_r"}),
    (SYNTY, {"hips": "Hips", "spine1": "Spine_03", "l_arm": "Shoulder_L", "r_elbow": "Elbow_R", "l_foot": "Ankle_L",
             "l_toe": "Ball_L", "r_toe": "Ball_R"}),
    (BENTO, {"hips": "mPelvis", "spine": "mTorso", "spine1": "mChest", "l_upleg": "mHipLeft", "r_knee": "mKneeRight",
             "l_foot": "mAnkleLeft", "l_toe": "mFootLeft", "r_arm": "mShoulderRight", "l_elbow": "mElbowLeft",
             "r_wrist": "mWristRight"}),
    (AVASTAR, {"hips": "Pelvis", "spine": "Torso", "spine1": "Chest", "l_upleg": "HipLeft", "r_knee": "KneeRight",
               "l_foot": "AnkleLeft", "r_toe": "FootRight", "l_arm": "ShoulderLeft", "r_elbow": "ElbowRight",
               "l_wrist": "WristLeft"}),
    (CATS, {"hips": "Hips", "spine1": "Upper Chest", "l_upleg": "Left leg", "l_knee": "Left knee",
            "r_upleg": "Right leg", "r_knee": "Right knee", "r_foot": "Right ankle", "l_toe": "Left toe",
            "l_arm": "Left arm", "r_elbow": "Right elbow"}),
    (GENESIS8, {"hips": "hip", "spine1": "chestUpper", "l_upleg": "lThighBend", "r_knee": "rShin", "l_foot": "lFoot",
                "l_toe": "lToe", "r_toe": "rToe", "l_arm": "lShldrBend", "r_elbow": "rForearmBend"}),
], ids=["motive", "motive_asset_prefix", "motionbuilder_character_prefix", "prefix_and_a_bare_reference_bone",
        "maya_jnt_suffix", "namespace_and_suffix", "auto_rig_pro_export", "ue5_manny_with_ik_and_twist_bones",
        "synty_ball_and_toes", "second_life_bento", "avastar_controls", "cats_vrchat", "daz_genesis8_metatarsals"])
def test_capture_system_names_and_a_character_prefix_map_fully(tree, want):
    """OptiTrack Motive abbreviates its arm bones after the side letter (LUArm, LFArm) and hangs them from a
    clavicle named LShoulder; MotionBuilder names every bone of a character after it (Character1_Hips), Motive after
    its asset (Skeleton_Hip), Maya rigs end each joint in _jnt or _JNT: the prefix and the suffix all bones share
    are read past, the map keeps the bones' own names. Auto-Rig Pro's exported skeleton deforms its limbs with
    *_stretch bones (thigh_stretch.l) under the pelvis root.x; Unreal's Manny has IK and twist bones besides; Synty's
    toe joint is the ball of the foot (Ball_L), above the tips (Toes_L). The Second Life skeleton glues its side
    after the word (mHipLeft; Avastar's controls HipLeft), its ball of the foot is mFootLeft; Cats names a VRChat
    avatar's thigh "Left leg" above "Left knee"; Daz's toes' bone hangs below the metatarsals."""
    _, mapping = auto_map(*_tree(tree))
    assert not missing(mapping)
    assert {j: mapping[j][0] for j in want} == want


def test_the_prefix_every_bone_shares_is_found_and_no_other():
    names = lambda tree: [n for n, _ in tree]
    assert shared_prefix(names(_prefixed(MIXAMO_PLAIN, "Character1_"))) == "Character1_"
    assert shared_prefix(names(_prefixed(MOTIVE, "Take 001:Skeleton_"))) == "Take 001:Skeleton_"
    assert shared_prefix(["Reference"] + names(_prefixed(MIXAMO_PLAIN, "Character1_"))) == "Character1_"
    assert shared_prefix(names(MIXAMO_PLAIN)) == ""  # LeftArm, LeftHand, ... share "Left" but no separator after it
    assert shared_prefix(names(VROID)) == "J_Bip_"  # found, but VRoid maps as it is, so it is never read past
    assert shared_prefix(["Character1_Hips", "Character1_Spine", "Character1_Head"]) == ""  # too few to tell
    half = names(MIXAMO_PLAIN)[:10] + names(_prefixed(MIXAMO_PLAIN, "Character1_"))[10:]
    assert shared_prefix(half) == ""
    assert shared_suffix([n + "_jnt" for n in names(UNREAL_NAMES)]) == "_jnt"  # not thigh_l_jnt's "_l_jnt"
    assert shared_suffix(names(UNREAL_NAMES)) == ""
    assert shared_suffix(["thigh.L", "shin.L", "foot.L", "thigh.R", "shin.R", "foot.R", "spine", "head"]) == ""
    assert bare_names([f"rig:{n}_JNT" for n in names(MIXAMO_PLAIN)]) == names(MIXAMO_PLAIN)


def _hand(tail_across: bool, fingers: bool):
    """An arm (names, parents, heads, tails): upperarm_l, lowerarm_l, hand_l and, with ``fingers``, middle_01_l to
    middle_03_l, along +X; each tail along its bone or, with ``tail_across``, across it (+Y)."""
    names = ["upperarm_l", "lowerarm_l", "hand_l"] + (["middle_01_l", "middle_02_l", "middle_03_l"] if fingers else [])
    parents = list(range(-1, len(names) - 1))
    heads = np.array([[0.3 * i if i < 3 else 0.6 + 0.04 * (i - 2), 0.0, 0.0] for i in range(len(names))])
    step = np.array([0.0, 0.05, 0.0]) if tail_across else np.array([0.05, 0.0, 0.0])
    return names, parents, heads, heads + step


def test_a_finger_tip_at_a_tail_that_points_across_the_bone_moves_to_a_head():
    """An FBX from Maya or Unreal imported without Automatic Bone Orientation points each bone's tail across it: a
    finger tip there is no finger tip. The last finger bone's own head takes its place, or, for the hand's tail, the
    middle finger's last head; with no finger bone the tail stays; a tail along the limb is left as it is."""
    names, parents, heads, tails = _hand(True, True)
    mapping = {"l_wrist": ("hand_l", False), "l_fingertip": ("middle_03_l", True)}
    fixed = heads_where_tails_point_across(mapping, names, parents, heads, tails)
    assert fixed["l_fingertip"] == ("middle_03_l", False) and fixed["l_wrist"] == ("hand_l", False)
    hand_tail = {"l_wrist": ("hand_l", False), "l_fingertip": ("hand_l", True)}
    assert heads_where_tails_point_across(hand_tail, names, parents, heads, tails)["l_fingertip"] == ("middle_03_l",
                                                                                                      False)
    names, parents, heads, tails = _hand(True, False)
    assert heads_where_tails_point_across(hand_tail, names, parents, heads, tails) == hand_tail
    names, parents, heads, tails = _hand(False, True)
    assert heads_where_tails_point_across(mapping, names, parents, heads, tails) == mapping
    assert heads_where_tails_point_across(hand_tail, names, parents, heads, tails) == hand_tail


@pytest.mark.parametrize("tree, tip", [
    (UE5_MANNY + [(f"middle_0{k}_{s}", f"middle_0{k - 1}_{s}") for s in "lr" for k in (2, 3)], "middle_03"),
    ([(n, p) for n, p in MIXAMO_PLAIN] + [(f"{S}HandMiddle{k}", f"{S}Hand" if k == 1 else f"{S}HandMiddle{k - 1}")
                                          for S in ("Left", "Right") for k in (1, 2, 3)], None),
    (MIXAMO_PLAIN + [
        (f"{S}MiddleProximal", f"{S}Hand") for S in ("Left", "Right")] + [
        (f"{S}MiddleIntermediate", f"{S}MiddleProximal") for S in ("Left", "Right")] + [
        (f"{S}MiddleDistal", f"{S}MiddleIntermediate") for S in ("Left", "Right")], "MiddleDistal"),
], ids=["unreal_middle_03", "mixamo_without_the_tip_bone", "unity_middle_distal"])
def test_a_finger_tip_no_word_names_is_the_middle_fingers_last_head(tree, tip):
    """Unreal's middle_01_l to middle_03_l, Unity's LeftMiddleProximal to LeftMiddleDistal: the finger tip is the
    last one's head, not the hand's tail; Mixamo's family without its LeftHandMiddle4 keeps its own reading (the
    third bone's tail, which :func:`heads_where_tails_point_across` checks against the rig's geometry)."""
    _, mapping = auto_map(*_tree(tree))
    if tip == "middle_03":
        assert mapping["l_fingertip"] == ("middle_03_l", False) and mapping["r_fingertip"] == ("middle_03_r", False)
    elif tip is None:
        assert mapping["l_fingertip"] == ("LeftHandMiddle3", True)
    else:
        assert mapping["l_fingertip"] == ("LeftMiddleDistal", False)


@pytest.mark.parametrize("tail, across", [((0.0, -0.14, -0.05), False), ((0.0, -0.10, -0.10), False),
                                          ((0.14, 0.0, 0.0), True), ((0.0, 0.0, 0.14), True),
                                          ((0.0, 0.14, 0.0), True)],
                         ids=["forward_and_down", "down_at_45", "sideways", "up", "backwards"])
def test_a_foot_tail_is_across_where_it_points_off_the_way_the_body_faces(tail, across):
    """A toe at a foot's tail (a foot with no toe bone) is across where the tail points off the way the body faces
    (Blender's -Y for a rig made facing the front view: across the thighs crossed with up the spine), not off the
    shin's line: a foot pointing forward and a little down, 70 degrees off its shin, is a foot as it should be."""
    tree = [("pelvis", None), ("spine", "pelvis"), ("head", "spine")] + [
        (f"{b}_{s}", p if p == "pelvis" else f"{p}_{s}") for s in "lr"
        for b, p in (("thigh", "pelvis"), ("calf", "thigh"), ("foot", "calf"))]
    names, parents = _tree(tree)
    x = {"l": 0.1, "r": -0.1}
    at = {"pelvis": (0, 0, 0.95), "spine": (0, 0, 1.2), "head": (0, 0, 1.6)}
    for s in "lr":
        at |= {f"thigh_{s}": (x[s], 0, 0.9), f"calf_{s}": (x[s], 0, 0.5), f"foot_{s}": (x[s], 0, 0.08)}
    heads = np.array([at[n] for n in names], dtype=float)
    tails = heads + np.array([(0, 0, 0.1)] * len(names))
    for s in "lr":
        tails[names.index(f"foot_{s}")] = heads[names.index(f"foot_{s}")] + np.array(tail)
    mapping = {"hips": ("pelvis", False), "spine": ("spine", False), "head": ("head", False)}
    for s in "lr":
        mapping |= {f"{s}_upleg": (f"thigh_{s}", False), f"{s}_knee": (f"calf_{s}", False),
                    f"{s}_foot": (f"foot_{s}", False), f"{s}_toe": (f"foot_{s}", True)}
    assert tails_across(mapping, names, parents, heads, tails) == (["l_toe", "r_toe"] if across else [])
