"""Extend Clip, Denoise Action and Foot Lock, as keyword-only workers the operators call.

Each worker is a step generator (``model_core.inference.steps``) that yields the name of each
stage (read, model, solve, write) before running it, and may yield the fraction of a stage
done as it goes (Follow Curve, window by window), so the operators can show progress and
stop on Esc in between; :func:`run` drives one to the end. Every check and all the computing happen
before the new action is created, so a failure or a cancel leaves the file unchanged.
"""

from __future__ import annotations

import contextlib
import tomllib
from pathlib import Path

import numpy as np

from ..model_core.inference.steps import drive
from ..model_core.ops import footlock
from ..model_core.rig.solve import solve
from . import engine_bridge, pipeline, rig_io
from .pipeline import UserError
from .props import preferences

STAGES = ("read", "model", "solve", "write")
EDGE_FADE_S = 0.2  # a partial Denoise range fades in and out over this long where it meets untouched frames
VERSION = tomllib.loads((Path(__file__).resolve().parent.parent / "blender_manifest.toml").read_text())["version"]
RECORD = "strnn"  # the custom property of a new action that says how it was made
MIN_LOCK_FRAMES = 3


def _noop(stage: str) -> None:
    pass


@contextlib.contextmanager
def _model_errors():
    """Model and engine errors raised inside as a :class:`UserError`."""
    try:
        yield
    except engine_bridge.EngineError as e:
        raise UserError(str(e)) from e
    except ValueError as e:
        raise UserError(f"The model could not run on this clip: {e}") from e


def _model_call(fn, *args):
    """Run one model call, turning model and engine errors into a :class:`UserError`."""
    with _model_errors():
        return fn(*args)


def _model_steps(steps):
    """``yield from`` a model's step generator (fractions done), turning its errors into a :class:`UserError`."""
    with _model_errors():
        return (yield from steps)


def run(steps, progress=_noop):
    """Drive a worker generator to the end, calling ``progress(stage)`` at each stage (not at the
    fractions a stage may yield as it goes); returns its result."""
    return drive(steps, lambda value: progress(value) if isinstance(value, str) else None)


def extend_clip(context, obj, *, progress=_noop, **options):
    """:func:`extend_steps` run to the end; returns the new action."""
    return run(extend_steps(context, obj, **options), progress)


def denoise_action(context, obj, *, progress=_noop, **options):
    """:func:`denoise_steps` run to the end; returns the new action."""
    return run(denoise_steps(context, obj, **options), progress)


def lock_feet(context, obj, *, progress=_noop, **options):
    """:func:`foot_lock_steps` run to the end; returns the new action."""
    return run(foot_lock_steps(context, obj, **options), progress)


def _frame_range(clip, frame_start: int | None, frame_end: int | None, need: int, why: str) -> tuple[int, int]:
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


def _context_range(clip, context_frames: int, frames: int, end: int) -> np.ndarray:
    """Scene frames ``[C]`` the model reads: the ``context_frames`` (0: just enough) up to ``end``."""
    need = pipeline.min_scene_frames(clip.fps)
    n_ctx = max(context_frames, need)
    if not clip.first <= end <= clip.last:
        raise UserError(f"Frame {end} lies outside the action {clip.action.name!r} (frames {clip.first}-"
                        f"{clip.last}): move the current frame into it to continue from there")
    span = end - clip.first + 1
    if n_ctx > span:
        before = f"up to frame {end}" if end < clip.last else "frames"
        raise UserError(f"The action {clip.action.name!r} has {span} {before}; extending needs at least "
                        f"{n_ctx} at {clip.fps:g} fps (the model reads {pipeline.MIN_MODEL_FRAMES} "
                        "frames at 30 fps): use a longer action, a later frame or a smaller context")
    if frames < 1:
        raise UserError("Frames to add must be at least 1")
    return np.arange(end - n_ctx + 1, end + 1, dtype=np.float64)


