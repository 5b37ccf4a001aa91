"""Small scenes built in code: a BVH file of a walking body, Mixamo- and Rigify-named armatures."""

from __future__ import annotations

import os
from pathlib import Path

import bpy
import numpy as np

from model_core.io.bvh_export import write_bvh
from model_core.motion.synthetic import walking_skeleton

REPO = Path(__file__).resolve().parents[2]


def release_folder() -> Path | None:
    """$STRNN_TEST_MODEL, the bundled model, or any trained release under runs/ (None: no model yet)."""
    if os.environ.get("STRNN_TEST_MODEL"):
        return Path(os.environ["STRNN_TEST_MODEL"])
    bundled = REPO / "models" / "strnn_default"
    if (bundled / "model.json").exists():
        return bundled
    found = sorted(REPO.glob("runs/*/release/model.json"))
    return found[0].parent if found else None


def find_mocap() -> Path | None:
    """Unpacked motion capture ($STRNN_MOCAP_DIR alone when set, else git-ignored data/mocap or
    ../shared/mocap), None when absent."""
    roots = [Path(os.environ["STRNN_MOCAP_DIR"])] if os.environ.get("STRNN_MOCAP_DIR") else \
        [REPO / "data" / "mocap", REPO.parent / "shared" / "mocap"]
    for root in roots:
        if any(root.glob("*/*/*.bvh")) or any(root.glob("*/*/*/*.bvh")):
            return root
    return None


def walk_bvh(folder: Path, frames: int = 90, fps: float = 30.0) -> Path:
    """Write a procedural walk as a BVH file (Mixamo joint names, metres, Y-up)."""
    return write_bvh(folder / "walk.bvh", walking_skeleton(frames, fps=fps), fps=fps)


def import_bvh(path: Path, **kw):
    """Import with Blender's own BVH importer; returns the new armature object."""
    assert bpy.ops.import_anim.bvh(filepath=str(path), **kw) == {"FINISHED"}
    return bpy.context.active_object


def action_of(obj):
    return obj.animation_data.action if obj.animation_data else None


def fcurves_of(obj, action=None):
    """F-curves of ``action`` (default: the active one) on ``obj``'s slot, any Blender version."""
    action = action or action_of(obj)
    if not hasattr(action, "slots"):
        return list(action.fcurves)
    from bpy_extras import anim_utils

    slot = obj.animation_data.action_slot if obj.animation_data.action == action else action.slots[0]
    bag = anim_utils.action_get_channelbag_for_slot(action, slot)
    return list(bag.fcurves) if bag else []


def key_snapshot(obj, action=None) -> dict:
    """{(data_path, index): keyframe co array} of an action, for 'nothing changed' checks."""
    out = {}
    for fc in fcurves_of(obj, action):
        co = np.empty(2 * len(fc.keyframe_points), dtype=np.float32)
        fc.keyframe_points.foreach_get("co", co)
        out[(fc.data_path, fc.array_index)] = co
    return out


def same_keys(a: dict, b: dict) -> bool:
    """The same F-curves with the same keys (a NaN key equals a NaN key)."""
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k], equal_nan=True) for k in a)


def _rest_joints() -> dict[str, np.ndarray]:
    """Canonical joint rest positions, Blender axes (Z up, facing -Y, left = +X), metres."""
    from model_core.motion.conventions import JOINTS, PARENT_NAMES, yup_to_zup
    from model_core.motion.synthetic import rest_offset

    pos: dict[str, np.ndarray] = {}
    for joint in JOINTS:
        parent = PARENT_NAMES[joint]
        base = pos[parent] if parent else np.array([0.0, 0.95, 0.0])
        pos[joint] = base + rest_offset(joint)
    return {j: yup_to_zup(p) for j, p in pos.items()}


def _mid(a, b, t=0.5):
    return a + (b - a) * t


def mixamo_bones() -> list[tuple]:
    """(name, parent, head, tail) of a Mixamo-style skeleton (``mixamorig:`` names)."""
    j = _rest_joints()
    up, fwd = np.array([0, 0, 0.1]), np.array([0, -0.06, 0])
    chest = _mid(j["spine"], j["spine1"])
    bones = [("Hips", None, j["hips"], j["spine"]), ("Spine", "Hips", j["spine"], chest),
             ("Spine1", "Spine", chest, j["spine1"]), ("Spine2", "Spine1", j["spine1"], j["neck"]),
             ("Neck", "Spine2", j["neck"], j["head"]), ("Head", "Neck", j["head"], j["head"] + up * 2)]
    for s, side in (("l", "Left"), ("r", "Right")):
        hand = [j[f"{s}_wrist"], *(_mid(j[f"{s}_wrist"], j[f"{s}_fingertip"], t) for t in (0.45, 0.65, 0.85)),
                j[f"{s}_fingertip"]]
        bones += [(f"{side}Shoulder", "Spine2", _mid(j["neck"], j[f"{s}_arm"], 0.3) - up, j[f"{s}_arm"]),
                  (f"{side}Arm", f"{side}Shoulder", j[f"{s}_arm"], j[f"{s}_elbow"]),
                  (f"{side}ForeArm", f"{side}Arm", j[f"{s}_elbow"], j[f"{s}_wrist"]),
                  (f"{side}Hand", f"{side}ForeArm", hand[0], hand[1])]
        parents = [f"{side}Hand"] + [f"{side}HandMiddle{k}" for k in (1, 2)]
        bones += [(f"{side}HandMiddle{k}", parents[k - 1], hand[k], hand[k + 1]) for k in (1, 2, 3)]
        bones += [(f"{side}HandMiddle4", f"{side}HandMiddle3", hand[4], hand[4] - up * 0.2),
                  (f"{side}UpLeg", "Hips", j[f"{s}_upleg"], j[f"{s}_knee"]),
                  (f"{side}Leg", f"{side}UpLeg", j[f"{s}_knee"], j[f"{s}_foot"]),
                  (f"{side}Foot", f"{side}Leg", j[f"{s}_foot"], j[f"{s}_toe"]),
                  (f"{side}ToeBase", f"{side}Foot", j[f"{s}_toe"], j[f"{s}_toe"] + fwd)]
    return [("mixamorig:" + n, p and "mixamorig:" + p, h, t) for n, p, h, t in bones]


