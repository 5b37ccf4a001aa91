"""Read an armature's rest pose and its action into arrays (the Blender boundary).

Everything returned is NumPy: the rest pose as a :class:`model_core.rig.solve.Rig`, the
local pose channels per frame, and canonical joint positions in world space. Frames
are the scene's; world space is Blender's Z-up in scene units.
"""

from __future__ import annotations

import re
import time
from contextlib import contextmanager, nullcontext

import bpy
import numpy as np
from mathutils import Matrix

from ...model_core.inference.steps import drive
from ...model_core.motion import rotations
from ...model_core.rig.solve import Rig, fk
from . import anim
from .anim import bone_path

_ROT_PATHS = {"QUATERNION": "rotation_quaternion", "AXIS_ANGLE": "rotation_axis_angle"}
STEP_SECONDS = 0.2  # a frame-by-frame read or bake hands back (progress, Esc) about this often, at the least
AWAY_SHARE = 0.1  # ... or so that the time the caller takes in between (drawing the scene) is at most this share
LONGEST_STEP = 5.0  # ... up to this many seconds a step


def matrices(coll, attr: str, n: int) -> np.ndarray:
    """Bulk-read a 4x4 matrix property of ``n`` items -> ``[n, 4, 4]`` (row-major)."""
    buf = np.empty(n * 16, dtype=np.float32)
    coll.foreach_get(attr, buf)
    return buf.reshape(n, 4, 4).transpose(0, 2, 1).astype(np.float64)


def read_rig(obj) -> Rig:
    """Rest pose of an armature object's bones, parents first (armature space)."""
    bones = obj.data.bones
    n = len(bones)
    rest = matrices(bones, "matrix_local", n)
    lengths = np.empty(n, dtype=np.float32)
    bones.foreach_get("length", lengths)
    names = [b.name for b in bones]
    connected = np.array([b.use_connect for b in bones], dtype=bool)  # heads on their parents' tails
    parent_name = [b.parent.name if b.parent else None for b in bones]
    order, placed = [], set()
    while len(order) < n:  # parents first, keeping Blender's order otherwise
        for i in range(n):
            if names[i] not in placed and (parent_name[i] is None or parent_name[i] in placed):
                order.append(i)
                placed.add(names[i])
    index = {names[i]: k for k, i in enumerate(order)}
    parents = [index[parent_name[i]] if parent_name[i] else -1 for i in order]
    return Rig([names[i] for i in order], np.array(parents), rest[order], lengths[order], connected[order])


class KeyCache:
    """The keys of F-curves, read once for many samplings (a long take read in chunks of frames). A baked
    curve (one key on every whole frame, no modifiers) keeps only its first frame and its values."""

    def __init__(self):
        self._keys: dict[int, tuple] = {}

    def keys(self, fc) -> tuple:
        """("baked", first frame, values float32 [n]) or ("keys", frames [n], values [n]) (float64)."""
        key = fc.as_pointer()
        if key not in self._keys:
            self._keys[key] = _read_keys(fc)
        return self._keys[key]


def _read_keys(fc) -> tuple:
    n = len(fc.keyframe_points)
    co = np.empty(2 * n, dtype=np.float32)
    fc.keyframe_points.foreach_get("co", co)
    kx, ky = co[0::2].astype(np.float64), co[1::2]
    plain = len(fc.modifiers) == 0 and fc.extrapolation == "CONSTANT"
    if n and plain and np.allclose(kx, kx[0] + np.arange(n), atol=1e-4) and float(kx[0]).is_integer():
        return ("baked", float(kx[0]), ky.copy())
    return ("keys", kx, ky.astype(np.float64))


