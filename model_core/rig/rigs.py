"""Name maps from known skeleton families onto the 21 canonical joints.

Each family maps a canonical joint to candidate joint names, most preferred
first. A candidate ending in ``_end`` names a BVH End Site (the reader names an
End Site ``<parent>_end``). Matching ignores case and a namespace prefix such as
``mixamorig:`` or ``Armature|``. A finger tip that no candidate provides is
estimated by extending the hand along its own rest direction.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..io.bvh import Bvh, BvhError, forward_kinematics, read_bvh, resample
from ..motion.conventions import JOINT_INDEX, JOINTS, MODEL_FPS, PARENT_NAMES, STANDARD_LEG_LENGTH, UP_AXIS
from ..motion.geometry import shortest_arc
from .names import bare_names
from .solve import HAND_TO_FOREARM


def _sided(template: dict[str, list[str]], left: tuple[str, str], right: tuple[str, str]):
    """Expand ``{side}`` placeholders: left/right keys get each side's spelling."""
    out: dict[str, list[str]] = {}
    for key, names in template.items():
        if key.startswith("{s}"):
            for side, spell in (("l", left), ("r", right)):
                out[f"{side}{key[3:]}"] = [n.format(S=spell[0], s=spell[1]) for n in names]
        else:
            out[key] = names
    return out


# MMD bone words (the model's Japanese) and the PMX format's standard English names for them.
MMD_ENGLISH = {"センター": "center", "下半身": "lower body", "上半身": "upper body", "上半身2": "upper body2",
               "上半身3": "upper body3", "首": "neck", "頭": "head", "肩": "shoulder", "腕": "arm", "ひじ": "elbow",
               "手首": "wrist", "足": "leg", "ひざ": "knee", "足首": "ankle", "足ＩＫ": "leg IK",
               "つま先ＩＫ": "toe IK"}
# How a model's MMD bones may be named: as mmd_tools renames them by default (``足.L``), with an underscore (``足_L``),
# as the model names them (``左足``), or by their standard English names (``leg_L``).
MMD_SPELLINGS = ("{w}.{S}", "{w}_{S}", "{side}{w}", "english")


def mmd_name(word: str, side: str | None, spelling: str) -> str:
    """The name of MMD bone ``word`` (Japanese: ``足``) on ``side`` (``"L"``, ``"R"`` or None for a centre bone) in
    ``spelling`` (:data:`MMD_SPELLINGS`)."""
    if spelling == "english":
        return f"{MMD_ENGLISH[word]}_{side}" if side else MMD_ENGLISH[word]
    return word if side is None else spelling.format(w=word, S=side, side="左" if side == "L" else "右")


def _mmd_family(spellings: tuple[str, ...], legs: str = "") -> dict[str, list[str]]:
    """An MMD family's candidates in ``spellings``: the hips at the lower body's tail, the toe at the ankle's (the
    ankle points at the toe's tip), the finger tip at the middle finger's last bone's tail where it is named;
    ``legs``: the legs' bones' suffix (``D``: the deform copies, ``足D``, the semi-standard toe ``足先EX`` first)."""
    torso = {"hips": [("下半身", "_end")], "spine": [("上半身", "")], "spine1": [("上半身2", "")],
             "neck": [("首", "")], "head": [("頭", "")]}
    out = {joint: [mmd_name(w, None, sp) + end for w, end in words for sp in spellings]
           for joint, words in torso.items()}
    limbs = {"upleg": [("足" + legs, "")], "knee": [("ひざ" + legs, "")], "foot": [("足首" + legs, "")],
             "toe": [("足先EX", "")] * bool(legs) + [("足首" + legs, "_end")],
             "arm": [("腕", "")], "elbow": [("ひじ", "")], "wrist": [("手首", "")]}
    for s, side in (("l", "L"), ("r", "R")):
        out.update({f"{s}_{joint}": [mmd_name(w, side, sp) + end for w, end in words for sp in spellings]
                    for joint, words in limbs.items()})
        out[f"{s}_fingertip"] = [mmd_name("中指３", side, sp) + "_end" for sp in spellings if sp != "english"]
    return out