def fewer_torso_bones(drop: tuple[str, ...]) -> list[tuple]:
    """:func:`mixamo_bones` without the torso bones ``drop`` (``Spine1``, ``Spine2``: one spine bone; ``Neck``: the
    head on the chest), plain names: each remaining bone's tail reaches the next one's head, and what hung from a
    dropped bone hangs from the bone below it, as in game rigs with a minimal humanoid torso."""
    bones = [(n.split(":")[1], p and p.split(":")[1], h, t) for n, p, h, t in mixamo_bones()]
    kept = {n: (p, h, t) for n, p, h, t in bones if n not in drop}
    heads = {n: h for n, _, h, _ in bones}
    torso = [n for n in ("Hips", "Spine", "Spine1", "Spine2", "Neck", "Head") if n in kept]
    out = []
    for n, (p, h, t) in kept.items():
        while p in drop:
            p = next(q for m, q, _, _ in bones if m == p)
        if n in torso[:-1]:
            t = heads[torso[torso.index(n) + 1]]
        out.append((n, p, h, t))
    return out


R15_NAMES = {"Hips": "LowerTorso", "Spine": "UpperTorso", "UpLeg": "UpperLeg", "Leg": "LowerLeg", "ForeArm": "LowerArm",
             "Arm": "UpperArm"}


def roblox_r15_bones() -> list[tuple]:
    """(name, parent, head, tail) of a Roblox R15-style skeleton: LowerTorso, UpperTorso and Head (no neck), arms
    straight from the upper torso, no toes or fingers (the Mixamo proportions of :func:`mixamo_bones`)."""
    extra = [f"{side}{part}" for side in ("Left", "Right") for part in
             ("Shoulder", "ToeBase", "HandMiddle1", "HandMiddle2", "HandMiddle3", "HandMiddle4")]
    bones = fewer_torso_bones(("Spine1", "Spine2", "Neck", *extra))

    def name(n):
        if not n:
            return n
        side = next((s for s in ("Left", "Right") if n.startswith(s)), "")
        return side + R15_NAMES.get(n[len(side):], n[len(side):])

    return [(name(n), name(p), h, t) for n, p, h, t in bones]


def rigify_bones() -> list[tuple]:
    """(name, parent, head, tail) of Rigify-style deform bones (``DEF-`` names, split limbs)."""
    j = _rest_joints()
    up, fwd = np.array([0, 0, 0.1]), np.array([0, -0.06, 0])
    spine = [j["hips"], j["spine"], _mid(j["spine"], j["spine1"]), j["spine1"], j["neck"], _mid(j["neck"], j["head"]),
             j["head"], j["head"] + up * 2]
    bones = [("root", None, np.zeros(3), fwd * 3)]
    names = ["DEF-spine"] + [f"DEF-spine.{k:03d}" for k in range(1, 7)]
    bones += [(names[k], "root" if k == 0 else names[k - 1], spine[k], spine[k + 1]) for k in range(7)]
    def split(name, parent, a, b, S):
        """A limb bone in two halves, like Rigify's twist segments."""
        return [(f"DEF-{name}.{S}", parent, a, _mid(a, b)), (f"DEF-{name}.{S}.001", f"DEF-{name}.{S}", _mid(a, b), b)]

    for s, S in (("l", "L"), ("r", "R")):
        bones += [(f"DEF-shoulder.{S}", "DEF-spine.003", _mid(j["neck"], j[f"{s}_arm"], 0.3) - up, j[f"{s}_arm"])]
        bones += split("upper_arm", f"DEF-shoulder.{S}", j[f"{s}_arm"], j[f"{s}_elbow"], S)
        bones += split("forearm", f"DEF-upper_arm.{S}.001", j[f"{s}_elbow"], j[f"{s}_wrist"], S)
        hand = [_mid(j[f"{s}_wrist"], j[f"{s}_fingertip"], t) for t in (0.0, 0.45, 0.65, 0.85, 1.0)]
        bones += [(f"DEF-hand.{S}", f"DEF-forearm.{S}.001", hand[0], hand[1])]
        parents = [f"DEF-hand.{S}", f"DEF-f_middle.01.{S}", f"DEF-f_middle.02.{S}"]
        bones += [(f"DEF-f_middle.0{k}.{S}", parents[k - 1], hand[k], hand[k + 1]) for k in (1, 2, 3)]
        bones += split("thigh", "DEF-spine", j[f"{s}_upleg"], j[f"{s}_knee"], S)
        bones += split("shin", f"DEF-thigh.{S}.001", j[f"{s}_knee"], j[f"{s}_foot"], S)
        bones += [(f"DEF-foot.{S}", f"DEF-shin.{S}.001", j[f"{s}_foot"], j[f"{s}_toe"]),
                  (f"DEF-toe.{S}", f"DEF-foot.{S}", j[f"{s}_toe"], j[f"{s}_toe"] + fwd)]
    return bones