def sample_fcurve(fc, frames: np.ndarray, cache: KeyCache | None = None) -> np.ndarray:
    """Values ``[F]`` of an F-curve at scene ``frames`` ``[F]``; exact and fast for baked keys. ``cache``:
    keys already read (else they are read now)."""
    if len(fc.keyframe_points) == 0:
        return np.full(len(frames), fc.evaluate(float(frames[0])) if len(frames) else 0.0)
    found = (cache or KeyCache()).keys(fc)
    frames = np.asarray(frames, np.float64)
    if found[0] == "baked":
        _, first, ky = found
        index = frames - first
        whole = np.abs(index - np.round(index)) < 1e-4
        if np.all(whole | (index < 0) | (index > len(ky) - 1)):
            at = np.clip(np.round(index).astype(np.int64), 0, len(ky) - 1)
            return ky[at].astype(np.float64)
        return np.array([fc.evaluate(float(f)) for f in frames])
    _, kx, ky = found
    n = len(kx)
    inside = (frames >= kx[0]) & (frames <= kx[-1])
    at = np.clip(np.searchsorted(kx, frames - 1e-4), 0, n - 1)
    on_key = np.abs(kx[at] - frames) < 1e-4
    plain = len(fc.modifiers) == 0 and fc.extrapolation == "CONSTANT"
    if plain and np.all(on_key | ~inside):
        return np.where(inside, ky[at], np.where(frames < kx[0], ky[0], ky[-1]))
    return np.array([fc.evaluate(float(f)) for f in frames])


BONE_PATH = re.compile(r'pose\.bones\["((?:[^"\\]|\\.)*)"\]\.(\w+)')  # pose.bones["name"].prop


def bone_channels(fcurves) -> dict[tuple[str, str], dict[int, object]]:
    """{(bone, property): {array index: fcurve}} for pose bone channels of an action."""
    out: dict[tuple[str, str], dict[int, object]] = {}
    for fc in fcurves:
        found = BONE_PATH.fullmatch(fc.data_path)
        if found:
            bone = bpy.utils.unescape_identifier(found[1])  # Blender escapes " and \ in names
            out.setdefault((bone, found[2]), {})[fc.array_index] = fc
    return out


def read_local_pose(obj, rig: Rig, fcurves, frames: np.ndarray, cache: KeyCache | None = None):
    """Local pose channels of every bone at scene ``frames`` ``[F]`` from the action's F-curves (``cache``:
    their keys, when read already).

    Returns ``loc`` ``[F, B, 3]``, ``rot`` ``[F, B, 3, 3]``, ``scale`` ``[F, B, 3]``; channels the
    action does not animate take the pose bone's current value.
    """
    chans = bone_channels(fcurves)
    f = len(frames)
    loc, scale = np.zeros((f, len(rig.names), 3)), np.ones((f, len(rig.names), 3))
    rot = np.empty((f, len(rig.names), 3, 3))
    for b, name in enumerate(rig.names):
        pb = obj.pose.bones[name]
        loc[:, b] = channel_values(chans, name, "location", pb.location, frames, cache)
        scale[:, b] = channel_values(chans, name, "scale", pb.scale, frames, cache)
        rot[:, b] = rotation_matrices(pb.rotation_mode, rotation_values(chans, pb, frames, cache))
    return loc, rot, scale


def channel_values(chans, bone: str, prop: str, current, frames: np.ndarray,
                   cache: KeyCache | None = None) -> np.ndarray:
    """One vector property ``[F, len(current)]`` sampled from its F-curves or held at ``current``."""
    curves = chans.get((bone, prop), {})
    out = np.tile(np.asarray(current, dtype=np.float64), (len(frames), 1))
    for i, fc in curves.items():
        if i < out.shape[1]:
            out[:, i] = sample_fcurve(fc, frames, cache)
    return out


def rotation_property(pb) -> str:
    """The pose bone property its rotation mode keys: ``rotation_quaternion``, ``rotation_axis_angle`` or
    ``rotation_euler``."""
    return _ROT_PATHS.get(pb.rotation_mode, "rotation_euler")


def rotation_values(chans, pb, frames: np.ndarray, cache: KeyCache | None = None) -> np.ndarray:
    prop = rotation_property(pb)
    return channel_values(chans, pb.name, prop, getattr(pb, prop), frames, cache)


