"""Auto-mapping bones onto the 21 canonical joints, and the map saved with the armature."""

from __future__ import annotations

import bpy
import numpy as np
import pytest
from scenes import (
    action_of,
    addon_module,
    build_armature,
    evaluated_joints,
    fewer_torso_bones,
    find_mocap,
    genesis8_bones,
    import_bvh,
    makehuman_bones,
    mixamo_bones,
    ramp,
    retargeted,
    rigify_bones,
    roblox_r15_bones,
    smpl_bones,
    walk_bvh,
)

from model_core.motion.conventions import JOINT_INDEX, JOINTS

FAMILY_CLIPS = {
    "bandai_namco": "bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh",
    "iclone_cc_base": "cmu/iclone/002_01.bvh",
    "acrnn": "cmu/acrnn-dance/salsa/01.bvh",
    "cmu_cgspeed": "cmu/cgspeed/tmoco_02_01.bvh",
    "cmu_bvh11": "cmu/cgspeed/bvh11_131_01.bvh",
}
UNREAL = [("pelvis", None), ("spine_01", "pelvis"), ("spine_02", "spine_01"), ("spine_03", "spine_02"),
          ("neck_01", "spine_03"), ("head", "neck_01")] + [
    (f"{bone}_{s}", parent.format(s=s)) for s in "lr" for bone, parent in (
        ("clavicle", "spine_03"), ("upperarm", "clavicle_{s}"), ("lowerarm", "upperarm_{s}"), ("hand", "lowerarm_{s}"),
        ("thigh", "pelvis"), ("calf", "thigh_{s}"), ("foot", "calf_{s}"), ("ball", "foot_{s}"))]


def stored(obj) -> dict:
    return {j: getattr(obj.strnn_map, j) for j in JOINTS}


def auto_map(obj) -> dict:
    bpy.context.view_layer.objects.active = obj
    assert bpy.ops.strnn.auto_map() == {"FINISHED"}
    return stored(obj)


def test_mixamo_armature_maps_fully(addon):
    found = auto_map(build_armature("Mixamo", mixamo_bones()))
    assert found["l_upleg"] == "mixamorig:LeftUpLeg" and found["spine1"] == "mixamorig:Spine2"
    assert found["l_fingertip"] == "mixamorig:LeftHandMiddle4"
    assert bpy.context.active_object.strnn_map.family == "mixamo"


def test_rigify_deform_bones_map_fully(addon):
    obj = build_armature("Rigify", rigify_bones())
    found = auto_map(obj)
    assert found["hips"] == "DEF-spine" and found["head"] == "DEF-spine.006"
    assert found["r_knee"] == "DEF-shin.R" and found["r_wrist"] == "DEF-hand.R"
    assert obj.strnn_map.family == "rigify_deform"


def test_generic_left_right_heuristic_maps_unreal_names(addon):
    j = {n: (0.0, 0.0, float(i)) for i, (n, _) in enumerate(UNREAL)}
    bones = [(n, p, j[n], (j[n][0], 0.1, j[n][2])) for n, p in UNREAL]
    obj = build_armature("Mannequin", bones)
    found = auto_map(obj)
    assert all(found.values()), [k for k, v in found.items() if not v]
    assert (found["hips"], found["spine"], found["spine1"], found["neck"]) == ("pelvis", "spine_01", "spine_03",
                                                                               "neck_01")
    assert (found["l_knee"], found["r_toe"], found["l_arm"]) == ("calf_l", "ball_r", "upperarm_l")
    assert found["l_fingertip"] == "hand_l" and obj.strnn_map.l_fingertip_tail


def test_makehuman_names_in_numbered_segments_map_to_each_limbs_first_segment(addon):
    """MakeHuman and MPFB split each limb in two (upperleg01.L, upperleg02.L): the joint is the first's head."""
    obj = build_armature("MakeHuman", makehuman_bones())
    found = auto_map(obj)
    assert all(found.values()), [k for k, v in found.items() if not v]
    assert (found["hips"], found["spine"], found["spine1"], found["neck"]) == ("root", "spine05", "spine01", "neck01")
    assert (found["l_upleg"], found["l_knee"], found["r_arm"], found["r_elbow"]) == (
        "upperleg01.L", "lowerleg01.L", "upperarm01.R", "lowerarm01.R")
    assert (found["l_foot"], found["l_toe"], found["r_wrist"]) == ("foot.L", "toe1-1.L", "wrist.R")


