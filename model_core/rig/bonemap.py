"""Map an armature's bones onto the 21 canonical joints (no bpy).

A mapping is ``{joint: (bone name, use_tail)}``: a canonical joint sits at a bone's
HEAD, or at its TAIL where ``use_tail`` is set (finger tips and toes a rig has no
bone for: the hand's or foot's tail; BVH End Sites, which Blender's importer turns
into the tail of the last bone). The known families of :data:`rigs.RIG_FAMILIES`
are tried first; what they leave open is filled by a generic left/right heuristic
(``.L`` / ``_L`` / ``Left`` / ``l`` prefixes and suffixes, common bone words) and by
the hierarchy (the chest is where the two arms meet, the hips where the legs meet).
A rig with one spine bone has no chest of its own, one whose head sits on its chest no neck:
those joints are left out and placed between their neighbours (:func:`solve.placed`).
"""

from __future__ import annotations

import re

import numpy as np

from ..motion.conventions import JOINTS, PARENT_NAMES
from .names import bare_names
from .rigs import RIG_FAMILIES, NameLookup, normalise_name
from .solve import ACROSS_DEG, facing_and_up, placed, points_across, toe_across

Mapping = dict[str, tuple[str, bool]]

# Bone words per canonical joint (side removed, lower case, only letters and digits), best first. Daz's
# Genesis 3 and 8 split limbs into Bend and Twist bones (lThighBend, lShldrBend): the joint is the Bend's head.
_WORDS: dict[str, tuple[str, ...]] = {
    "hips": ("hips", "hip", "pelvis"), "head": ("head",), "neck": ("neck", "neck1", "neck01"),
    "upleg": ("upleg", "upperleg", "thigh", "legupper", "thighbend", "thighstretch", "hip"),
    "knee": ("leg", "lowerleg", "shin", "calf", "knee", "leglower", "legstretch"),
    "foot": ("foot", "ankle"), "toe": ("toebase", "toe", "toes", "ball"),
    "arm": ("arm", "upperarm", "uparm", "uarm", "armupper", "shldr", "shldrbend", "armstretch", "shoulder"),
    "elbow": ("forearm", "lowerarm", "elbow", "armlower", "forearmbend", "farm", "forearmstretch"),
    "wrist": ("hand", "wrist", "fist", "palm"),
    "fingertip": ("handmiddle4", "middle4", "handmiddle3end", "middle3", "fmiddle03", "middlefinger3"),
}
_SUFFIX = re.compile(r"^(?P<base>.+?)[._\-\s](?P<side>l|r|left|right)(?:[._]\d+)?$")
_PREFIX = re.compile(r"^(?P<side>left|right|l|r)[._\-\s]?(?P<base>.+)$")
_INFIX = re.compile(r"^(?P<pre>.+?)[._\-\s](?P<side>l|r|left|right)[._\-\s](?P<base>.+)$")
# A centre marker: VRoid's ``J_Bip_C_Neck``, Auto-Rig Pro's ``neck.x``, AdvancedSkeleton's (Maya) ``Neck_M``.
_CENTRE = re.compile(r"^(?:.+?[._\-\s]c[._\-\s](?P<base>.+)|(?P<suffixed>.+?)(?:[._]x|_m))$")
# A side letter before a capital: ``lThigh``, ``LShoulder``, and OptiTrack Motive's ``LUArm`` / ``LFArm`` (upper and
# fore arm, the word after the letter itself abbreviated).
_CAMEL = re.compile(r"^(?:[^:|]*[:|])?(?P<side>[lrLR])(?=[A-Z]{1,2}[a-z])(?P<base>.+)$")
# A side word glued after a word: the Second Life skeleton's ``mHipLeft``, Avastar's ``ShoulderRight``.
_CAMEL_SUFFIX = re.compile(r"^(?:[^:|]*[:|])?(?P<base>.*[a-z0-9])(?P<side>Left|Right)$")
_LEAVES = ("fingertip", "toe")  # joints a hand's or foot's tail can stand in for
_STRIP = re.compile(r"^(def|org|mch|bip\d*|b|cc_base)[._\-\s]+")


