"""Denoise Action: clean an armature's action with the denoising model, as a stage generator."""

from __future__ import annotations

import numpy as np

from ...model_core.ops.seam import fade_edges
from .. import engine_bridge
from ..scene import pipeline
from .common import (
    familiarity_record,
    frame_range,
    lock,
    made_by,
    model_call,
    model_steps,
    noop,
    pace_record,
    prefs,
    run,
    write_new,
)


def denoise_action(context, obj, *, progress=noop, **options):
    """:func:`denoise_steps` run to the end; returns the new action."""
    return run(denoise_steps(context, obj, **options), progress)


def denoise_steps(context, obj, *, frame_start: int | None = None, frame_end: int | None = None,
                  strength: float = 1.0, foot_lock: bool = False, only_selected: bool = False):
    """Denoise ``obj``'s action over [frame_start, frame_end] (default: the whole action),
    blending the model's output by ``strength``, then lock the feet when ``foot_lock``; with
    ``only_selected`` only the selected bones get new keys (the others keep theirs exactly).
    A generator like :func:`.extend.extend_steps`."""
    clip = pipeline.prepare(context, obj)
    bones = pipeline.only_selected(clip, pipeline.written_bones(clip), "Denoise writes") if only_selected else None
    need = pipeline.min_scene_frames(clip.fps)
    a, b = frame_range(clip, frame_start, frame_end, need, f"denoising needs at least {need} at {clip.fps:g} fps")
    step, keys = pipeline.key_grid(clip, a, b)  # keys on twos: read and cleaned at its keys, written on them
    if len(keys) < pipeline.min_scene_frames(clip.fps / step):
        step, keys = 1, np.arange(a, b + 1)
    frames, fps = keys.astype(np.float64), clip.fps / step
    yield "read"
    pos = yield from pipeline.joint_positions_steps(context, clip, frames)
    previous = pipeline.raw_rotations(clip, a)
    yield "model"
    clean = yield from model_steps(engine_bridge.run_denoise(prefs(context), pos, fps, float(strength)))
    found = model_call(engine_bridge.run_denoised_familiarity, prefs(context), pos, clean, fps, float(strength))
    clean = fade_edges(pos, clean, fps, frames[0] > clip.first, frames[-1] < clip.last)
    if foot_lock:
        clean = lock(clean, fps)
    yield "solve"
    loc, rot, joints = yield from pipeline.solve_frames_steps(context, clip, frames, clean)
    record = made_by("Denoise Action", clip, engine_bridge.model_used(prefs(context), "denoise"), key_step=step,
                     frame_start=a, frame_end=b, strength=float(strength), foot_lock=foot_lock,
                     only_selected=only_selected)
    record.update(familiarity_record(found, denoised=True))
    record.update(pace_record(context, clip))
    yield "write"  # every check and every read done: only the writing is left
    return (yield from write_new(context, clip, "denoised", frames, loc, rot, previous, (a, b), record, bones=bones,
                                 joints=joints))