def makehuman_bones() -> list[tuple]:
    """(name, parent, head, tail) of a MakeHuman / MPFB default skeleton: ``root``, ``spine05`` up to
    ``spine01``, ``neck01..03``, limbs in numbered segments (``upperleg01.L``, ``upperleg02.L``, ...),
    ``pelvis.L`` from the root to each leg, ``toe1-1.L``."""
    j = _rest_joints()
    up, fwd = np.array([0, 0, 0.1]), np.array([0, -0.06, 0])
    spine = [_mid(j["spine"], j["spine1"], t) for t in (0.0, 0.25, 0.5, 0.75, 1.0)] + [j["neck"]]
    names = ["spine05", "spine04", "spine03", "spine02", "spine01"]
    bones = [("root", None, j["hips"], j["spine"])]
    bones += [(names[k], "root" if k == 0 else names[k - 1], spine[k], spine[k + 1]) for k in range(5)]
    neck = [_mid(j["neck"], j["head"], t) for t in (0.0, 1 / 3, 2 / 3, 1.0)]
    bones += [(f"neck0{k + 1}", "spine01" if k == 0 else f"neck0{k}", neck[k], neck[k + 1]) for k in range(3)]
    bones += [("head", "neck03", j["head"], j["head"] + up * 2)]

    def segments(name, parent, a, b, S):
        return [(f"{name}01.{S}", parent, a, _mid(a, b)), (f"{name}02.{S}", f"{name}01.{S}", _mid(a, b), b)]

    for s, S in (("l", "L"), ("r", "R")):
        arm = j[f"{s}_arm"]
        bones += [(f"clavicle.{S}", "spine01", _mid(j["neck"], arm, 0.3) - up, _mid(j["neck"], arm, 0.9)),
                  (f"shoulder01.{S}", f"clavicle.{S}", _mid(j["neck"], arm, 0.9), arm)]
        bones += segments("upperarm", f"shoulder01.{S}", arm, j[f"{s}_elbow"], S)
        bones += segments("lowerarm", f"upperarm02.{S}", j[f"{s}_elbow"], j[f"{s}_wrist"], S)
        hand = [_mid(j[f"{s}_wrist"], j[f"{s}_fingertip"], t) for t in (0.0, 0.45, 0.65, 0.85, 1.0)]
        bones += [(f"wrist.{S}", f"lowerarm02.{S}", hand[0], hand[1])]
        bones += [(f"finger3-{k}.{S}", f"wrist.{S}" if k == 1 else f"finger3-{k - 1}.{S}", hand[k], hand[k + 1])
                  for k in (1, 2, 3)]
        bones += [(f"pelvis.{S}", "root", j["hips"], j[f"{s}_upleg"])]
        bones += segments("upperleg", f"pelvis.{S}", j[f"{s}_upleg"], j[f"{s}_knee"], S)
        bones += segments("lowerleg", f"upperleg02.{S}", j[f"{s}_knee"], j[f"{s}_foot"], S)
        bones += [(f"foot.{S}", f"lowerleg02.{S}", j[f"{s}_foot"], j[f"{s}_toe"]),
                  (f"toe1-1.{S}", f"foot.{S}", j[f"{s}_toe"], j[f"{s}_toe"] + fwd),
                  (f"toe3-1.{S}", f"foot.{S}", j[f"{s}_toe"] + np.array([0.03 if s == "l" else -0.03, 0, 0]),
                   j[f"{s}_toe"] + fwd)]
    return bones


def genesis8_bones() -> list[tuple]:
    """(name, parent, head, tail) of a Daz Genesis 8 figure as Diffeo imports it: ``hip`` with ``pelvis`` (the legs)
    and ``abdomenLower`` (the spine) hanging from it apart, two abdomen, two chest and two neck bones, and each limb
    in a Bend and a Twist bone (``lThighBend`` > ``lThighTwist`` > ``lShin``; ``lShldrBend`` > ``lShldrTwist`` >
    ``lForearmBend`` > ``lForearmTwist`` > ``lHand``), the legs straight down: long chains of bones that point along
    an axis."""
    j = _rest_joints()
    up, fwd = np.array([0, 0, 0.1]), np.array([0, -0.06, 0])
    spine = [_mid(j["spine"], j["spine1"], t) for t in (0.0, 0.5, 0.8)] + [j["spine1"], j["neck"]]
    bones = [("hip", None, j["hips"], j["spine"]), ("pelvis", "hip", j["hips"], j["hips"] - up),
             ("abdomenLower", "hip", spine[0], spine[1]), ("abdomenUpper", "abdomenLower", spine[1], spine[2]),
             ("chestLower", "abdomenUpper", spine[2], spine[3]), ("chestUpper", "chestLower", spine[3], spine[4]),
             ("neckLower", "chestUpper", j["neck"], _mid(j["neck"], j["head"])),
             ("neckUpper", "neckLower", _mid(j["neck"], j["head"]), j["head"]),
             ("head", "neckUpper", j["head"], j["head"] + up * 2)]
    for s in "lr":
        hand = [_mid(j[f"{s}_wrist"], j[f"{s}_fingertip"], t) for t in (0.0, 0.45, 0.65, 0.85, 1.0)]
        bones += [(f"{s}Collar", "chestUpper", _mid(j["neck"], j[f"{s}_arm"], 0.3) - up, j[f"{s}_arm"]),
                  (f"{s}ShldrBend", f"{s}Collar", j[f"{s}_arm"], _mid(j[f"{s}_arm"], j[f"{s}_elbow"])),
                  (f"{s}ShldrTwist", f"{s}ShldrBend", _mid(j[f"{s}_arm"], j[f"{s}_elbow"]), j[f"{s}_elbow"]),
                  (f"{s}ForearmBend", f"{s}ShldrTwist", j[f"{s}_elbow"], _mid(j[f"{s}_elbow"], j[f"{s}_wrist"])),
                  (f"{s}ForearmTwist", f"{s}ForearmBend", _mid(j[f"{s}_elbow"], j[f"{s}_wrist"]), j[f"{s}_wrist"]),
                  (f"{s}Hand", f"{s}ForearmTwist", hand[0], hand[1])]
        fingers = [f"{s}Hand"] + [f"{s}Mid{k}" for k in (1, 2, 3)]
        bones += [(fingers[k], fingers[k - 1], hand[k], hand[k + 1]) for k in (1, 2, 3)]
        bones += [(f"{s}ThighBend", "pelvis", j[f"{s}_upleg"], _mid(j[f"{s}_upleg"], j[f"{s}_knee"], 0.4)),
                  (f"{s}ThighTwist", f"{s}ThighBend", _mid(j[f"{s}_upleg"], j[f"{s}_knee"], 0.4), j[f"{s}_knee"]),
                  (f"{s}Shin", f"{s}ThighTwist", j[f"{s}_knee"], j[f"{s}_foot"]),
                  (f"{s}Foot", f"{s}Shin", j[f"{s}_foot"], j[f"{s}_toe"]),
                  (f"{s}Toe", f"{s}Foot", j[f"{s}_toe"], j[f"{s}_toe"] + fwd)]
    return bones