def extend_steps(context, obj, *, frames: int = 120, context_frames: int = 0, foot_lock: bool = False,
                 from_frame: int | None = None):
    """Continue ``obj``'s action by ``frames`` scene frames from its last ``context_frames``
    (0: just enough for the model's 20-frame context), feet locked on the new frames when
    ``foot_lock``. ``from_frame``: continue after this frame instead of the action's last, the
    written bones' keys after it replaced. A generator: yields each stage's name before running
    it (so a caller can report progress or stop), returns the new action."""
    clip = pipeline.prepare(context, obj)
    end = clip.last if from_frame is None else int(from_frame)
    ctx_frames = _context_range(clip, context_frames, frames, end)
    yield "read"
    pos = pipeline.joint_positions(context, clip, ctx_frames)
    held_loc, held_rot, _ = rig_io.read_local_pose(clip.obj, clip.rig, clip.channels.fcurves, ctx_frames[-1:])
    previous = pipeline.raw_rotations(clip, end)
    yield "model"
    new_pos = _model_call(engine_bridge.extend, _prefs(context), pos, clip.fps, frames)
    if foot_lock:
        new_pos = _lock(np.concatenate([pos, new_pos]), clip.fps, fixed=np.arange(len(pos) + frames) < len(pos))
        new_pos = new_pos[len(pos):]
    yield "solve"
    targets = pipeline.to_armature(clip, new_pos)
    loc, rot = solve(clip.rig, clip.anchors, targets, np.repeat(held_loc, frames, 0), np.repeat(held_rot, frames, 0))
    yield "write"
    new_frames = end + 1 + np.arange(frames, dtype=np.float64)
    record = made_by("Extend Clip", clip, engine_bridge.model_used(_prefs(context)), frames=frames,
                     context_frames=len(ctx_frames), foot_lock=foot_lock, from_frame=from_frame)
    record.update(familiarity_record(_model_call(engine_bridge.familiarity, _prefs(context), pos, clip.fps)))
    replace = None if end == clip.last else (end + 0.5, float("inf"))  # the old tail goes
    return _write_new(context, clip, "extended", new_frames, loc, rot, previous, replace, record)


def denoise_steps(context, obj, *, frame_start: int | None = None, frame_end: int | None = None,
                  strength: float = 1.0, foot_lock: bool = False):
    """Denoise ``obj``'s action over [frame_start, frame_end] (default: the whole action),
    blending the model's output by ``strength``, then lock the feet when ``foot_lock``.
    A generator like :func:`extend_steps`."""
    clip = pipeline.prepare(context, obj)
    need = pipeline.min_scene_frames(clip.fps)
    a, b = _frame_range(clip, frame_start, frame_end, need, f"denoising needs at least {need} at {clip.fps:g} fps")
    frames = np.arange(a, b + 1, dtype=np.float64)
    yield "read"
    pos = pipeline.joint_positions(context, clip, frames)
    ref_loc, ref_rot, _ = rig_io.read_local_pose(clip.obj, clip.rig, clip.channels.fcurves, frames)
    previous = pipeline.raw_rotations(clip, a)
    yield "model"
    clean = yield from _model_steps(engine_bridge.denoise_steps(_prefs(context), pos, clip.fps, float(strength)))
    clean = _fade_edges(pos, clean, clip.fps, a > clip.first, b < clip.last)
    if foot_lock:
        clean = _lock(clean, clip.fps)
    yield "solve"
    loc, rot = solve(clip.rig, clip.anchors, pipeline.to_armature(clip, clean), ref_loc, ref_rot)
    yield "write"
    record = made_by("Denoise Action", clip, engine_bridge.model_used(_prefs(context), "denoise"), frame_start=a,
                     frame_end=b, strength=float(strength), foot_lock=foot_lock)
    return _write_new(context, clip, "denoised", frames, loc, rot, previous, (a, b), record)


