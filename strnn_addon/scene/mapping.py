"""The bone map on an armature: read, write, auto-map, and resolve into solve anchors."""

from __future__ import annotations

from ...model_core.motion.conventions import JOINTS
from ...model_core.rig import bonemap, controls
from ...model_core.rig.solve import Anchors, Rig, SolveError
from ..props import TAIL_JOINTS, joint_label


class MapError(ValueError):
    """The armature's bones cannot be mapped; the message says what is missing and how to fix it."""


def stored_map(arm) -> bonemap.Mapping:
    """The mapping saved on armature data ``arm``: {joint: (bone, use_tail)} for joints set."""
    props = arm.strnn_map
    out = {}
    for joint in JOINTS:
        bone = getattr(props, joint)
        if bone:
            out[joint] = (bone, bool(getattr(props, f"{joint}_tail", False)))
    return out


def store_map(arm, mapping: bonemap.Mapping, family: str = "") -> None:
    """Save ``mapping`` on armature data ``arm`` (joints absent from it are cleared)."""
    props = arm.strnn_map
    for joint in JOINTS:
        bone, tail = mapping.get(joint, ("", False))
        setattr(props, joint, bone)
        if joint in TAIL_JOINTS:
            setattr(props, f"{joint}_tail", tail)
    props.family = family


def auto_map(arm) -> tuple[str, bonemap.Mapping]:
    """(family, mapping) guessed from armature data ``arm``'s bone names and hierarchy."""
    names = [b.name for b in arm.bones]
    index = {n: i for i, n in enumerate(names)}
    parents = [index[b.parent.name] if b.parent else -1 for b in arm.bones]
    return bonemap.auto_map(names, parents)


def effective_map(arm) -> bonemap.Mapping:
    """The stored mapping, completed by auto-mapping where it leaves joints open."""
    stored = stored_map(arm)
    if len(stored) == len(JOINTS):
        return stored
    _, guess = auto_map(arm)
    return {**guess, **stored}


def resolve(arm, rig: Rig, joint_skeleton: bool = False) -> tuple[Anchors, bonemap.Mapping, Rig]:
    """(anchors of the canonical joints, mapping, the rig they are on): ``rig`` itself, or with
    ``joint_skeleton`` (a control rig) its joint skeleton (:func:`controls.joint_rig`). Raises
    :class:`MapError` naming what is wrong."""
    mapping = effective_map(arm)
    absent = [j for j in JOINTS if j in mapping and mapping[j][0] not in rig.names]
    if absent:
        bones = ", ".join(f"{joint_label(j)} -> {mapping[j][0]!r}" for j in absent)
        raise MapError(f"Bone map names bones this armature does not have ({bones}); "
                       "fix them in the STRNN > Bone Map panel")
    missing = bonemap.missing(mapping)
    if missing:
        raise MapError(f"Cannot map the rig: no bone found for {', '.join(joint_label(j) for j in missing)}. "
                       "Pick them in the sidebar's STRNN > Bone Map panel")
    try:
        if joint_skeleton:
            rig = controls.joint_rig(rig, mapping)
        return Anchors.from_map(rig, mapping), mapping, rig
    except SolveError as e:
        raise MapError(f"Bone map does not fit the hierarchy: {e}; fix it in STRNN > Bone Map") from e