def unreal_bones() -> list[tuple]:
    """(name, parent, head, tail) of an Unreal Engine 5 mannequin as Blender's FBX importer brings it in: ``root`` at
    the floor, ``pelvis``, ``spine_01`` to ``spine_05``, two neck bones, twist bones beside the limbs, and the IK bones
    a game reads (``ik_foot_root`` > ``ik_foot_l``; ``ik_hand_root`` > ``ik_hand_gun`` > ``ik_hand_l``, ``ik_hand_r``),
    which hang from the root and are keyed onto the feet and hands."""
    j = _rest_joints()
    up, fwd = np.array([0, 0, 0.1]), np.array([0, -0.06, 0])
    spine = [_mid(j["spine"], j["spine1"], t) for t in (0.0, 0.25, 0.5, 0.75, 1.0)] + [j["neck"]]
    bones = [("root", None, np.zeros(3), up), ("pelvis", "root", j["hips"], j["spine"])]
    bones += [(f"spine_0{k + 1}", "pelvis" if k == 0 else f"spine_0{k}", spine[k], spine[k + 1]) for k in range(5)]
    bones += [("neck_01", "spine_05", j["neck"], _mid(j["neck"], j["head"])),
              ("neck_02", "neck_01", _mid(j["neck"], j["head"]), j["head"]),
              ("head", "neck_02", j["head"], j["head"] + up * 2),
              ("ik_foot_root", "root", np.zeros(3), up), ("ik_hand_root", "root", np.zeros(3), up),
              ("ik_hand_gun", "ik_hand_root", j["r_wrist"], j["r_fingertip"])]
    for s in "lr":
        hand = [_mid(j[f"{s}_wrist"], j[f"{s}_fingertip"], t) for t in (0.0, 0.45, 0.65, 0.85, 1.0)]
        bones += [(f"clavicle_{s}", "spine_05", _mid(j["neck"], j[f"{s}_arm"], 0.3) - up, j[f"{s}_arm"]),
                  (f"upperarm_{s}", f"clavicle_{s}", j[f"{s}_arm"], j[f"{s}_elbow"]),
                  (f"upperarm_twist_01_{s}", f"upperarm_{s}", _mid(j[f"{s}_arm"], j[f"{s}_elbow"]), j[f"{s}_elbow"]),
                  (f"lowerarm_{s}", f"upperarm_{s}", j[f"{s}_elbow"], j[f"{s}_wrist"]),
                  (f"lowerarm_twist_01_{s}", f"lowerarm_{s}", _mid(j[f"{s}_elbow"], j[f"{s}_wrist"]), j[f"{s}_wrist"]),
                  (f"hand_{s}", f"lowerarm_{s}", hand[0], hand[1]),
                  (f"middle_01_{s}", f"hand_{s}", hand[1], hand[2]),
                  (f"middle_02_{s}", f"middle_01_{s}", hand[2], hand[3]),
                  (f"middle_03_{s}", f"middle_02_{s}", hand[3], hand[4]),
                  (f"thigh_{s}", "pelvis", j[f"{s}_upleg"], j[f"{s}_knee"]),
                  (f"thigh_twist_01_{s}", f"thigh_{s}", _mid(j[f"{s}_upleg"], j[f"{s}_knee"]), j[f"{s}_knee"]),
                  (f"calf_{s}", f"thigh_{s}", j[f"{s}_knee"], j[f"{s}_foot"]),
                  (f"foot_{s}", f"calf_{s}", j[f"{s}_foot"], j[f"{s}_toe"]),
                  (f"ball_{s}", f"foot_{s}", j[f"{s}_toe"], j[f"{s}_toe"] + fwd),
                  (f"ik_foot_{s}", "ik_foot_root", j[f"{s}_foot"], j[f"{s}_toe"]),
                  (f"ik_hand_{s}", "ik_hand_gun", hand[0], hand[1])]
    return bones