def split_side(name: str) -> tuple[str | None, str]:
    """(``"l"``, ``"r"`` or None, base word) of a bone name: ``"thigh.L"`` -> (``"l"``, ``"thigh"``)."""
    camel, camel_suffix = _CAMEL.match(name), _CAMEL_SUFFIX.match(name)
    low = normalise_name(name)
    side, base = None, low
    for pattern in (_SUFFIX, _INFIX):
        m = pattern.match(low)
        if m:
            side, base = m["side"][0], m["base"]
            break
    else:
        m = _PREFIX.match(low)
        if m and m["side"] in ("left", "right"):
            side, base = m["side"][0], m["base"]
        elif camel:
            side, base = camel["side"].lower(), camel["base"].lower()
        elif camel_suffix:
            side, base = camel_suffix["side"][0].lower(), camel_suffix["base"].lower()
        elif m and low[1:2] in "._- ":
            side, base = m["side"], m["base"]
        else:
            centre = _CENTRE.match(low)
            base = centre["base"] or centre["suffixed"] if centre else base
    base = re.sub(r"[^a-z0-9]", "", _STRIP.sub("", base))
    return side, base


# Families read only where they find every body joint (their names mean other joints in other rigs).
WHOLE_ONLY = {"rigify_metarig", "auto_rig_pro", "mmd_english"}


def _family_map(names: list[str], prefer: set[str] | None = None) -> tuple[str, Mapping]:
    """The known family matching most joints: (family, partial mapping); a family of :data:`WHOLE_ONLY` only where
    it finds every joint but the leaves. Of families that match as many, the one with more of its bones in
    ``prefer`` (the bones that carry the skin of a baked rig: :func:`auto_map`), else the first."""
    lookup = NameLookup(names)
    best: tuple[str, Mapping] = ("", {})
    score = (0, 0)
    for family, table in RIG_FAMILIES.items():
        found: Mapping = {}
        for joint in JOINTS:
            for cand in table[joint]:
                if bone := lookup.get(cand):
                    found[joint] = (bone, False)
                    break
                if cand.lower().endswith("_end") and (bone := lookup.get(cand[:-4])):
                    found[joint] = (bone, True)
                    break
        if family in WHOLE_ONLY and any(j not in found and not j.endswith(_LEAVES) for j in JOINTS):
            continue
        this = (len(found), sum(bone in prefer for bone, _ in found.values()) if prefer else 0)
        if this > score:
            best, score = (family, found), this
    return best


def _by_words(names: list[str], mapping: Mapping) -> None:
    """Fill joints still open from bone words and sides, in place. A word matches a bone's base exactly
    first; failing that, the base with its numbering removed, words in order, then the lowest number
    (MakeHuman's and MPFB's ``upperleg01.L`` / ``upperleg02.L``: the joint is at the first segment's head)."""
    parsed = [split_side(n) for n in names]
    numbered = [(s, *_numbering(b)) for s, b in parsed]
    used = {bone for bone, _ in mapping.values()}
    for joint in JOINTS:
        if joint in mapping:
            continue
        side, key = (joint[0], joint[2:]) if joint[1] == "_" else (None, joint)
        words = _WORDS.get(key, ())
        hit = next((n for word in words for n, (s, b) in zip(names, parsed)
                    if s == side and b == word and n not in used), None)
        if hit is None:
            hits = [(w, number, n) for w, word in enumerate(words) for n, (s, b, number) in zip(names, numbered)
                    if s == side and b == word and number is not None and n not in used]
            hit = min(hits)[2] if hits else None
        if hit:
            mapping[joint] = (hit, False)
            used.add(hit)


def _leg_above_the_knee(names: list[str], parents: list[int], mapping: Mapping) -> None:
    """A knee read at a ``leg`` bone with a knee-word bone below it on the same side and no thigh found (the names
    Cats gives a VRChat avatar: ``Left leg``, ``Left knee``, ``Left ankle``, as MMD's ``leg_L``, ``knee_L``): the
    ``leg`` is the thigh and the bone below it the knee. ``leg`` alone is Mixamo's shin (``LeftUpLeg``,
    ``LeftLeg``), which no knee-word bone hangs below. In place."""
    parsed = [split_side(n) for n in names]
    idx = {n: i for i, n in enumerate(names)}
    for side in "lr":
        knee = mapping.get(f"{side}_knee")
        if f"{side}_upleg" in mapping or knee is None or knee[1] or parsed[idx[knee[0]]][1] != "leg":
            continue
        below = [i for i, (s, b) in enumerate(parsed) if s == side and b in _WORDS["knee"] and b != "leg"
                 and is_below(parents, i, idx[knee[0]])]
        if below:
            nearest = min(below, key=lambda i: len(_chain(parents, i)))
            mapping[f"{side}_upleg"], mapping[f"{side}_knee"] = knee, (names[nearest], False)


