"""Building blocks of the stages (``stages/``): check the input, read joint positions,
convert between world and armature space, and write solved poses into a new action.

Bad input raises :class:`UserError` (what is wrong and how to fix it) before anything in
the file changes, so a failed run leaves the scene exactly as it was.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace as replace_set

import bpy
import numpy as np

from ...model_core.inference.steps import drive, share
from ...model_core.motion import rotations
from ...model_core.motion.conventions import (  # noqa: F401  (MIN_MODEL_FRAMES, min_scene_frames: the stages')
    JOINT_INDEX,
    JOINTS,
    MIN_MODEL_FRAMES,
    min_scene_frames,
    yup_to_zup,
    zup_to_yup,
)
from ...model_core.motion.features import facing
from ...model_core.motion.geometry import nearest_rotation
from ...model_core.ops.root_motion import carried_root
from ...model_core.rig import controls as controls_core
from ...model_core.rig.controls import Control, ControlSet, chains_on_joints, visual_local
from ...model_core.rig.rigs import leg_length
from ...model_core.rig.solve import Anchors, Rig, anchor_positions, fk, hips_carrier, solve, solved_bones
from . import anim, controls, mapping, rig_io
from .anim import bone_path


class UserError(ValueError):
    """Bad input: the message says what is wrong and how to fix it."""


@dataclass
class Clip:
    """An armature with its action, rig and bone map, ready to read and write."""

    obj: object
    action: object
    channels: anim.Channels
    rig: Rig
    anchors: Anchors
    mapping: dict
    world: np.ndarray  # (4, 4)
    fps: float
    first: int
    last: int
    controls: ControlSet | None = None  # a control rig's: ``rig`` is then its joint skeleton, written by a bake
    layered: bool = False  # NLA strips under the action show through it (rig_io.nla_beneath)
    # {bone: the written bone carrying it}: a baked control rig's skin (:func:`carried`), a plain rig's keyed
    # followers (:func:`followers`)
    carried: dict[str, str] = field(default_factory=dict)
    # {scene frame: (pose matrices [B, 4, 4], world matrix [4, 4])} of ``rig`` as Blender evaluated it during this
    # operation (:func:`skeleton_pose`): a frame read for the joints is not evaluated again for the solve
    evaluated: dict = field(default_factory=dict, repr=False)


def scene_fps(scene) -> float:
    return scene.render.fps / scene.render.fps_base


def keys_per_second(context, obj) -> float:
    """How many of the action's frames make one second of its motion: the armature's Keys per Second
    (a take imported at another rate than it was captured), else the scene's frame rate."""
    return float(getattr(obj, "strnn_keys_per_second", 0.0) or scene_fps(context.scene))


def check_object(obj, need_action: bool = True) -> None:
    """Raise :class:`UserError` unless ``obj`` is an editable, animated (or, without ``need_action``,
    any) armature with positive scale."""
    if obj is None:
        raise UserError("No active object: select an armature with an action in the 3D Viewport")
    if obj.type != "ARMATURE":
        raise UserError(f"{obj.name!r} is a {obj.type.lower()}, not an armature: select an armature")
    if obj.library is not None:  # an override is local (its armature data may stay linked: only read)
        raise UserError(f"The object {obj.name!r} is linked from {obj.library.filepath!r} and cannot be animated "
                        "here: add a library override (Object > Library Override > Make) or make it local")
    if obj.animation_data and obj.animation_data.use_tweak_mode:
        raise UserError(f"{obj.name!r} is in NLA tweak mode, so its action cannot be swapped for a new one: "
                        "leave it (NLA Editor > Edit > Stop Tweaking Strip Actions, or Tab there) and try again")
    action = obj.animation_data.action if obj.animation_data else None
    if action is None and need_action:
        raise UserError(f"{obj.name!r} has no action: assign one in the Action Editor, or import a BVH")
    world = np.array(obj.matrix_world)[:3, :3]
    if min(obj.scale) <= 0 or np.linalg.det(world) <= 1e-12:
        raise UserError(f"{obj.name!r} has zero or negative scale {tuple(round(s, 3) for s in obj.scale)}: "
                        "set a positive scale (or apply it with Object > Apply > Scale)")


def prepare(context, obj) -> Clip:
    """Check ``obj`` and gather what reading and writing need; raises :class:`UserError`."""
    check_object(obj)
    action = obj.animation_data.action
    channels = anim.Channels(action, obj.animation_data)
    if not any(fc.data_path.startswith("pose.bones") for fc in channels.fcurves):
        raise UserError(f"The action {action.name!r} animates no bones: key the armature's pose first")
    check_keys(action, channels.fcurves)
    first, last = (int(round(x)) for x in action.frame_range)
    return clip_of(context, obj, action, channels, first, last)


def prepare_any(context, obj) -> Clip:
    """:func:`prepare`, or for an armature without an action the same minus the action."""
    if obj is not None and obj.type == "ARMATURE" and obj.animation_data and obj.animation_data.action:
        return prepare(context, obj)
    check_object(obj, need_action=False)
    frame = context.scene.frame_start
    return clip_of(context, obj, None, None, frame, frame)


def clip_of(context, obj, action, channels, first: int, last: int) -> Clip:
    """The :class:`Clip` of a checked armature (see :func:`rig_of`)."""
    rig, anchors, bone_map, found = rig_of(obj)
    fcurves = channels.fcurves if channels else []
    check_evaluated(context, obj, fcurves, found)
    clip = Clip(obj, action, channels, rig, anchors, bone_map, rig_io.world_matrix(obj),
                keys_per_second(context, obj), first, last, found, rig_io.nla_beneath(obj, fcurves))
    if found is not None and found.name == BAKED_BONES:
        clip.carried = carried(context, clip)
    elif found is None:
        clip.carried = followers(context, clip)
    return clip


CARRY_SAMPLES = 32  # frames of the take read to tell which bone each carried bone moves with


def carried(context, clip: Clip) -> dict[str, str]:
    """{bone: the written bone it moves with} for the bones to carry so that a baked control rig's skin
    (:func:`mapping.skin`) is not left behind by keys on its deform bones alone (:func:`controls.carried_bones`:
    Rigify's face, pelvis and shoulders hang from MCH-, ORG- and control bones, which no longer follow anything),
    read over the take."""
    full = rig_io.read_rig(clip.obj)
    frames = np.unique(np.linspace(clip.first, clip.last, CARRY_SAMPLES).round())
    pose, _ = rig_io.pose_matrices(context, clip.obj, full.names, _fcurves(clip), frames)
    leg = leg_length(anchor_positions(clip.rig, clip.anchors, clip.rig.rest[None]))  # armature units
    found = controls_core.carried_bones(full, [clip.rig.names[b] for b in written_bones(clip)],
                                        mapping.skin(clip.obj), pose, leg)
    return {full.names[c]: full.names[w] for c, w in found.items()}