def across(bones: list[tuple], unit: float = 100.0) -> list[tuple]:
    """``bones`` (name, parent, head, tail) in ``unit`` s a metre (an FBX in centimetres), each tail turned across its
    bone, as Blender's FBX importer leaves bones from Maya or Unreal without *Automatic Bone Orientation*: the bone's
    length kept, its tail a quarter turn about the vertical from where the bone points (straight ahead where it points
    up or down)."""
    out = []
    for name, parent, head, tail in bones:
        way = np.asarray(tail, np.float64) - head
        side = np.cross(way, [0.0, 0.0, 1.0])
        flat = np.linalg.norm(side) > 1e-3 * np.linalg.norm(way)
        side = side / np.linalg.norm(side) if flat else np.array([0.0, -1.0, 0.0])
        out.append((name, parent, np.asarray(head) * unit, (head + side * np.linalg.norm(way)) * unit))
    return out


def smpl_bones() -> list[tuple]:
    """(name, parent, head, tail) of an SMPL skeleton as the SMPL-X add-on and AMASS conversions name it: the ankle
    above ``L_Foot`` (the ball of the foot), the wrist above ``L_Hand`` (the knuckles), ``Spine1..3`` with the arms
    hanging from ``Spine3``."""
    j = _rest_joints()
    up, fwd = np.array([0, 0, 0.1]), np.array([0, -0.06, 0])
    spine = [_mid(j["spine"], j["spine1"], t) for t in (0.0, 0.5, 1.0)]
    bones = [("Pelvis", None, j["hips"], j["spine"]), ("Spine1", "Pelvis", spine[0], spine[1]),
             ("Spine2", "Spine1", spine[1], spine[2]), ("Spine3", "Spine2", spine[2], j["neck"]),
             ("Neck", "Spine3", j["neck"], j["head"]), ("Head", "Neck", j["head"], j["head"] + up * 2)]
    for s, S in (("l", "L"), ("r", "R")):
        knuckles = _mid(j[f"{s}_wrist"], j[f"{s}_fingertip"], 0.45)
        bones += [(f"{S}_Collar", "Spine3", _mid(j["neck"], j[f"{s}_arm"], 0.3) - up, j[f"{s}_arm"]),
                  (f"{S}_Shoulder", f"{S}_Collar", j[f"{s}_arm"], j[f"{s}_elbow"]),
                  (f"{S}_Elbow", f"{S}_Shoulder", j[f"{s}_elbow"], j[f"{s}_wrist"]),
                  (f"{S}_Wrist", f"{S}_Elbow", j[f"{s}_wrist"], knuckles),
                  (f"{S}_Hand", f"{S}_Wrist", knuckles, j[f"{s}_fingertip"]),
                  (f"{S}_Hip", "Pelvis", j[f"{s}_upleg"], j[f"{s}_knee"]),
                  (f"{S}_Knee", f"{S}_Hip", j[f"{s}_knee"], j[f"{s}_foot"]),
                  (f"{S}_Ankle", f"{S}_Knee", j[f"{s}_foot"], j[f"{s}_toe"]),
                  (f"{S}_Foot", f"{S}_Ankle", j[f"{s}_toe"], j[f"{s}_toe"] + fwd)]
    return bones


def build_armature(name: str, bones: list[tuple], rotation_mode: str = "QUATERNION"):
    """An armature object made in edit mode from (name, parent, head, tail), active and selected."""
    arm = bpy.data.armatures.new(name)
    obj = bpy.data.objects.new(name, arm)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    bpy.ops.object.mode_set(mode="EDIT")
    for bone, parent, head, tail in bones:
        eb = arm.edit_bones.new(bone)
        eb.head, eb.tail = head, tail
        if parent:
            eb.parent = arm.edit_bones[parent]
    bpy.ops.object.mode_set(mode="OBJECT")
    for pb in obj.pose.bones:
        pb.rotation_mode = rotation_mode
    return obj


def key_walk(obj, frames: int = 60, hips: str = "", legs=(), knees=(), arms=(), step: float = 0.02):
    """Key a crude walk with Blender's own ``keyframe_insert``: the hips bone moves forward
    (-Y), legs and arms swing in opposition, knees bend. Bone names in pairs (left, right)."""
    from mathutils import Euler

    for f in range(1, frames + 1):
        phase = 2 * np.pi * f / 30.0
        pose = {}
        for side, sign in ((0, 1.0), (1, -1.0)):
            if legs:
                pose[legs[side]] = Euler((0.5 * sign * np.sin(phase), 0, 0))
            if knees:
                pose[knees[side]] = Euler((0.6 * max(0.0, np.sin(phase + sign)), 0, 0))
            if arms:
                pose[arms[side]] = Euler((-0.4 * sign * np.sin(phase), 0, 0))
        for bone, euler in pose.items():
            _key_rotation(obj.pose.bones[bone], euler, f)
        pb = obj.pose.bones[hips]
        pb.location = (0.0, step * f, 0.02 * np.sin(2 * phase))  # bone space: +Y runs along the hips bone
        pb.keyframe_insert("location", frame=f)
        _key_rotation(pb, Euler((0, 0.05 * np.sin(phase), 0)), f)


def nod_head(obj, bone: str = "head", frames: int = 60) -> None:
    """Key bone ``bone`` of ``obj`` nodding (Euler angles about its X axis) over ``frames`` frames from frame 1."""
    pb = obj.pose.bones[bone]
    pb.rotation_mode = "XYZ"
    for f in range(1, frames + 1):
        pb.rotation_euler = (0.3 * np.sin(2 * np.pi * f / 40), 0.0, 0.0)
        pb.keyframe_insert("rotation_euler", frame=f)


def _key_rotation(pb, euler, frame: int) -> None:
    mode = pb.rotation_mode
    if mode == "QUATERNION":
        pb.rotation_quaternion = euler.to_quaternion()
        pb.keyframe_insert("rotation_quaternion", frame=frame)
    elif mode == "AXIS_ANGLE":
        axis, angle = euler.to_quaternion().to_axis_angle()
        pb.rotation_axis_angle = (angle, *axis)
        pb.keyframe_insert("rotation_axis_angle", frame=frame)
    else:
        pb.rotation_euler = euler.to_matrix().to_euler(mode)
        pb.keyframe_insert("rotation_euler", frame=frame)