RIG_FAMILIES: dict[str, dict[str, list[str]]] = {
    "bandai_namco": _sided({
        "hips": ["Hips"], "spine": ["Spine"], "spine1": ["Chest"], "neck": ["Neck"], "head": ["Head"],
        "{s}_upleg": ["UpperLeg_{S}"], "{s}_knee": ["LowerLeg_{S}"], "{s}_foot": ["Foot_{S}"],
        "{s}_toe": ["Toes_{S}"], "{s}_arm": ["UpperArm_{S}"], "{s}_elbow": ["LowerArm_{S}"],
        "{s}_wrist": ["Hand_{S}"], "{s}_fingertip": [],
    }, ("L", ""), ("R", "")),
    "cmu_cgspeed": _sided({
        "hips": ["Hips"], "spine": ["Spine"], "spine1": ["Spine1"], "neck": ["Neck1"], "head": ["Head"],
        "{s}_upleg": ["{S}UpLeg"], "{s}_knee": ["{S}Leg"], "{s}_foot": ["{S}Foot"],
        "{s}_toe": ["{S}ToeBase"], "{s}_arm": ["{S}Arm"], "{s}_elbow": ["{S}ForeArm"],
        "{s}_wrist": ["{S}Hand"], "{s}_fingertip": [],  # CMU finger joints are short stubs
    }, ("Left", ""), ("Right", "")),
    "cmu_bvh11": _sided({
        "hips": ["Hips"], "spine": ["Chest"], "spine1": ["Chest2"], "neck": ["Neck"], "head": ["Head"],
        "{s}_upleg": ["{S}Hip"], "{s}_knee": ["{S}Knee"], "{s}_foot": ["{S}Ankle"],
        "{s}_toe": ["{S}Toe"], "{s}_arm": ["{S}Shoulder"], "{s}_elbow": ["{S}Elbow"],
        "{s}_wrist": ["{S}Wrist"], "{s}_fingertip": [],
    }, ("Left", "L"), ("Right", "R")),
    "iclone_cc_base": _sided({
        "hips": ["CC_Base_Hip"], "spine": ["CC_Base_Waist"], "spine1": ["CC_Base_Spine02"],
        "neck": ["CC_Base_NeckTwist01"], "head": ["CC_Base_Head"],
        "{s}_upleg": ["CC_Base_{S}_Thigh"], "{s}_knee": ["CC_Base_{S}_Calf"], "{s}_foot": ["CC_Base_{S}_Foot"],
        "{s}_toe": ["CC_Base_{S}_ToeBase"], "{s}_arm": ["CC_Base_{S}_Upperarm"],
        "{s}_elbow": ["CC_Base_{S}_Forearm"], "{s}_wrist": ["CC_Base_{S}_Hand"],
        "{s}_fingertip": ["CC_Base_{S}_Mid3_end", "CC_Base_{S}_Mid3"],
    }, ("L", ""), ("R", "")),
    "acrnn": _sided({
        "hips": ["hip"], "spine": ["abdomen"], "spine1": ["chest"], "neck": ["neck"], "head": ["head"],
        "{s}_upleg": ["{S}Thigh"], "{s}_knee": ["{S}Shin"], "{s}_foot": ["{S}Foot"],
        "{s}_toe": ["{S}Foot_end"], "{s}_arm": ["{S}Shldr"], "{s}_elbow": ["{S}ForeArm"],
        "{s}_wrist": ["{S}Hand"], "{s}_fingertip": ["{S}Mid2_end", "{S}Mid2"],
    }, ("l", ""), ("r", "")),
    "mixamo": _sided({
        "hips": ["Hips"], "spine": ["Spine"], "spine1": ["Spine2", "Spine1"], "neck": ["Neck"], "head": ["Head"],
        "{s}_upleg": ["{S}UpLeg"], "{s}_knee": ["{S}Leg"], "{s}_foot": ["{S}Foot"],
        "{s}_toe": ["{S}ToeBase"], "{s}_arm": ["{S}Arm"], "{s}_elbow": ["{S}ForeArm"],
        "{s}_wrist": ["{S}Hand"],
        "{s}_fingertip": ["{S}HandMiddle4", "{S}HandMiddle3_end", "{S}HandMiddle3"],
    }, ("Left", ""), ("Right", "")),
    # Auto-Rig Pro's human rig: the body's root control ``c_root_master.x`` has its head at the pelvis (the deform
    # ``root.x`` points the other way, its head at the waist); the limbs' joints sit on the bones that blend the FK and
    # IK chains (``thigh.l``, ``leg.l``, ``arm.l``, ``forearm.l``), which follow the controls whole, where the twist
    # and stretch bones that deform each split a segment in two.
    "auto_rig_pro": _sided({
        "hips": ["c_root_master.x"], "spine": ["spine_01.x"], "spine1": ["spine_03.x", "spine_02.x"],
        "neck": ["neck.x"], "head": ["head.x"],
        "{s}_upleg": ["thigh.{S}"], "{s}_knee": ["leg.{S}"], "{s}_foot": ["foot.{S}"],
        "{s}_toe": ["toes_01.{S}"], "{s}_arm": ["arm.{S}"], "{s}_elbow": ["forearm.{S}"], "{s}_wrist": ["hand.{S}"],
        "{s}_fingertip": [],
    }, ("l", ""), ("r", "")),
    # A generated Rigify rig: its ORG bones follow the controls rigidly (model_core/rig/controls.py).
    "rigify": _sided({
        "hips": ["ORG-spine"], "spine": ["ORG-spine.001"], "spine1": ["ORG-spine.003"],
        "neck": ["ORG-spine.004"], "head": ["ORG-spine.006"],
        "{s}_upleg": ["ORG-thigh.{S}"], "{s}_knee": ["ORG-shin.{S}"], "{s}_foot": ["ORG-foot.{S}"],
        "{s}_toe": ["ORG-toe.{S}"], "{s}_arm": ["ORG-upper_arm.{S}"], "{s}_elbow": ["ORG-forearm.{S}"],
        "{s}_wrist": ["ORG-hand.{S}"], "{s}_fingertip": ["ORG-f_middle.03.{S}_end", "ORG-f_middle.03.{S}"],
    }, ("L", ""), ("R", "")),
    # Rigify's human metarig itself (animated as it is, before a rig is generated from it): bones without prefixes.
    # Read only where every body joint is found (``bonemap.WHOLE_ONLY``): its ``spine`` is a hips bone, where other
    # rigs' ``spine`` is the spine.
    "rigify_metarig": _sided({
        "hips": ["spine"], "spine": ["spine.001"], "spine1": ["spine.003"], "neck": ["spine.004"],
        "head": ["spine.006"], "{s}_upleg": ["thigh.{S}"], "{s}_knee": ["shin.{S}"], "{s}_foot": ["foot.{S}"],
        "{s}_toe": ["toe.{S}"], "{s}_arm": ["upper_arm.{S}"], "{s}_elbow": ["forearm.{S}"], "{s}_wrist": ["hand.{S}"],
        "{s}_fingertip": ["f_middle.03.{S}_end", "f_middle.03.{S}"],
    }, ("L", ""), ("R", "")),
    # MikuMikuDance models as mmd_tools imports them: Japanese names, left and right as a suffix (``足.L``, the
    # default), with an underscore (``足_L``) or as the model has them (``左足``) (:func:`mmd_name`). No bone sits at
    # the pelvis: the lower body (``下半身``) hangs from the centre and points down from the waist to it, so the hips
    # are its tail. The legs' FK bones (``足``, ``ひざ``, ``足首``) are what the IK solves and the deform bones
    # (``足D``) copy.
    "mmd": _mmd_family(("{w}.{S}", "{w}_{S}", "{side}{w}")),
    # The same named in English, as the PMX format's standard English names (``leg_L``) that mmd_tools can rename
    # the bones to: read only where every body joint is found (``bonemap.WHOLE_ONLY``), as other rigs' ``leg`` is the
    # shin.
    "mmd_english": _mmd_family(("english",)),
    # The same with the legs on their deform copies (``足D``, and the semi-standard toe ``足先EX``): a model whose
    # constraints an exporter baked (FBX, glTF), its skin on those copies, which no longer follow the legs.
    "mmd_deform": _mmd_family(("{w}.{S}", "{w}_{S}", "{side}{w}"), "D"),
    # The Second Life (and OpenSimulator) avatar skeleton, Bento's included: ``mPelvis`` > ``mTorso`` > ``mChest``,
    # ``mHipLeft`` > ``mKneeLeft`` > ``mAnkleLeft`` > ``mFootLeft`` (the ball of the foot) > ``mToeLeft``;
    # ``mCollarLeft`` > ``mShoulderLeft`` (the upper arm) > ``mElbowLeft`` > ``mWristLeft``.
    "second_life": _sided({
        "hips": ["mPelvis"], "spine": ["mTorso"], "spine1": ["mChest"], "neck": ["mNeck"], "head": ["mHead"],
        "{s}_upleg": ["mHip{S}"], "{s}_knee": ["mKnee{S}"], "{s}_foot": ["mAnkle{S}"], "{s}_toe": ["mFoot{S}"],
        "{s}_arm": ["mShoulder{S}"], "{s}_elbow": ["mElbow{S}"], "{s}_wrist": ["mWrist{S}"],
        "{s}_fingertip": ["mHandMiddle3{S}_end", "mHandMiddle3{S}"],
    }, ("Left", ""), ("Right", "")),
    "rigify_deform": _sided({
        "hips": ["DEF-spine"], "spine": ["DEF-spine.001"], "spine1": ["DEF-spine.003"],
        "neck": ["DEF-spine.004"], "head": ["DEF-spine.006"],
        "{s}_upleg": ["DEF-thigh.{S}"], "{s}_knee": ["DEF-shin.{S}"], "{s}_foot": ["DEF-foot.{S}"],
        "{s}_toe": ["DEF-toe.{S}"], "{s}_arm": ["DEF-upper_arm.{S}"], "{s}_elbow": ["DEF-forearm.{S}"],
        "{s}_wrist": ["DEF-hand.{S}"], "{s}_fingertip": ["DEF-f_middle.03.{S}_end", "DEF-f_middle.03.{S}"],
    }, ("L", ""), ("R", "")),
}


