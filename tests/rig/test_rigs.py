"""Rig detection for every known skeleton family, skeletons of no known family read by body part and side,
and the error that lists what is missing."""

from __future__ import annotations

import re

import numpy as np
import pytest

from model_core.io.bvh_export import write_bvh
from model_core.motion.conventions import JOINTS, STANDARD_LEG_LENGTH
from model_core.motion.synthetic import walking_skeleton
from model_core.rig.rigs import (
    RIG_FAMILIES,
    NameLookup,
    RigError,
    detect_rig,
    leg_length,
    load_clip,
    normalise_name,
)


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


@pytest.mark.parametrize("family", ["rigify", "rigify_deform", "rigify_metarig", "auto_rig_pro"])
def test_names_that_came_back_through_usd_or_maya_are_read_as_their_family(family):
    """USD's joint names and Maya's nodes allow no ``-``, ``.`` or space, so a rig's names come back from either with
    ``_`` for them (Rigify's ``DEF-thigh.L`` as ``DEF_thigh_L``): read as the family spells them where only one bone
    reads so, and the map keeps the bones' own names."""
    names = [re.sub(r"[-. ]", "_", n) for n in family_names(family)]
    rig = detect_rig(names + ["SomeExtraBone"])
    assert rig.family == family and set(rig.sources) == set(JOINTS)
    assert all(source is None or source in names for source in rig.sources.values())
    mixed = names + ["DEF-thigh.L", "DEF_thigh.L"]  # two bones that read alike: neither is taken by the loose reading
    assert NameLookup(mixed).get("DEF-thigh.L") == "DEF-thigh.L" and NameLookup(mixed[:-2] + ["a.b", "a-b"]).get(
        "a_b") is None


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


# How other libraries and tools name the joints of a written take (Mixamo names, as `write_bvh` writes them).
_LIMBS = ("Arm", "ForeArm", "Hand", "HandMiddle4", "UpLeg", "Leg", "Foot", "ToeBase")
_NAMINGS = {
    "lafan1": ({"Spine1": "Spine2"},
               lambda side, limb: side + {"ToeBase": "Toe", "HandMiddle4": "HandMiddle1"}.get(limb, limb)),
    "unreal": ({"Hips": "pelvis", "Spine": "spine_01", "Spine1": "spine_03", "Neck": "neck_01", "Head": "head"},
               lambda side, limb: dict(zip(_LIMBS, ("upperarm", "lowerarm", "hand", "middle_01", "thigh", "calf",
                                                    "foot", "ball")))[limb] + "_" + side[0].lower()),
    "daz": ({"Hips": "hip", "Spine": "abdomen", "Spine1": "chest", "Neck": "neck", "Head": "head"},
            lambda side, limb: side[0].lower() + dict(zip(_LIMBS, ("Shldr", "ForeArm", "Hand", "Mid1", "Thigh",
                                                                   "Shin", "Foot", "Toe")))[limb]),
    # 3ds Max's Biped: names with spaces, which the reader joins with underscores as Blender's importer does
    "biped": ({"Hips": "Bip01 Pelvis", "Spine": "Bip01 Spine", "Spine1": "Bip01 Spine1", "Neck": "Bip01 Neck",
               "Head": "Bip01 Head", "LeftShoulder": "Bip01 L Clavicle", "RightShoulder": "Bip01 R Clavicle"},
              lambda side, limb: f"Bip01 {side[0]} " + dict(zip(_LIMBS, ("UpperArm", "Forearm", "Hand", "Finger2",
                                                                        "Thigh", "Calf", "Foot", "Toe0")))[limb]),
    # SMPL's joints, as AMASS conversions name them: the ankle above L_Foot (the ball of the foot), the wrist
    # above L_Hand, three spine joints with the arms hanging from the third.
    "smpl": ({"Hips": "Pelvis", "Spine": "Spine1", "Spine1": "Spine3", "LeftShoulder": "L_Collar",
              "RightShoulder": "R_Collar"},
             lambda side, limb: side[0] + "_" + dict(zip(_LIMBS, ("Shoulder", "Elbow", "Wrist", "Hand", "Hip", "Knee",
                                                                 "Ankle", "Foot")))[limb]),
    # OptiTrack Motive: Hip, Ab, Chest; the clavicle LShoulder, the upper and fore arm LUArm and LFArm
    "motive": ({"Hips": "Hip", "Spine": "Ab", "Spine1": "Chest", "LeftShoulder": "LShoulder",
                "RightShoulder": "RShoulder"},
               lambda side, limb: side[0] + dict(zip(_LIMBS, ("UArm", "FArm", "Hand", "Finger", "Thigh", "Shin",
                                                             "Foot", "Toe")))[limb]),
}