def followers(context, clip: Clip) -> dict[str, str]:
    """{bone: the written bone it moves with} for a plain rig's keyed bones that kept to a written bone over the take
    (:func:`controls.keyed_followers`: an Unreal rig's ``ik_foot_l`` on ``foot_l``, a prop keyed in a hand), or on a
    rig with no action yet those that rest where a written bone rests (:func:`controls.rest_twins`), keyed with it
    wherever an operation writes (:func:`write_pose`). Only bones whose pose their curves alone say, as those of the
    written bones (no constraint, driver or unusual inheritance on them or above them:
    :func:`rig_io.chain_needs_evaluation`; a twist bone's constraint elsewhere does not count), are read and set so."""
    fcurves = _fcurves(clip)
    written = [clip.rig.names[b] for b in written_bones(clip)]
    plain = rig_io.plain_bones(clip.obj, fcurves)
    if not plain.issuperset(written):
        return {}
    plain -= set(written)
    full = rig_io.read_rig(clip.obj)
    leg = leg_length(anchor_positions(clip.rig, clip.anchors, clip.rig.rest[None]))  # armature units
    if clip.channels is None:
        found = {c: w for c, w in controls_core.rest_twins(full, written, leg).items() if full.names[c] in plain}
    else:
        keyed = {bone for bone, _ in rig_io.bone_channels(fcurves)} & plain
        if not keyed:
            return {}
        frames = np.unique(np.linspace(clip.first, clip.last, CARRY_SAMPLES).round())
        index = {n: b for b, n in enumerate(full.names)}
        read = sorted(keyed | set(written), key=index.__getitem__)
        pose = np.broadcast_to(np.eye(4), (len(frames), len(full.names), 4, 4)).copy()  # only those read are used
        pose[:, [index[n] for n in read]] = rig_io.armature_poses(context, clip.obj, read, fcurves, frames)
        found = controls_core.keyed_followers(full, written, keyed, pose, leg)
    return {full.names[c]: full.names[w] for c, w in found.items()}


OWN_BONES = "own bones"  # the controls of a plain rig keyed by the visual bake: each written bone its own


def check_evaluated(context, obj, fcurves, found: ControlSet | None) -> None:
    """A :class:`UserError` where reading or writing ``obj`` needs Blender to evaluate it frame by frame
    (constraints, drivers, a moving object, controls to bake) but it is disabled in viewports, itself or through
    its collections (Blender then leaves its pose as it is at every frame), or shows its Rest Position (every
    frame evaluates to the rest pose)."""
    disabled, at_rest = rig_io.disabled_in_viewports(obj, context.scene), obj.data.pose_position == "REST"
    if not disabled and not at_rest:
        return
    why = ("its controls are set by a visual bake" if found is not None
           else rig_io.needs_scene_evaluation(obj, fcurves)
           or ("the object itself moves" if rig_io.object_moves(obj, fcurves) else ""))
    if why and disabled:
        raise UserError(f"{obj.name!r} is disabled in viewports (itself or its collection), so Blender does not "
                        f"evaluate its pose, which this needs ({why}): enable it (Object Properties > Visibility > "
                        "Show in Viewports, or the collection's screen icon in the Outliner) and run it again")
    if why:
        raise UserError(f"{obj.name!r} shows its Rest Position, so Blender evaluates every frame in the rest pose, and "
                        f"this needs its animated pose ({why}): switch it to Pose Position (Armature Properties > "
                        "Skeleton) and run it again")


# Families of control rigs whose deform bones hang from other bones than each other (Rigify's DEF- limbs from its
# ORG- bones; Auto-Rig Pro's): once an exporter has baked them, no bone map of theirs fits the hierarchy.
BAKED_CONTROL_RIGS = {"rigify", "rigify_deform", "auto_rig_pro", "mmd", "mmd_english", "mmd_deform"}
# The controls of such a rig: its mapped deform bones, each keyed by the visual bake on the joint skeleton.
BAKED_BONES = "baked bones"


def rig_of(obj) -> tuple[Rig, Anchors, dict, ControlSet | None]:
    """(rig, anchors, bone map, controls) of an armature: its rig (a control rig's joint skeleton) with the
    canonical joints on it; raises :class:`UserError` when the bone map or the controls do not fit, or
    keys on the mapped bones would not show."""
    rig = rig_io.read_rig(obj)
    found, problems = controls.listed(obj)
    if problems:
        raise UserError(f"The controls set for {obj.name!r} in STRNN > Bone Map > Controls: {problems[0]}")
    if found is not None:  # each limb keyed where the action animates it (its IK/FK switch at its last frame)
        found = controls.as_animated(obj, found)
        absent = found.missing(set(rig.names))
        if absent:
            raise UserError(f"The controls set for {obj.name!r} name bones it does not have ({', '.join(absent)}): "
                            "fix them in STRNN > Bone Map > Controls")
    try:
        anchors, bone_map, rig = mapping.resolve(obj, rig, joint_skeleton=found is not None)
    except mapping.MapError as e:
        if not (found is None and e.__cause__ is not None and mapping.baked(obj)
                and mapping.auto_map(obj)[0] in BAKED_CONTROL_RIGS):  # (a bone map that does not fit the hierarchy)
            raise UserError(str(e)) from e
        # a control rig an exporter baked: its deform bones keyed on a joint skeleton, each its own control, and the
        # rest of its skin carried with them (:func:`carried`)
        full = rig
        try:
            anchors, bone_map, rig = mapping.resolve(obj, rig, joint_skeleton=True)
        except mapping.MapError as again:
            raise UserError(str(again)) from again
        written = [rig.names[b] for b in solved_bones(rig, anchors)]
        loose = controls_core.loose_bones(full, written)
        found = ControlSet(BAKED_BONES, [Control(name, name, name in loose) for name in written])
    ad, fcurves = obj.animation_data, anim.active_fcurves(obj)
    layered = rig_io.nla_beneath(obj, fcurves)
    if layered and ad.action is not None and ad.action_blend_type != "REPLACE":
        raise UserError(f"{obj.name!r}'s action blends over its NLA strips by {ad.action_blend_type.title()}, so new "
                        "keys would add to the strips' motion: set the action's Blending to Replace (NLA Editor, the "
                        "action's track, Sidebar > Animation Data), or bake the strips into one action (Object > "
                        "Animation > Bake Action), and run it again")
    if found is None:
        written, hips = [rig.names[b] for b in solved_bones(rig, anchors)], bone_map["hips"][0]
        mover = rig.names[located(rig, anchors)]  # the bone keyed with the hips' place
        check_not_driven(obj, written + ([mover] if mover != hips else []), mover)
        # keys set by solving alone would land elsewhere (bones that do not simply follow their parents), or blend
        # with NLA strips under the action: bake them, each written bone its own control, the hips moved by theirs
        # where they can move (connected to a root, the root carries them: _hips_on_root)
        if rig_io.own_inheritance(obj, written) or layered:
            found = ControlSet(OWN_BONES, [Control(name, name, name == hips == mover) for name in written])
            anchors, bone_map, rig = mapping.resolve(obj, rig, joint_skeleton=True)
    return rig, anchors, bone_map, found


def located(rig: Rig, anchors: Anchors) -> int:
    """The bone that the hips' place is keyed on: the hips bone, or where that is connected to its parent (its
    location does nothing in Blender) the bone above that carries it (:func:`solve.hips_carrier`)."""
    hips = int(anchors.bone[JOINT_INDEX["hips"]])
    carrier = hips_carrier(rig, hips)
    return hips if carrier is None else carrier