def _shoulder_segments(names: list[str], parents: list[int], mapping: Mapping) -> None:
    """An arm read at the first of numbered ``shoulder`` segments whose last holds the elbow (XPS / XNALara's
    ``arm left shoulder 1``, the clavicle, and ``arm left shoulder 2``, the upper arm) moves to that last segment:
    the word names a clavicle as often as an upper arm, and the upper arm is what the elbow hangs from. In place."""
    index = {n: i for i, n in enumerate(names)}
    for side in "lr":
        arm, elbow = mapping.get(f"{side}_arm"), mapping.get(f"{side}_elbow")
        if arm is None or elbow is None or arm[1] or elbow[1]:
            continue
        above = parents[index[elbow[0]]]
        if above < 0 or names[above] == arm[0]:
            continue
        (s1, b1), (s2, b2) = split_side(arm[0]), split_side(names[above])
        w1, w2 = _numbering(re.sub(r"[^a-z0-9]", "", b1)), _numbering(re.sub(r"[^a-z0-9]", "", b2))
        if s1 == s2 and w1[0] == w2[0] == "shoulder" and None not in (w1[1], w2[1]) and is_below(
                parents, above, index[arm[0]]):
            mapping[f"{side}_arm"] = (names[above], False)


def _numbering(base: str) -> tuple[str, int | None]:
    """(base without its trailing number, the number or None): ``"upperleg02"`` -> (``"upperleg"``, 2)."""
    m = re.match(r"^(?P<word>.*?[a-z])(?P<number>\d+)$", base)
    return (m["word"], int(m["number"])) if m else (base, None)


def _chain(parents: list[int], b: int) -> list[int]:
    """Bone ``b`` and its ancestors, nearest first."""
    out = []
    while b >= 0:
        out.append(b)
        b = parents[b]
    return out


def _common(parents: list[int], a: int, b: int) -> int:
    """Lowest common ancestor of bones ``a`` and ``b`` (-1 if none)."""
    up = set(_chain(parents, a))
    return next((x for x in _chain(parents, b) if x in up), -1)


def _by_hierarchy(names: list[str], parents: list[int], mapping: Mapping) -> None:
    """Fill hips, chest (spine1), spine and neck from where the limbs meet, in place."""
    idx = {n: i for i, n in enumerate(names)}
    have = lambda j: j in mapping and not mapping[j][1]
    if "hips" not in mapping and have("l_upleg") and have("r_upleg"):  # (hips at a tail are an MMD model's)
        c = _common(parents, idx[mapping["l_upleg"][0]], idx[mapping["r_upleg"][0]])
        if c >= 0:
            mapping["hips"] = (names[c], False)
    if not have("spine1") and have("l_arm") and have("r_arm"):
        c = _arms_meet(names, parents, mapping)
        if c >= 0:
            mapping["spine1"] = (names[c], False)
    if have("hips") and have("spine1") and not have("spine"):
        path = _chain(parents, idx[mapping["spine1"][0]])
        h = idx[mapping["hips"][0]]
        if h in path and path.index(h) >= 2:
            mapping["spine"] = (names[path[path.index(h) - 1]], False)
    if have("spine1") and have("head") and not have("neck"):
        path = _chain(parents, idx[mapping["head"][0]])
        s = idx[mapping["spine1"][0]]
        if s in path and path.index(s) >= 2:
            mapping["neck"] = (names[path[path.index(s) - 1]], False)


# Joints whose distal word some skeletons give to the next joint down: SMPL's (AMASS's) L_Ankle -> L_Foot
# (the ball of the foot) and L_Wrist -> L_Hand (the knuckles). (joint, distal words, proximal words, leaf)
_PROXIMAL = (("foot", ("foot",), ("ankle",), "toe"), ("wrist", ("hand",), ("wrist",), "fingertip"))


def is_below(parents: list[int], a: int, b: int) -> bool:
    """Whether bone ``a`` lies below bone ``b`` (``b`` a strict ancestor of ``a``)."""
    a = parents[a]
    while a >= 0 and a != b:
        a = parents[a]
    return a == b