def _renamed(path, naming: str):
    """The BVH at ``path`` with its joints named as ``naming`` names them."""
    torso, limb = _NAMINGS[naming]
    pattern = re.compile(r"^(Left|Right)(" + "|".join(sorted(_LIMBS, key=len, reverse=True)) + r")$")

    def name(m):
        old = m[2]
        side = pattern.match(old)
        return f"{m[1]} {limb(side[1], side[2]) if side else torso.get(old, old)}"

    out = path.with_name(f"{naming}.bvh")
    out.write_text(re.sub(r"(ROOT|JOINT) (\S+)", name, path.read_text()))
    return out


@pytest.mark.parametrize("naming", list(_NAMINGS))
def test_a_take_named_as_another_library_names_it_reads_as_the_same_motion(tmp_path, naming):
    """A take of no known family (LAFAN1's LeftToe, Unreal's pelvis/thigh_l/ball_l, Daz's lThigh/lToe) is
    read by body part, side and hierarchy into the same motion its Mixamo-named twin gives."""
    take = write_bvh(tmp_path / "walk.bvh", walking_skeleton(30))
    renamed = _renamed(take, naming)
    with pytest.raises(RigError):
        detect_rig([n for n in re.findall(r"(?:ROOT|JOINT) (\S+)", renamed.read_text())])  # names alone
    got, want = load_clip(renamed), load_clip(take)
    body = [i for i, j in enumerate(JOINTS) if not j.endswith("fingertip")]
    np.testing.assert_allclose(got[:, body], want[:, body], atol=1e-6)
    # SMPL's finger tip is L_Hand's End Site, a little past the middle finger's last joint
    assert np.linalg.norm(got - want, axis=-1).max() < (0.05 if naming == "smpl" else 1e-6)


@pytest.mark.parametrize("naming, prefix, suffix", [(None, "Character1_", ""), ("motive", "Skeleton_", ""),
                                                    ("unreal", "Take 001:hero_", ""), ("unreal", "", "_jnt"),
                                                    (None, "", "_JNT")])
def test_a_take_whose_joints_carry_a_characters_name_reads_as_the_same_motion(tmp_path, naming, prefix, suffix):
    """MotionBuilder names each joint after its character (Character1_Hips), OptiTrack Motive after its asset
    (Skeleton_Hip), Maya rigs end them in _jnt: the prefix or suffix all the joints share is read past, whatever
    naming it wraps."""
    take = write_bvh(tmp_path / "walk.bvh", walking_skeleton(30))
    named = _renamed(take, naming) if naming else take
    prefixed = tmp_path / "prefixed.bvh"
    prefixed.write_text(re.sub(r"(ROOT|JOINT) (\S+)", lambda m: f"{m[1]} {prefix}{m[2]}{suffix}",
                               named.read_text()))
    np.testing.assert_allclose(load_clip(prefixed), load_clip(take), atol=1e-6)
    if naming is None:  # a whole family's names behind the prefix are that family's, names alone
        names = re.findall(r"(?:ROOT|JOINT) (\S+)", prefixed.read_text())
        rig = detect_rig(names)
        assert rig.family == "mixamo" and rig.sources["l_upleg"] == f"{prefix}LeftUpLeg{suffix}"