def mixamo_walk(frames: int = 60):
    """A Mixamo-named armature (quaternions; an axis-angle and a YXZ forearm) with a keyed walk."""
    obj = build_armature("Mixamo", mixamo_bones())
    obj.pose.bones["mixamorig:LeftForeArm"].rotation_mode = "AXIS_ANGLE"
    obj.pose.bones["mixamorig:RightForeArm"].rotation_mode = "YXZ"
    n = lambda *names: tuple("mixamorig:" + x for x in names)
    key_walk(obj, frames, "mixamorig:Hips", n("LeftUpLeg", "RightUpLeg"), n("LeftLeg", "RightLeg"),
             n("LeftArm", "RightArm"))
    return obj


def rigify_walk(frames: int = 60):
    """A Rigify-style deform armature (quaternions) with a keyed walk."""
    obj = build_armature("Rigify", rigify_bones())
    key_walk(obj, frames, "DEF-spine", ("DEF-thigh.L", "DEF-thigh.R"), ("DEF-shin.L", "DEF-shin.R"),
             ("DEF-upper_arm.L", "DEF-upper_arm.R"))
    return obj


def makehuman_walk(frames: int = 60):
    """A MakeHuman / MPFB-style armature (quaternions) with a keyed walk."""
    obj = build_armature("MakeHuman", makehuman_bones())
    key_walk(obj, frames, "root", ("upperleg01.L", "upperleg01.R"), ("lowerleg01.L", "lowerleg01.R"),
             ("upperarm01.L", "upperarm01.R"))
    return obj


def smpl_walk(frames: int = 60):
    """An SMPL-named armature (quaternions) with a keyed walk."""
    obj = build_armature("SMPL", smpl_bones())
    key_walk(obj, frames, "Pelvis", ("L_Hip", "R_Hip"), ("L_Knee", "R_Knee"), ("L_Shoulder", "R_Shoulder"))
    return obj


def object_walk(frames: int = 60, step: float = 0.02):
    """:func:`mixamo_walk` whose travel is keyed on the armature object itself (as game pipelines' root motion and
    many hand-keyed shots have it), the hips bone walking in place."""
    obj = mixamo_walk(frames)
    for fc in fcurves_of(obj):
        if fc.data_path == 'pose.bones["mixamorig:Hips"].location' and fc.array_index == 1:
            for key in fc.keyframe_points:
                key.co[1] = key.handle_left[1] = key.handle_right[1] = 0.0
    for f in range(1, frames + 1):
        obj.location = (0.0, -step * f, 0.0)
        obj.keyframe_insert("location", frame=f)
    return obj


def open_rig(path, name: str = "rig"):
    """Open the .blend at ``path`` and make its armature ``name`` the active, only selected object, at frame 1."""
    bpy.ops.wm.open_mainfile(filepath=str(path))
    obj = bpy.data.objects[name]
    for other in bpy.context.view_layer.objects:
        other.select_set(other is obj)
    bpy.context.view_layer.objects.active = obj
    bpy.context.scene.frame_set(1)
    return obj


def addon_module(addon, name: str):
    """A submodule of the installed extension, e.g. ``addon_module(addon, "strnn_addon.scene.pipeline")``."""
    import importlib

    return importlib.import_module(f"{addon.__name__}.{name}")


def world_bones(obj, names: list[str], frames) -> np.ndarray:
    """World matrices ``[F, N, 4, 4]`` of pose bones ``names`` as Blender plays ``frames``."""
    out = []
    for f in frames:
        bpy.context.scene.frame_set(int(f))
        world = np.array(obj.matrix_world)
        out.append([world @ np.array(obj.pose.bones[n].matrix) for n in names])
    return np.array(out)


def skinned(obj, bones) -> None:
    """Give armature ``obj`` a skin: a small mesh it deforms, weighted to each bone of ``bones``."""
    bpy.ops.mesh.primitive_cube_add(size=0.3, location=(0, 0, 1))
    body = bpy.context.active_object
    body.modifiers.new("Armature", "ARMATURE").object = obj
    for bone in bones:
        body.vertex_groups.new(name=bone).add(range(len(body.data.vertices)), 0.1, "REPLACE")


def through_fbx(obj, path: Path, leaf_bones: bool = False):
    """Armature ``obj`` and the meshes it deforms through Blender's FBX exporter (every bone baked, the constraints
    dropped; ``leaf_bones``: its *Add Leaf Bones*) to ``path`` and its importer into an empty scene: the imported
    armature, active and alone selected."""
    meshes = [o for o in bpy.context.view_layer.objects
              if any(m.type == "ARMATURE" and m.object is obj for m in getattr(o, "modifiers", ()))]
    for other in bpy.context.view_layer.objects:
        other.select_set(other is obj or other in meshes)
    bpy.ops.export_scene.fbx(filepath=str(path), use_selection=True, add_leaf_bones=leaf_bones,
                             bake_anim_use_all_actions=False, bake_anim_use_nla_strips=False)
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.ops.import_scene.fbx(filepath=str(path))
    baked = next(o for o in bpy.data.objects if o.type == "ARMATURE")
    assert not any(len(pb.constraints) for pb in baked.pose.bones)
    for other in bpy.context.view_layer.objects:
        other.select_set(other is baked)
    bpy.context.view_layer.objects.active = baked
    return baked