def rotation_matrices(mode: str, values: np.ndarray) -> np.ndarray:
    """Blender rotation channel values ``[F, 3 or 4]`` in ``mode`` -> matrices ``[F, 3, 3]``."""
    if mode == "QUATERNION":
        return rotations.quat_to_matrix(values)
    if mode == "AXIS_ANGLE":
        return rotations.axis_angle_to_matrix(values)
    return rotations.euler_to_matrix(values, mode)


def world_matrix(obj) -> np.ndarray:
    """The object's world matrix ``[4, 4]``."""
    return np.array(obj.matrix_world, dtype=np.float64)


def needs_scene_evaluation(obj, fcurves) -> str:
    """Why NumPy forward kinematics would not match Blender for this rig ('' when it does), its place in the world
    included."""
    why = pose_needs_evaluation(obj, fcurves)
    if why:
        return why
    if any(not fc.data_path.startswith("pose.bones") for fc in fcurves):
        return "the action animates the object itself"
    if obj.constraints or obj.parent:
        return "the object has constraints or a parent"
    return ""


def pose_needs_evaluation(obj, fcurves) -> str:
    """Why NumPy forward kinematics would not match Blender for this rig's pose in armature space ('' when it does:
    the object's own motion, parent and constraints do not change it)."""
    why = chain_needs_evaluation(obj, obj.data.bones.keys(), fcurves)
    ad = obj.animation_data
    return why or ("the object has drivers" if ad and len(ad.drivers) else "")


def _driven_bones(obj) -> set[str]:
    """The bones a driver of ``obj`` sets a transform channel of."""
    ad = obj.animation_data
    found = (BONE_PATH.fullmatch(d.data_path) for d in (ad.drivers if ad else ()))
    return {bpy.utils.unescape_identifier(m[1]) for m in found if m}


def _own_reason(obj, bone, driven: set[str]) -> str:
    """Why a bone's own setup keeps NumPy forward kinematics from playing it as Blender does ('' when nothing)."""
    if len(obj.pose.bones[bone.name].constraints):
        return f"bone {bone.name!r} has constraints"
    if not bone.use_inherit_rotation or bone.inherit_scale != "FULL" or not bone.use_local_location:
        return f"bone {bone.name!r} has non-default inheritance"
    return f"bone {bone.name!r} has a driver" if bone.name in driven else ""


def chain_needs_evaluation(obj, names, fcurves) -> str:
    """Why NumPy forward kinematics would not match Blender for the pose in armature space of the bones ``names``
    ('' when it does): a constraint, an inheritance other than the usual or a driver on one of them or a bone above
    them, or NLA strips under the action. Constraints and drivers elsewhere in the rig (its twist bones') do not
    change these bones' pose."""
    bones, seen, driven = obj.data.bones, set(), _driven_bones(obj)
    for name in names:
        b = bones[name]
        while b is not None and b.name not in seen:
            seen.add(b.name)
            why = _own_reason(obj, b, driven)
            if why:
                return why
            b = b.parent
    return "NLA strips play under its action" if nla_beneath(obj, fcurves) else ""


def plain_bones(obj, fcurves) -> set[str]:
    """The bones whose pose in armature space NumPy forward kinematics plays as Blender does
    (:func:`chain_needs_evaluation` finds nothing for them)."""
    if nla_beneath(obj, fcurves):
        return set()
    driven, plain = _driven_bones(obj), {}

    def is_plain(b) -> bool:
        if b.name not in plain:
            plain[b.name] = not _own_reason(obj, b, driven) and (b.parent is None or is_plain(b.parent))
        return plain[b.name]

    return {b.name for b in obj.data.bones if is_plain(b)}


def armature_poses(context, obj, names: list[str], fcurves, frames: np.ndarray) -> np.ndarray:
    """Armature-space pose matrices ``[F, N, 4, 4]`` of the bones ``names`` at scene ``frames`` as the action of
    ``fcurves`` plays them: by NumPy forward kinematics where that plays as Blender does for them
    (:func:`chain_needs_evaluation`; the object may move), else by letting Blender evaluate each frame (the action
    the object plays)."""
    frames = np.asarray(frames, np.float64)
    if chain_needs_evaluation(obj, names, fcurves):
        return pose_matrices_evaluated(context, obj, names, frames)[0]
    return _closed_form(obj, names, fcurves, frames)


