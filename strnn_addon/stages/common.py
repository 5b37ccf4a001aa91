"""What the stages of every operation share: driving a stage generator, model errors as
:class:`UserError`, the foot lock on scene positions, and the new action with its record.

Each operation (:mod:`.extend`, :mod:`.denoise`, :mod:`.footlock`, :mod:`.follow`) is a step
generator (``model_core.inference.steps``) that yields the name of each stage (read, model,
solve, write) before running it, and may yield the fraction of a stage done as it goes (Follow
Curve, window by window), so the operators can show progress and stop on Esc in between;
:func:`run` drives one to the end. Every check, read and all the computing happen before it yields
``write``, and the new action is created after, so a failure or a cancel leaves the file unchanged, and an
operator on several armatures can take each to its ``write`` before writing any. On a control rig the write stage
yields the fraction of its bake done as it goes; closed there, the new action is removed and the rig put back, and
:class:`Unwritten` puts back armatures written before it.
"""

from __future__ import annotations

import contextlib
import math
import tomllib
from pathlib import Path

import bpy
import numpy as np

from ...model_core.inference.steps import drive
from ...model_core.io.checkpoint import CheckpointError
from ...model_core.motion.conventions import UP_AXIS, yup_to_zup
from ...model_core.ops import footlock
from ...model_core.ops.extend import STALL_FRAMES, stalled_end
from ...model_core.ops.pace import Pace, stride_period
from ...model_core.rig.rigs import axis_name, standing_axis
from .. import engine_bridge
from ..props import joint_label, preferences
from ..scene import anim, mapping, pipeline
from ..scene.pipeline import UserError

STAGES = ("read", "model", "solve", "write")
VERSION = tomllib.loads((Path(__file__).resolve().parents[2] / "blender_manifest.toml").read_text())["version"]
RECORD = "strnn"  # the custom property of a new action that says how it was made


def noop(stage: str) -> None:
    pass


@contextlib.contextmanager
def model_errors():
    """Model and engine errors raised inside as a :class:`UserError`."""
    try:
        yield
    except engine_bridge.EngineError as e:
        raise UserError(str(e)) from e
    except CheckpointError as e:  # a part of the model read when first needed (the gap model) is damaged
        raise UserError(f"Could not read the model: {e}") from e
    except ValueError as e:
        raise UserError(f"The model could not run on this clip: {e}") from e


def model_call(fn, *args):
    """Run one model call, turning model and engine errors into a :class:`UserError`."""
    with model_errors():
        return fn(*args)


def model_steps(steps):
    """``yield from`` a model's step generator (fractions done), turning its errors into a :class:`UserError`."""
    with model_errors():
        return (yield from steps)


def run(steps, progress=noop):
    """Drive a worker generator to the end, calling ``progress(stage)`` at each stage (not at the
    fractions a stage may yield as it goes); returns its result."""
    return drive(steps, lambda value: progress(value) if isinstance(value, str) else None)


def frame_range(clip, frame_start: int | None, frame_end: int | None, need: int, why: str) -> tuple[int, int]:
    """The asked frames (None: the action's first / last) clipped to the action; a :class:`UserError`
    when they are reversed, miss the action or are fewer than ``need`` (``why`` says who needs them)."""
    name = clip.action.name
    if frame_start is not None and frame_end is not None:
        if frame_start > frame_end:
            raise UserError(f"Start {frame_start} is after End {frame_end}: swap them")
        if frame_end < clip.first or frame_start > clip.last:
            raise UserError(f"Frames {frame_start}-{frame_end} lie outside the action {name!r} (frames "
                            f"{clip.first}-{clip.last}): pick a range inside it")
    a = clip.first if frame_start is None else max(int(frame_start), clip.first)
    b = clip.last if frame_end is None else min(int(frame_end), clip.last)
    if b - a + 1 < need:
        raise UserError(f"The frame range {a}-{b} of {name!r} has {max(b - a + 1, 0)} frames; {why}: widen the range")
    return a, b