class RigError(ValueError):
    """A skeleton could not be mapped onto the canonical joints."""


@dataclass
class RigMap:
    """Which source joint feeds each canonical joint (None: estimated tip, or placed: ``between``); ``between``:
    torso joints the skeleton has none for, {joint: (joint below, joint above, share of the way)}
    (:func:`solve.placed_between`)."""

    family: str
    sources: dict[str, str | None]
    between: dict[str, tuple[str, str, float]] = field(default_factory=dict)


def normalise_name(name: str) -> str:
    """Lower-case a joint name and drop a namespace prefix (``mixamorig:``, ``Armature|``)."""
    return re.split(r"[:|]", name)[-1].lower()


def loose_name(name: str) -> str:
    """:func:`normalise_name` with ``-``, ``.`` and spaces read as ``_``: how a rig's names come back from a tool
    whose names allow none of them (USD's prim and joint names, Maya's nodes: Rigify's ``DEF-thigh.L`` is
    ``DEF_thigh_L`` after a round trip through USD or Maya)."""
    return re.sub(r"[-. ]", "_", normalise_name(name))


class NameLookup:
    """The bone of each name as a family spells it: by :func:`normalise_name`, or failing that by
    :func:`loose_name` where only one bone reads so."""

    def __init__(self, names: list[str]):
        self.exact = {normalise_name(n): n for n in names}
        loose: dict[str, list[str]] = {}
        for n in names:
            loose.setdefault(loose_name(n), []).append(n)
        self.loose = {k: v[0] for k, v in loose.items() if len(v) == 1}

    def get(self, name: str) -> str | None:
        return self.exact.get(name.lower()) or self.loose.get(loose_name(name))