def _proximal_first(names: list[str], parents: list[int], mapping: Mapping) -> None:
    """Where a joint took a distal word (``L_Foot``) and a bone of the proximal word (``L_Ankle``) lies above
    it on the same side, the joint is the proximal bone and the distal one is the leaf below it: the toe at its
    head (also where a toe-word bone hangs below it: the Second Life skeleton's ``AnkleLeft`` > ``FootLeft``, the
    ball of the foot, > ``ToeLeft``), the finger tip at its tail. In place."""
    parsed = [split_side(n) for n in names]
    idx = {n: i for i, n in enumerate(names)}
    for side in "lr":
        for key, distal, proximal, leaf in _PROXIMAL:
            joint = f"{side}_{key}"
            bone, tail = mapping.get(joint, ("", True))
            if tail or parsed[idx[bone]][1] not in distal:
                continue
            above = [i for i, (s, b) in enumerate(parsed) if s == side and b in proximal
                     and is_below(parents, idx[bone], i)]
            if above:
                mapping[joint] = (names[above[-1]], False)
                mapping.setdefault(f"{side}_{leaf}", (bone, leaf == "fingertip"))
                further = mapping[f"{side}_{leaf}"]
                if leaf == "toe" and not further[1] and is_below(parents, idx[further[0]], idx[bone]):
                    mapping[f"{side}_{leaf}"] = (bone, False)  # the ball of the foot, not the toe's tip below it


def _ball_of_the_foot(names: list[str], parents: list[int], mapping: Mapping) -> None:
    """Where the mapped toe has another toe-word bone above it and below the foot (Synty's ``Ankle_L``, ``Ball_L``,
    ``Toes_L``), the toe joint is the one nearest the foot: the ball of the foot, where the model's toe joint is, not
    the tips of the toes. A toe a family put at the foot's tail (a BVH End Site's name, ``lFoot_end``) is the head of
    the toe-word bone nearest below the foot where the rig has one (Daz's ``lFoot`` > ``lMetatarsals`` > ``lToe``):
    a head is where the joint is, a tail only where the bone points. In place."""
    parsed = [split_side(n) for n in names]
    idx = {n: i for i, n in enumerate(names)}
    for side in "lr":
        (toe, tail), (foot, _) = mapping.get(f"{side}_toe", ("", True)), mapping.get(f"{side}_foot", ("", True))
        if tail and foot and toe == foot:
            below = [i for i, (s, b) in enumerate(parsed) if s == side and b in _WORDS["toe"]
                     and is_below(parents, i, idx[foot])]
            if below:
                mapping[f"{side}_toe"] = (names[min(below, key=lambda i: len(_chain(parents, i)))], False)
            continue
        if tail or not foot:
            continue
        b, nearest = parents[idx[toe]], None
        while b >= 0 and b != idx[foot]:
            if parsed[b][0] == side and parsed[b][1] in _WORDS["toe"]:
                nearest = b
            b = parents[b]
        if nearest is not None and b == idx[foot]:
            mapping[f"{side}_toe"] = (names[nearest], False)


_MIDDLE_FINGER = re.compile(r"^(?:hand|finger|f)?(?:middle|mid)(?:finger)?(?:\d+|proximal|intermediate|distal)?$")


def _middle_finger_tip(names: list[str], parents: list[int], wrist: int, side: str) -> int:
    """The last bone of the middle finger below bone ``wrist`` on ``side`` (``middle_03_l``, ``LeftMiddleDistal``,
    ``lMid3``), or -1: the deepest of the bones below the wrist that a middle-finger word names."""
    best, depth = -1, 0
    for b, name in enumerate(names):
        s, base = split_side(name)
        if s != side or not _MIDDLE_FINGER.match(base):
            continue
        k, d = b, 0
        while k >= 0 and k != wrist:
            k, d = parents[k], d + 1
        if k == wrist and d > depth:
            best, depth = b, d
    return best