def test_a_real_take_named_as_lafan1_names_it_reads_as_the_same_motion(mocap_root, smallest_bvh, tmp_path):
    take = smallest_bvh(mocap_root / "bandai-namco")
    names = {"Chest": "Spine1", **{f"{a}_{s}": f"{side}{b}" for s, side in (("L", "Left"), ("R", "Right"))
                                   for a, b in (("Shoulder", "Shoulder"), ("UpperArm", "Arm"),
                                                ("LowerArm", "ForeArm"), ("Hand", "Hand"), ("UpperLeg", "UpLeg"),
                                                ("LowerLeg", "Leg"), ("Foot", "Foot"), ("Toes", "Toe"))}}
    renamed = tmp_path / "lafan1.bvh"
    renamed.write_text(re.sub(r"(ROOT|JOINT)(\s+)(\S+)", lambda m: m[1] + m[2] + names.get(m[3], m[3]),
                              take.read_text()))
    # Bandai's hands end in a zero-length End Site: the finger tip is estimated, as for the family, not the wrist
    np.testing.assert_allclose(load_clip(renamed), load_clip(take), atol=1e-6)


def test_a_skeleton_read_by_name_whose_hierarchy_disagrees_says_where(tmp_path):
    take = write_bvh(tmp_path / "walk.bvh", walking_skeleton(30))
    text = _renamed(take, "lafan1").read_text()
    swapped = tmp_path / "swapped.bvh"  # the left shin named as the foot and the foot as the shin
    swapped.write_text(text.replace("JOINT LeftLeg", "JOINT @").replace("JOINT LeftFoot", "JOINT LeftLeg")
                       .replace("JOINT @", "JOINT LeftFoot"))
    with pytest.raises(RigError, match=r"unknown rig.*l_foot -> 'LeftFoot' is not below l_knee -> 'LeftLeg'"):
        load_clip(swapped)


_TURNS = {"z_up": [[1, 0, 0], [0, 0, -1], [0, 1, 0]], "x_up": [[0, 1, 0], [-1, 0, 0], [0, 0, 1]],
          "upside_down": [[1, 0, 0], [0, -1, 0], [0, 0, -1]]}


@pytest.mark.parametrize("turn", list(_TURNS))
def test_a_take_that_stands_along_another_axis_is_stood_up(tmp_path, turn):
    """A Z-up file (AMASS conversions, some exporters), or one standing along X or upside down, reads as the same
    motion as its Y-up twin: the same heights over the floor and the same distances between joints."""
    pos = walking_skeleton(60)
    want = load_clip(write_bvh(tmp_path / "y_up.bvh", pos))
    got = load_clip(write_bvh(tmp_path / f"{turn}.bvh", pos @ np.array(_TURNS[turn], float).T))
    np.testing.assert_allclose(got[..., 1], want[..., 1], atol=1e-5)
    dist = lambda p: np.linalg.norm(p[:, :, None] - p[:, None], axis=-1)
    np.testing.assert_allclose(dist(got), dist(want), atol=1e-5)


def test_a_take_lying_down_half_the_time_is_left_as_it_is(tmp_path):
    """No axis holds three quarters of the frames: the file's own up is kept (a take of someone lying down is
    not stood up)."""
    from model_core.io.bvh import read_bvh
    from model_core.rig.rigs import canonical_positions, standing_axis

    pos = walking_skeleton(60)
    pos[30:] = pos[30:] @ np.array(_TURNS["z_up"], float).T
    path = write_bvh(tmp_path / "half.bvh", pos)
    assert standing_axis(canonical_positions(read_bvh(path))) is None
    clip = load_clip(path)
    head = clip[:, JOINTS.index("head")] - clip[:, [JOINTS.index("l_foot"), JOINTS.index("r_foot")]].mean(1)
    assert (head[:30, 1] > 1.2).all() and (head[30:, 2] > 1.2).all()  # standing, then lying along +Z, as written


