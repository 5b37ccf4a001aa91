"""The bone map of an armature object: read, write, auto-map, and resolve into solve anchors.

The map lives on the object (``Object.strnn_map``), which a library override can hold even
where the armature data stays linked; files saved when it lived on the armature data are read
from there until the map is stored again.
"""

from __future__ import annotations

import bpy
import numpy as np

from ...model_core.motion.conventions import JOINTS
from ...model_core.rig import bonemap, controls
from ...model_core.rig.solve import Anchors, Rig, SolveError, tips_along_the_limb
from ..props import TAIL_JOINTS, joint_label


class MapError(ValueError):
    """The armature's bones cannot be mapped; the message says what is missing and how to fix it."""


def stored_map(obj) -> bonemap.Mapping:
    """The mapping saved on armature object ``obj``: {joint: (bone, use_tail)} for joints set (or, from
    an older file, on its armature data)."""
    props = obj.strnn_map
    bones = {j: getattr(props, j) for j in JOINTS}
    tails = {j: getattr(props, f"{j}_tail") for j in TAIL_JOINTS}
    legacy = obj.data.get("strnn_map")  # the ID properties an older version left on the armature data
    if not any(bones.values()) and legacy is not None:
        bones = {j: str(legacy.get(j, "")) for j in JOINTS}
        tails = {j: bool(legacy.get(f"{j}_tail", False)) for j in TAIL_JOINTS}
    return {j: (bone, bool(tails.get(j, False))) for j, bone in bones.items() if bone}


def store_map(obj, mapping: bonemap.Mapping, family: str = "") -> None:
    """Save ``mapping`` on armature object ``obj`` (joints absent from it are cleared)."""
    props = obj.strnn_map
    for joint in JOINTS:
        bone, tail = mapping.get(joint, ("", False))
        setattr(props, joint, bone)
        if joint in TAIL_JOINTS:
            setattr(props, f"{joint}_tail", tail)
    props.family = family


def auto_map(obj) -> tuple[str, bonemap.Mapping]:
    """(family, mapping) guessed from armature object ``obj``'s bone names and hierarchy, a finger tip or toe at a
    bone's tail only where that tail continues the limb (:func:`bonemap.heads_where_tails_point_across`); on a baked
    rig (:func:`baked`) the bones of its skin (:func:`skin`) rather than others of the same names' family."""
    names, parents, heads, tails = _rest_bones(obj)
    family, mapping = bonemap.auto_map(names, parents, skin(obj) if baked(obj) else None)
    return family, bonemap.heads_where_tails_point_across(mapping, names, parents, heads, tails)


def baked(obj) -> bool:
    """Whether no bone of armature object ``obj`` follows a constraint: a rig whose every bone carries its own
    motion (a BVH's or a mocap skeleton, or a control rig that came back from an FBX, glTF or USD exporter, which bakes
    each bone and drops the constraints), so that no control drives another bone."""
    return not any(len(pb.constraints) for pb in obj.pose.bones)


def skinned_bones(obj) -> set[str]:
    """The bones of ``obj`` that the meshes it deforms (an Armature modifier on it) are weighted to: the vertex
    groups of those meshes that name a bone and weigh some vertex (a glTF importer makes a group for every joint of
    the skin, a Rigify character's ORG-, MCH- and control bones too, most of them weighing nothing)."""
    bones = obj.data.bones
    out: set[str] = set()
    for o in bpy.data.objects:
        if o.type != "MESH" or not any(m.type == "ARMATURE" and m.object is obj for m in o.modifiers):
            continue
        named = {g.index: g.name for g in o.vertex_groups if g.name in bones}
        weighed = {g.group for v in o.data.vertices for g in v.groups if g.weight > 0.0} if named else set()
        out |= {named[i] for i in weighed if i in named}
    return out


def skin(obj) -> set[str]:
    """The bones that carry ``obj``'s skin: :func:`skinned_bones`, or where no mesh is skinned to it its deform
    bones."""
    return skinned_bones(obj) or {b.name for b in obj.data.bones if b.use_deform}


def _rest_bones(obj) -> tuple[list[str], list[int], np.ndarray, np.ndarray]:
    """(names, parent indices, rest heads ``[B, 3]``, rest tails ``[B, 3]``) of armature object ``obj``'s bones."""
    bones = obj.data.bones
    names = [b.name for b in bones]
    index = {n: i for i, n in enumerate(names)}
    parents = [index[b.parent.name] if b.parent else -1 for b in bones]
    heads = np.array([b.head_local for b in bones], dtype=np.float64).reshape(-1, 3)
    tails = np.array([b.tail_local for b in bones], dtype=np.float64).reshape(-1, 3)
    return names, parents, heads, tails


def tails_across(obj, mapping: bonemap.Mapping) -> list[str]:
    """The finger tips and toes ``mapping`` puts at a tail of ``obj``'s that points across its bone (nothing else on
    the rig marks them: :func:`bonemap.tails_across`)."""
    names, parents, heads, tails = _rest_bones(obj)
    return bonemap.tails_across(mapping, names, parents, heads, tails)


def effective_map(obj) -> bonemap.Mapping:
    """The stored mapping, completed by auto-mapping where it leaves joints open."""
    stored = stored_map(obj)
    if len(stored) == len(JOINTS):
        return stored
    _, guess = auto_map(obj)
    return {**guess, **stored}


def resolve(obj, rig: Rig, joint_skeleton: bool = False) -> tuple[Anchors, bonemap.Mapping, Rig]:
    """(anchors of the canonical joints, mapping, the rig they are on): ``rig`` itself, or with
    ``joint_skeleton`` (a control rig) its joint skeleton (:func:`controls.joint_rig`). Raises
    :class:`MapError` naming what is wrong."""
    mapping = effective_map(obj)
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
        anchors = Anchors.from_map(rig, mapping)
        return anchors, mapping, tips_along_the_limb(rig, anchors)  # a hand's tail across it is no finger tip
    except SolveError as e:
        raise MapError(f"Bone map does not fit the hierarchy: {e}; fix it in STRNN > Bone Map") from e
