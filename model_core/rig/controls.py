"""Control rigs (no bpy): the skeleton the solve works on, and which controls drive it.

On a rig whose deform or mechanism bones follow controls through constraints (Rigify's
generated rigs, Auto-Rig Pro-style rigs), the mapped bones do not form a plain chain:
Rigify's ``ORG-thigh.L`` hangs below ``ORG-spine`` while ``ORG-spine.001`` hangs below a
tweak bone, and keys written on them would not show, because their constraints override
them. Such a rig is read by its evaluated pose and solved on a *joint skeleton*
(:func:`joint_rig`): the mapped bones with their rest matrices, each parented to the bone of
its canonical parent joint (through the real bones in between where the rig has them, such
as a clavicle). The solved pose is then written on the controls by a visual bake (the
Blender side, ``strnn_addon/scene/controls.py``): each :class:`Control` is turned until the
bone it drives sits where the solve put it.

:data:`PRESETS` holds the control sets that ship (Rigify's, the Mixamo Rig add-on's, Auto-Rig Pro's, and MMD models'
as mmd_tools imports them): their FK controls, and for each limb animated in IK (:class:`IkLimb`) its IK controls
(an MMD model's legs, always in IK, have theirs among the controls), so that results are keyed where the animator
animates; any other rig gets its controls from the Bone Map panel.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..motion.conventions import JOINT_INDEX, JOINTS, PARENT_NAMES
from ..motion.geometry import closing_weights, nearest_rotation, shortest_arc
from ..motion.rotations import closing_turns
from .rigs import MMD_SPELLINGS, mmd_name, normalise_name
from .solve import Anchors, Rig, SolveError, compose, placed as placed_in


@dataclass(frozen=True)
class Control:
    """A control bone and the mapped (or bridge) bone it drives; ``location``: it also moves
    (the body's root control), otherwise it only turns; ``optional``: a preset fits a rig without it (a spine
    bone some rigs of the family have and others not)."""

    bone: str
    drives: str
    location: bool = False
    optional: bool = False
    twist: bool = False  # it only turns about its own axis (an IK chain's base, which sets the knee's plane)
    turns: bool = True  # False: it only moves (an MMD model's centre, the bones below it turning the body)
    pole: bool = False  # an IK pole: moved in front of the driven bone's head, in the plane of its chain
    end: bool = False  # an IK chain's end: first put where its driven bone's target puts it as the two stand at rest


@dataclass(frozen=True)
class IkLimb:
    """A limb that is keyed on its IK controls where it is animated in IK: where ``switch`` stands at ``ik_value``,
    the limb's FK controls (``fk``) give way to ``ik`` (the IK end control, which moves; the chain's base, turned
    about its own axis; a toe), or where the limb has a pole (``pole``, always, or where the property ``pole_prop``
    of the switch's bone is on), to ``ik`` without its base and with the ``pole`` control; the switch is kept at its
    IK value."""

    switch: Switch
    ik_value: float
    fk: tuple[str, ...]
    ik: tuple[Control, ...]
    pole: Control | None = None
    pole_prop: str = ""

    def _bones(self) -> list[str]:
        out = [self.switch.bone, *self.fk] + [b for c in self.ik for b in (c.bone, c.drives)]
        return out + ([self.pole.bone, self.pole.drives] if self.pole is not None else [])


@dataclass(frozen=True)
class Switch:
    """A custom property keyed to ``value`` on the written frames (e.g. Rigify's IK/FK switch to FK)."""

    bone: str
    prop: str
    value: float


@dataclass
class ControlSet:
    """What a rig's results are keyed on: its controls and the switches that make them act."""

    name: str
    controls: list[Control] = field(default_factory=list)
    switches: list[Switch] = field(default_factory=list)
    ik_limbs: list[IkLimb] = field(default_factory=list)
    keyed_ik: list[str] = field(default_factory=list)  # of a set made by :meth:`keyed`: the limbs' switches keyed IK

    def missing(self, names: set[str]) -> list[str]:
        """Bones this set names that the rig lacks."""
        return sorted({b for b in self._bones() if b not in names})

    def _bones(self) -> list[str]:
        return [c.bone for c in self.controls] + [c.drives for c in self.controls] + [s.bone for s in self.switches]

    def on(self, names: list[str] | set[str]) -> ControlSet | None:
        """This set with each bone it names spelt as the rig spells it: the name itself, else the rig's one bone of
        that name in another namespace (``mixamorig1:Hips`` or ``Hips`` for ``mixamorig:Hips``); an optional control
        the rig lacks left out; None if any other bone is missing."""
        names = set(names)
        by_base: dict[str, list[str]] = {}
        for n in names:
            by_base.setdefault(normalise_name(n), []).append(n)

        def spell(b: str) -> str | None:
            if b in names:
                return b
            found = by_base.get(normalise_name(b), [])
            return found[0] if len(found) == 1 else None

        controls = []
        for c in self.controls:
            bone, drives = spell(c.bone), spell(c.drives)
            if bone is None or drives is None:
                if c.optional:
                    continue
                return None
            controls.append(replace(c, bone=bone, drives=drives))
        switches = [replace(s, bone=spell(s.bone)) for s in self.switches]
        if any(s.bone is None for s in switches):
            return None
        limbs = []
        for limb in self.ik_limbs:  # a limb whose IK controls the rig lacks is keyed on its FK controls
            if any(spell(b) is None for b in limb._bones()):
                continue
            pole = limb.pole and replace(limb.pole, bone=spell(limb.pole.bone), drives=spell(limb.pole.drives))
            limbs.append(replace(limb, switch=replace(limb.switch, bone=spell(limb.switch.bone)),
                                 fk=tuple(spell(b) for b in limb.fk), pole=pole,
                                 ik=tuple(replace(c, bone=spell(c.bone), drives=spell(c.drives)) for c in limb.ik)))
        return ControlSet(self.name, controls, switches, limbs)

    def ik_off(self, ends: set[str], chains: set[str]) -> ControlSet:
        """This set where the IK of the IK End controls of no switch ``ends`` is turned off (an MMD model posed with
        its leg IK off): those ends left out, and each chain base among ``chains`` (the bones of their IK chains)
        keyed whole, turned as its bone goes, as FK."""
        if not ends:
            return self
        controls = [replace(c, twist=False) if c.twist and c.bone in chains else c
                    for c in self.controls if c.bone not in ends]
        return replace(self, controls=controls)

    def keyed(self, values: dict[tuple[str, str], float]) -> ControlSet:
        """The controls to key where each switch and pole property stands at ``values`` {(bone, property): value}
        (a property not given: as the set keys it, FK): a limb found at its IK value keyed on its IK controls, its
        switch kept there."""
        controls, switches, on_ik = list(self.controls), list(self.switches), []
        for limb in self.ik_limbs:
            v = values.get((limb.switch.bone, limb.switch.prop), limb.switch.value)
            if abs(v - limb.ik_value) >= abs(v - limb.switch.value):  # nearer FK: keyed on FK, switched there
                continue
            pole = limb.pole is not None and (not limb.pole_prop or bool(values.get((limb.switch.bone,
                                                                                      limb.pole_prop), 0.0)))
            ik = [c for c in limb.ik if not (pole and c.twist)] + ([limb.pole] if pole else [])
            controls = [c for c in controls if c.bone not in limb.fk] + ik
            switches = [replace(s, value=limb.ik_value) if s == limb.switch else s for s in switches]
            on_ik.append(limb.switch.bone)
        return ControlSet(self.name, controls, switches, keyed_ik=on_ik)


# What a control is for in an edited control list (the Bone Map panel's): keyed always or where its limb is in FK
# (turned, or with Moves also moved), or the same but moved and never turned (a centre whose children turn the body);
# or, where its limb is in IK (or always, a control of no switch), an IK chain's end, the chain's base (turned about
# its own axis; left alone where the limb's pole is used), another IK control (a toe), or the pole.
IK_ROLES = ("IK_END", "IK_BASE", "IK", "POLE")
ROLES = ("FK", "MOVE") + IK_ROLES


@dataclass(frozen=True)
class Row:
    """A row of an edited control list: a :class:`Control` with its ``role`` (:data:`ROLES`) and ``switch``, the
    bone of the switch whose limb it belongs to ("": none, keyed always)."""

    bone: str
    drives: str
    location: bool = False
    role: str = "FK"
    switch: str = ""


@dataclass(frozen=True)
class SwitchRow:
    """A row of an edited switch list: a :class:`Switch` (``value`` keys its limb on FK) with the value that puts its
    limb in IK (``ik_value``) and the property of its bone that says the limb's pole is used (``pole_prop``; "": its
    pole, if the list gives it one, always is)."""

    bone: str
    prop: str
    value: float
    ik_value: float = 0.0
    pole_prop: str = ""


def as_rows(found: ControlSet) -> tuple[list[Row], list[SwitchRow]]:
    """``found`` as an edited list (:func:`from_rows` gives it back): each FK control that a limb gives way to names
    the limb's switch, and each limb's IK controls follow, limb by limb."""
    limb_of = {b: limb for limb in found.ik_limbs for b in limb.fk}
    rows = [Row(c.bone, c.drives, c.location, _role(c, "FK"), limb_of[c.bone].switch.bone if c.bone in limb_of else "")
            for c in found.controls]
    for limb in found.ik_limbs:
        rows += [Row(c.bone, c.drives, c.location, _role(c, "IK"), limb.switch.bone) for c in limb.ik]
        rows += [Row(limb.pole.bone, limb.pole.drives, limb.pole.location, "POLE", limb.switch.bone)] \
            if limb.pole is not None else []
    ik = {limb.switch: limb for limb in found.ik_limbs}
    switches = [SwitchRow(s.bone, s.prop, s.value, ik[s].ik_value if s in ik else 0.0,
                          ik[s].pole_prop if s in ik else "") for s in found.switches]
    return rows, switches


def _role(c: Control, plain: str) -> str:
    """The role of control ``c`` in a list (:data:`ROLES`); ``plain``: that of a control that only turns or moves."""
    return "IK_END" if c.end else "IK_BASE" if c.twist else "POLE" if c.pole else "MOVE" if not c.turns else plain


def from_rows(name: str, rows: list[Row], switches: list[SwitchRow]) -> tuple[ControlSet, list[str]]:
    """The control set an edited list gives, and what is wrong with the list (each a sentence saying how to fix
    it; the set leaves out what is wrong). A switch with IK controls makes a limb (:class:`IkLimb`) of them, the
    FK controls that name it and its pole; one without keys its FK controls alone, as a switch always did. A control of
    no switch is keyed always, whatever its role: an IK control of no switch belongs to a limb that never leaves IK
    (an MMD model's legs)."""
    by_bone = {s.bone: s for s in switches}
    problems = [f"Control {r.bone!r} is {'an IK' if r.role in IK_ROLES else 'an FK'} control of the switch on "
                f"{r.switch!r}, which the switch list does not have: add that switch, or clear the control's Switch"
                for r in rows if r.switch and r.switch not in by_bone]
    controls = [Control(r.bone, r.drives, r.location or r.role in ("IK_END", "POLE", "MOVE"), twist=r.role == "IK_BASE",
                        pole=r.role == "POLE", end=r.role == "IK_END", turns=r.role != "MOVE")
                for r in rows if r.role in ("FK", "MOVE") or not r.switch]
    limbs = []
    for bone in dict.fromkeys(r.switch for r in rows if r.role in IK_ROLES and r.switch in by_bone):
        sw = by_bone[bone]
        ik = [r for r in rows if r.switch == bone and r.role in ("IK_END", "IK_BASE", "IK")]
        poles = [r for r in rows if r.switch == bone and r.role == "POLE"]
        if not any(r.role == "IK_END" for r in ik):
            problems.append(f"The limb of the switch on {bone!r} has IK controls but no IK End: set the Role of its "
                            "foot's or hand's IK control to IK End, or remove its IK controls to key it on FK")
            continue
        if len(poles) > 1:
            problems.append(f"The limb of the switch on {bone!r} has {len(poles)} Pole controls "
                            f"({', '.join(r.bone for r in poles)}): keep one and remove the others")
            continue
        pole = Control(poles[0].bone, poles[0].drives, True, pole=True) if poles else None
        limbs.append(IkLimb(Switch(sw.bone, sw.prop, sw.value), sw.ik_value,
                            tuple(r.bone for r in rows if r.switch == bone and r.role in ("FK", "MOVE")),
                            tuple(Control(r.bone, r.drives, r.location or r.role == "IK_END",
                                          twist=r.role == "IK_BASE", end=r.role == "IK_END") for r in ik),
                            pole, sw.pole_prop))
    return ControlSet(name, controls, [Switch(s.bone, s.prop, s.value) for s in switches], limbs), problems


def _sides(pairs: list[tuple], *more: tuple) -> list[tuple]:
    """Each ``{S}`` template in ``pairs`` for both sides (``.L``, ``.R``), after ``more``."""
    return list(more) + [tuple(x.format(S=s) if isinstance(x, str) else x for x in p) for s in "LR" for p in pairs]


# Rigify (Blender's bundled rig generator, human metarig): joints on the ORG bones, which copy the
# FK controls' transforms once the limbs' IK_FK switch is 1 (FK); torso carries the body.
_RIGIFY_CONTROLS = _sides(
    [("shoulder.{S}", "ORG-shoulder.{S}", False), ("upper_arm_fk.{S}", "ORG-upper_arm.{S}", False),
     ("forearm_fk.{S}", "ORG-forearm.{S}", False), ("hand_fk.{S}", "ORG-hand.{S}", False),
     ("thigh_fk.{S}", "ORG-thigh.{S}", False), ("shin_fk.{S}", "ORG-shin.{S}", False),
     ("foot_fk.{S}", "ORG-foot.{S}", False), ("toe_fk.{S}", "ORG-toe.{S}", False)],
    ("torso", "ORG-spine", True), ("chest", "ORG-spine.003", True), ("neck", "ORG-spine.004", False),
    ("head", "ORG-spine.006", False))
# Artell's Mixamo Rig add-on (a control rig built into a Mixamo character's armature): each ``mixamorig:`` bone
# copies its ``Ctrl_`` control (the hips through Ctrl_Hips_Free's helper, the foot through a bone below
# Ctrl_Foot_FK); the limbs follow the FK chain where the ``ik_fk_switch`` on their IK control is 1 (FK), the IK
# chain where it is 0; Ctrl_Hips carries the body. Its FK legs and arms are not copies of the deform bones (their
# rolls differ), which the visual bake does not mind.
_MIXAMO_RIG_CONTROLS = [
    ("Ctrl_Hips", "mixamorig:Hips", True), ("Ctrl_Spine", "mixamorig:Spine", False),
    ("Ctrl_Spine1", "mixamorig:Spine1", False), ("Ctrl_Spine2", "mixamorig:Spine2", False),
    ("Ctrl_Neck", "mixamorig:Neck", False), ("Ctrl_Head", "mixamorig:Head", False)] + [
    (c.format(S=side), d.format(S=side), False) for side in ("Left", "Right") for c, d in (
        ("Ctrl_Shoulder_{S}", "mixamorig:{S}Shoulder"), ("Ctrl_Arm_FK_{S}", "mixamorig:{S}Arm"),
        ("Ctrl_ForeArm_FK_{S}", "mixamorig:{S}ForeArm"), ("Ctrl_Hand_FK_{S}", "mixamorig:{S}Hand"),
        ("Ctrl_UpLeg_FK_{S}", "mixamorig:{S}UpLeg"), ("Ctrl_Leg_FK_{S}", "mixamorig:{S}Leg"),
        ("Ctrl_Foot_FK_{S}", "mixamorig:{S}Foot"), ("Ctrl_Toe_FK_{S}", "mixamorig:{S}ToeBase"))]
# Its limbs in IK: Ctrl_Foot_IK / Ctrl_Hand_IK carry the chain's end, the knee and elbow aim at their poles.
_MIXAMO_RIG_IK_LIMBS = [
    IkLimb(Switch(f"Ctrl_Foot_IK_{S}", "ik_fk_switch", 1.0), 0.0,
           tuple(f"Ctrl_{b}_FK_{S}" for b in ("UpLeg", "Leg", "Foot", "Toe")),
           (Control(f"Ctrl_Foot_IK_{S}", f"mixamorig:{S}Foot", True, end=True),
            Control(f"Ctrl_Toe_IK_{S}", f"mixamorig:{S}ToeBase")),
           Control(f"Ctrl_LegPole_IK_{S}", f"mixamorig:{S}Leg", True, pole=True)) for S in ("Left", "Right")] + [
    IkLimb(Switch(f"Ctrl_Hand_IK_{S}", "ik_fk_switch", 1.0), 0.0,
           tuple(f"Ctrl_{b}_FK_{S}" for b in ("Arm", "ForeArm", "Hand")),
           (Control(f"Ctrl_Hand_IK_{S}", f"mixamorig:{S}Hand", True, end=True),),
           Control(f"Ctrl_ArmPole_IK_{S}", f"mixamorig:{S}ForeArm", True, pole=True)) for S in ("Left", "Right")]
# Auto-Rig Pro's human rig (Artell's widely used commercial add-on): the body's root control c_root_master.x
# carries everything (c_root.x, which only turns the hips about the waist, is left as it is); each deform or
# blending bone follows its ``c_`` FK control where the ``ik_fk_switch`` on c_foot_ik / c_hand_ik is 1 (FK), the IK
# chain where it is 0. The controls' rest orientations are not all the bones' (c_foot_fk lies along the ground),
# which the visual bake does not mind. A rig built with two spine bones has no spine_03, one built without toes
# no toes_01 (its feet then carry the toes).
_AUTO_RIG_PRO_CONTROLS = [
    Control("c_root_master.x", "c_root_master.x", True), Control("c_spine_01.x", "spine_01.x"),
    Control("c_spine_02.x", "spine_02.x"), Control("c_spine_03.x", "spine_03.x", optional=True),
    Control("c_neck.x", "neck.x"), Control("c_head.x", "head.x")] + [
    Control(c.format(S=side), d.format(S=side)) for side in "lr" for c, d in (
        ("c_shoulder.{S}", "shoulder.{S}"), ("c_arm_fk.{S}", "arm.{S}"), ("c_forearm_fk.{S}", "forearm.{S}"),
        ("c_hand_fk.{S}", "hand.{S}"), ("c_thigh_fk.{S}", "thigh.{S}"), ("c_leg_fk.{S}", "leg.{S}"),
        ("c_foot_fk.{S}", "foot.{S}"))] + [
    Control(f"c_toes_fk.{side}", f"toes_01.{side}", optional=True) for side in "lr"]
# Rigify's limbs in IK: the foot (hand) IK control carries the chain's end, the base (thigh_ik, upper_arm_ik) turns
# about its own axis to set the knee's (elbow's) plane where the limb has no pole, the pole control where it has
# (the ``pole_vector`` property, off on a generated rig); toe_ik turns the toe. As Rigify's own IK->FK snap.
_RIGIFY_IK_LIMBS = [
    IkLimb(Switch(f"thigh_parent.{S}", "IK_FK", 1.0), 0.0,
           tuple(f"{b}_fk.{S}" for b in ("thigh", "shin", "foot", "toe")),
           (Control(f"foot_ik.{S}", f"ORG-foot.{S}", True, end=True),
            Control(f"thigh_ik.{S}", f"ORG-thigh.{S}", twist=True),
            Control(f"toe_ik.{S}", f"ORG-toe.{S}")),
           Control(f"thigh_ik_target.{S}", f"ORG-shin.{S}", True, pole=True), "pole_vector") for S in "LR"] + [
    IkLimb(Switch(f"upper_arm_parent.{S}", "IK_FK", 1.0), 0.0,
           tuple(f"{b}_fk.{S}" for b in ("upper_arm", "forearm", "hand")),
           (Control(f"hand_ik.{S}", f"ORG-hand.{S}", True, end=True),
            Control(f"upper_arm_ik.{S}", f"ORG-upper_arm.{S}", twist=True)),
           Control(f"upper_arm_ik_target.{S}", f"ORG-forearm.{S}", True, pole=True), "pole_vector") for S in "LR"]
# Its limbs in IK: c_foot_ik / c_hand_ik carry the chain's end, the knee and elbow aim at c_leg_pole / c_arms_pole.
_AUTO_RIG_PRO_IK_LIMBS = [
    IkLimb(Switch(f"c_foot_ik.{S}", "ik_fk_switch", 1.0), 0.0,
           tuple(f"c_{b}_fk.{S}" for b in ("thigh", "leg", "foot", "toes")),
           (Control(f"c_foot_ik.{S}", f"foot.{S}", True, end=True), Control(f"c_toes_ik.{S}", f"toes_01.{S}")),
           Control(f"c_leg_pole.{S}", f"leg.{S}", True, pole=True)) for S in "lr"] + [
    IkLimb(Switch(f"c_hand_ik.{S}", "ik_fk_switch", 1.0), 0.0,
           tuple(f"c_{b}_fk.{S}" for b in ("arm", "forearm", "hand")),
           (Control(f"c_hand_ik.{S}", f"hand.{S}", True, end=True),),
           Control(f"c_arms_pole.{S}", f"forearm.{S}", True, pole=True)) for S in "lr"]
# MikuMikuDance models as mmd_tools imports them (``足.L``; :data:`rigs.RIG_FAMILIES` ``mmd``): the centre
# (``センター``) carries the body, the lower body (``下半身``, the hips) and the upper body hanging from it apart; as
# MMD animators key it, the centre only moves and the lower and upper bodies turn.
# The legs are always in IK: an IK constraint on the knee (``ひざ``, two bones, to ``足ＩＫ``; the knee bends only
# about its X axis) and on the ankle (``足首``, one bone, aimed at ``つま先ＩＫ``, which hangs from ``足ＩＫ``), so
# ``足ＩＫ`` puts the foot where it goes, turned so that its toe IK takes the toe there, and the thigh (``足``) is
# turned about its own axis to set the knee's plane (as Rigify's ``thigh_ik``); the knee and ankle are keyed too, as
# a VMD motion has them, so that each IK starts from the solved pose. No switch: the legs never leave IK.
def _mmd_controls(spelling: str) -> list[Control]:
    """The controls of an MMD model whose bones are named in ``spelling`` (:data:`rigs.MMD_SPELLINGS`)."""
    n = lambda word, side=None: mmd_name(word, side, spelling)
    return [Control(n("センター"), n("下半身"), True, turns=False), Control(n("下半身"), n("下半身")),
            Control(n("上半身"), n("上半身")), Control(n("上半身2"), n("上半身2"), optional=True),
            Control(n("上半身3"), n("上半身3"), optional=True),  # some models' chest, from which the arms hang
            Control(n("首"), n("首")), Control(n("頭"), n("頭"))] + [
        Control(n(bone, S), n(bone, S)) for S in "LR" for bone in ("肩", "腕", "ひじ", "手首", "ひざ", "足首")] + [
        c for S in "LR"
        for c in (Control(n("足", S), n("足", S), twist=True), Control(n("足ＩＫ", S), n("足首", S), True, end=True))]


PRESETS: dict[str, ControlSet] = {
    "rigify": ControlSet(
        "rigify",
        [Control(*c) for c in _RIGIFY_CONTROLS],
        [Switch(*s) for s in _sides([("thigh_parent.{S}", "IK_FK", 1.0), ("upper_arm_parent.{S}", "IK_FK", 1.0)])],
        _RIGIFY_IK_LIMBS),
    "mixamo_rig": ControlSet(
        "mixamo_rig",
        [Control(*c) for c in _MIXAMO_RIG_CONTROLS],
        [Switch(f"Ctrl_{limb}_IK_{side}", "ik_fk_switch", 1.0)
         for side in ("Left", "Right") for limb in ("Foot", "Hand")], _MIXAMO_RIG_IK_LIMBS),
    "auto_rig_pro": ControlSet(
        "auto_rig_pro", _AUTO_RIG_PRO_CONTROLS,
        [Switch(f"c_{limb}_ik.{side}", "ik_fk_switch", 1.0) for side in "lr" for limb in ("foot", "hand")],
        _AUTO_RIG_PRO_IK_LIMBS),
    # one per way the bones may be named, each the "mmd" preset
    **{"mmd" + ("" if k == 0 else f"_{k}"): ControlSet("mmd", _mmd_controls(spelling))
       for k, spelling in enumerate(MMD_SPELLINGS)},
}


def preset_for(names: list[str] | set[str]) -> ControlSet | None:
    """The shipped control set whose every bone the rig has, spelt as the rig spells them (:meth:`ControlSet.on`:
    a Mixamo character's bones may be ``mixamorig1:Hips`` or ``Hips``); None if none fits."""
    return next((found for p in PRESETS.values() if (found := p.on(names)) is not None), None)


def _ancestors(rig: Rig, b: int) -> list[int]:
    out = []
    b = int(rig.parents[b])
    while b >= 0:
        out.append(b)
        b = int(rig.parents[b])
    return out


def joint_rig(rig: Rig, mapping: dict[str, tuple[str, bool]]) -> Rig:
    """The joint skeleton of ``rig`` under ``mapping`` (see the module's docstring): the mapped
    bones, parents first from the hips bone, each below the bone of its canonical parent joint, with
    the real bones in between where that bone is a real ancestor (a clavicle between chest and upper
    arm). Raises :class:`SolveError` when a joint has no bone on ``rig``."""
    index = {n: i for i, n in enumerate(rig.names)}
    placed = placed_in(mapping)
    missing = [j for j in JOINTS if j not in placed and (j not in mapping or mapping[j][0] not in index)]
    if missing:
        raise SolveError(f"no bone mapped for: {', '.join(missing)}")
    order: list[int] = []
    parent_of: dict[int, int] = {}
    for joint in JOINTS:  # parents first
        if joint in placed:  # no bone of its own: the one below it carries it
            continue
        b = index[mapping[joint][0]]
        if b in parent_of:  # a tail on a bone already placed (a foot's tail as the toe)
            continue
        if PARENT_NAMES[joint] is None:
            parent_of[b] = -1
            order.append(b)
            continue
        parent = PARENT_NAMES[joint]
        top = index[mapping[placed[parent][0] if parent in placed else parent][0]]
        up = _ancestors(rig, b)
        between = up[:up.index(top)] if top in up else []
        above = top
        for x in [x for x in reversed(between) if x not in parent_of] + [b]:
            parent_of[x] = above
            order.append(x)
            above = x
    new = {b: k for k, b in enumerate(order)}
    parents = np.array([new[parent_of[b]] if parent_of[b] >= 0 else -1 for b in order])
    return Rig([rig.names[b] for b in order], parents, rig.rest[order], rig.lengths[order], tails=rig.tails[order])


# A bone moves with a written bone over the take where the spread of its transform relative to it (its place in the
# rig's ``scale`` units plus its turn, the rotation matrices' mean distance) is within this of the least over the
# written bones; of several, the one whose rest segment it lies nearest carries it (on a take that does not move the
# two apart, the bone it belongs to).
CARRY_TIE = 0.01


def hanging_from(rig: Rig, moved: set[str]) -> np.ndarray:
    """bool ``[B]``: whether each bone of ``rig`` is in ``moved`` or hangs from one of them through its parents."""
    out = np.zeros(len(rig.names), dtype=bool)
    for b, name in enumerate(rig.names):  # parents first
        out[b] = name in moved or (rig.parents[b] >= 0 and bool(out[rig.parents[b]]))
    return out


def _segment_distances(rig: Rig, written: np.ndarray, b: int) -> np.ndarray:
    """``[W]``: how far bone ``b``'s rest head lies from each ``written`` bone's rest segment (head to tail)."""
    heads = rig.rest[:, :3, 3]
    a = heads[written]
    seg = np.einsum("bij,bj->bi", rig.rest[written], np.c_[rig.tails[written], np.ones(len(written))])[:, :3] - a
    t = np.clip(np.einsum("wi,wi->w", heads[b] - a, seg) / np.maximum(np.einsum("wi,wi->w", seg, seg), 1e-12), 0, 1)
    return np.linalg.norm(a + t[:, None] * seg - heads[b], axis=-1)


def _spreads(pose: np.ndarray, bones: np.ndarray, written: np.ndarray, scale: float) -> np.ndarray:
    """``[len(bones), W]``: how far each bone's transform relative to each written bone varies over the take's poses
    ``pose`` ``[S, B, 4, 4]`` (:data:`CARRY_TIE`)."""
    rel = np.linalg.inv(pose[:, written])[:, None] @ pose[:, bones][:, :, None]  # [S, N, W, 4, 4]
    place = np.linalg.norm(rel[..., :3, 3] - rel[..., :3, 3].mean(axis=0), axis=-1).mean(axis=0) / scale
    turn = np.linalg.norm(rel[..., :3, :3] - rel[..., :3, :3].mean(axis=0), axis=(-2, -1)).mean(axis=0)
    return place + turn


def carried_bones(rig: Rig, written: list[str], skinned: set[str], pose: np.ndarray, scale: float) -> dict[int, int]:
    """{bone to carry: the written bone it moves with} so that none of ``skinned`` (what the rig's meshes follow) is
    left behind by keys on the ``written`` bones alone: a baked Rigify rig's face, pelvis and shoulders hang from its
    ORG-, MCH- and control bones, which no longer follow anything. Over the take's poses ``pose`` ``[S, B, 4, 4]``
    (armature space; ``scale``: a length of the rig, its leg), each skinned bone that hangs neither from a written
    bone (through skinned bones alone) nor from a carried one it moved with (:data:`CARRY_TIE`) goes with the
    written bone it moved with, carried
    by the highest bone above it that moved with that one too, as did every skinned bone below it that hangs from no
    written bone, and has no written bone below it (Rigify's ORG-spine.006 for the whole face); where that bone is
    connected to its parent (Blender keeps its head on the parent's tail), the parent too, with the bone it moved
    with."""
    index = {n: b for b, n in enumerate(rig.names)}
    w = np.array([index[n] for n in written])
    if not len(w):
        return {}
    n = len(rig.names)
    below_written = np.isin(np.arange(n), w)  # a written bone is this one or below it
    skin_below: list[list[int]] = [[] for _ in range(n)]
    for b in range(n - 1, -1, -1):  # children first
        if rig.names[b] in skinned:
            skin_below[b].append(b)
        p = int(rig.parents[b])
        if p >= 0:
            below_written[p] |= below_written[b]
            skin_below[p].extend(skin_below[b])
    # a skinned bone follows a written bone above it through skinned bones alone: one that hangs from it through a
    # bone of no skin (a baked MMD model's FK leg, which its IK turned as the deform copy beside it) is left behind
    under_written = np.zeros(n, dtype=bool)
    for b, name in enumerate(rig.names):  # parents first
        p = int(rig.parents[b])
        under_written[b] = name in written or (p >= 0 and bool(under_written[p])
                                               and (rig.names[p] in written or rig.names[p] in skinned))
    spread: dict[int, np.ndarray] = {}

    def spread_of(b: int) -> np.ndarray:
        if b not in spread:
            spread[b] = _spreads(pose, np.array([b]), w, scale)[0]
        return spread[b]

    def moves_with(b: int, k: int) -> bool:
        return bool(spread_of(b)[k] <= spread_of(b).min() + CARRY_TIE)

    out: dict[int, int] = {}  # carried bone: index into ``w`` of its carrier

    def fits(p: int, k: int) -> bool:
        """Whether ``p`` can carry the bones below it with written bone ``w[k]``."""
        return (p not in out and not below_written[p] and moves_with(p, k)
                and all(moves_with(x, k) for x in skin_below[p] if not under_written[x]))

    def left_behind() -> int | None:
        """The first skinned bone that hangs from no written bone and from no carried bone it moves with."""
        carrier = np.full(n, -1)  # the carrier (index into ``w``) of the nearest carried bone at or above each bone
        for b in range(n):
            carrier[b] = out[b] if b in out else (carrier[rig.parents[b]] if rig.parents[b] >= 0 else -1)
        return next((b for b, name in enumerate(rig.names) if name in skinned and not under_written[b]
                     and (carrier[b] < 0 or not moves_with(b, int(carrier[b])))), None)

    def best(b: int) -> int:
        """The written bone (index into ``w``) ``b`` moved with; of several, the one whose rest segment it lies on."""
        near = _segment_distances(rig, w, b)
        near[[not moves_with(b, k) for k in range(len(w))]] = np.inf
        return int(np.argmin(near))

    while (left := left_behind()) is not None:
        k = best(left)
        top = left
        while (p := int(rig.parents[top])) >= 0 and fits(p, k):
            top = p
        out[top] = k
        # a connected bone keeps its head on its parent's tail, whatever its place is keyed: its parents are carried
        # too, each with the bone it moved with (Rigify's ORG-spine.006 on ORG-spine.005, the neck's)
        while rig.connected[top] and (p := int(rig.parents[top])) not in out and not under_written[p]:
            out[p] = best(p)
            top = p
    return {b: int(w[k]) for b, k in sorted(out.items())}


def _free_bones(rig: Rig, written: np.ndarray) -> np.ndarray:
    """bool ``[B]``: the bones of ``rig`` that neither hang from a bone of ``written`` (indices) nor have one below."""
    below = np.isin(np.arange(len(rig.names)), written)
    for b in range(len(rig.names) - 1, -1, -1):  # children first
        if rig.parents[b] >= 0:
            below[rig.parents[b]] |= below[b]
    return ~below & ~hanging_from(rig, {rig.names[b] for b in written})


# A keyed bone moved with a written bone over the take where the spread of its transform relative to it
# (:func:`_spreads`) is at most this: kept on it to within millimetres and a fraction of a degree, as an exporter bakes
# a game rig's IK bones onto its feet and hands; and it moved where its own spread in the armature is at least this.
FOLLOW_TIE = 0.005
FOLLOW_MOVED = 0.05


def keyed_followers(rig: Rig, written: list[str], keyed: set[str], pose: np.ndarray, scale: float) -> dict[int, int]:
    """{keyed bone: the written bone it moved with} for the bones of a plain rig that the action keys, that the
    written bones do not carry and that kept to one of them over the take (:data:`FOLLOW_TIE`) while moving
    (:data:`FOLLOW_MOVED`): an Unreal rig's ``ik_foot_l`` keyed on ``foot_l`` and ``ik_hand_gun`` on ``hand_r``, a prop
    keyed in a hand. Where new frames key the written bones alone, such a bone would stay where the take left it.
    ``pose`` ``[S, B, 4, 4]``: the take's poses (armature space) of ``rig``'s bones; ``scale``: a length of the rig (its
    leg). A bone that hangs from a written bone (which carries it) or has one below it (a root, which the written
    bones hang from) is left out."""
    index = {n: b for b, n in enumerate(rig.names)}
    w = np.array([index[n] for n in written if n in index], dtype=int)
    if not len(w):
        return {}
    free = _free_bones(rig, w)
    bones = np.array([b for b, n in enumerate(rig.names) if n in keyed and free[b]], dtype=int)
    if not len(bones):
        return {}
    own = pose[:, bones]  # [S, N, 4, 4]
    moved = (np.linalg.norm(own[..., :3, 3] - own[..., :3, 3].mean(axis=0), axis=-1).mean(axis=0) / scale
             + np.linalg.norm(own[..., :3, :3] - own[..., :3, :3].mean(axis=0), axis=(-2, -1)).mean(axis=0))
    spread = _spreads(pose, bones, w, scale)  # [N, W]
    out = {}
    for i, b in enumerate(bones):
        if moved[i] < FOLLOW_MOVED or spread[i].min() > FOLLOW_TIE:
            continue
        # of the written bones it kept to (a hand and its still fingers), the one whose rest segment it lies nearest
        near = np.where(spread[i] <= FOLLOW_TIE, _segment_distances(rig, w, int(b)), np.inf)
        out[int(b)] = int(w[np.argmin(near)])
    return out


# A bone sits where a written bone does at rest where its rest place is within this share of the rig's scale of that
# bone's and its rest axes within this of that bone's (the rotation matrices' largest difference).
TWIN_TIE = 1e-4


def rest_twins(rig: Rig, written: list[str], scale: float) -> dict[int, int]:
    """{bone: the written bone it sits on at rest} for the bones of a rig without a take to read (Transfer Motion onto a
    character that has no action yet) that hang from no written bone, have none below them and rest exactly where a
    written bone rests, axes and all: an Unreal rig's ``ik_foot_l`` on ``foot_l``, ``ik_hand_gun`` on ``hand_r``, which
    Unreal's animations key on those bones. ``scale``: a length of the rig (its leg)."""
    index = {n: b for b, n in enumerate(rig.names)}
    w = np.array([index[n] for n in written if n in index], dtype=int)
    if not len(w):
        return {}
    out = {}
    for b in np.flatnonzero(_free_bones(rig, w)):
        place = np.linalg.norm(rig.rest[w, :3, 3] - rig.rest[b, :3, 3], axis=-1) / scale
        axes = np.abs(rig.rest[w, :3, :3] - rig.rest[b, :3, :3]).max(axis=(-2, -1))
        near = np.flatnonzero((place <= TWIN_TIE) & (axes <= TWIN_TIE))
        if len(near):
            out[int(b)] = int(w[near[0]])
    return out


def loose_bones(rig: Rig, written: list[str]) -> list[str]:
    """The ``written`` bones of ``rig`` whose parent is not written and hangs from no written bone (a baked Rigify
    rig's DEF-thigh.L hangs from ORG-spine): keys on their rotation alone would leave their heads where that parent
    holds them, so their place is keyed too."""
    follows = hanging_from(rig, set(written))
    index = {n: b for b, n in enumerate(rig.names)}
    return [n for n in written if rig.parents[index[n]] < 0 or not follows[rig.parents[index[n]]]]


STILL = 1e-5  # a bone at rest over a cycle: its place moves less than this share of the rig's size, its turn less


def closed_cycle(rig: Rig, pose: np.ndarray, travel: np.ndarray, blend: int, kept: np.ndarray, turned: np.ndarray,
                 placed: np.ndarray, scale: float) -> np.ndarray:
    """A cycle's poses ``pose`` ``[L + 1, B, 4, 4]`` (armature space: its first frame to its seam) with every bone
    made to end where it began carried by the cycle's ``travel`` ``[3]``, so that the rig played on cycle after
    cycle, each location repeated with its offset, stays whole: a baked control rig's keyed bones were set against
    mechanism bones (Rigify's ``torso``) that travel as far as the take did, not as far as the cycle does, and a
    location keyed under a bone that turns repeats its offset turned.

    A bone's place misses by as much as it ends off its first place carried by ``travel``: that is spread evenly over
    the cycle; its turn's miss is eased in over the last ``blend`` frames (at least a tenth of the cycle). The bones
    of ``kept`` (bool ``[B]``: those the solve wrote, whose cycle it is) keep their poses, as does each bone at rest
    over the whole cycle with every bone above it (a root that stays put, which keeps its children's offsets the
    travel; :data:`STILL` of ``scale``, a length of the rig). A bone goes where its parent takes it in what it is not
    keyed in: its turn unless ``turned`` (bool ``[B]``), its place unless ``placed`` (bool ``[B]``: a location keyed
    and not connected, which Blender would leave out)."""
    pose = np.asarray(pose, dtype=np.float64)
    frames = len(pose) - 1
    out = pose.copy()
    ease = closing_weights(frames + 1, blend)
    ramp = np.arange(frames + 1) / max(frames, 1)
    still = np.zeros(len(rig.names), dtype=bool)
    for b, p in enumerate(rig.parents):  # parents first
        moved = p >= 0 and not still[p] and not kept[p]
        if kept[b]:
            continue
        if (p < 0 or still[p]) and np.abs(pose[:, b, :3, 3] - pose[0, b, :3, 3]).max() < STILL * scale \
                and np.abs(pose[:, b, :3, :3] - pose[0, b, :3, :3]).max() < STILL:
            still[b] = True
            continue
        target = out[:, p] @ np.linalg.inv(pose[:, p]) @ pose[:, b] if moved else pose[:, b].copy()
        if turned[b]:
            own = nearest_rotation(pose[:, b, :3, :3])  # (its scale kept)
            target[:, :3, :3] = closing_turns(own, ease) @ np.swapaxes(own, -1, -2) @ pose[:, b, :3, :3]
        if placed[b]:
            target[:, :3, 3] = pose[:, b, :3, 3] + ramp[:, None] * (pose[0, b, :3, 3] + travel - pose[-1, b, :3, 3])
        out[:, b] = target
    return out


def placed_on_targets(rig: Rig, loc: np.ndarray, rot: np.ndarray, scale: np.ndarray, chosen: list[int],
                      located: list[bool], targets: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The visual bake in closed form, for a rig on which no bone follows anything but its parent (a rig an exporter
    baked): each bone of ``chosen``, its own control, turned (and, where ``located``, moved: not where it is
    connected, which Blender keeps on its parent's tail) so that it lands on its ``targets`` ``[F, C, 4, 4]``
    (armature space), the others keeping their local ``loc`` ``[F, B, 3]``, ``rot`` ``[F, B, 3, 3]`` and ``scale``
    ``[F, B, 3]``, parents first. Returns the chosen bones' local ``loc`` ``[F, C, 3]`` and ``rot`` ``[F, C, 3, 3]``,
    and the largest distance of a chosen bone's head or tail from its target (armature units)."""
    at = {b: k for k, b in enumerate(chosen)}
    basis = compose(np.where(rig.connected[None, :, None], 0.0, loc), rot * scale[..., None, :])
    pose = np.empty(basis.shape)
    out_loc, out_rot = np.array(loc[:, chosen], dtype=np.float64), np.array(rot[:, chosen], dtype=np.float64)
    worst = 0.0
    for b, p in enumerate(rig.parents):  # parents first
        frame = rig.rel_rest[b] if p < 0 else pose[:, p] @ rig.rel_rest[b]
        if b in at:
            k, want = at[b], np.array(targets[:, at[b]], dtype=np.float64)
            local = np.linalg.inv(frame) @ want
            out_rot[:, k] = nearest_rotation(local[:, :3, :3])
            if located[k] and not rig.connected[b]:
                out_loc[:, k] = local[:, :3, 3]
            basis[:, b] = compose(np.where(rig.connected[b], 0.0, out_loc[:, k]), out_rot[:, k] * scale[:, b, None, :])
        pose[:, b] = frame @ basis[:, b]
        if b in at:
            tip = np.array([0.0, rig.lengths[b], 0.0, 1.0])
            worst = max(worst, float(np.linalg.norm(pose[:, b, :3, 3] - want[:, :3, 3], axis=-1).max()),
                        float(np.linalg.norm((pose[:, b] @ tip - want @ tip)[:, :3], axis=-1).max()))
    return out_loc, out_rot, worst


def visual_local(rig: Rig, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Local ``loc`` ``[F, B, 3]`` and rotation ``[F, B, 3, 3]`` that reproduce pose matrices
    ``pose`` ``[F, B, 4, 4]`` (armature space) under ``rig``'s parents (Blender's visual transform)."""
    parent = np.where((rig.parents < 0)[None, :, None, None], np.eye(4),
                      pose[:, np.maximum(rig.parents, 0)])
    local = np.linalg.inv(parent @ rig.rel_rest) @ pose
    return local[..., :3, 3], nearest_rotation(local[..., :3, :3])  # drops scale and shear


# An IK chain whose motion is this much shorter than its bones (a share of their length, the median over the frames)
# is put on the motion's joints (:func:`chains_on_joints`); one within it is left as the solve has it.
SHORT_CHAIN = 0.001


def chains_on_joints(rig: Rig, anchors: Anchors, pose: np.ndarray, ends: list[int],
                     joints: np.ndarray) -> dict[int, np.ndarray]:
    """Pose matrices ``{bone: [F, 4, 4]}`` (armature space) that put each IK chain ending on a bone of ``ends`` on
    ``joints`` ``[F, 21, 3]``: the chain's two bones above the end (the thigh and the shin), the end (the foot) and
    the bones below it (the toe), from ``pose`` ``[F, B, 4, 4]`` (the solve's), each bone whose head is a joint
    moved there and turned (by the shortest arc) to point at the next joint down, the bones below the end carried
    with it; ``anchors``: where the joints sit.

    The solve keeps the bones' lengths, but Blender's IK solver plays a chain that may stretch shorter than its
    bones (Rigify's legs, ``ik_stretch`` 0.1: by 0.2 to 3 % as the knee bends), so the legs read off the rig, and
    the motion made of them, are that much shorter, and the solve puts the ankle further along the leg (a real
    walk's ankles 0.9 cm from the motion's on average, 0.8 cm under them). An IK chain reaches its end wherever
    that is put, so the end goes on the joint itself and the chain's bones point where the joints are. A chain
    whose motion is as long as its bones (within :data:`SHORT_CHAIN`: an IK that does not stretch plays them so) is
    left as the solve has it, which then puts the knee as well as the foot where the motion has them (a nearly
    straight leg's knee would move many times as far as a foot put on a joint a millimetre off the bones' reach)."""
    at_head = {b: JOINT_INDEX[name] for b, name in anchors.on_bones().items()}
    at_tail = {int(b): j for j, (b, tail) in enumerate(zip(anchors.bone, anchors.tail))
               if tail and j not in anchors.between}
    out: dict[int, np.ndarray] = {}

    def next_joint(b: int) -> int | None:  # the joint a bone points at: its tail's, or the head's of a child's
        if b in at_tail:
            return at_tail[b]
        kids = [k for k in range(len(rig.parents)) if rig.parents[k] == b and k in at_head]
        return at_head[kids[0]] if len(kids) == 1 else None

    def placed(b: int, m: np.ndarray) -> np.ndarray:
        head = joints[:, at_head[b]]
        toward = next_joint(b)
        new = m.copy()
        new[:, :3, 3] = head
        if toward is not None:  # the bone's tail (where a joint sits at it: :attr:`Rig.tails`) towards the joint
            tail = rig.tails[b] / max(float(np.linalg.norm(rig.tails[b])), 1e-12) if b in at_tail else (0.0, 1.0, 0.0)
            turn = shortest_arc(m[:, :3, :3] @ np.asarray(tail), joints[:, toward] - head)
            new[:, :3, :3] = turn @ m[:, :3, :3]
        return new

    for end in ends:
        if end not in at_head:
            continue
        knee = int(rig.parents[end])
        hip = int(rig.parents[knee]) if knee >= 0 else -1
        if hip < 0 or knee not in at_head or hip not in at_head or not _shorter(
                rig, joints, [(hip, at_head[hip]), (knee, at_head[knee]), (end, at_head[end])]):
            continue
        for b in (hip, knee):
            out[b] = placed(b, pose[:, b])
        moved = placed(end, pose[:, end])
        carry = moved @ np.linalg.inv(pose[:, end])
        for b in range(len(rig.parents)):
            if b != end and rig.is_ancestor(end, b):
                out[b] = carry @ pose[:, b]
        out[end] = moved
    return out


def _shorter(rig: Rig, joints: np.ndarray, chain: list[tuple[int, int]]) -> bool:
    """Whether the motion's ``joints`` ``[F, 21, 3]`` make a chain of (bone, joint at its head) pairs, from the top,
    shorter than the rig's bones by :data:`SHORT_CHAIN` or more, one bone or the other (the median over the
    frames)."""
    for (a, ja), (b, jb) in zip(chain, chain[1:]):
        rest = float(np.linalg.norm(rig.rest[b, :3, 3] - rig.rest[a, :3, 3]))
        now = float(np.median(np.linalg.norm(joints[:, jb] - joints[:, ja], axis=-1)))
        if rest > 1e-9 and now < (1.0 - SHORT_CHAIN) * rest:
            return True
    return False