def evaluated_joints(addon, obj, frames) -> np.ndarray:
    """World canonical joints ``[F, 21, 3]`` (Blender axes) as Blender evaluates them, frame by frame: the scene set
    to each frame, as playback does (not the extension's own reads); the scene's frame put back."""
    pipeline = addon_module(addon, "strnn_addon.scene.pipeline")
    solve = addon_module(addon, "model_core.rig.solve")
    clip = pipeline.prepare_any(bpy.context, obj)
    scene, keep = bpy.context.scene, bpy.context.scene.frame_current
    pose, world = [], []
    for f in np.asarray(frames, dtype=np.float64):
        scene.frame_set(int(np.floor(f)), subframe=float(f - np.floor(f)))
        pose.append([np.array(obj.pose.bones[n].matrix) for n in clip.rig.names])
        world.append(np.array(obj.matrix_world))
    scene.frame_set(keep)
    pose, world = np.array(pose), np.array(world)
    local = solve.anchor_positions(clip.rig, clip.anchors, pose)
    return np.einsum("fij,fkj->fki", world[:, :3, :3], local) + world[:, None, :3, 3]


def retargeted(addon, source, rest: np.ndarray, frames) -> np.ndarray:
    """Where ``source``'s joints at ``frames`` go on a body of the ``rest`` joints ``[1, 21, 3]`` (Blender axes), as
    Transfer Motion retargets them: ``[F, 21, 3]``."""
    transfer = addon_module(addon, "model_core.ops.transfer")
    conventions = addon_module(addon, "model_core.motion.conventions")
    src = conventions.zup_to_yup(evaluated_joints(addon, source, frames))
    return conventions.yup_to_zup(transfer.retarget(src, conventions.zup_to_yup(rest)))


def winding_path(obj):
    """A winding NURBS path (Blender's primitive, 3 times its size) added to the scene, ``obj`` then the only selected
    and the active object, as Follow Curve runs on it: the path."""
    bpy.ops.curve.primitive_nurbs_path_add()
    path = bpy.context.active_object
    path.scale = (3.0, 3.0, 3.0)
    for other in bpy.context.view_layer.objects:
        other.select_set(other is obj)
    bpy.context.view_layer.objects.active = obj
    return path


def follow_from_rest(addon, obj, frames: int):
    """``obj`` (no action: it stands as it is) walked along a winding NURBS path by Follow Curve: (the new action, its
    joints ``[F, 21, 3]``, each frame's lowest heel or toe over the floor ``obj`` stood on ``[F]``)."""
    from model_core.motion.conventions import CONTACT_JOINTS

    floor = float(evaluated_joints(addon, obj, [1])[0, CONTACT_JOINTS, 2].min())
    path = winding_path(obj)
    assert bpy.ops.strnn.follow_curve(curve=path.name, frames=frames) == {"FINISHED"}
    new = action_of(obj)
    joints = evaluated_joints(addon, obj, np.arange(int(new.frame_range[0]), int(new.frame_range[1]) + 1))
    return new, joints, joints[:, CONTACT_JOINTS, 2].min(1) - floor


def on_steps(obj, step: int, interpolation: str = "CONSTANT") -> None:
    """Key ``obj``'s action on ``step``s: keep the keys on every ``step``-th frame from the first, with
    ``interpolation`` (Constant: the stepped look of animation on twos)."""
    for fc in fcurves_of(obj):
        points = fc.keyframe_points
        first = points[0].co[0]
        for k in range(len(points) - 1, -1, -1):
            if round(points[k].co[0] - first) % step:
                points.remove(points[k])
        for p in points:
            p.interpolation = interpolation



def stairs(name: str, start: float, tread: float, rise: float, steps: int, floor: float = 0.0):
    """A flight of ``steps`` stairs ``name`` going up along Blender's +X from ``x = start`` (a floor at height
    ``floor`` before it, a landing after it, 20 units wide), and the function that gives its height under Blender
    points ``[..., 3]``."""
    verts, faces = [], []

    def quad(*corners):
        faces.append(tuple(range(len(verts), len(verts) + 4)))
        verts.extend((x, y, z + floor) for x, y, z in corners)

    quad((-10, -10, 0), (start, -10, 0), (start, 10, 0), (-10, 10, 0))
    for k in range(steps):
        near, far, low, high = start + k * tread, start + (k + 1) * tread, k * rise, (k + 1) * rise
        far = far if k < steps - 1 else start + 20.0
        quad((near, -10, low), (near, 10, low), (near, 10, high), (near, -10, high))  # the riser
        quad((near, -10, high), (far, -10, high), (far, 10, high), (near, 10, high))  # the tread
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    bpy.context.scene.collection.objects.link(bpy.data.objects.new(name, mesh))

    def height(p):
        return floor + np.clip(np.floor((np.asarray(p)[..., 0] - start) / tread) + 1, 0, steps) * rise
    return height


def ramp(name: str, start: np.ndarray, way: np.ndarray, slope: float, size: float = 20.0):
    """A square mesh ``name`` ``2 size`` across that rises ``slope`` per unit along ``way`` from ``start`` (both
    Y-up, model axes: the ground point where it is at height 0 and a horizontal direction), and the function that
    gives its height under Y-up points ``[..., 3]``."""
    from model_core.motion.conventions import yup_to_zup

    way = np.asarray(way, np.float64) / np.linalg.norm(way)
    side = np.cross(way, [0.0, 1.0, 0.0])
    start = np.asarray(start, np.float64) * np.array([1.0, 0.0, 1.0])

    def height(p):
        return slope * ((np.asarray(p) - start) @ way)

    corners = np.array([start + size * (a * way + b * side) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    corners[:, 1] = height(corners)
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(c) for c in yup_to_zup(corners)], [], [(0, 1, 2, 3)])
    bpy.context.scene.collection.objects.link(bpy.data.objects.new(name, mesh))
    return height