def foot_lock_steps(context, obj, *, frame_start: int | None = None, frame_end: int | None = None,
                    blend: float = footlock.FootLockSettings.blend_s):
    """Pin the feet of ``obj``'s action on the ground while they touch it, over [frame_start,
    frame_end] (default: the whole action), fading locks in and out over ``blend`` seconds.
    Only the leg bones get new keys. A generator like :func:`extend_steps`."""
    clip = pipeline.prepare(context, obj)
    a, b = _frame_range(clip, frame_start, frame_end, MIN_LOCK_FRAMES, f"foot lock needs at least {MIN_LOCK_FRAMES}")
    frames = np.arange(max(a - 1, clip.first), min(b + 1, clip.last) + 1, dtype=np.float64)
    inside = (frames >= a) & (frames <= b)  # plus one untouched frame either side to continue from
    yield "read"
    pos = pipeline.joint_positions(context, clip, frames)
    ref_loc, ref_rot, _ = rig_io.read_local_pose(clip.obj, clip.rig, clip.channels.fcurves, frames)
    previous = pipeline.raw_rotations(clip, a)
    yield "model"
    contacts = _lock(pos, clip.fps, detect_only=True)
    if not contacts[inside].any():
        raise UserError(f"No foot touches the ground in frames {a}-{b} of {clip.action.name!r} (feet near their "
                        "lowest height and slower than 0.6 m/s): nothing to lock")
    locked = _lock(pos, clip.fps, contacts=contacts, fixed=~inside, blend=blend)
    yield "solve"
    loc, rot = solve(clip.rig, clip.anchors, pipeline.to_armature(clip, locked), ref_loc, ref_rot)
    yield "write"
    record = made_by("Foot Lock", clip, frame_start=a, frame_end=b, blend=float(blend))
    return _write_new(context, clip, "footlocked", frames[inside], loc[inside], rot[inside], previous, (a, b),
                      record, bones=pipeline.leg_bones(clip))


def _fade_edges(before: np.ndarray, after: np.ndarray, fps: float, fade_in: bool, fade_out: bool) -> np.ndarray:
    """``after`` ``[F, 21, 3]`` blended from ``before`` over :data:`EDGE_FADE_S` at the start
    (``fade_in``) and end (``fade_out``) of a range, so it meets the frames around it without a pop."""
    n = len(after)
    k = min(int(round(EDGE_FADE_S * fps)), n // 4)
    weight = np.ones(n)
    ramp = np.arange(1, k + 1) / (k + 1)
    if k and fade_in:
        weight[:k] = np.minimum(weight[:k], ramp)
    if k and fade_out:
        weight[n - k:] = np.minimum(weight[n - k:], ramp[::-1])
    return before + weight[:, None, None] * (after - before)


def _lock(pos, fps, *, blend: float | None = None, detect_only: bool = False, **kw):
    """:func:`footlock.foot_lock` of scene positions ``[F, 21, 3]`` (or, with ``detect_only``, their
    contacts ``[F, 4]``), its errors as :class:`UserError`."""
    settings = footlock.FootLockSettings()
    if blend is not None:
        settings.blend_s = max(float(blend), 0.0)
    try:
        if detect_only:
            return footlock.detect_foot_contacts(pos, fps)
        return footlock.foot_lock(pos, fps, settings=settings, **kw)
    except ValueError as e:
        raise UserError(f"Foot lock could not run on this clip: {e}") from e


def _prefs(context):
    return preferences(context)


def made_by(operation: str, clip, model: str = "", **settings) -> dict:
    """The :data:`RECORD` a new action carries: the operation and extension version that made it,
    the action it was made from, the model folder it used (if any) and its settings."""
    record = {"operation": operation, "version": VERSION,
              "source_action": clip.action.name if clip.action is not None else ""}
    if model:
        record["model"] = model
    record["settings"] = {k: v for k, v in settings.items() if v is not None}
    return record


def familiarity_record(found) -> dict:
    """The record's ``familiarity`` entry: the clip's reconstruction error against the model's usual,
    and the note the operator reports when the clip is unlike what the model learnt."""
    entry = {"reconstruction_cm": round(found.error_cm, 2)}
    if found.usual_cm:
        entry["usual_cm_p90"] = found.usual_cm
    if found.note():
        entry["note"] = found.note()
    return {"familiarity": entry}


def report_note(action) -> str:
    """The familiarity note of a new action's record, as a sentence to append to a report ('' if none)."""
    note = action.get(RECORD, {}).get("familiarity", {}).get("note", "")
    return f". {note}" if note else ""


def _write_new(context, clip, suffix, frames, loc, rot, previous, replace, record: dict, bones=None):
    """Create the new action, key it (``bones``: only these), label it with ``record`` and assign
    it; on failure remove it again."""
    action = pipeline.new_action_from(clip, suffix)
    try:
        action[RECORD] = record
        pipeline.write_pose(clip, action, frames, loc, rot, previous, replace, bones)
        pipeline.finish(context, clip, action)
    except Exception:
        import bpy

        bpy.data.actions.remove(action)
        raise
    return action