# Constraints that set a bone's transform outright (keys on the bone would not show); limits and the like pass.
OVERRIDING = {"COPY_TRANSFORMS", "COPY_ROTATION", "CHILD_OF", "DAMPED_TRACK", "TRACK_TO", "LOCKED_TRACK",
              "STRETCH_TO", "ARMATURE", "TRANSFORM", "IK", "SPLINE_IK"}


def check_not_driven(obj, bones: list[str], moved: str = "") -> None:
    """A :class:`UserError` when a bone that would be keyed follows a constraint that overrides its keys, or a
    driver sets one of the channels it would be keyed on (its rotation; the location of ``moved``, the hips
    bone), saying to key its controls instead."""
    ad = obj.animation_data
    driven = {(d.data_path, d.array_index) for d in ad.drivers} if ad else set()
    for name in bones:
        props = (rig_io.rotation_property(obj.pose.bones[name]),) + (("location",) if name == moved else ())
        hit = next(((prop, i) for prop in props for p, i in sorted(driven) if p == bone_path(name, prop)), None)
        if hit is not None:
            raise UserError(f"Bone {name!r} has a driver on {hit[0]}[{hit[1]}], so keys written on "
                            "it would not show: remove the driver, or set the bones the animator keys in STRNN > "
                            "Bone Map > Controls")
        for con in obj.pose.bones[name].constraints:
            if con.type in OVERRIDING and not con.mute and con.influence > 0:
                target = getattr(con, "subtarget", "") or getattr(getattr(con, "target", None), "name", "")
                raise UserError(f"Bone {name!r} follows a {con.type} constraint{f' ({target!r})' if target else ''}, "
                                "so keys written on it would not show: set the bones the animator keys in STRNN > "
                                "Bone Map > Controls (Controls from Preset fills them for a known rig)")


def check_keys(action, fcurves) -> None:
    """A :class:`UserError` naming the bone, channel and frame of the first key that is not a finite
    number (NaN or infinite, or the largest float that Blender keeps for infinity), before any model
    runs on it."""
    for fc in fcurves:
        co = np.empty(2 * len(fc.keyframe_points), np.float64)
        fc.keyframe_points.foreach_get("co", co)
        bad = ~(np.abs(co.reshape(-1, 2)) < 1e30).all(1)  # NaN, or inf (which Blender stores as the largest float)
        if bad.any():
            frame, value = co.reshape(-1, 2)[int(np.argmax(bad))]
            found = rig_io.BONE_PATH.fullmatch(fc.data_path)
            what = (f"bone {bpy.utils.unescape_identifier(found[1])!r}, {found[2]}[{fc.array_index}]" if found
                    else f"{fc.data_path}[{fc.array_index}]")
            raise UserError(f"The action {action.name!r} has a key of {value} at frame {frame:g} ({what}): fix "
                            "or delete that key in the Graph Editor and run again")


EVALUATED_BYTES = 64 << 20  # a clip remembers the frames Blender evaluated for it up to this size
CHUNK_FRAMES = 1024  # frames read or solved at a time: a long take's per-bone arrays never all at once


def chunks(n: int, size: int = CHUNK_FRAMES):
    """Slices ``[a, b)`` covering ``range(n)`` in pieces of at most ``size``."""
    return [slice(a, min(a + size, n)) for a in range(0, n, size)]


def _fcurves(clip: Clip) -> list:
    """The F-curves of the clip's action (none where the armature has no action)."""
    return list(clip.channels.fcurves) if clip.channels is not None else []


def skeleton_pose(context, clip: Clip, frames: np.ndarray,
                  cache: rig_io.KeyCache | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`skeleton_pose_steps` run to the end."""
    return drive(skeleton_pose_steps(context, clip, frames, cache))


def skeleton_pose_steps(context, clip: Clip, frames: np.ndarray, cache: rig_io.KeyCache | None = None):
    """Armature-space pose matrices ``[F, B, 4, 4]`` of the clip's rig (a control rig's joint skeleton) and world
    matrices ``[F, 4, 4]`` at scene ``frames`` as its action plays (:func:`rig_io.pose_matrices`). Where Blender
    evaluates each frame, a step generator of the fraction read (:func:`rig_io.pose_matrices_evaluated_steps`), and
    the frames are remembered on the clip (:attr:`Clip.evaluated`, up to :data:`EVALUATED_BYTES`): a frame read
    before is not evaluated again, as an operation reads the take for the joints, then for the solve's reference
    pose and the pace, and each evaluation of a control rig costs the rig's constraints and drivers. Nothing in the
    file changes between an operation's reads."""
    fcurves = _fcurves(clip)
    if not rig_io.needs_scene_evaluation(clip.obj, fcurves):
        return rig_io.pose_matrices(context, clip.obj, clip.rig.names, fcurves, frames, cache)
    frames = np.asarray(frames, np.float64)
    memo = clip.evaluated
    new = np.array(sorted({float(f) for f in frames} - memo.keys()), np.float64)
    fresh = {}
    if len(new):
        pose, world = yield from rig_io.pose_matrices_evaluated_steps(context, clip.obj, clip.rig.names, new)
        fresh = {float(f): (pose[k], world[k]) for k, f in enumerate(new)}
        per_frame = pose[0].nbytes + world[0].nbytes
        if (len(memo) + len(new)) * per_frame <= EVALUATED_BYTES:
            memo.update(fresh)
    at = [fresh.get(float(f)) or memo[float(f)] for f in frames]
    return np.stack([p for p, _ in at]), np.stack([w for _, w in at])


def joint_positions(context, clip: Clip, frames: np.ndarray) -> np.ndarray:
    """:func:`joint_positions_steps` run to the end."""
    return drive(joint_positions_steps(context, clip, frames))


def joint_positions_steps(context, clip: Clip, frames: np.ndarray):
    """World-space canonical joints ``[F, 21, 3]`` at scene ``frames``, Y-up (model axes), scene units;
    read :data:`CHUNK_FRAMES` frames at a time. A step generator: on a rig Blender evaluates frame by frame, the
    fraction of the frames read (:func:`skeleton_pose_steps`)."""
    frames = np.asarray(frames, dtype=np.float64)
    out, cache = np.empty((len(frames), len(JOINTS), 3)), rig_io.KeyCache()
    for part in chunks(len(frames)):
        # (a joint skeleton, a control rig's, is not the armature's hierarchy: its bones are placed by the bones
        # above them in the armature, as a baked MMD model's lower body by the centre that carries its travel)
        pose, world = yield from share(skeleton_pose_steps(context, clip, frames[part], cache),
                                       part.start / len(frames), len(frames[part]) / len(frames))
        local = anchor_positions(clip.rig, clip.anchors, pose)
        out[part] = np.einsum("fij,fkj->fki", world[:, :3, :3], local) + world[:, None, :3, 3]
    return zup_to_yup(out)