def test_smpl_armature_maps_the_ankle_wrist_and_chest(addon):
    found = auto_map(build_armature("SMPL", smpl_bones()))
    assert all(found.values()), [k for k, v in found.items() if not v]
    assert (found["spine1"], found["l_foot"], found["l_toe"], found["r_wrist"]) == ("Spine3", "L_Ankle", "L_Foot",
                                                                                   "R_Wrist")
    assert found["l_fingertip"] == "L_Hand" and bpy.context.active_object.strnn_map.l_fingertip_tail


def test_unmappable_rig_lists_missing_joints(addon):
    obj = build_armature("Blob", [("a", None, (0, 0, 0), (0, 0, 1)), ("b", "a", (0, 0, 1), (0, 0, 2))])
    bpy.ops.strnn.auto_map()
    assert not obj.strnn_map.l_knee


def test_bvh_fixture_maps_and_map_is_saved_in_blend(addon, tmp_path):
    obj = import_bvh(walk_bvh(tmp_path))
    name = obj.name
    found = auto_map(obj)
    assert all(found.values())
    obj.strnn_map.l_wrist = "LeftForeArm"  # a hand edit must survive save and reload
    path = tmp_path / "mapped.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.wm.open_mainfile(filepath=str(path))
    arm = bpy.data.objects[name]
    assert arm.strnn_map.l_wrist == "LeftForeArm"
    assert arm.strnn_map.l_upleg == found["l_upleg"]


@pytest.mark.parametrize("family", sorted(FAMILY_CLIPS))
def test_bvh_imports_of_every_rig_family_map_fully(addon, family):
    root = find_mocap()
    if root is None or not (root / FAMILY_CLIPS[family]).exists():
        pytest.skip("motion capture not unpacked (data/mocap or ../shared/mocap)")
    obj = import_bvh(root / FAMILY_CLIPS[family])
    found = auto_map(obj)
    assert all(found.values()), [k for k, v in found.items() if not v]
    assert obj.strnn_map.family == family


FEWER_TORSO_BONES = {"one_spine": lambda: fewer_torso_bones(("Spine1", "Spine2")),
                     "no_neck": lambda: fewer_torso_bones(("Neck",)),
                     "spine_and_head": lambda: fewer_torso_bones(("Spine1", "Spine2", "Neck")),
                     "roblox_r15": roblox_r15_bones}
PLACED = {"one_spine": {"spine1"}, "no_neck": {"neck"}, "spine_and_head": {"spine1", "neck"},
          "roblox_r15": {"spine1", "neck"}}


REPORTS = {"one_spine": "Mapped 20 joints (generic rig); it has no Spine 1 bone, so that joint is placed between "
                        "Spine and Neck",
           "no_neck": "Mapped 20 joints (generic rig); it has no Neck bone, so that joint is placed between Spine 1 "
                      "and Head",
           "spine_and_head": "Mapped 19 joints (generic rig); it has no Spine 1 or Neck bone, so those joints are "
                             "placed between Spine and Head"}
REPORTS["roblox_r15"] = REPORTS["spine_and_head"]


@pytest.mark.parametrize("kind", sorted(FEWER_TORSO_BONES))
def test_a_rig_with_fewer_torso_bones_maps_all_it_has_and_places_the_rest(addon, kind, capfd):
    """One spine bone (no chest of its own), a head on the chest (no neck bone), or both (a minimal game
    humanoid; Roblox's R15, whose upper torso is its one spine bone): every joint the rig has a bone for is mapped,
    the chest or neck left to be placed between its neighbours, and the operators take the map."""
    obj = build_armature("Game", FEWER_TORSO_BONES[kind]())
    capfd.readouterr()
    found = auto_map(obj)
    assert REPORTS[kind] in capfd.readouterr().out
    assert {j for j, bone in found.items() if not bone} == PLACED[kind]
    r15 = kind == "roblox_r15"
    assert (found["spine"], found["head"], found["l_arm"], found["l_toe"]) == (
        ("UpperTorso", "Head", "LeftUpperArm", "LeftFoot") if r15 else ("Spine", "Head", "LeftArm", "LeftToeBase"))
    pipeline = addon_module(addon, "strnn_addon.scene.pipeline")
    _, anchors, _, _ = pipeline.rig_of(obj)
    assert {JOINTS[j] for j in anchors.between} == PLACED[kind]