def _match(family: dict[str, list[str]], names: list[str]) -> tuple[dict[str, str | None], list[str]]:
    lookup = NameLookup(names)
    found: dict[str, str | None] = {}
    missing = []
    for joint in JOINTS:
        hit = next((bone for c in family[joint] if (bone := lookup.get(c))), None)
        if hit is None and joint.endswith("fingertip"):
            found[joint] = None  # estimated from the wrist
        elif hit is None:
            missing.append(joint)
        else:
            found[joint] = hit
    return found, missing


def detect_rig(names: list[str], source: str = "skeleton", parents=None, offsets=None) -> RigMap:
    """The rig family of a skeleton from its joint names; raise :class:`RigError` listing what is missing.

    A skeleton no known family spells in full is mapped, where ``parents`` (int indices, -1 for roots) is
    given (and ``offsets``, each joint's from its parent, where End Sites may be zero-length), as the
    Blender bone map maps an armature (:func:`bonemap.auto_map`: bone words, sides, where the
    limbs meet), family ``"generic"``, if that finds every joint and each lies below its parent's in the
    hierarchy: LAFAN1's ``LeftToe``, Unreal's ``pelvis``/``thigh_l``/``ball_l``, Daz's ``lThigh``/``lToe``.
    """
    best = None
    for fam, table in RIG_FAMILIES.items():
        found, missing = _match(table, names)
        if not missing:
            if parents is not None:  # the chest where the arms meet, if that is above the family's (Xsens' Chest4)
                from .bonemap import chest_where_the_arms_meet

                mapping = {j: (b, False) for j, b in found.items() if b is not None}
                chest_where_the_arms_meet(names, [int(p) for p in parents], mapping)
                found["spine1"] = mapping["spine1"][0]
            return RigMap(fam, found)
        if best is None or len(missing) < len(best[2]):
            best = (fam, found, missing)
    fam, _, missing = best
    hierarchy = ""
    if parents is not None:
        generic, missing_generic, hierarchy = _generic(names, [int(p) for p in parents], offsets)
        if generic is not None:
            return generic
        if len(missing_generic) < len(missing):
            fam, missing = "generic", missing_generic
    bare = bare_names(names)
    if bare != names and len(set(bare)) == len(bare):  # every bone named after its character (or _jnt): read past it
        try:
            rig = detect_rig(bare, source, parents, offsets)
        except RigError:
            pass
        else:
            original = dict(zip(bare, names))
            return RigMap(rig.family, {j: None if b is None else original[b] for j, b in rig.sources.items()},
                          rig.between)
    raise RigError(
        f"{source}: unknown rig; closest family is {fam!r} but these canonical joints were not found: "
        f"{', '.join(missing) or 'none'}{hierarchy}. Known families: {', '.join(RIG_FAMILIES)}, and any "
        "skeleton whose joint names say the body part and side (Hips, LeftUpLeg, thigh_l, lShin, ...)."
    )