def lock(pos, fps, *, blend: float | None = None, detect_only: bool = False, lower_body: bool = True,
         passes: int = 1, **kw):
    """:func:`footlock.foot_lock` of scene positions ``[F, 21, 3]`` (or, with ``detect_only``, their
    contacts ``[F, 4]``), its errors as :class:`UserError`; ``lower_body`` False when only the legs
    will be written (the body stays at its height); ``passes`` > 1 settles the lock."""
    settings = footlock.FootLockSettings(lower_body=lower_body, passes=passes)
    if blend is not None:
        settings.blend_s = max(float(blend), 0.0)
    try:
        if detect_only:
            return footlock.detect_foot_contacts(pos, fps, ground=kw.get("ground"))
        return footlock.foot_lock(pos, fps, settings=settings, **kw)
    except ValueError as e:
        raise UserError(f"Foot lock could not run on this clip: {e}") from e


def prefs(context):
    return preferences(context)


def made_by(operation: str, clip, model: str = "", key_step: int = 1, **settings) -> dict:
    """The :data:`RECORD` a new action carries: the operation and extension version that made it,
    the action it was made from, the model folder it used (if any), the step of the keys it read and wrote on an
    action on twos (``key_step``, :func:`pipeline.key_grid`) and its settings."""
    record = {"operation": operation, "version": VERSION,
              "source_action": clip.action.name if clip.action is not None else ""}
    if model:
        record["model"] = model
    record["keys_per_second"] = float(clip.fps)
    if key_step > 1:
        record["key_step"] = key_step
    record["settings"] = {k: v for k, v in settings.items() if v is not None}
    record |= bone_map_record(clip)
    return record


def bone_map_record(clip) -> dict:
    """The record's ``bone_map`` entry where a toe of the clip's map sits at the tail of a toe bone that points across
    it (picked in the map on an FBX imported without Automatic Bone Orientation, :func:`mapping.tails_across`): the
    foot turns to put that tail where the model's toe goes. A foot's own tail across it (a foot with no toe bone) and
    a hand's are placed where the toes and fingers go (:func:`solve.tips_along_the_limb`). Empty otherwise."""
    toes = [j for j in mapping.tails_across(clip.obj, clip.mapping)
            if j.endswith("toe") and not mapping.bonemap.at_the_foot_tail(clip.mapping, j)]
    if not toes:
        return {}
    tips = " and ".join(f"the {joint_label(j)} at the tail of {clip.mapping[j][0]!r}" for j in toes)
    return {"bone_map": {"tails_across": toes, "note": (
        f"The bone map puts {tips}, a tail that points across its bone (an FBX imported without Automatic Bone "
        "Orientation?), so the foot turns to put that tail where the model's toe goes: re-import with Automatic "
        "Bone Orientation on, or pick a toe bone in STRNN > Bone Map")}}


def familiarity_record(found, denoised: bool = False) -> dict:
    """The record's ``familiarity`` entry: the clip's reconstruction error against the model's usual,
    and the note the operator reports when the clip is unlike what the model learnt (Denoise's, which judges its
    result, with ``denoised``); empty for ``found`` None."""
    if found is None:
        return {}
    entry = {"reconstruction_cm": round(found.error_cm, 2)}
    if found.usual_cm:
        entry["usual_cm_p90"] = found.usual_cm
    note = found.denoised_note() if denoised else found.note()
    if note:
        entry["note"] = note
    return {"familiarity": entry}


def first_window_record(found, back: bool = False) -> dict:
    """The record's ``first_window`` entry where Extend held its first window near the clip's last pose (``back``:
    its first, the frames added before it) (:class:`extend.FirstWindow`): the share of the model's motion kept, how
    long, and the note the operator reports; empty where the first window is the model's own."""
    if found.motion >= 1.0:
        return {}
    entry = {"motion_kept": round(found.motion, 3), "seconds": round(found.seconds, 3)}
    if found.note(back):
        entry["note"] = found.note(back)
    return {"first_window": entry}