def walk_onto(obj, folder):
    """A walk (real motion capture where it is unpacked) moved onto ``obj`` with Transfer Motion: (the source,
    the frames written)."""
    mocap = find_mocap()
    take = "bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh"
    path = mocap / take if mocap is not None and (mocap / take).exists() else walk_bvh(folder, frames=120)
    source = import_bvh(path, update_scene_fps=True, update_scene_duration=True)
    source.location.x = -2.0
    for other in bpy.context.view_layer.objects:
        other.select_set(other in (source, obj))
    bpy.context.view_layer.objects.active = obj
    assert bpy.ops.strnn.transfer_motion(foot_lock=False) == {"FINISHED"}
    new = action_of(obj)
    return source, np.arange(int(new.frame_range[0]), int(new.frame_range[1]) + 1)


def walk_and_its_error(addon, obj, folder):
    """:func:`walk_onto` ``obj``, and how far (metres) each of its joints is frame by frame ``[F, 21]`` from where the
    source's motion on ``obj``'s proportions has it: (the source, the frames written, that distance)."""
    rest = evaluated_joints(addon, obj, [1])
    source, frames = walk_onto(obj, folder)
    want = retargeted(addon, source, rest, frames)
    return source, frames, np.linalg.norm(evaluated_joints(addon, obj, frames) - want, axis=-1)


def extended_walk(addon, obj, frames: int) -> tuple[float, float]:
    """Extend Clip on ``obj``'s walk by ``frames``: (the joints' step at the seam against the largest of the 29
    before it, their mean step after the seam against before it)."""
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    last = int(action_of(obj).frame_range[1])
    assert bpy.ops.strnn.extend_clip(frames=frames) == {"FINISHED"}
    pos = evaluated_joints(addon, obj, np.arange(last - 29, last + frames + 1))
    step = np.linalg.norm(np.diff(pos, axis=0), axis=-1).mean(-1)
    return step[29] / step[:29].max(), step[30:].mean() / step[:29].mean()


@pytest.mark.parametrize("kind", sorted(FEWER_TORSO_BONES))
def test_motion_moved_onto_a_rig_with_fewer_torso_bones_follows_and_extends(addon, real_model, tmp_path, kind):
    """A walk moved onto such a rig puts its every joint where the source's motion on the rig's proportions
    has it (the one spine bone turning to carry the arms and the head), and Extend walks it on from there."""
    obj = build_armature("Game", FEWER_TORSO_BONES[kind]())
    source, frames, err = walk_and_its_error(addon, obj, tmp_path)
    err = err.mean(0)
    own = [k for j, k in JOINT_INDEX.items() if j not in PLACED[kind]]
    print(kind, "transfer, mean cm per joint:", np.round(100 * err, 2))
    assert err[own].max() < 0.015 and err.max() < 0.02  # metres; a placed joint lies on its neighbours' line
    bpy.data.objects.remove(source)
    seam, speed = extended_walk(addon, obj, 90)
    print(kind, f"extend: seam {seam:.2f}, speed {speed:.2f}")
    assert seam < 1.5 and 0.6 < speed < 1.6


def test_motion_on_twos_moves_onto_another_rig_on_twos(addon, tmp_path):
    """A source keyed on twos with Constant interpolation: the target is keyed on the same frames, Constant, so it
    holds each pose two frames as the source does (the feet locked on the keys, at their rate)."""
    from scenes import fcurves_of, on_steps

    source = import_bvh(walk_bvh(tmp_path, frames=91))
    on_steps(source, 2)  # keys on 1, 3, ..., 91
    source.location.x = -2.0
    target = build_armature("Mixamo", mixamo_bones())
    for other in bpy.context.view_layer.objects:
        other.select_set(other in (source, target))
    bpy.context.view_layer.objects.active = target
    assert bpy.ops.strnn.transfer_motion() == {"FINISHED"}
    new = action_of(target)
    assert new["strnn"]["key_step"] == 2
    for fc in fcurves_of(target, new):
        assert {int(p.co[0]) % 2 for p in fc.keyframe_points} == {1}, fc.data_path
        assert {p.interpolation for p in fc.keyframe_points} == {"CONSTANT"}, fc.data_path
    pos = evaluated_joints(addon, target, np.arange(1, 92))
    moved = np.linalg.norm(np.diff(pos, axis=0), axis=-1).mean(-1)
    assert moved[0::2].max() < 1e-6 and moved[1::2].min() > 1e-3  # held onto each even frame, moving onto each key