def solve_frames_steps(context, clip: Clip, frames: np.ndarray, positions: np.ndarray,
                       root: tuple[str, np.ndarray] | None = None, world: np.ndarray | None = None):
    """The rig's local pose ``loc`` ``[F, B, 3]``, ``rot`` ``[F, B, 3, 3]`` (float32), and the joints it was solved
    for in armature space ``[F, 21, 3]`` (:func:`write_pose`'s ``joints``), that puts its joints on
    ``positions`` ``[F, 21, 3]`` (Y-up, scene units) at scene ``frames``, each frame starting from its own
    reference pose (:func:`reference_pose_steps`; ``root``: (a root bone carrying the travel, its armature-space pose
    ``[F, 4, 4]`` there), :func:`root_carried`): read and solved :data:`CHUNK_FRAMES` frames at a time, so a
    long take never holds more than one chunk's reference and working arrays. ``world``: the object's world
    matrices there (:func:`world_at_steps`), where the caller has them already. A step generator: where Blender
    evaluates frames the read did not (the object's place, a control rig's pose), the fraction done."""
    frames = np.asarray(frames, dtype=np.float64)
    arm_world = world if world is not None else (yield from share(world_at_steps(context, clip, frames), 0.0, 0.5))
    targets = to_armature(clip, positions, arm_world)
    n, b = len(frames), len(clip.rig.names)
    loc, rot = np.empty((n, b, 3), np.float32), np.empty((n, b, 3, 3), np.float32)
    cache = rig_io.KeyCache()
    for part in chunks(n):
        ref_loc, ref_rot = yield from share(reference_pose_steps(context, clip, frames[part], cache),
                                            0.5 + 0.5 * part.start / n, 0.5 * len(frames[part]) / n)
        if root is not None:
            ref_loc, ref_rot = root_carried(clip, root[0], ref_loc, ref_rot, root[1][part])
        loc[part], rot[part] = solve(clip.rig, clip.anchors, targets[part], ref_loc, ref_rot)
    return loc, rot, targets