def _generic(names: list[str], parents: list[int], offsets=None) -> tuple[RigMap | None, list[str], str]:
    """(rig map, [], "") of a skeleton mapped by bone words and hierarchy, or (None, joints not found,
    what in the hierarchy is wrong) where that does not give a whole body. A tail at no distance from its
    bone (a zero-length End Site, as Bandai's hands have) is no joint: a finger tip is then estimated."""
    from .bonemap import auto_map, is_below, placed  # bonemap reads this module's families

    _, mapping = auto_map(names, parents)
    between = placed(mapping)
    children: dict[int, list[int]] = {}
    for i, p in enumerate(parents):
        children.setdefault(p, []).append(i)
    sources: dict[str, str | None] = {}
    missing = []
    for joint in JOINTS:
        bone, tail = mapping.get(joint, ("", False))
        if bone and tail:  # the joint at a bone's tail: its End Site, or its one child
            end = f"{bone}_end"
            kids = children.get(names.index(bone), [])
            bone = end if end in names else (names[kids[0]] if len(kids) == 1 else "")
            if bone and offsets is not None and np.linalg.norm(offsets[names.index(bone)]) < 1e-6:
                bone = ""
        if bone:
            sources[joint] = bone
        elif joint.endswith("fingertip") or joint in between:
            sources[joint] = None  # estimated from the wrist, or placed between its neighbours
        else:
            missing.append(joint)
    if missing:
        return None, missing, ""
    index = {n: i for i, n in enumerate(names)}
    for joint, parent in PARENT_NAMES.items():
        if parent is None or sources[joint] is None:
            continue
        parent = between[parent][0] if parent in between else parent
        if not is_below(parents, index[sources[joint]], index[sources[parent]]):
            return None, [], (f" (read by body part and side, {joint} -> {sources[joint]!r} is not below "
                              f"{parent} -> {sources[parent]!r} in the hierarchy)")
    return RigMap("generic", sources, between), [], ""


def leg_length(pos: np.ndarray) -> float:
    """Median hip-to-ankle length over frames and both legs. ``pos``: canonical ``[F, 21, 3]``."""
    lengths = []
    for s in ("l", "r"):
        a, b, c = (JOINT_INDEX[f"{s}_{j}"] for j in ("upleg", "knee", "foot"))
        lengths.append(np.linalg.norm(pos[:, a] - pos[:, b], axis=-1) + np.linalg.norm(pos[:, b] - pos[:, c], axis=-1))
    return float(np.median(np.concatenate(lengths)))