def disabled_in_viewports(obj, scene) -> bool:
    """Whether ``obj`` is left out of ``scene``'s evaluation: disabled in viewports itself, or reachable only
    through collections that are (hidden with H it is still evaluated)."""
    if obj.hide_viewport:
        return True

    def reaches(coll) -> bool:
        if getattr(coll, "hide_viewport", False):
            return False
        return obj.name in coll.objects or any(reaches(child) for child in coll.children)

    return not reaches(scene.collection)


def nla_beneath(obj, fcurves) -> bool:
    """Whether NLA strips under the object's action show in its pose (a layered shot: the body's motion in strips,
    the action a tweak over them), so that the action's keys (``fcurves``) alone do not say it: the action blends
    other than Replace or at less than full influence, or a strip animates a channel the action does not key."""
    ad = obj.animation_data
    if not (ad and ad.use_nla):
        return False
    strips = [s for t in ad.nla_tracks if not t.mute for s in t.strips if s.action is not None and not s.mute]
    if not strips:
        return False
    if ad.action is None or ad.action_blend_type != "REPLACE" or ad.action_influence < 1.0:
        return True
    keyed = {(fc.data_path, fc.array_index) for fc in fcurves}
    return any((fc.data_path, fc.array_index) not in keyed
               for s in strips for fc in anim.Channels(s.action, None).fcurves)


def own_inheritance(obj, bones: list[str]) -> list[str]:
    """Those of ``bones`` and their ancestors whose pose does not simply follow their parent's: Inherit Rotation off
    (a hinge) or Local Location off (Bone Properties > Relations). The solve's forward kinematics assumes the
    usual inheritance, so keys it computes for such a rig would put the bones elsewhere."""
    out, seen = [], set()
    for name in bones:
        bone = obj.data.bones[name]
        while bone is not None and bone.name not in seen:
            seen.add(bone.name)
            if not bone.use_inherit_rotation or not bone.use_local_location:
                out.append(bone.name)
            bone = bone.parent
    return out


def object_moves(obj, fcurves) -> bool:
    """Whether the armature object's own world matrix can change from frame to frame: its action (``fcurves``) or
    drivers animate the object itself, or it has a parent or constraints."""
    ad = obj.animation_data
    paths = [fc.data_path for fc in fcurves] + ([d.data_path for d in ad.drivers] if ad else [])
    return bool(obj.parent or len(obj.constraints) or any(not p.startswith("pose.bones") for p in paths))


def stays_put(obj) -> bool:
    """Whether ``obj`` is an empty that nothing moves: no animation (action, NLA strips, drivers), no constraint, and a
    parent, if any, that stays put too. Its place is the same at every frame."""
    while obj is not None:
        ad = obj.animation_data
        if obj.type != "EMPTY" or len(obj.constraints) or (ad is not None and (
                ad.action is not None or len(ad.nla_tracks) or len(ad.drivers))):
            return False
        obj = obj.parent
    return True


def _read_others(obj) -> list:
    """The objects but ``obj`` itself that it reads (:func:`_read_by`); None for a name not found (a linked
    library's object of the same name as a local one)."""
    return [bpy.data.objects.get(n) for n in sorted(_read_by(obj) - {obj.name})]


def _read_by(obj) -> set[str]:
    """The objects ``obj``'s pose or place is read from: its parent, its and its bones' constraints' targets, its
    drivers' (and its armature's) variables' objects."""
    out = {obj.parent.name} if obj.parent is not None else set()
    cons = list(obj.constraints) + [c for pb in getattr(obj.pose, "bones", ()) for c in pb.constraints]
    for con in cons:
        for target in [getattr(con, "target", None), getattr(con, "pole_target", None)] + [
                t.target for t in getattr(con, "targets", ())]:
            if target is not None:
                out.add(target.name)
    for ad in (obj.animation_data, obj.data.animation_data):
        for d in ad.drivers if ad else ():
            out |= {t.id.name for v in d.driver.variables for t in v.targets if isinstance(t.id, bpy.types.Object)}
    return out