def following_record(found) -> dict:
    """The record's ``follow_clip`` entry (:class:`extend.Following`): how many seconds of the clip Follow the Clip
    had, how many it needs to play on through it, and where it had fewer how it played the clip on (``plays``:
    "back and forth" or "round"; ``cycle_s``: how often it comes round again) and the note the operator reports;
    empty where it did not follow the clip or the extension ends before it plays on (``found`` None)."""
    if found is None:
        return {}
    entry = {"seconds": round(found.seconds, 3), "needed_s": round(found.needed_s, 3)}
    if found.note():
        entry |= {"plays": found.plays, "cycle_s": round(found.cycle_s, 3), "note": found.note()}
    return {"follow_clip": entry}


PACE_SECONDS = 8.0  # how much of the action, up to its end, the pace is read from
PACE_SAMPLES = 96  # at most this many frames of it are read (evaluated rigs pay per frame)


def pace_record(context, clip, end: int | None = None) -> dict:
    """The record's ``pace`` entry: the stride of the action's locomotion (up to its last
    :data:`PACE_SECONDS` before ``end``) at the keys per second it was read at, and the note the
    operator reports when that stride is one people do not take (keys at another rate than the
    take's: set Keys per Second). Empty for motion without strides. With it, read from the same frames, the
    ``stance`` entry where the body stands along another axis than up (:func:`stance_record`)."""
    end = clip.last if end is None else int(end)
    span = min(end - clip.first, int(PACE_SECONDS * clip.fps))
    if span < 8:
        return {}
    step = max(1, math.ceil(span / PACE_SAMPLES))
    frames = np.arange(end - span, end + 1, step, dtype=np.float64)
    pos = pipeline.joint_positions(context, clip, frames)
    record = stance_record(pos)
    try:  # every ``step``-th key: read at ``fps / step``; the stride in seconds is the same
        stride = stride_period(pos, clip.fps / step)
    except ValueError:  # legs of zero length: the operation itself says so
        return record
    if stride is None:
        return record
    pace = Pace(stride, float(clip.fps))
    entry = {"stride_s": round(pace.stride_s, 3), "keys_per_second": float(clip.fps)}
    if pace.note():
        entry["note"] = pace.note()
        entry["suggested_keys_per_second"] = pace.suggested_rate()
    return {"pace": entry, **record}


def stance_record(pos) -> dict:
    """The record's ``stance`` entry where the body of ``pos`` (Y-up, model axes) stands along another axis than
    up in most frames (``rigs.standing_axis``: a BVH imported with the wrong Up axis lies on its back), with the
    note that says so and how to fix it; empty where it stands up, or lies or tumbles only some of the time."""
    axis = standing_axis(pos)
    if axis is None or axis[UP_AXIS] > 0:
        return {}
    label = axis_name(yup_to_zup(axis))
    note = (f"The character stands along the scene's {label} axis in most of the action, not up (Z), and the model "
            "learnt bodies standing on a floor, so the result may not hold: a BVH imported with the wrong Up axis? "
            "Import it again with Transform > Up set to the file's (Z for a Z-up file), or turn the armature "
            "object to stand")
    return {"stance": {"axis": label, "note": note}}


def stalls(context, clip, edge: int, back: bool = False) -> bool:
    """Whether the clip ends on a stalled frame at ``edge`` (:func:`extend.stalled_end`; ``back``: starts on one,
    read backwards in time), judged on its last :data:`extend.STALL_FRAMES` + 2 frames up to ``edge``, where each of
    them is keyed (motion baked frame by frame: a hand-keyed pass that eases into its last key means it)."""
    first = edge if back else edge - STALL_FRAMES - 1
    last = first + STALL_FRAMES + 1
    if first < clip.first or last > clip.last or not pipeline.keyed_every_frame(clip, first, last):
        return False
    pos = pipeline.joint_positions(context, clip, np.arange(first, last + 1, dtype=np.float64))
    return stalled_end(pos[::-1] if back else pos, clip.fps)