def canonical_positions(bvh: Bvh, rig: RigMap | None = None) -> np.ndarray:
    """Canonical joint positions ``[frames, 21, 3]`` in file units at the file's frame rate."""
    rig = rig or detect_rig(bvh.names, bvh.path, bvh.parents, bvh.offsets)
    gpos, grot = forward_kinematics(bvh)
    out = np.empty((bvh.frames, len(JOINTS), 3))
    for j, joint in enumerate(JOINTS):
        src = rig.sources[joint]
        if src is not None:
            out[:, j] = gpos[:, bvh.index(src)]
            continue
        if joint in rig.between:
            continue  # placed once its neighbours are read
        wrist = bvh.index(rig.sources[joint.replace("fingertip", "wrist")])
        rest_dir = bvh.offsets[wrist]  # rest frames align with the world, so this is the hand's axis too
        tip = rest_dir * HAND_TO_FOREARM
        out[:, j] = gpos[:, wrist] + np.einsum("fij,j->fi", grot[:, wrist], tip)
    for joint, (below, above, share) in rig.between.items():
        out[:, JOINT_INDEX[joint]] = (1.0 - share) * out[:, JOINT_INDEX[below]] + share * out[:, JOINT_INDEX[above]]
    return out


def load_clip(path: str | Path, fps: float | None = None, rate: float = MODEL_FPS) -> np.ndarray:
    """Read a BVH file as canonical motion ``float32 [frames, 21, 3]``: metres, standard
    leg length, ``rate`` frames per second (the model's), ground at y = 0.

    ``fps`` overrides a wrong header frame rate. Raises ``BvhError`` or ``RigError``.
    """
    return canonical_clip(read_bvh(path, fps=fps), rate)


def canonical_clip(bvh, rate: float = MODEL_FPS) -> np.ndarray:
    """A read BVH (:func:`read_bvh`) as :func:`load_clip` returns it, stood up where the file stands its
    body along another axis (:func:`upright_rotation`: a Z-up file)."""
    pos = canonical_positions(bvh)
    turn = upright_rotation(pos)
    if turn is not None:
        pos = pos @ turn.T
    legs = leg_length(pos)
    if not np.isfinite(legs) or legs <= 1e-6:
        raise BvhError(f"{bvh.path}: legs have zero length; cannot normalise the skeleton's scale")
    return on_ground(resample(pos * (STANDARD_LEG_LENGTH / legs), bvh.fps, rate))


# A body stands along an axis where its head is within 45 degrees of it from the feet in this share of frames.
STANDING_SHARE = 0.75


def standing_axis(pos: np.ndarray) -> np.ndarray | None:
    """The file axis (+-X, +-Y or +-Z, a unit vector) the body of canonical joints ``pos`` ``[F, 21, 3]``
    stands along: its head within 45 degrees of it from the middle of its feet in :data:`STANDING_SHARE` of
    the frames; None where no axis holds so many (a take lying down or tumbling)."""
    feet = pos[:, [JOINT_INDEX["l_foot"], JOINT_INDEX["r_foot"]]].mean(1)
    v = pos[:, JOINT_INDEX["head"]] - feet
    n = np.linalg.norm(v, axis=-1)
    v = v[n > 1e-9] / n[n > 1e-9, None]
    for axis in range(3):
        for sign in (1.0, -1.0):
            if len(v) and np.mean(sign * v[:, axis] > np.cos(np.pi / 4)) >= STANDING_SHARE:
                return np.eye(3)[axis] * sign
    return None


def axis_name(axis: np.ndarray) -> str:
    """``"X"``, ``"-Z"``, ...: the name of a unit axis (:func:`standing_axis`), as Blender's importers spell it."""
    return ("-" if axis.sum() < 0 else "") + "XYZ"[int(np.abs(axis).argmax())]


def upright_rotation(pos: np.ndarray) -> np.ndarray | None:
    """The smallest rotation ``[3, 3]`` that stands the body of ``pos`` up along +Y where it stands along another
    axis (:func:`standing_axis`; a Z-up file's +Z, a file upside down), else None."""
    axis = standing_axis(pos)
    if axis is None or axis[UP_AXIS] > 0:
        return None
    return shortest_arc(axis, np.eye(3)[UP_AXIS])


def on_ground(pos: np.ndarray) -> np.ndarray:
    """``float32`` copy of canonical joints ``[F, 21, 3]`` raised or lowered so that the lowest foot's 5th
    percentile height is 0 (the ground)."""
    pos = np.array(pos)
    feet = pos[:, [JOINT_INDEX[j] for j in ("l_foot", "l_toe", "r_foot", "r_toe")], UP_AXIS]
    pos[..., UP_AXIS] -= np.percentile(feet.min(axis=1), 5)
    return pos.astype(np.float32)