class StandIn:
    """The object's action played through a stand-in action of one key per channel, while its controls are baked or
    while a rig that plays alone (:func:`plays_alone`) is read: at each frame (:meth:`at`) every channel the action
    animates takes its value there (sampled once, F-curve modifiers and all; not a muted channel or group), and a
    control is set by its keys (:meth:`put`). Blender re-evaluates the pose after a key of
    a small action changes at the cost of the pose alone, where a pose bone's transform set directly has it copy the
    whole object first, and a key of a long action the whole action (a generated Rigify rig: about 3 ms against 6 to
    9). Where the object had no action (nothing keyed yet), the controls' channels alone. :meth:`close` puts the
    action (or none) back and removes the stand-in."""

    def __init__(self, obj, chosen: list, switches: list, frames: np.ndarray):
        """``chosen``: the controls to be set (each with ``.bone``); ``switches``: those held at their ``.value``
        (each with ``.bone``, ``.prop``); ``frames``: the scene frames :meth:`at` plays."""
        self.obj, self.made = obj, obj.animation_data is None
        ad = obj.animation_data or obj.animation_data_create()
        self.action, self.slot = ad.action, getattr(anim.slot_of(obj), "identifier", None)
        source = [fc for fc in anim.active_fcurves(obj) if not fc.mute and not (fc.group and fc.group.mute)]
        self.stand_in = bpy.data.actions.new("STRNN bake")
        try:
            channels = anim.Channels(self.stand_in, ad, ensure=True)
            on = {f'pose.bones["{bpy.utils.escape_identifier(s.bone)}"]["{bpy.utils.escape_identifier(s.prop)}"]':
                  s.value for s in switches}
            self.curves, columns = [], []
            for fc in source:
                self.curves.append(self._curve(channels, fc.data_path, fc.array_index, frames[0]))
                value = on.get(fc.data_path)
                columns.append(np.full(len(frames), value, np.float64) if value is not None
                               else np.array([fc.evaluate(float(f)) for f in frames], np.float64))
            index = {(fc.data_path, fc.array_index): k for k, fc in enumerate(source)}
            self.channels: dict[str, tuple[list[int], list[int]]] = {}  # bone: (location, rotation) columns
            for c in chosen:
                pb = obj.pose.bones[c.bone]
                ks = []
                for prop in ("location", rotation_property(pb)):
                    path = bone_path(c.bone, prop)
                    for i in range(len(getattr(pb, prop))):
                        if (path, i) not in index:  # not keyed: it starts where the frame before left it
                            index[path, i] = len(self.curves)
                            self.curves.append(self._curve(channels, path, i, frames[0], getattr(pb, prop)[i]))
                            columns.append(np.full(len(frames), np.nan))
                        ks.append(index[path, i])
                self.channels[c.bone] = (ks[:3], ks[3:])
            self.values = np.stack(columns, axis=1) if columns else np.zeros((len(frames), 0))
            self.now = np.array([fc.keyframe_points[0].co[1] for fc in self.curves], np.float64)
            slots = getattr(self.stand_in, "slots", ())
            anim.assign_action(obj, self.stand_in, slots[0].identifier if len(slots) else None)
        except Exception:
            self.close()
            raise

    @staticmethod
    def _curve(channels: anim.Channels, path: str, index: int, frame: float, value: float = 0.0):
        fc = channels.ensure(path, index, "STRNN")
        fc.keyframe_points.insert(float(frame), float(value), options={"FAST"})
        return fc

    def _set(self, k: int, value: float) -> None:
        if value != self.now[k]:
            self.curves[k].keyframe_points[0].co[1] = value
            self.now[k] = value

    def at(self, i: int) -> None:
        """Every channel at the ``i``-th frame's value; a control's channel the action does not key, as it is."""
        for k, value in enumerate(self.values[i]):
            if not np.isnan(value):
                self._set(k, float(value))

    def put(self, pb, basis: Matrix) -> None:
        """Key pose bone ``pb`` (a chosen control) to the local transform ``basis`` (its scale as it is)."""
        loc_ks, rot_ks = self.channels[pb.name]
        loc, quat, _ = basis.decompose()
        if pb.rotation_mode == "QUATERNION":
            rot = tuple(quat)
        elif pb.rotation_mode == "AXIS_ANGLE":
            axis, angle = quat.to_axis_angle()
            rot = (angle, *axis)
        else:
            rot = tuple(quat.to_euler(pb.rotation_mode, pb.rotation_euler))
        for k, value in zip(loc_ks + rot_ks, tuple(loc) + rot):
            self._set(k, float(value))

    def close(self) -> None:
        ad = self.obj.animation_data
        if ad is not None and ad.action == self.stand_in:
            anim.assign_action(self.obj, self.action, self.slot)
        if self.made and self.obj.animation_data is not None:
            self.obj.animation_data_clear()
        bpy.data.actions.remove(self.stand_in)