def stalled_record(stalled: int, edge: int, back: bool = False) -> dict:
    """The record's ``stalled_end`` entry where the action's last frame ``stalled`` (``back``: its first) repeated the
    one before and the new frames went on from ``edge`` instead, with the note the operator reports."""
    return {"stalled_end": {"frame": int(stalled), "note": (
        f"The action's {'first' if back else 'last'} frame ({stalled}) nearly repeats the one "
        f"{'after' if back else 'before'} it while the body moves (a stalled frame, as converted motion capture "
        f"often {'starts' if back else 'ends'}): the new frames go on from frame {edge} and the first of them "
        "takes its place in the new action, so the motion does not stumble at the cut; the original action "
        "keeps it")}}


def record_notes(action) -> list[str]:
    """The notes of a new action's record (a toe at a tail across its bone, its stance, pace,
    familiarity, held first window, what Follow the Clip had to follow, where a ground mesh was under no foot, a floor
    that rose under the clip, a stalled frame the new frames replaced and the keyed bones carried with the written
    ones), in that order."""
    record = action.get(RECORD, {})
    notes = [record.get(key, {}).get("note", "") for key in ("bone_map", "stance", "pace", "familiarity",
                                                            "first_window", "follow_clip", "ground", "floor_rise",
                                                            "stalled_end", "followers")]
    return [str(note) for note in notes if note]


def report_note(action) -> str:
    """:func:`record_notes` as sentences to append to an operator's report ('' if none)."""
    return "".join(f". {note}" for note in record_notes(action))


def with_bake(record: dict, clip, error: float, frames) -> dict:
    """``record``, with the first and last frame written, on a plain rig the keyed bones carried with the written
    ones they moved with (:func:`pipeline.followers`) and, on a control rig, how far (cm) the bake left a driven bone
    from the solve at worst."""
    record["frames_written"] = [int(frames[0]), int(frames[-1])]
    if clip.controls is None and clip.carried:  # a plain rig's keyed followers (an Unreal rig's IK bones)
        pairs = sorted(clip.carried.items())
        shown = ", ".join(f"{bone} on {carrier}" for bone, carrier in pairs[:4]) + (", ..." if len(pairs) > 4 else "")
        many = len(pairs) > 1
        if clip.channels is not None:  # read from the take's keys
            how = f"keyed bone{'s' if many else ''} outside the bone map followed {'bones' if many else 'a bone'} " \
                  "it writes over the take"
        else:  # no take: where they rest
            how = f"bone{'s' if many else ''} outside the bone map rest{'' if many else 's'} on " \
                  f"{'bones' if many else 'a bone'} it writes"
        record["followers"] = {"bones": dict(pairs), "note": (
            f"{len(pairs)} {how} ({shown}) and {'go' if many else 'goes'} on with {'them' if many else 'it'}")}
    if clip.controls is not None:
        worst_cm = round(100 * error * pipeline.world_scale(clip), 2)
        record["controls"] = {"set": clip.controls.name, "max_error_cm": worst_cm}
        if clip.controls.keyed_ik:  # limbs animated in IK, keyed on their IK controls
            record["controls"]["ik"] = list(clip.controls.keyed_ik)
    return record


def write_new(context, clip, suffix, frames, loc, rot, previous, replace, record: dict, bones=None,
              scene_range: bool = True, follows: bool = False, shape=None, first=None, root=None, joints=None):
    """Create the new action, hand it to ``first`` (a change before the keys go in, e.g. baking its cycles), key it
    (``bones``: only these; ``follows``: ``previous`` is the key after the frames, which come before it), label it
    with ``record``, hand it to ``shape`` (a last change to the whole action, e.g. making it cyclic) and assign it
    (widening the scene's range to it with ``scene_range``; ``root``: a root bone carrying the travel, keyed too);
    on failure remove it again. An action on twos (``record``'s ``key_step``) gets Constant keys in the channels this
    makes, as its own hold theirs. ``joints``: the joints ``loc``, ``rot`` were solved for
    (:func:`pipeline.write_pose`). A step generator (the fractions of a control rig's bake) that returns the action;
    closed part way (Esc), it removes the action again."""
    action = pipeline.new_action_from(clip, suffix)
    made = "CONSTANT" if record.get("key_step", 1) > 1 else ""
    try:
        if first is not None:
            first(action)
        error = yield from pipeline.write_pose(context, clip, action, frames, loc, rot, previous, replace, bones,
                                               follows, made, root, joints)
        action[RECORD] = with_bake(record, clip, error, frames)
        if action.use_frame_range:  # a manual frame range the animator set: widened to hold the written frames
            action.frame_start = min(action.frame_start, float(frames[0]))
            action.frame_end = max(action.frame_end, float(frames[-1]))
        if shape is not None:
            shape(action)
        pipeline.finish(context, clip, action, scene_range)
    except BaseException:  # a failure, or closed part way
        bpy.data.actions.remove(action)
        raise
    return action