def reference_pose(context, clip: Clip, frames: np.ndarray,
                   cache: rig_io.KeyCache | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`reference_pose_steps` run to the end."""
    return drive(reference_pose_steps(context, clip, frames, cache))


def reference_pose_steps(context, clip: Clip, frames: np.ndarray, cache: rig_io.KeyCache | None = None):
    """The local pose ``loc`` ``[F, B, 3]``, ``rot`` ``[F, B, 3, 3]`` the solve starts from at scene
    ``frames``: the keyed channels (``cache``: their keys, when read already), or on a control rig the
    evaluated (visual) pose of its joint skeleton (a step generator there: :func:`skeleton_pose_steps`)."""
    if clip.controls is not None:
        pose, _ = yield from skeleton_pose_steps(context, clip, frames, cache)
        return visual_local(clip.rig, pose)
    loc, rot, _ = rig_io.read_local_pose(clip.obj, clip.rig, clip.channels.fcurves if clip.channels else [], frames,
                                         cache)
    return loc, rot


def pose_joints(clip: Clip, loc: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """World canonical joints ``[F, 21, 3]`` (Y-up) of the rig in the local pose ``loc``, ``rot`` ``[F, B, ...]``."""
    local = anchor_positions(clip.rig, clip.anchors, fk(clip.rig, loc, rot))
    return zup_to_yup(local @ clip.world[:3, :3].T + clip.world[:3, 3])


def world_scale(clip: Clip) -> float:
    """Scene units per armature unit (the armature object's scale)."""
    return float(abs(np.linalg.det(clip.world[:3, :3])) ** (1 / 3))


def world_at_steps(context, clip: Clip, frames: np.ndarray):
    """The armature object's world matrices ``[F, 4, 4]`` at scene ``frames``: its matrix now where the object
    stays put, else as Blender evaluates it frame by frame (an action that moves the object itself, a parent,
    constraints), so that new frames land where the object will be, wherever the playhead stands; frames the
    operation has had Blender evaluate already (:attr:`Clip.evaluated`) are not evaluated again. A step generator
    where Blender evaluates frames (:func:`rig_io.world_matrices_evaluated_steps`)."""
    frames = np.asarray(frames, dtype=np.float64)
    if not rig_io.object_moves(clip.obj, clip.channels.fcurves if clip.channels else []):
        return np.broadcast_to(clip.world, (len(frames), 4, 4))
    memo = clip.evaluated
    if len(frames) and all(float(f) in memo for f in frames):
        return np.stack([memo[float(f)][1] for f in frames])
    return (yield from rig_io.world_matrices_evaluated_steps(context, clip.obj, frames))


def to_armature(clip: Clip, pos_yup: np.ndarray, world: np.ndarray | None = None) -> np.ndarray:
    """World Y-up positions ``[F, 21, 3]`` -> armature space (Blender axes), through the object's world matrix
    now or ``world`` ``[F, 4, 4]``, frame by frame (:func:`world_at_steps`)."""
    inv = np.linalg.inv(np.broadcast_to(clip.world if world is None else world, (len(pos_yup), 4, 4)))
    return np.einsum("fij,fkj->fki", inv[:, :3, :3], yup_to_zup(pos_yup)) + inv[:, None, :3, 3]


def written_bones(clip: Clip) -> list[int]:
    """Bones whose rotation the solve sets (mapped bones and the unmapped ones just above a joint)."""
    return solved_bones(clip.rig, clip.anchors)


# A root bone carries the action's travel where its head moves this share of the rig's leg over the clip.
ROOT_MOTION_SHARE = 0.1
ROOT_SAMPLES = 24  # frames of the clip read to tell whether a root bone travels


@dataclass
class Root:
    """A bone above the hips that carries the travel (a game rig's root, as Unreal's ``root`` or Auto-Rig Pro's
    ``c_traj``) and its world matrix ``start`` ``[4, 4]`` on the frame the new frames go on from."""

    bone: str
    start: np.ndarray

    def track(self, positions: np.ndarray, seam: int, fps: float, ground=None) -> np.ndarray:
        """World matrices ``[F - seam + 1, 4, 4]`` on frames ``seam - 1`` on of ``positions`` ``[F, 21, 3]`` (world,
        Y-up, ``fps``): ``start``, then carried with the body (:func:`root_motion.carried_root`), riding the ``ground``
        the body was carried over (``ground.carried``, its ``lift``) as the body does."""
        carried = carried_root(self.start, yup_to_zup(positions[:, 0]), yup_to_zup(facing(positions)), seam, fps,
                               lift=ground.lift if ground is not None else None)
        return np.concatenate([self.start[None], carried])


# Prefixes of a generated rig's mechanism, original and deform bones (Rigify's), which no animator keys.
MECHANISM = ("MCH-", "ORG-", "DEF-")


def above_hips(clip: Clip) -> list[str]:
    """The bones of the armature above the hips bone (on a control rig, above the control that carries the body)
    that an animator keys, nearest first: a game rig's root, Auto-Rig Pro's ``c_traj``; none where there is none
    (a generated Rigify rig's ``torso`` hangs from a mechanism bone that follows ``root`` by a constraint)."""
    hips = clip.rig.names[int(clip.anchors.bone[JOINT_INDEX["hips"]])]
    if clip.controls is not None:
        hips = next((c.bone for c in clip.controls.controls if c.drives == hips), hips)
    out, pb = [], clip.obj.pose.bones[hips].parent
    while pb is not None:
        if not pb.name.startswith(MECHANISM):
            out.append(pb.name)
        pb = pb.parent
    return out


def world_matrices(context, obj, names: list[str], frames: np.ndarray) -> np.ndarray:
    """World matrices ``[F, N, 4, 4]`` of pose bones ``names`` as Blender plays scene ``frames`` (constraints and
    all; :func:`rig_io.pose_matrices`)."""
    pose, world = rig_io.pose_matrices(context, obj, names, anim.active_fcurves(obj), frames)
    return world[:, None] @ pose


def moving_root(context, clip: Clip, frames: np.ndarray, at: float) -> Root | None:
    """The bone above the hips that carries the action's travel over the ground, as a game rig's root does: the
    nearest one the action keys whose head it moves over the ground (the world's X and Y: a rise is no travel) by a
    tenth of a leg or more over scene ``frames`` (the clip read), as far against the next such bone above it (a baked
    MMD model's groove only rides the centre, which carries the travel), with its world matrix on frame ``at``; None
    where there is none."""
    if clip.channels is None:
        return None
    keyed = {bone for bone, prop in rig_io.bone_channels(clip.channels.fcurves) if prop == "location"}
    above = [name for name in above_hips(clip) if name in keyed]
    if not above:
        return None
    frames = np.asarray(frames, np.float64)
    sample = frames[np.unique(np.linspace(0, len(frames) - 1, min(ROOT_SAMPLES, len(frames))).round().astype(int))]
    read = world_matrices(context, clip.obj, above, np.r_[sample, at])  # [S + 1, N, 4, 4]: the samples, then ``at``
    heads = read[:-1, :, :2, 3]
    leg = leg_length(joint_positions(context, clip, sample[:1]))
    for k, name in enumerate(above):
        if np.linalg.norm(heads[:, k] - heads[:1, k], axis=-1).max() < ROOT_MOTION_SHARE * leg:
            continue
        if k + 1 < len(above):  # where it goes, against the bone above it
            rel = (np.linalg.inv(read[:-1, k + 1]) @ read[:-1, k])[:, :3, 3] * world_scale(clip)
            if np.linalg.norm(rel - rel[:1], axis=-1).max() < ROOT_MOTION_SHARE * leg:
                continue
        return Root(name, read[-1, k])
    return None


def root_carried(clip: Clip, root: str, ref_loc: np.ndarray, ref_rot: np.ndarray,
                 pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``ref_loc`` ``[F, B, 3]``, ``ref_rot`` ``[F, B, 3, 3]`` (the reference pose of the new frames) with bone
    ``root`` at the armature-space pose matrices ``pose`` ``[F, 4, 4]``, through its parent's reference pose (a plain
    rig's; a control rig's root is keyed by the bake, :func:`write_controls`)."""
    if clip.controls is not None:
        return ref_loc, ref_rot
    b = clip.rig.names.index(root)
    loc, rot = np.array(ref_loc, np.float64), np.array(ref_rot, np.float64)
    parent = int(clip.rig.parents[b])
    base = clip.rig.rel_rest[b] if parent < 0 else fk(clip.rig, loc, rot)[:, parent] @ clip.rig.rel_rest[b]
    local = np.linalg.inv(base) @ pose
    loc[:, b], rot[:, b] = local[:, :3, 3], nearest_rotation(local[:, :3, :3])
    return loc, rot


def keyed_names(clip: Clip) -> list[str]:
    """Names of the bones that get keys: the written bones, or on a control rig their controls."""
    if clip.controls is not None:
        return [c.bone for c in keyed_controls(clip)]
    return [clip.rig.names[b] for b in written_bones(clip)]


def written_paths(clip: Clip, root: str | None = None) -> set[str]:
    """The F-curve data paths :func:`write_pose` keys: each written bone's rotation and the location of the bone
    the hips' place is keyed on (:func:`located`), a plain rig's followers' (:func:`followers`) rotations and
    locations, and a ``root`` bone's rotation and location; on a control rig its controls' rotations, and the
    locations of those that move."""
    carried = ({bone_path(root, rig_io.rotation_property(clip.obj.pose.bones[root])), bone_path(root, "location")}
               if root is not None else set())
    if clip.controls is not None:
        return carried | {bone_path(c.bone, prop) for c in keyed_controls(clip)
                          for prop in (rig_io.rotation_property(clip.obj.pose.bones[c.bone]),)
                          + (("location",) if c.location else ())}
    paths = {bone_path(name, rig_io.rotation_property(clip.obj.pose.bones[name]))
             for name in [clip.rig.names[b] for b in written_bones(clip)] + list(clip.carried)}
    paths |= {bone_path(name, "location") for name in clip.carried if not clip.obj.data.bones[name].use_connect}
    return carried | paths | {bone_path(clip.rig.names[located(clip.rig, clip.anchors)], "location")}


# Keys on twos (threes, ...) held by Constant interpolation, the stepped look of hand-drawn-style animation: at least
# STEP_KEYS keys make the pattern; Extend and Fill Gap read it over the last STEP_SECONDS before the frame they
# continue from.
STEP_SECONDS, STEP_KEYS = 2.0, 6


def keyed_curves(clip: Clip) -> list:
    """The unmuted F-curves of the bones that get keys (:func:`keyed_names`)."""
    names = set(keyed_names(clip))
    return [fc for (bone, _), by_index in rig_io.bone_channels(clip.channels.fcurves).items() if bone in names
            for fc in by_index.values() if not fc.mute]


def keyed_every_frame(clip: Clip, first: int, last: int) -> bool:
    """Whether every whole frame from ``first`` to ``last`` holds a key on each of :func:`keyed_curves` (an action
    baked frame by frame, as imported motion capture is), not poses interpolated between keys."""
    curves = keyed_curves(clip)
    wanted = np.arange(first, last + 1)
    for fc in curves:
        co = np.empty(2 * len(fc.keyframe_points))
        fc.keyframe_points.foreach_get("co", co)
        if not np.isin(wanted, np.round(co[0::2])).all():
            return False
    return bool(curves)


def key_grid(clip: Clip, first: float, last: float) -> tuple[int, np.ndarray]:
    """(step, keys): the frames ``[K]`` the keyed bones' poses are held from in frames ``first`` to ``last`` and their
    step (2 for animation on twos), where the bones' F-curves hold them on one grid of whole frames every ``step``
    >= 2: by keys there with Constant interpolation, or by a Stepped Interpolation modifier on every one of those
    F-curves (its step and offset; keys anywhere). Else (1, no keys): keys on ones, other interpolation or modifiers,
    another spacing, or too few (:data:`STEP_KEYS`). The operations read such an action at those frames and key
    only them."""
    constant = bpy.types.Keyframe.bl_rna.properties["interpolation"].enum_items["CONSTANT"].value
    found, stepped = [], set()
    for fc in keyed_curves(clip):
        if len(fc.modifiers):
            mod = fc.modifiers[0]
            if (len(fc.modifiers) > 1 or mod.type != "STEPPED" or mod.mute or mod.use_frame_start
                    or mod.use_frame_end or mod.use_restricted_range or (mod.use_influence and mod.influence < 1.0)):
                return 1, np.empty(0)
            stepped.add((float(mod.frame_step), float(mod.frame_offset)))
            continue
        n = len(fc.keyframe_points)
        co, interp = np.empty(2 * n), np.empty(n, np.int32)
        fc.keyframe_points.foreach_get("co", co)
        fc.keyframe_points.foreach_get("interpolation", interp)
        near = (co[0::2] >= first - 0.5) & (co[0::2] <= last + 0.5)
        if (interp[near] != constant).any():
            return 1, np.empty(0)
        found.append(co[0::2][near])
    if stepped:  # every modified curve steps alike; plain curves (Constant) must keep to its grid
        if len(stepped) > 1:
            return 1, np.empty(0)
        step, offset = stepped.pop()
        if step < 2 or step != round(step) or offset != round(offset):
            return 1, np.empty(0)
        grid = np.arange(offset + np.ceil((first - offset) / step) * step, last + 0.5, step)
        plain = np.concatenate(found) if found else np.empty(0)
        if len(grid) < STEP_KEYS or not np.isin(np.round(plain), grid).all():
            return 1, np.empty(0)
        return int(step), grid
    keys = np.unique(np.concatenate(found)) if found else np.empty(0)
    if len(keys) < STEP_KEYS or np.abs(keys - np.round(keys)).max() > 1e-3:
        return 1, np.empty(0)
    keys = np.round(keys)
    gaps = np.unique(np.diff(keys))
    return (int(gaps[0]), keys) if len(gaps) == 1 and gaps[0] >= 2 else (1, np.empty(0))


def key_step(clip: Clip, end: int, back: bool = False) -> tuple[int, int]:
    """(step, key): the step of the keys held by Constant interpolation (:func:`key_grid`) over the last
    :data:`STEP_SECONDS` up to frame ``end`` (2: keys on twos) and the last of them, whose pose frame ``end``
    holds; (1, ``end``) where they are not stepped. ``back`` (frames to add before ``end``): over the first
    :data:`STEP_SECONDS` from ``end``, which must be one of the keys."""
    if back:
        step, keys = key_grid(clip, end, end + STEP_SECONDS * clip.fps)
        return (step, end) if len(keys) and keys[0] == end else (1, end)
    step, keys = key_grid(clip, end - STEP_SECONDS * clip.fps, end)
    return (step, int(keys[-1])) if len(keys) and end - keys[-1] < step else (1, end)


def keyed_controls(clip: Clip, bones: list[int] | None = None) -> list:
    """The controls of a control rig that drive the written ``bones`` (default: all written bones)."""
    names = {clip.rig.names[b] for b in (written_bones(clip) if bones is None else bones)}
    return [c for c in clip.controls.controls if c.drives in names]


def new_action_from(clip: Clip, suffix: str):
    """A copy of the clip's action named after it (``walk.extended``; run again on that result:
    ``walk.extended.001``, not ``walk.extended.extended``); the original is kept with a fake user."""
    new = clip.action.copy()
    root = re.sub(rf"\.{re.escape(suffix)}(\.\d{{3}})?$", "", clip.action.name)
    new.name = f"{root}.{suffix}"  # Blender numbers it when the name is taken
    return new


def selected_bones(clip: Clip, among: list[int]) -> list[int]:
    """The bones of ``among`` selected in the armature (pose selection; Blender 5 keeps it on the pose
    bone, 4.x on the bone)."""
    def selected(name: str) -> bool:
        pb = clip.obj.pose.bones[name]
        return bool(pb.select if hasattr(pb, "select") else pb.bone.select)

    control = {c.drives: c.bone for c in clip.controls.controls} if clip.controls is not None else {}
    return [b for b in among if selected(control.get(clip.rig.names[b], clip.rig.names[b]))]


def only_selected(clip: Clip, among: list[int], what: str) -> list[int]:
    """:func:`selected_bones`, or a :class:`UserError` saying what to select when none is."""
    chosen = selected_bones(clip, among)
    if not chosen:
        raise UserError(f"No bone that {what} is selected in {clip.obj.name!r}: select them in Pose Mode, or turn "
                        "off Only Selected Bones")
    return chosen


def leg_bones(clip: Clip) -> list[int]:
    """The written bones from each upper leg down (what a foot lock changes)."""
    uplegs = [int(clip.anchors.bone[JOINT_INDEX[j]]) for j in ("l_upleg", "r_upleg")]
    return [b for b in written_bones(clip) if any(clip.rig.is_ancestor(u, b) for u in uplegs)]


def write_pose(context, clip: Clip, action, frames: np.ndarray, loc: np.ndarray, rot: np.ndarray,
               previous: dict, replace: tuple[float, float] | None, bones: list[int] | None = None,
               follows: bool = False, interpolation: str = "", root: tuple[str, np.ndarray] | None = None,
               joints: np.ndarray | None = None):
    """Key the solved rotations of mapped bones (and the hips' place: :func:`located`) at ``frames``, and the rotation
    and location of a ``root`` bone carrying the travel ((name, its armature-space pose ``[F, 4, 4]``):
    :func:`moving_root`, already in ``loc``, ``rot`` on a plain rig); on a control rig, key its controls by a visual
    bake instead (:func:`write_controls`). A step generator (the bake's fractions done, :func:`controls.bake_steps`);
    returns how far (armature units) a written bone ends up from the solve at worst (0 when keyed directly).

    ``loc`` ``[F, B, 3]``, ``rot`` ``[F, B, 3, 3]``; ``previous`` {bone: raw channel values} keeps
    Euler angles and quaternion signs continuous with the keys before (``follows``: after, frames added before
    them); ``bones``: only these (default: all :func:`written_bones`); ``interpolation``: that of the keys of the
    channels this makes (default: Linear; a channel the action has keeps that of its last key); ``joints``: the joints
    ``[F, 21, 3]`` (armature space) ``loc``, ``rot`` were solved for, where an IK chain's end goes on a control rig
    (:func:`write_controls`)."""
    channels = anim.Channels(action, clip.obj.animation_data, ensure=True)
    if clip.controls is not None:
        return (yield from write_controls(context, clip, channels, frames, loc, rot, previous, replace, bones,
                                          follows, interpolation, root, joints))
    placed = located(clip.rig, clip.anchors)  # the hips bone, or the bone that carries it
    moved = clip.rig.names.index(root[0]) if root is not None else None
    turned = (written_bones(clip) if bones is None else bones) + ([moved] if moved is not None else [])
    hips_written = int(clip.anchors.bone[JOINT_INDEX["hips"]]) in turned
    for b in turned + ([placed] if hips_written and placed not in turned else []):
        pb = clip.obj.pose.bones[clip.rig.names[b]]
        if b in turned:
            prop, values = encode_rotation(pb.rotation_mode, rot[:, b], previous.get(pb.name), follows)
            _key_property(clip, channels, pb, prop, frames, values, replace, interpolation=interpolation)
        if b in (placed, moved):
            _key_property(clip, channels, pb, "location", frames, loc[:, b], replace, interpolation=interpolation)
    if clip.carried:
        _key_followers(context, clip, channels, frames, previous, replace, follows, interpolation, turned)
    return 0.0


def _key_followers(context, clip: Clip, channels: anim.Channels, frames: np.ndarray, previous: dict,
                   replace: tuple[float, float] | None, follows: bool, interpolation: str, turned: list[int]) -> None:
    """Key a plain rig's followers (:func:`followers`) whose bones moved (``turned``, the bones keyed, or a bone above
    them) at ``frames`` where they keep to those bones as they are now keyed in ``channels`` (:func:`_carried_poses`),
    each set in closed form against its parent as the new keys play it (:func:`controls.bake_closed`); ``previous``,
    ``replace``, ``follows``, ``interpolation`` as :func:`write_pose` has them."""
    index = {n: b for b, n in enumerate(clip.rig.names)}
    carriers = sorted({w for w in clip.carried.values() if any(clip.rig.is_ancestor(t, index[w]) for t in turned)})
    if not carriers:
        return
    now = rig_io.armature_poses(context, clip.obj, carriers, channels.fcurves, frames)  # closed form: plain chains
    carry = _carried_poses(context, clip, frames, {w: now[:, k] for k, w in enumerate(carriers)})
    bones = clip.obj.data.bones
    chosen = [Control(name, name, not bones[name].use_connect) for name in carry]
    baked = controls.bake_closed(clip.obj, chosen, channels.fcurves, frames, carry)
    chans = rig_io.bone_channels(channels.fcurves)
    edge = np.array([frames[-1] + 1 if follows else frames[0] - 1], np.float64)
    for k, c in enumerate(chosen):
        pb = clip.obj.pose.bones[c.bone]
        before = previous.get(pb.name, rig_io.rotation_values(chans, pb, edge)[0])
        prop, values = encode_rotation(pb.rotation_mode, baked.rot[:, k], before, follows)
        _key_property(clip, channels, pb, prop, frames, values, replace, interpolation=interpolation)
        if c.location:
            _key_property(clip, channels, pb, "location", frames, baked.loc[:, k], replace,
                          interpolation=interpolation)


def write_controls(context, clip: Clip, channels: anim.Channels, frames: np.ndarray, loc: np.ndarray,
                   rot: np.ndarray, previous: dict, replace: tuple[float, float] | None,
                   bones: list[int] | None, follows: bool = False, interpolation: str = "",
                   root: tuple[str, np.ndarray] | None = None, joints: np.ndarray | None = None):
    """Key a control rig's controls (and switches) so that its joint skeleton takes the solved pose; a ``root``
    control carrying the travel ((name, armature-space pose ``[F, 4, 4]``)) is set there first and keyed too. An IK
    chain Blender plays shorter than its bones has its end (a foot on its IK control) where ``joints`` (the joints
    solved for, armature space) put it (:func:`_ends_on_joints`). A step generator, as :func:`write_pose`."""
    pose = fk(clip.rig, loc, rot)
    chosen = keyed_controls(clip, bones)
    index = {n: b for b, n in enumerate(clip.rig.names)}
    targets = {c.drives: pose[:, index[c.drives]] for c in chosen}
    if joints is not None:
        _ends_on_joints(clip, chosen, index, pose, targets, joints)
    control_set = clip.controls
    if root is not None:  # the root control drives itself, to where it is carried; it goes first
        carrier = Control(root[0], root[0], True)
        chosen, targets[root[0]] = [carrier] + chosen, np.array(root[1], np.float64)
        control_set = replace_set(control_set, controls=[carrier] + list(control_set.controls))
        _hips_on_root(clip, targets, root[0])
    # where NLA strips show through, a channel the action lacks takes the pose as played on its other frames: read
    # before the bake turns any bone, and only if such a channel will be made
    lacking = clip.layered and any(
        channels.find(bone_path(c.bone, prop), 0) is None
        for c in chosen for prop in (rig_io.rotation_property(clip.obj.pose.bones[c.bone]),)
        + (("location",) if c.location else ()))
    played = _played(context, clip, frames) if lacking else None
    carry = _carried_poses(context, clip, frames, targets)  # read before the bake turns any bone
    if carry:  # a baked control rig's carried bones, each its own control, set by the bake with the rest: a written
        # bone may hang from one (Auto-Rig Pro's deform spine from its deform root)
        chans = rig_io.bone_channels(channels.fcurves)
        edge = np.array([frames[-1] + 1 if follows else frames[0] - 1], np.float64)
        previous = {n: rig_io.rotation_values(chans, clip.obj.pose.bones[n], edge)[0] for n in carry} | previous
        extra = [Control(name, name, True) for name in carry]
        chosen, targets = chosen + extra, targets | carry
        control_set = replace_set(control_set, controls=list(control_set.controls) + extra)
    baked = yield from controls.bake_steps(context, clip.obj, control_set, frames, targets)
    for k, c in enumerate(chosen):
        pb = clip.obj.pose.bones[c.bone]
        prop, values = encode_rotation(pb.rotation_mode, baked.rot[:, k], previous.get(pb.name), follows)
        fill = None
        if played is not None and channels.find(bone_path(c.bone, prop), 0) is None:
            at, full, loc_p, rot_p = played
            fill = (at, encode_rotation(pb.rotation_mode, rot_p[:, full.index(c.bone)], None)[1])
        _key_property(clip, channels, pb, prop, frames, values, replace, fill, interpolation)
        if c.location:
            fill = None if played is None else (played[0], played[2][:, played[1].index(c.bone)])
            _key_property(clip, channels, pb, "location", frames, baked.loc[:, k], replace, fill, interpolation)
    edges = np.array([f for f in (frames[0] - 1, frames[-1] + 1) if clip.first <= f <= clip.last])
    controls.key_switches(channels, clip.obj, clip.controls, frames, edges)
    return baked.error


def holders(clip: Clip) -> list[str]:
    """The bones of a baked control rig that its keyed bones (the written ones and :attr:`Clip.carried`) hang from,
    following none of them (Rigify's ORG-spine above DEF-thigh.L, the MCH- and control bones above its face): what
    those keys were set against, so that an action of new keys alone must hold them as they played then
    (:func:`hold`)."""
    if clip.controls is None or clip.controls.name != BAKED_BONES:
        return []
    full = rig_io.read_rig(clip.obj)
    keyed = {clip.rig.names[b] for b in written_bones(clip)} | set(clip.carried)
    follows = controls_core.hanging_from(full, keyed)
    out: set[int] = set()
    for b, name in enumerate(full.names):
        p = int(full.parents[b]) if name in keyed else -1
        while p >= 0 and not follows[p]:
            out.add(p)
            p = int(full.parents[p])
    return [full.names[b] for b in sorted(out)]


def hold(clip: Clip, action, frames: np.ndarray, interpolation: str = "") -> None:
    """Key in ``action`` (a new action of new keys alone) the :func:`holders` of a baked control rig at ``frames`` as
    the clip's own action plays them (each channel it animates), so that the keys set against them stay where they
    were put."""
    if clip.channels is None:  # no action: they keep their pose, as they had it when the keys were set
        return
    chans = rig_io.bone_channels(clip.channels.fcurves)
    channels = anim.Channels(action, clip.obj.animation_data, ensure=True)
    frames = np.asarray(frames, np.float64)
    for name in holders(clip):
        pb = clip.obj.pose.bones[name]
        for prop in ("location", rig_io.rotation_property(pb), "scale"):
            if (name, prop) in chans:
                values = rig_io.channel_values(chans, name, prop, getattr(pb, prop), frames)
                _key_property(clip, channels, pb, prop, frames, values, None, interpolation=interpolation)


def _carried_poses(context, clip: Clip, frames: np.ndarray, targets: dict) -> dict[str, np.ndarray]:
    """{carried bone (:attr:`Clip.carried`): its armature-space pose ``[F, 4, 4]`` at ``frames``} that keeps it where
    it stood against the bone carrying it as the action plays those frames now (inside the take, as it was on that
    frame; past it, as on its last), that bone going to its ``targets`` {bone: armature-space ``[F, 4, 4]``}; only
    the bones whose carrier is among the ``targets``."""
    these = {c: w for c, w in clip.carried.items() if w in targets}
    if not these:
        return {}
    names = sorted(set(these) | set(these.values()))
    at = {n: k for k, n in enumerate(names)}
    now = rig_io.armature_poses(context, clip.obj, names, _fcurves(clip), frames)
    return {c: targets[w] @ np.linalg.inv(now[:, at[w]]) @ now[:, at[c]] for c, w in these.items()}


def _hips_on_root(clip: Clip, targets: dict, root: str) -> None:
    """Where the hips bone is connected to the ``root`` bone (a Character Creator take baked by controls, each bone
    its own), the root's target moved by as far as the hips would miss theirs: Blender leaves a connected bone's
    location out, so its head goes where the root puts it (:func:`located` for a plain rig)."""
    hips = clip.rig.names[int(clip.anchors.bone[JOINT_INDEX["hips"]])]
    bone = clip.obj.data.bones.get(hips)
    if bone is None or not bone.use_connect or bone.parent is None or bone.parent.name != root or hips not in targets:
        return
    rest = np.linalg.inv(np.array(bone.parent.matrix_local)) @ np.array(bone.matrix_local)
    head = targets[root] @ rest[:, 3]  # [F, 4]: where the hips' head goes with the root at its target
    targets[root][:, :3, 3] += targets[hips][:, :3, 3] - head[:, :3]


def _ends_on_joints(clip: Clip, chosen: list, index: dict[str, int], pose: np.ndarray, targets: dict,
                    joints: np.ndarray) -> None:
    """The targets of the bones of each IK chain whose end control is keyed (a leg in IK) put on ``joints`` ``[F, 21,
    3]`` where the solve (``pose``) has them off: :func:`controls.chains_on_joints` (``index``: {bone name: bone})."""
    ends = [index[c.drives] for c in chosen if c.end]
    if not ends:
        return
    placed = chains_on_joints(clip.rig, clip.anchors, pose, ends, joints)
    for c in chosen:
        if index[c.drives] in placed:
            targets[c.drives] = placed[index[c.drives]]


def _played(context, clip: Clip, frames: np.ndarray) -> tuple[np.ndarray, list[str], np.ndarray, np.ndarray] | None:
    """The action's frames other than ``frames`` and every bone's local ``loc`` ``[F, B, 3]`` and ``rot``
    ``[F, B, 3, 3]`` there as Blender plays them (NLA strips and all): (frames, bone names, loc, rot); None where
    there is no other frame."""
    span = np.arange(clip.first, clip.last + 1, dtype=np.float64)
    at = span[~np.isin(span, np.asarray(frames, dtype=np.float64))]
    if not len(at):
        return None
    full = rig_io.read_rig(clip.obj)
    pose, _ = rig_io.pose_matrices_evaluated(context, clip.obj, full, at)
    loc, rot = visual_local(full, pose)
    return at, full.names, loc, rot


def _key_property(clip: Clip, channels: anim.Channels, pb, prop: str, frames: np.ndarray, values: np.ndarray,
                  replace: tuple[float, float] | None, fill: tuple[np.ndarray, np.ndarray] | None = None,
                  interpolation: str = "") -> None:
    """Key ``values`` ``[F, n]`` on each array index of a pose bone property. A channel the action did
    not animate gets its static value keyed just outside ``frames`` first, so other frames keep it; or, with
    ``fill`` (frames, values ``[G, n]``: where NLA strips show through the action), those values on those frames,
    so that the new channel keeps the pose the strips play there instead of hiding them. ``interpolation``: that of
    the keys of a channel made here (a channel the action has keeps that of its last key)."""
    path = bone_path(pb.name, prop)
    static = np.asarray(getattr(pb, prop), dtype=np.float64)
    edges = np.array([f for f in (frames[0] - 1, frames[-1] + 1) if clip.first <= f <= clip.last])
    for i in range(values.shape[1]):
        fc, made = channels.find(path, i), ""
        if fc is None:
            fc, made = channels.ensure(path, i, pb.name), interpolation
            if fill is not None and len(fill[0]):
                anim.write_keys(fc, fill[0], fill[1][:, i], interpolation=made)
            elif len(edges):
                anim.write_keys(fc, edges, np.full(len(edges), static[i]), interpolation=made)
        anim.write_keys(fc, frames, values[:, i], replace, made)


def encode_rotation(mode: str, m: np.ndarray, previous: np.ndarray | None,
                    follows: bool = False) -> tuple[str, np.ndarray]:
    """(property, values ``[F, 3 or 4]``) of rotations ``m`` ``[F, 3, 3]`` in a bone's rotation mode, continuous with
    the raw values ``previous`` of the key before them (``follows``: of the key after them, frames added before it)."""
    if follows:
        prop, values = encode_rotation(mode, np.asarray(m)[::-1], previous)
        return prop, values[::-1]
    m = np.asarray(m, dtype=np.float64)
    if mode in ("QUATERNION", "AXIS_ANGLE"):
        prev_q = previous
        if mode == "AXIS_ANGLE" and previous is not None:
            prev_q = rotations.matrix_to_quat(rotations.axis_angle_to_matrix(previous))
        q = rotations.quat_continuous(rotations.matrix_to_quat(m), prev_q)
        if mode == "QUATERNION":
            return "rotation_quaternion", q
        return "rotation_axis_angle", rotations.quat_to_axis_angle(q)
    return "rotation_euler", rotations.euler_continuous(rotations.matrix_to_euler(m, mode), mode, previous)


def raw_rotations(clip: Clip, frame: float, names: list[str] | None = None) -> dict:
    """{bone: rotation channel values} of the written bones (or of the bones ``names``) at one scene frame."""
    chans = rig_io.bone_channels(clip.channels.fcurves)
    out = {}
    for name in keyed_names(clip) if names is None else names:
        pb = clip.obj.pose.bones[name]
        out[pb.name] = rig_io.rotation_values(chans, pb, np.array([float(frame)]))[0]
    return out


def finish(context, clip: Clip, new_action, scene_range: bool = True) -> None:
    """Keep the original action (fake user) and assign the new one on the same slot; with
    ``scene_range``, widen the scene's frame range to the new action's end (and to its start where it starts
    before the original: frames added before it)."""
    slot = anim.slot_of(clip.obj)
    if mapping.stored_map(clip.obj) != clip.mapping:  # keep the auto-map that was used, for the panel
        mapping.store_map(clip.obj, clip.mapping, clip.obj.strnn_map.family)
    clip.action.use_fake_user = True
    anim.assign_action(clip.obj, new_action, slot.identifier if slot else None)
    first, last = (int(round(x)) for x in new_action.frame_range)
    if scene_range and context.scene.frame_end < last:
        context.scene.frame_end = last
    if scene_range and first < min(context.scene.frame_start, clip.action.frame_range[0]):  # added before it
        context.scene.frame_start = max(first, 0)  # a scene starts at frame 0 at the earliest
