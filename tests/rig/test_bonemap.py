"""Bone auto-mapping (no Blender): families, the left/right heuristic, the hierarchy fallback."""

from __future__ import annotations

import pytest

from model_core.motion.conventions import JOINTS
from model_core.rig.bonemap import auto_map, missing, split_side


@pytest.mark.parametrize("name, want", [
    ("thigh.L", ("l", "thigh")), ("DEF-upper_arm.R.001", ("r", "upperarm")), ("CC_Base_L_Thigh", ("l", "thigh")),
    ("LeftUpLeg", ("l", "upleg")), ("mixamorig:RightHand", ("r", "hand")), ("lThigh", ("l", "thigh")),
    ("LHipJoint", ("l", "hipjoint")), ("upperarm_l", ("l", "upperarm")), ("L_Foot", ("l", "foot")),
    ("Root", (None, "root")), ("spine_01", (None, "spine01")), ("ball_r", ("r", "ball")),
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


def test_end_site_candidates_become_tails():
    names = ["CC_Base_Hip", "CC_Base_Waist", "CC_Base_Spine02", "CC_Base_NeckTwist01", "CC_Base_Head"]
    names += [f"CC_Base_{s}_{b}" for s in "LR" for b in ("Thigh", "Calf", "Foot", "ToeBase", "Upperarm",
                                                           "Forearm", "Hand", "Mid3")]
    family, mapping = auto_map(names, [-1] * len(names))
    assert family == "iclone_cc_base" and mapping["l_fingertip"] == ("CC_Base_L_Mid3", True)


def test_missing_joints_are_listed():
    _, mapping = auto_map(*chain("a", "b", "c"))
    assert set(missing(mapping)) == set(JOINTS) - set(mapping)
    assert "l_knee" in missing(mapping)