def test_motion_moved_onto_a_rig_over_a_ramp_goes_up_it(addon, tmp_path):
    """Transfer Motion with Ground: a walk moved onto a rig standing at the foot of a ramp (rising 15 cm a metre
    the way the walk goes) is carried up it, the hips as high over the ramp all the way as the same transfer's over
    the floor (within 5 cm), the lowest foot each second as near it (within 2 cm), the feet locked on it."""
    from model_core.motion.conventions import CONTACT_JOINTS, zup_to_yup

    target = build_armature("Mixamo", mixamo_bones())
    source = import_bvh(walk_bvh(tmp_path, frames=120), update_scene_fps=True, update_scene_duration=True)
    source.location.x = -2.0
    for other in bpy.context.view_layer.objects:
        other.select_set(other in (source, target))
    bpy.context.view_layer.objects.active = target
    got = {}
    for ground in ("", "Ramp"):
        if target.animation_data:
            target.animation_data.action = None
        for pb in target.pose.bones:
            pb.matrix_basis.identity()
        assert bpy.ops.strnn.transfer_motion(ground=ground) == {"FINISHED"}
        frames = np.arange(int(action_of(target).frame_range[0]), int(action_of(target).frame_range[1]) + 1)
        got[ground] = zup_to_yup(evaluated_joints(addon, target, frames))
        if not ground:
            flat = got[""]
            height = ramp("Ramp", flat[0, 0], flat[-1, 0] - flat[0, 0], 0.15)
    flat, over = got[""], got["Ramp"]
    fps = bpy.context.scene.render.fps

    def lowest_each_second(feet):
        low = feet.min(axis=1)
        return np.array([low[s:s + fps].min() for s in range(0, len(low) - fps + 1, fps)])

    hips = over[:, 0, 1] - height(over[:, 0])
    on_ramp = lowest_each_second(over[:, CONTACT_JOINTS, 1] - height(over[:, CONTACT_JOINTS]))
    on_floor = lowest_each_second(flat[:, CONTACT_JOINTS, 1])
    print(f"the ramp {height(over[-1, 0]):.2f} m up at the end; hips over it {hips.min():.2f} to {hips.max():.2f}, "
          f"over the floor {flat[:, 0, 1].min():.2f} to {flat[:, 0, 1].max():.2f}; lowest foot each second over the "
          f"ramp {np.round(on_ramp, 3).tolist()}, over the floor {np.round(on_floor, 3).tolist()}")
    assert height(over[-1, 0]) > 0.3 and action_of(target)["strnn"]["ground"]["object"] == "Ramp"
    assert np.abs(hips - flat[:, 0, 1]).max() < 0.05
    assert np.abs(on_ramp - on_floor).max() < 0.02


@pytest.mark.parametrize("kind", ["genesis8", "makehuman"])
def test_a_walk_moved_onto_limbs_of_bend_and_twist_bones_or_numbered_segments_lands_every_joint(addon, tmp_path, kind):
    """A Daz Genesis 8 figure (each limb a Bend and a Twist bone, the legs hanging straight down from the pelvis) and
    a MakeHuman skeleton (limbs in numbered segments) are auto-mapped, and a walk moved onto them puts every joint
    within a few millimetres of where the walk on their proportions has it: the bones between the joints turn with
    the joint above them."""
    obj = build_armature("Figure", genesis8_bones() if kind == "genesis8" else makehuman_bones())
    found = auto_map(obj)
    assert all(found.values()), found
    assert (found["l_knee"], found["r_elbow"]) == (
        ("lShin", "rForearmBend") if kind == "genesis8" else ("lowerleg01.L", "lowerarm01.R"))
    _, _, err = walk_and_its_error(addon, obj, tmp_path)
    print(kind, "transfer, mean cm per joint:", np.round(100 * err.mean(0), 2))
    assert err.mean(0).max() < 0.006 and err.max() < 0.01  # metres


MOTIVE_NAMES = {"Hips": "Hip", "Spine": "Ab", "Spine2": "Chest", "Shoulder": "Shoulder", "Arm": "UArm",
                "ForeArm": "FArm", "Hand": "Hand", "UpLeg": "Thigh", "Leg": "Shin", "Foot": "Foot", "ToeBase": "Toe"}