def _finger_tip_on_the_middle_finger(names: list[str], parents: list[int], mapping: Mapping) -> None:
    """A finger tip no word names sits at the head of the middle finger's last bone where the hand has one (Unreal's
    ``middle_03_l``, Unity's ``LeftMiddleDistal``, Daz's ``lMid3``), rather than at the hand's tail: a bone's head
    is where the joint is in any file, where its tail is only where the bone's own axis points, which an FBX from
    Maya or Unreal imported without Automatic Bone Orientation turns across the bone (the hands came out turned a
    quarter turn). In place."""
    idx = {n: i for i, n in enumerate(names)}
    for side in "lr":
        joint, wrist = f"{side}_fingertip", mapping.get(f"{side}_wrist", ("", True))
        if joint in mapping or wrist[1] or not wrist[0]:
            continue
        tip = _middle_finger_tip(names, parents, idx[wrist[0]], side)
        if tip >= 0:
            mapping[joint] = (names[tip], False)


def heads_where_tails_point_across(mapping: Mapping, names: list[str], parents: list[int], heads: np.ndarray,
                                   tails: np.ndarray, limit_deg: float = ACROSS_DEG) -> Mapping:
    """``mapping`` with each finger tip or toe that sits at a bone's tail moved where the tail does not continue the
    limb: an FBX from Maya or Unreal imported without Automatic Bone Orientation can point a bone's tail across
    it, and a tail more than ``limit_deg`` off the line from the bone's parent's head to its head is no finger tip
    or toe. The bone's own head takes its place where it is a finger's or a toe's (below the wrist or the foot), the
    middle finger's last head where the tail is the hand's; otherwise the tail stays (nothing else marks the
    tip). ``heads``, ``tails`` ``[B, 3]`` at rest, in ``names``' order."""
    out = dict(mapping)
    idx = {n: i for i, n in enumerate(names)}
    for joint in tails_across(mapping, names, parents, heads, tails, limit_deg):
        b = idx[out[joint][0]]
        parent_joint = PARENT_NAMES[joint]
        if out.get(parent_joint, ("", False))[0] != names[b]:  # the tail of a finger's or a toe's own bone
            out[joint] = (names[b], False)
        elif joint.endswith("fingertip"):
            tip = _middle_finger_tip(names, parents, b, joint[0])
            if tip >= 0:
                out[joint] = (names[tip], False)
    return out


def at_the_foot_tail(mapping: Mapping, joint: str) -> bool:
    """Whether ``joint`` is a toe ``mapping`` puts at its foot bone's own tail (a foot with no toe bone)."""
    return (joint.endswith("toe") and joint in mapping and mapping[joint][1]
            and mapping.get(PARENT_NAMES[joint], ("", True)) == (mapping[joint][0], False))


def tails_across(mapping: Mapping, names: list[str], parents: list[int], heads: np.ndarray, tails: np.ndarray,
                 limit_deg: float = ACROSS_DEG) -> list[str]:
    """The finger tips and toes of ``mapping`` at a bone's tail that points across the limb
    (:func:`heads_where_tails_point_across`): a finger tip's more than ``limit_deg`` off the line from the bone's
    parent's head to its head; a toe's at a foot's tail, off the way the body faces (:func:`solve.toe_across`;
    the shin's line where the map gives no legs, hips and head to tell it by), a toe's own bone's, off its line."""
    idx = {n: i for i, n in enumerate(names)}
    body = facing_and_up({j: (tails if tail else heads)[idx[bone]] for j, (bone, tail) in mapping.items()
                          if bone in idx})
    out = []
    for joint in JOINTS:
        if not joint.endswith(_LEAVES) or joint not in mapping or not mapping[joint][1]:
            continue
        b = idx.get(mapping[joint][0], -1)
        if b < 0 or parents[b] < 0:
            continue
        if at_the_foot_tail(mapping, joint) and body is not None:
            if toe_across(tails[b] - heads[b], body[0]):
                out.append(joint)
        elif points_across(tails[b] - heads[b], heads[b] - heads[parents[b]], limit_deg):
            out.append(joint)
    return out


def _arms_meet(names: list[str], parents: list[int], mapping: Mapping) -> int:
    """The bone where the mapped arms meet (-1 if none), or the one below it where that is the mapped neck (3ds
    Max's Biped hangs its arms from the neck)."""
    idx = {n: i for i, n in enumerate(names)}
    meet = _common(parents, idx[mapping["l_arm"][0]], idx[mapping["r_arm"][0]])
    if meet >= 0 and "neck" in mapping and names[meet] == mapping["neck"][0]:
        meet = parents[meet]
    return meet