def test_a_whole_family_whose_arms_hang_higher_takes_the_chest_where_they_meet():
    """Xsens MVN's BVH spells the CMU 'LeftHip' family whole, but its arms hang from Chest4, not Chest2: read with
    its hierarchy (as every file is), the chest is where the arms meet, in the reader and in the bone map alike."""
    from model_core.rig.bonemap import auto_map

    parent = {"Hips": None, "Chest": "Hips", "Chest2": "Chest", "Chest3": "Chest2", "Chest4": "Chest3",
              "Neck": "Chest4", "Head": "Neck"}
    for s in ("Left", "Right"):
        parent |= {f"{s}Collar": "Chest4", f"{s}Shoulder": f"{s}Collar", f"{s}Elbow": f"{s}Shoulder",
                   f"{s}Wrist": f"{s}Elbow", f"{s}Hip": "Hips", f"{s}Knee": f"{s}Hip", f"{s}Ankle": f"{s}Knee",
                   f"{s}Toe": f"{s}Ankle"}
    names = list(parent)
    parents = [names.index(parent[n]) if parent[n] else -1 for n in names]
    assert detect_rig(names).sources["spine1"] == "Chest2"  # by names alone, the family's chest
    rig = detect_rig(names, parents=parents)
    assert rig.family == "cmu_bvh11" and (rig.sources["spine"], rig.sources["spine1"]) == ("Chest", "Chest4")
    assert auto_map(names, parents)[1]["spine1"] == ("Chest4", False)


def _without_neck(path, out):
    """The BVH file at ``path`` without its Neck joint: the head hangs from the chest (the neck's offset added to
    its own), the neck's three rotation channels dropped from every frame."""
    lines = open(path).read().splitlines()
    start = next(i for i, t in enumerate(lines) if t.strip() == "JOINT Neck")
    indent = len(lines[start]) - len(lines[start].lstrip())
    end = next(i for i in range(start + 1, len(lines)) if lines[i] == " " * indent + "}")
    offset = np.array(lines[start + 2].split()[1:], float)
    head = next(i for i in range(start, end) if lines[i].strip() == "JOINT Head") + 2
    lines[head] = "OFFSET " + " ".join(f"{v:.6f}" for v in np.array(lines[head].split()[1:], float) + offset)
    column = sum(int(t.split()[1]) for t in lines[:start] if t.strip().startswith("CHANNELS"))
    motion = lines.index("MOTION") + 3
    frames = [t.split() for t in lines[motion:]]
    lines = lines[:start] + lines[start + 4:end] + lines[end + 1:motion] + [
        " ".join(f[:column] + f[column + 3:]) for f in frames]
    out.write_text("\n".join(lines) + "\n")
    return out


def test_a_skeleton_without_a_neck_joint_places_the_neck_between_chest_and_head(tmp_path):
    """A skeleton whose head hangs from its chest is read by body part and hierarchy, the neck placed on the line
    from the chest to the head at the share of the way the model's body has it; every other joint as before."""
    path = write_bvh(tmp_path / "walk.bvh", walking_skeleton(60))
    bare = _without_neck(path, tmp_path / "no_neck.bvh")
    from model_core.io.bvh import read_bvh

    bvh = read_bvh(bare)
    assert "Neck" not in bvh.names
    rig = detect_rig(bvh.names, str(bare), bvh.parents, bvh.offsets)
    assert rig.family == "generic" and set(rig.between) == {"neck"}
    below, above, share = rig.between["neck"]
    assert (below, above) == ("spine1", "head") and 0.5 < share < 0.9
    before, after = load_clip(path), load_clip(bare)
    j = {name: k for k, name in enumerate(JOINTS)}
    between = (1 - share) * after[:, j["spine1"]] + share * after[:, j["head"]]
    assert np.allclose(after[:, j["neck"]], between, atol=1e-6)
    others = [k for name, k in j.items() if name not in ("neck", "head")]
    assert np.abs(after[:, others] - before[:, others]).max() < 1e-4