# Auto-Rig Pro's exported skeleton (what its Export FBX writes, and a game rig made from it): the pelvis is root.x,
# the limbs' deforming bones are the *_stretch ones.
ARP_EXPORT_NAMES = {"Hips": "root.x", "Spine": "spine_01.x", "Spine2": "spine_03.x", "Neck": "neck.x", "Head": "head.x",
                    "Shoulder": "shoulder.{s}", "Arm": "arm_stretch.{s}", "ForeArm": "forearm_stretch.{s}",
                    "Hand": "hand.{s}", "UpLeg": "thigh_stretch.{s}", "Leg": "leg_stretch.{s}", "Foot": "foot.{s}",
                    "ToeBase": "toes_01.{s}"}


# The Second Life avatar skeleton (the side glued after the word; mShoulderLeft is the upper arm, mFootLeft the ball
# of the foot) and a VRChat avatar as the Cats plugin names it ("Left leg" is the thigh, above "Left knee").
SECOND_LIFE_NAMES = {"Hips": "mPelvis", "Spine": "mTorso", "Spine2": "mChest", "Neck": "mNeck", "Head": "mHead",
                     "Shoulder": "mCollar{S}", "Arm": "mShoulder{S}", "ForeArm": "mElbow{S}", "Hand": "mWrist{S}",
                     "UpLeg": "mHip{S}", "Leg": "mKnee{S}", "Foot": "mAnkle{S}", "ToeBase": "mFoot{S}"}
CATS_NAMES = {"Spine2": "Chest", "Shoulder": "{S} shoulder", "Arm": "{S} arm", "ForeArm": "{S} elbow",
              "Hand": "{S} wrist", "UpLeg": "{S} leg", "Leg": "{S} knee", "Foot": "{S} ankle", "ToeBase": "{S} toe"}


def renamed_bones(names: dict, sides=("L", "R"), prefix: str = "") -> list[tuple]:
    """(name, parent, head, tail) of :func:`mixamo_bones` with one spine bone fewer and no fingers, each bone named
    as ``names`` says (``{s}``: the side, as ``sides`` spells it, in lower case, ``{S}`` as spelt; otherwise the side
    before the name), ``prefix`` before every name."""
    fingers = [f"{side}HandMiddle{k}" for side in ("Left", "Right") for k in (1, 2, 3, 4)]
    bones = fewer_torso_bones(("Spine1", *fingers))

    def name(n):
        if not n:
            return n
        side = next((s for s in ("Left", "Right") if n.startswith(s)), "")
        spelt = sides[("Left", "Right").index(side)] if side else ""
        word = names.get(n[len(side):], n[len(side):])
        return prefix + (word.format(s=spelt.lower(), S=spelt) if "{" in word else spelt + word)

    return [(name(n), name(p), h, t) for n, p, h, t in bones]


def affixed_bones(prefix: str, suffix: str = "") -> list[tuple]:
    """:func:`mixamo_bones` with ``prefix`` (MotionBuilder's ``Character1_``) and ``suffix`` (Maya's ``_jnt``) on
    every bone's name in place of ``mixamorig:``."""
    name = lambda n: n and prefix + n.split(":")[1] + suffix
    return [(name(n), name(p), h, t) for n, p, h, t in mixamo_bones()]


