"""Rig detection for every known skeleton family, and the error that lists what is missing."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.motion.conventions import JOINTS, STANDARD_LEG_LENGTH
from model_core.motion.synthetic import walking_skeleton
from model_core.rig.rigs import RIG_FAMILIES, RigError, detect_rig, leg_length, normalise_name


def family_names(family: str) -> list[str]:
    """The joint names a file of ``family`` would have: each canonical joint's first candidate."""
    return [names[0] for names in RIG_FAMILIES[family].values() if names]


@pytest.mark.parametrize("family", list(RIG_FAMILIES))
def test_each_family_is_detected_from_its_names(family):
    rig = detect_rig(family_names(family) + ["SomeExtraBone", "Another_end"])
    assert rig.family == family
    assert set(rig.sources) == set(JOINTS)


@pytest.mark.parametrize("prefix", ["mixamorig:", "Armature|"])
def test_namespace_prefixes_are_ignored(prefix):
    names = [prefix + n for n in family_names("mixamo")]
    rig = detect_rig(names)
    assert rig.family == "mixamo"
    assert rig.sources["hips"] == prefix + "Hips"


def test_matching_ignores_case():
    names = [n.upper() for n in family_names("bandai_namco")]
    assert detect_rig(names).family == "bandai_namco"
    assert normalise_name("mixamorig:LeftUpLeg") == "leftupleg"


def test_missing_finger_tip_is_estimated_not_an_error():
    names = [n for n in family_names("mixamo") if "Middle" not in n]
    rig = detect_rig(names)
    assert rig.sources["l_fingertip"] is None and rig.sources["r_fingertip"] is None


def test_unknown_rig_lists_the_missing_canonical_joints():
    names = [n for n in family_names("bandai_namco") if n not in ("Foot_L", "Head")]
    with pytest.raises(RigError) as err:
        detect_rig(names, source="walk.bvh")
    msg = str(err.value)
    assert msg.startswith("walk.bvh: unknown rig")
    assert "'bandai_namco'" in msg
    assert "l_foot" in msg and "head" in msg
    assert "r_foot" not in msg  # only what is actually missing


def test_leg_length_of_the_synthetic_walker():
    pos = walking_skeleton(30)
    # thigh 0.44 m, shin sqrt(0.43^2 + 0.01^2) m in the synthetic skeleton
    assert leg_length(pos) == pytest.approx(0.44 + np.hypot(0.43, 0.01), abs=1e-6)
    assert STANDARD_LEG_LENGTH > 0