def chest_where_the_arms_meet(names: list[str], parents: list[int], mapping: Mapping) -> None:
    """A chest a known family's names gave lower than where the two arms meet moves up to where they meet: SMPL's
    Spine2 (Mixamo's name) where its arms hang from Spine3, Xsens MVN's Chest2 (CMU's name) where they hang from
    Chest4. In place."""
    idx = {n: i for i, n in enumerate(names)}
    if "spine1" not in mapping or any(j not in mapping or mapping[j][1] for j in ("l_arm", "r_arm")):
        return
    meet = _arms_meet(names, parents, mapping)
    if meet >= 0 and is_below(parents, meet, idx[mapping["spine1"][0]]):
        mapping["spine1"] = (names[meet], False)


def auto_map(names: list[str], parents: list[int], prefer: set[str] | None = None) -> tuple[str, Mapping]:
    """Map bones (``names``, ``parents`` int indices, -1 for roots) onto the canonical joints.

    Returns (rig family or ``"generic"``, mapping); joints that could not be found are absent
    (see :func:`missing`). Finger tips and toes fall back to the hand's and foot's tail. ``prefer``: bones to map
    rather than others a family names as well (a Rigify rig baked by an exporter, its constraints gone, has its
    ``ORG-`` and its ``DEF-`` bones; its skin follows the ``DEF-`` bones alone).
    """
    family, mapping = _mapped(names, parents, prefer)
    bare = bare_names(names) if missing(mapping) else names
    if bare != names and len(set(bare)) == len(bare):
        # every bone named after its character or take (Character1_Hips), or Maya's Hips_jnt: read past that
        bare_family, bare_mapping = _mapped(bare, parents)
        if len(missing(bare_mapping)) < len(missing(mapping)):
            original = dict(zip(bare, names))
            family, mapping = bare_family, {j: (original[b], tail) for j, (b, tail) in bare_mapping.items()}
    return family, mapping


def _mapped(names: list[str], parents: list[int], prefer: set[str] | None = None) -> tuple[str, Mapping]:
    """:func:`auto_map` of the names as they are."""
    family, mapping = _family_map(names, prefer)
    if any(j not in mapping and not j.endswith(_LEAVES) for j in JOINTS):
        family = "generic"  # the family's names left body joints open
    if len(mapping) < len(JOINTS):
        _by_words(names, mapping)
        _shoulder_segments(names, parents, mapping)
        _leg_above_the_knee(names, parents, mapping)
        _proximal_first(names, parents, mapping)
        _ball_of_the_foot(names, parents, mapping)
        _finger_tip_on_the_middle_finger(names, parents, mapping)
        chest_where_the_arms_meet(names, parents, mapping)  # before the spine is read off the path below it
        _by_hierarchy(names, parents, mapping)
    chest_where_the_arms_meet(names, parents, mapping)  # a whole family's chest too
    _no_bone_of_their_own(mapping)
    for side in "lr":
        for leaf in ("fingertip", "toe"):
            joint = f"{side}_{leaf}"
            parent = PARENT_NAMES[joint]
            if joint not in mapping and parent in mapping and not mapping[parent][1]:
                mapping[joint] = (mapping[parent][0], True)
    return family, mapping


def _no_bone_of_their_own(mapping: Mapping) -> None:
    """Leave out a chest or a neck found at the same place as the joint below it (the arms of a rig with one spine
    bone meet on it, where the spine is too): :func:`solve.placed_between` places it. A chest with no spine bone
    between it and the hips (Roblox's R15: LowerTorso, UpperTorso, Head) is the one spine bone. In place."""
    if "spine" not in mapping and "hips" in mapping and "spine1" in mapping and not mapping["spine1"][1]:
        mapping["spine"] = mapping.pop("spine1")
    for joint, below in (("spine1", "spine"), ("neck", "spine1")):
        if joint in mapping and mapping.get(below) == mapping[joint]:
            del mapping[joint]


def missing(mapping: Mapping) -> list[str]:
    """Canonical joints with no bone in ``mapping`` that cannot be placed between others (:func:`solve.placed`,
    which this module also offers as ``placed``)."""
    between = placed(mapping)
    return [j for j in JOINTS if (not mapping.get(j) or not mapping[j][0]) and j not in between]