@pytest.mark.parametrize("kind", ["motive", "arp_export", "motionbuilder", "maya_jnt", "second_life", "cats"])
def test_a_rig_named_as_a_capture_system_names_it_maps_takes_a_walk_and_extends(addon, real_model, tmp_path, kind):
    """An OptiTrack Motive skeleton (LUArm, LFArm after the clavicle LShoulder, every bone after its asset:
    Skeleton_Hip), Auto-Rig Pro's exported skeleton (root.x, thigh_stretch.l), a MotionBuilder character
    (Character1_Hips, ...), a Maya rig (Hips_jnt, ...), the Second Life skeleton (mHipLeft) and a VRChat avatar named
    by Cats (Left leg, Left knee) map fully, a walk moved onto them lands every joint where
    the walk on their proportions has it, and Extend walks it on."""
    bones = {"motive": lambda: renamed_bones(MOTIVE_NAMES, prefix="Skeleton_"),
             "arp_export": lambda: renamed_bones(ARP_EXPORT_NAMES),
             "motionbuilder": lambda: affixed_bones("Character1_"),
             "maya_jnt": lambda: affixed_bones("", "_jnt"),
             "second_life": lambda: renamed_bones(SECOND_LIFE_NAMES, sides=("Left", "Right")),
             "cats": lambda: renamed_bones(CATS_NAMES, sides=("Left", "Right"))}[kind]()
    obj = build_armature("Capture", bones)
    found = auto_map(obj)
    assert all(found.values()), found
    want = {"motive": {"hips": "Skeleton_Hip", "spine": "Skeleton_Ab", "l_arm": "Skeleton_LUArm",
                       "r_elbow": "Skeleton_RFArm", "l_knee": "Skeleton_LShin"},
            "motionbuilder": {"hips": "Character1_Hips", "spine1": "Character1_Spine2", "l_arm": "Character1_LeftArm",
                              "r_fingertip": "Character1_RightHandMiddle4"},
            "maya_jnt": {"hips": "Hips_jnt", "l_upleg": "LeftUpLeg_jnt", "r_wrist": "RightHand_jnt"},
            "second_life": {"hips": "mPelvis", "spine": "mTorso", "l_upleg": "mHipLeft", "r_knee": "mKneeRight",
                            "l_foot": "mAnkleLeft", "r_toe": "mFootRight", "l_arm": "mShoulderLeft",
                            "r_wrist": "mWristRight"},
            "cats": {"l_upleg": "Left leg", "l_knee": "Left knee", "r_upleg": "Right leg", "r_knee": "Right knee",
                     "l_foot": "Left ankle", "r_toe": "Right toe", "l_arm": "Left arm", "r_elbow": "Right elbow"},
            "arp_export": {"hips": "root.x", "spine": "spine_01.x", "l_upleg": "thigh_stretch.l",
                           "r_knee": "leg_stretch.r", "l_arm": "arm_stretch.l", "r_elbow": "forearm_stretch.r"}}[kind]
    assert {j: found[j] for j in want} == want
    source, _, err = walk_and_its_error(addon, obj, tmp_path)
    print(kind, "transfer, mean cm per joint:", np.round(100 * err.mean(0), 2))
    assert err.mean(0).max() < 0.006 and err.max() < 0.015  # metres
    bpy.data.objects.remove(source)
    seam, speed = extended_walk(addon, obj, 60)
    print(kind, f"extend: seam {seam:.2f}, speed {speed:.2f}")
    assert seam < 1.5 and 0.6 < speed < 1.6


UNREAL_NAMES = {"Hips": "pelvis", "Spine": "spine_01", "Spine1": "spine_02", "Spine2": "spine_03", "Neck": "neck_01",
                "Head": "head", "Shoulder": "clavicle", "Arm": "upperarm", "ForeArm": "lowerarm", "Hand": "hand",
                "HandMiddle1": "middle_01", "HandMiddle2": "middle_02", "HandMiddle3": "middle_03", "UpLeg": "thigh",
                "Leg": "calf", "Foot": "foot", "ToeBase": "ball"}


def fingered_bones(naming: str, across: bool, fingers: bool = True, toes: bool = True) -> list[tuple]:
    """:func:`mixamo_bones` without the finger tips' bones (LeftHandMiddle4), named as Unreal names them (``unreal``:
    middle_01_l to middle_03_l) or as Mixamo does (``mixamo``); with ``across``, every bone's tail points across the
    bone, as an FBX from Maya or Unreal comes in without Automatic Bone Orientation."""
    out = []
    for n, p, h, t in mixamo_bones():
        if n.endswith("HandMiddle4") or (not fingers and "HandMiddle" in n) or (not toes and "ToeBase" in n):
            continue

        def name(x):
            if not x or naming == "mixamo":
                return x
            x = x.split(":")[1]
            side = next((s for s in ("Left", "Right") if x.startswith(s)), "")
            return UNREAL_NAMES[x[len(side):]] + (f"_{side[0].lower()}" if side else "")

        h, t = np.asarray(h, float), np.asarray(t, float)
        if across:
            d = t - h
            side = np.cross(d, (0.0, 0.0, 1.0) if abs(d[2]) < 0.9 * np.linalg.norm(d) else (1.0, 0.0, 0.0))
            t = h + side / np.linalg.norm(side) * np.linalg.norm(d)
        out.append((name(n), name(p), tuple(h), tuple(t)))
    return out