TIMED_CONSTRAINTS = {"FOLLOW_TRACK", "CAMERA_SOLVER", "OBJECT_SOLVER", "TRANSFORM_CACHE"}  # read the scene's time


def plays_alone(obj) -> bool:
    """Whether armature ``obj``'s pose and place at a frame are its action's channels there and nothing else of the
    scene: no parent or constraint reading another object (but an empty that stays put, below), no driver reading
    another object or the scene's time, no NLA strips playing, its armature not animated. Such a rig can be played frame
    by frame through a :class:`StandIn` and Blender made to evaluate it alone, where setting the scene's frame evaluates
    every animated object in it (the other characters of a shot). A parent or a constraint's target that stays put
    (:func:`stays_put`: an empty nothing moves, as a character's root or an IK target left where it was placed) is not
    the scene moving it. Where unsure (a driver's Python expression), not."""
    if any(o is None or not stays_put(o) for o in _read_others(obj)):  # (a driver reading one: below)
        return False
    cons = list(obj.constraints) + [c for pb in obj.pose.bones for c in pb.constraints]
    if any(c.type in TIMED_CONSTRAINTS for c in cons):
        return False
    ad, data_ad = obj.animation_data, obj.data.animation_data
    if ad is not None and ad.use_nla and any(not t.mute and len(t.strips) for t in ad.nla_tracks):
        return False
    if data_ad is not None and (data_ad.action is not None or len(data_ad.nla_tracks)):
        return False
    for d in [d for a in (ad, data_ad) if a is not None for d in a.drivers]:
        driver = d.driver
        if driver.type == "SCRIPTED" and (not driver.is_simple_expression
                                          or re.search(r"\bframe\b", driver.expression)):
            return False
        for v in driver.variables:
            if v.type == "CONTEXT_PROP" or any(t.id not in (None, obj, obj.data) for t in v.targets):
                return False
    return True


@contextmanager
def evaluated_alone(context, obj):
    """A view layer where Blender evaluates ``obj`` and nothing else: a scene of its own (removed on exit) in which the
    object is linked, not copied (with the empties that stay put it hangs from or aims at). For a rig that plays alone
    (:func:`plays_alone`), played through a :class:`StandIn`: updating the scene's own view layer pays for every object
    of the shot at each update (a generated Rigify rig, 2 ms a frame alone in its scene, 9 ms beside three more
    characters and a set of 2,000 objects), this one for the rig alone. Its update makes its evaluation the one Blender
    writes back to the rig (as the scene's would); after it, :func:`back_in_its_scene` makes the scene's own the one
    again."""
    alone = bpy.data.scenes.new("STRNN evaluation")
    try:
        for o in [obj] + _read_others(obj):  # the rig, and the empties that stay put it hangs from or aims at
            alone.collection.objects.link(o)
        yield alone.view_layers[0]
    finally:
        bpy.data.scenes.remove(alone)