def write_fresh(context, clip, name: str, frames, loc, rot, record: dict, scene_range: bool = True,
                interpolation: str = "", root=None, joints=None):
    """A new action ``name`` holding only the new frames (keys of ``interpolation``, default Linear: Constant for a
    source on twos; ``root``: a root bone carrying the travel, keyed too): keyed, labelled, assigned, the scene's
    range widened (with ``scene_range``); an action the armature had is kept (fake user). ``joints``: the joints
    ``loc``, ``rot`` were solved for (:func:`pipeline.write_pose`). A step generator, as :func:`write_new`."""
    action = bpy.data.actions.new(name)
    clip.first, clip.last = int(frames[0]), int(frames[-1])  # no static keys outside the new frames
    old = clip.obj.animation_data.action if clip.obj.animation_data else None
    try:
        error = yield from pipeline.write_pose(context, clip, action, frames, loc, rot, {}, None,
                                               interpolation=interpolation, root=root, joints=joints)
        pipeline.hold(clip, action, frames, interpolation)
        action[RECORD] = with_bake(record, clip, error, frames)
        anim.assign_action(clip.obj, action, None)
        ad = clip.obj.animation_data
        if getattr(ad, "action_slot", True) is None and len(action.slots):
            ad.action_slot = action.slots[0]
    except BaseException:  # a failure, or closed part way
        bpy.data.actions.remove(action)
        raise
    if old is not None:
        old.use_fake_user = True
    if scene_range:
        context.scene.frame_end = max(context.scene.frame_end, clip.last)
    return action


class Unwritten:
    """What writing an armature's new action changes besides the action itself (:func:`write_new`,
    :func:`write_fresh`): its animation data (the action and slot it plays, or none at all), the fake user of that
    action, its saved bone map, and the scene's frame range, taken before the writing; :meth:`undo` puts them back
    and removes the new action. An operator on several armatures that stops while writing a later one (Esc, a
    failure) so leaves the ones already written as they were too."""

    def __init__(self, context, obj):
        self.obj, self.scene = obj, context.scene
        ad = obj.animation_data
        self.had_data = ad is not None
        self.action = ad.action if ad else None
        slot = anim.slot_of(obj)
        self.slot = slot.identifier if slot else None
        self.fake_user = self.action.use_fake_user if self.action else False
        props = obj.strnn_map
        self.map = {p.identifier: getattr(props, p.identifier) for p in props.bl_rna.properties
                    if p.identifier != "rna_type"}
        self.frames = (self.scene.frame_start, self.scene.frame_end)

    def undo(self, made) -> None:
        """Put back what was taken, removing the new action ``made`` (None: nothing was made)."""
        obj = self.obj
        if not self.had_data:
            if obj.animation_data is not None:
                obj.animation_data_clear()
        elif obj.animation_data.action is not self.action:
            anim.assign_action(obj, self.action, self.slot)
        if self.action is not None:
            self.action.use_fake_user = self.fake_user
        props = obj.strnn_map
        for name, value in self.map.items():
            if getattr(props, name) != value:
                setattr(props, name, value)
        if made is not None and any(a == made for a in bpy.data.actions):  # (a failure may have removed it)
            bpy.data.actions.remove(made)
        self.scene.frame_start, self.scene.frame_end = self.frames