@pytest.mark.parametrize("naming", ["unreal", "mixamo"])
def test_a_rig_whose_bones_point_across_themselves_plays_its_hands_as_one_whose_bones_point_along(addon, tmp_path,
                                                                                                   naming):
    """An FBX from Maya or Unreal imported without Automatic Bone Orientation can point each bone's tail across the
    bone. A finger tip read at a tail (the hand's, for Unreal's middle_01_l to middle_03_l; the last finger bone's,
    for Mixamo's names without LeftHandMiddle4) turned each hand a quarter turn under a walk moved onto the rig; now
    the finger tip is the middle finger's last head (Mixamo's tail where it continues the finger), and the fingers
    point as they do on the same rig with its tails along its bones."""
    fingers = {"unreal": ("hand_{s}", "middle_01_{s}"), "mixamo": ("mixamorig:{S}Hand", "mixamorig:{S}HandMiddle1")}
    played = {}
    for across in (False, True):
        for o in list(bpy.data.objects):
            bpy.data.objects.remove(o)
        obj = build_armature("Character", fingered_bones(naming, across))
        found = auto_map(obj)
        assert found["l_fingertip"] == ("middle_03_l" if naming == "unreal" else "mixamorig:LeftHandMiddle3")
        # a tail along its bone is where the finger ends, and is kept
        assert obj.strnn_map.l_fingertip_tail == (naming == "mixamo" and not across)
        _, frames = walk_onto(obj, tmp_path)
        scene, out = bpy.context.scene, []
        for f in frames[::10]:
            scene.frame_set(int(f))
            out.append([[np.array(obj.matrix_world @ obj.pose.bones[b.format(s=s, S=S)].head) for b in fingers[naming]]
                        for s, S in (("l", "Left"), ("r", "Right"))])
        played[across] = np.array(out)  # [F, side, (hand, finger), 3]
    along, across = (played[k][:, :, 1] - played[k][:, :, 0] for k in (False, True))
    cos = (along * across).sum(-1) / np.linalg.norm(along, axis=-1) / np.linalg.norm(across, axis=-1)
    assert np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).max() < 1.0


def hand_angles(joints: np.ndarray) -> np.ndarray:
    """Each hand's angle (degrees) from its forearm's line ``[2, F]`` (left, right) in canonical joints ``[F, 21, 3]``:
    a finger tip read across the hand turns it a quarter turn."""
    out = []
    for s in "lr":
        fore = joints[:, JOINT_INDEX[f"{s}_wrist"]] - joints[:, JOINT_INDEX[f"{s}_elbow"]]
        hand = joints[:, JOINT_INDEX[f"{s}_fingertip"]] - joints[:, JOINT_INDEX[f"{s}_wrist"]]
        cos = (fore * hand).sum(-1) / np.linalg.norm(fore, axis=-1) / np.linalg.norm(hand, axis=-1)
        out.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    return np.array(out)


def game_rig_mapped(capfd, across: bool, **parts):
    """The only object in the scene an Unreal-named rig of :func:`fingered_bones` (``across``, ``parts``), auto-mapped:
    (the rig, its map, what Auto-Map said)."""
    for o in list(bpy.data.objects):
        bpy.data.objects.remove(o)
    obj = build_armature("Game", fingered_bones("unreal", across, **parts))
    capfd.readouterr()
    found = auto_map(obj)
    return obj, found, capfd.readouterr().out


def test_a_hand_with_no_finger_bone_whose_tail_points_across_it_takes_its_finger_tip_along_the_forearm(
        addon, tmp_path, capfd):
    """With no finger bone, nothing on such a rig marks where the fingers go: the finger tip is taken along the
    forearm, as a BVH file's is estimated (Auto-Map says so), and a walk moved onto the rig turns its hands from the
    forearms as the same rig with its tails along its bones does (it was a quarter turn)."""
    played = {}
    for across in (False, True):
        obj, found, out = game_rig_mapped(capfd, across, fingers=False)
        assert found["l_fingertip"] == "hand_l" and obj.strnn_map.l_fingertip_tail
        said = "its hands have no finger bone and their tails point across them, so the finger tips are taken" in out
        assert said == across, out
        _, frames = walk_onto(obj, tmp_path)
        assert "bone_map" not in action_of(obj)["strnn"]
        played[across] = hand_angles(evaluated_joints(addon, obj, frames[::5]))
    assert np.abs(played[True] - played[False]).max() < 3.0 and np.median(played[True]) < 30.0