def back_in_its_scene(context, obj, frame: tuple[int, float] | None) -> None:
    """After a frame-by-frame read or bake of ``obj``, the scene evaluated as it stands: set back to ``frame`` (frame,
    subframe) where the read set the scene's frame (the meshes ``obj`` deforms paused meanwhile: they are evaluated
    once, after), else (the rig evaluated alone, :func:`evaluated_alone`; the scene's frame never moved) its view
    layer updated, which evaluates the rig with its own action again and makes the scene's evaluation the one Blender
    writes back to it. Either costs one evaluation of the shot."""
    if frame is None:
        context.view_layer.update()
        return
    with skin_paused(context, obj):
        context.scene.frame_set(frame[0], subframe=frame[1])


@contextmanager
def skin_paused(context, obj):
    """While Blender evaluates armature ``obj`` frame by frame for a read or a bake, the meshes it deforms (each
    Armature modifier on it shown in viewports) are left undeformed, so each evaluation costs the rig alone and not
    every skinned mesh too (a 30,000-vertex body adds half a generated Rigify rig's own evaluation). A mesh the rig's
    pose or place is read from (:func:`_read_by`) and a linked or overridden one are left as they are. Every
    modifier is put back as it was, whatever happens; nothing in between is drawn."""
    needed, paused = _read_by(obj), []
    try:
        for other in context.scene.objects:
            if other.name in needed or other.library is not None or other.override_library is not None:
                continue
            for md in getattr(other, "modifiers", ()):
                if md.type == "ARMATURE" and md.object == obj and md.show_viewport:
                    md.show_viewport = False
                    paused.append(md)
        yield
    finally:
        for md in paused:
            md.show_viewport = True


def in_steps(context, obj, count: int, each):
    """Call ``each(i)`` for ``i`` in ``range(count)``, frame by frame of a read or bake of armature ``obj``, the
    meshes it deforms paused meanwhile (:func:`skin_paused`): a step generator that hands back after about
    :data:`STEP_SECONDS` of them (at least one) with the fraction done, so that an operator shows progress and stops
    on Esc; in between the meshes are deformed again, as Blender then draws the scene. Where the caller keeps it
    waiting longer (a heavy scene to draw), each step lasts longer in proportion, so that the time away stays at most
    :data:`AWAY_SHARE` of the whole (a step at most :data:`LONGEST_STEP` seconds)."""
    i, step = 0, STEP_SECONDS
    while i < count:
        since = time.perf_counter()
        with skin_paused(context, obj):
            while i < count:
                each(i)
                i += 1
                if time.perf_counter() - since >= step:
                    break
        if i < count:
            left = time.perf_counter()
            yield i / count
            away = time.perf_counter() - left
            step = min(max(STEP_SECONDS, away * (1.0 - AWAY_SHARE) / AWAY_SHARE), LONGEST_STEP)


def world_matrices_evaluated_steps(context, obj, frames: np.ndarray):
    """The object's world matrices ``[F, 4, 4]`` at scene ``frames`` as Blender evaluates each frame (a parent,
    constraints, its own channels): :func:`pose_matrices_evaluated_steps` reading no bone, so a step generator the
    same way (the fraction of the frames read; closed part way, the scene's frame put back), and an object that plays
    alone is evaluated alone."""
    _, world = yield from pose_matrices_evaluated_steps(context, obj, [], frames)
    return world


def pose_matrices_fast(obj, rig: Rig, fcurves, frames: np.ndarray, cache: KeyCache | None = None) -> np.ndarray:
    """Armature-space pose matrices ``[F, B, 4, 4]`` by NumPy forward kinematics."""
    loc, rot, scale = read_local_pose(obj, rig, fcurves, frames, cache)
    return fk(rig, loc, rot, scale)


def with_bones_above(rig: Rig, names: list[str]) -> Rig:
    """The bones ``names`` of ``rig`` and every bone above them, parents first: all that forward kinematics needs to
    place them."""
    keep = np.zeros(len(rig.names), dtype=bool)
    index = {n: b for b, n in enumerate(rig.names)}
    for name in names:
        b = index[name]
        while b >= 0 and not keep[b]:
            keep[b] = True
            b = int(rig.parents[b])
    if keep.all():
        return rig
    order = np.flatnonzero(keep)
    new = np.full(len(rig.names), -1)
    new[order] = np.arange(len(order))
    parents = [int(new[p]) if p >= 0 else -1 for p in rig.parents[order]]
    return Rig([rig.names[b] for b in order], np.array(parents), rig.rest[order], rig.lengths[order],
               rig.connected[order])