def switch_driver(obj, con, switch_bone: str, prop: str = "ik_fk_switch") -> None:
    """Constraint ``con``'s influence driven by the custom property ``prop`` of ``switch_bone`` (an IK/FK switch)."""
    fc = con.driver_add("influence")
    var = fc.driver.variables.new()
    var.type = "SINGLE_PROP"
    var.targets[0].id = obj
    var.targets[0].data_path = f'pose.bones["{switch_bone}"]["{prop}"]'
    fc.driver.expression = "var"


def switch_keys(obj, action, bone: str, prop: str = "ik_fk_switch") -> dict[int, float]:
    """{frame: value} of the keys ``action`` has on ``bone``'s custom property ``prop``."""
    path = f'pose.bones["{bone}"]["{prop}"]'
    fc = next(fc for fc in fcurves_of(obj, action) if fc.data_path == path)
    return {round(k.co[0]): k.co[1] for k in fc.keyframe_points}


def _local(obj, bone: str, world: np.ndarray):
    """A location in ``bone``'s rest space that moves it by ``world`` (armature space)."""
    from mathutils import Vector

    return Vector((np.array(obj.data.bones[bone].matrix_local)[:3, :3].T @ world).tolist())


def key_ik_walk(obj, frames: int, root: str, feet: tuple[str, str], arms: tuple[str, str], speed: float = 1.2,
                drop: float = 0.0) -> None:
    """Key a walk on a control rig: ``root`` forward (-Y) at ``speed`` m/s with a bob, ``drop`` metres low; each IK
    foot control of ``feet`` (left, right) planted under the hips' mid-stance for 60 % of its second-long stride,
    then carried a stride forward; the FK arm controls of ``arms`` swing."""
    from mathutils import Euler

    stride = speed  # metres a second-long stride
    for f in range(1, frames + 1):
        phase = 2 * np.pi * f / 30.0
        pb = obj.pose.bones[root]
        bob = 0.02 * speed / 1.2 * np.sin(2 * phase)
        pb.location = _local(obj, root, np.array([0.0, -speed * f / 30.0, bob - drop]))
        pb.keyframe_insert("location", frame=f)
        for k in range(2):
            t = (f / 30.0 + 0.5 * k) % 1.0  # this foot's share of its stride cycle: planted for the first 60 %
            along = np.floor(f / 30.0 + 0.5 * k) + (0.0 if t < 0.6 else (t - 0.6) / 0.4)
            lift = 0.0 if t < 0.6 else 0.06 * np.sin(np.pi * (t - 0.6) / 0.4)
            foot = obj.pose.bones[feet[k]]
            foot.location = _local(obj, foot.name, np.array([0.0, stride * (0.5 * k - 0.3 - along), lift]))
            foot.keyframe_insert("location", frame=f)
            _key_rotation(obj.pose.bones[arms[k]], Euler((0.0, 0.0, 0.4 * np.sin(phase + np.pi * k))), f)


def set_pole(obj, ik, pole: str) -> None:
    """Give IK constraint ``ik`` the pole bone ``pole``, at the pole angle (of a quarter turn's) that keeps its chain
    as it stands at rest, as a rigger sets it."""
    owner = next(pb for pb in obj.pose.bones if ik in pb.constraints.values())
    ik.pole_target, ik.pole_subtarget = obj, pole
    bones = [owner, owner.parent]
    best = None
    for angle in (-np.pi / 2, 0.0, np.pi / 2, np.pi):
        ik.pole_angle = angle
        bpy.context.view_layer.update()
        off = sum(float(np.linalg.norm(np.array(b.matrix) - np.array(b.bone.matrix_local))) for b in bones)
        if best is None or off < best[0]:
            best = (off, angle)
    ik.pole_angle = best[1]


def frames_set_until(steps, stage: str = "write") -> list[int]:
    """The scene frames Blender is set to (each ``frame_change_post``) while the operation's ``steps`` run up to
    ``stage``."""
    seen = []

    def watch(scene, depsgraph=None):
        seen.append(scene.frame_current)

    bpy.app.handlers.frame_change_post.append(watch)
    try:
        while next(steps) != stage:
            pass
    finally:
        bpy.app.handlers.frame_change_post.remove(watch)
    return seen


def first_fractions(steps, stage: str, count: int = 5) -> list[float]:
    """The first ``count`` values the operation's ``steps`` yield after ``stage``, each checked to be a fraction of
    that stage, rising, and all under half of it."""
    while next(steps) != stage:
        pass
    fractions = [next(steps) for _ in range(count)]
    assert all(isinstance(f, float) for f in fractions) and fractions == sorted(fractions), fractions
    assert 0 < fractions[0] < fractions[-1] < 0.5, fractions
    return fractions


def on_moving_parent(obj, travel: float = 3.0, frames: int = 60, linear: bool = False):
    """Parent ``obj`` to an empty ("Vehicle") keyed ``travel`` m along X over ``frames`` frames from frame 1 (a rider
    on a moving vehicle); ``linear``: at a steady pace up to its last key."""
    empty = bpy.data.objects.new("Vehicle", None)
    bpy.context.scene.collection.objects.link(empty)
    for f, x in ((1, 0.0), (frames, travel)):
        empty.location.x = x
        empty.keyframe_insert("location", index=0, frame=f)
    if linear:
        for key in fcurves_of(empty)[0].keyframe_points:
            key.interpolation = "LINEAR"
    obj.parent = empty
    return empty