def test_a_bvh_hand_that_ends_in_a_zero_length_end_site_keeps_its_turn_on_the_rig(addon, tmp_path):
    """Blender's BVH importer stands a bone that ends in a zero-length End Site (a Bandai take's hands) straight up:
    read at that tail, a Bandai walk moved onto a Mixamo rig held every hand a quarter turn off its forearm (97 and
    80 degrees on average). Its finger tips are taken along the forearm, as the file's reading estimates them: the
    rig's hands turn from the forearms as the take's do, within 3 degrees."""
    from model_core.rig.rigs import load_clip

    take = "bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh"
    mocap = find_mocap()
    if mocap is None or not (mocap / take).exists():
        pytest.skip("motion capture not unpacked (data/mocap or ../shared/mocap)")
    obj = build_armature("Hero", mixamo_bones())
    source, frames = walk_onto(obj, tmp_path)
    want = np.median(hand_angles(load_clip(mocap / take)), axis=1)
    for got in (hand_angles(evaluated_joints(addon, source, frames[::5])),
                hand_angles(evaluated_joints(addon, obj, frames[::5]))):
        assert np.abs(np.median(got, axis=1) - want).max() < 3.0, (np.median(got, axis=1), want)


def toe_ways(addon, obj, bones: list[tuple], frames) -> np.ndarray:
    """Each foot's way from its ankle to where its toes are at rest, carried by the foot bone as played at ``frames``:
    ``[2, F, 3]`` unit (left, right). Where the toes are is the foot's tail in the rig built with its tails along its
    bones (``bones``' ``foot_l`` of :func:`fingered_bones` with ``across`` off), so a foot turned on its bone's axis
    shows, whatever tail the rig has."""
    rig_io = addon_module(addon, "strnn_addon.scene.rig_io")
    pipeline = addon_module(addon, "strnn_addon.scene.pipeline")
    rig = pipeline.prepare_any(bpy.context, obj).rig
    pose, _ = rig_io.pose_matrices_evaluated(bpy.context, obj, rig, np.asarray(frames, dtype=np.float64))
    out = []
    for s in "lr":
        b = rig.names.index(f"foot_{s}")
        toe = np.r_[next(t for n, _, _, t in bones if n == f"foot_{s}"), 1.0]
        carried = pose[:, b] @ np.linalg.inv(rig.rest[b]) @ toe
        way = carried[:, :3] - pose[:, b, :3, 3]
        out.append(way / np.linalg.norm(way, axis=-1, keepdims=True))
    return np.array(out)


def test_a_foot_with_no_toe_bone_whose_tail_points_across_it_takes_its_toe_forward_of_the_ankle(addon, tmp_path,
                                                                                                capfd):
    """With no toe bone, nothing on such a foot marks where the toes are: the toe is placed forward of the ankle, the
    way the body faces (Auto-Map says so), and a walk moved onto the rig and extended turns its feet as the same rig
    with its tails along its bones does (read at the tail, the foot turned a quarter turn about the shin). A foot
    whose tail points along it, forward, is read at its tail as it is: 70 degrees off the shin's line, it used to be
    named as across."""
    ways = {}
    along = fingered_bones("unreal", False, toes=False)
    for across in (False, True):
        obj, found, out = game_rig_mapped(capfd, across, toes=False)
        assert found["l_toe"] == "foot_l" and obj.strnn_map.l_toe_tail
        said = "its feet have no toe bone and their tails point across them, so the toes are placed forward" in out
        assert said == across and "tail that points across the bone" not in out, out
        source, frames = walk_onto(obj, tmp_path)
        assert "bone_map" not in action_of(obj)["strnn"]
        bpy.data.objects.remove(source)
        last = int(frames[-1])
        obj.select_set(True)
        bpy.context.view_layer.objects.active = obj
        assert bpy.ops.strnn.extend_clip(frames=30) == {"FINISHED"}
        assert "bone_map" not in action_of(obj)["strnn"]
        ways[across] = toe_ways(addon, obj, along, np.arange(int(frames[0]), last + 31, 3))
    apart = np.degrees(np.arccos(np.clip((ways[True] * ways[False]).sum(-1), -1.0, 1.0)))
    print("feet apart, degrees: mean", apart.mean(1).round(2), "max", apart.max(1).round(2))
    assert apart.max() < 5.0