def pose_matrices(context, obj, names: list[str], fcurves, frames: np.ndarray,
                  cache: KeyCache | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Pose matrices ``[F, N, 4, 4]`` of the bones ``names`` and world matrices ``[F, 4, 4]`` at scene ``frames`` as
    Blender plays the action of F-curves ``fcurves``: by NumPy forward kinematics over them and the bones above them
    where that plays as Blender does (:func:`needs_scene_evaluation`: a rig an exporter baked), else by letting
    Blender evaluate each frame (:func:`pose_matrices_evaluated`)."""
    frames = np.asarray(frames, np.float64)
    if needs_scene_evaluation(obj, fcurves):
        return pose_matrices_evaluated(context, obj, names, frames)
    return _closed_form(obj, names, fcurves, frames, cache), np.broadcast_to(world_matrix(obj), (len(frames), 4, 4))


def _closed_form(obj, names: list[str], fcurves, frames: np.ndarray, cache: KeyCache | None = None) -> np.ndarray:
    """Armature-space pose matrices ``[F, N, 4, 4]`` of the bones ``names`` by NumPy forward kinematics over them and
    the bones above them, from the F-curves ``fcurves``."""
    rig = with_bones_above(read_rig(obj), names)
    index = {n: b for b, n in enumerate(rig.names)}
    return pose_matrices_fast(obj, rig, fcurves, frames, cache)[:, [index[n] for n in names]]


def pose_matrices_evaluated(context, obj, rig: Rig | list[str], frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`pose_matrices_evaluated_steps` run to the end."""
    return drive(pose_matrices_evaluated_steps(context, obj, rig, frames))


def pose_matrices_evaluated_steps(context, obj, rig: Rig | list[str], frames: np.ndarray):
    """Pose matrices ``[F, B, 4, 4]`` of the bones of ``rig`` (or of the bones named) and world matrices ``[F, 4, 4]``
    by letting Blender evaluate each frame (constraints, drivers, parents; its skin paused); the scene's current frame
    is restored, closed part way too. A step generator (:func:`in_steps`: the fraction of the frames read). A rig
    that plays alone (:func:`plays_alone`) is played through a :class:`StandIn` and evaluated alone, the scene's other
    animated objects left as they are."""
    scene, layer = context.scene, context.view_layer
    keep = (scene.frame_current, scene.frame_subframe)
    names = rig.names if isinstance(rig, Rig) else list(rig)
    order = {name: i for i, name in enumerate(obj.pose.bones.keys())}
    perm = [order[n] for n in names]
    out = np.empty((len(frames), len(names), 4, 4))
    world = np.empty((len(frames), 4, 4))
    stand_in = None

    def read(k: int) -> None:
        if stand_in is not None:  # the rig alone: its channels at the frame, the scene's frame as it is
            stand_in.at(k)
            layer.update()
        else:
            f = frames[k]
            scene.frame_set(int(np.floor(f)), subframe=float(f - np.floor(f)))
        if perm:
            out[k] = matrices(obj.pose.bones, "matrix", len(order))[perm]
        world[k] = world_matrix(obj)

    alone = len(frames) > 0 and plays_alone(obj)
    try:
        if alone and not anim.active_fcurves(obj):  # nothing plays: one pose
            with skin_paused(context, obj):
                layer.update()
                out[:], world[:] = matrices(obj.pose.bones, "matrix", len(order))[perm], world_matrix(obj)
            return out, world
        if alone:
            stand_in = StandIn(obj, [], [], frames)
        try:
            with evaluated_alone(context, obj) if alone else nullcontext(layer) as layer:
                yield from in_steps(context, obj, len(frames), read)
        finally:
            if stand_in is not None:
                stand_in.close()
    finally:
        back_in_its_scene(context, obj, None if alone else keep)
    return out, world
