"""Fill Gap (in-betweening): the frames between the keys before and after a gap in an armature's
action, made by the model, as a stage generator."""

from __future__ import annotations

import numpy as np

from ...model_core.inference.steps import share
from ...model_core.ops.extend import MEMORY_S
from ...model_core.ops.footlock import SETTLE_PASSES
from ...model_core.ops.inbetween import MAX_GAP_S
from .. import engine_bridge
from ..scene import pipeline, rig_io
from ..scene.pipeline import UserError
from .common import familiarity_record, lock, made_by, model_call, noop, pace_record, prefs, run, write_new

MIN_GAP_FRAMES = 2


def fill_gap(context, obj, *, progress=noop, **options):
    """:func:`inbetween_steps` run to the end; returns the new action."""
    return run(inbetween_steps(context, obj, **options), progress)


def key_frames(clip) -> np.ndarray:
    """Sorted whole frames ``[K]`` that hold a key on any written (mapped) bone, or on a control rig
    on any of their controls."""
    names = set(pipeline.keyed_names(clip))
    frames = set()
    for (bone, _prop), curves in rig_io.bone_channels(clip.channels.fcurves).items():
        if bone in names:
            for fc in curves.values():
                co = np.empty(2 * len(fc.keyframe_points))
                fc.keyframe_points.foreach_get("co", co)
                frames.update(np.round(co[0::2]).astype(int).tolist())
    return np.array(sorted(frames), dtype=int)


def find_gap(clip, keys: np.ndarray, frame_start: int | None, frame_end: int | None,
             current: int | None) -> tuple[int, int]:
    """First and last frame to fill: the given range; else the gap between keys around ``current``;
    else the first run of frames without keys on the mapped bones. A :class:`UserError` says why not."""
    name = clip.action.name
    if frame_start is not None and frame_end is not None:
        if frame_start > frame_end:
            raise UserError(f"Start {frame_start} is after End {frame_end}: swap them")
        return int(frame_start), int(frame_end)
    if len(keys) < 2:
        raise UserError(f"The mapped bones of {name!r} have keys on {len(keys)} frame(s): key a pose before and "
                        "after the gap")
    spacing = np.diff(keys)
    usual = int(np.bincount(spacing).argmax())  # animation on twos (up to fours): the frames between keys are no gap
    gaps = [(int(a) + 1, int(b) - 1) for a, b in zip(keys[:-1], keys[1:]) if b - a > (usual if usual <= 4 else 1)]
    if current is not None:
        around = [g for g in gaps if g[0] <= current <= g[1]]
        if around:
            return around[0]
    if current is not None and current > keys[-1]:
        raise UserError(f"No key on the mapped bones of {name!r} after frame {keys[-1]}: key a pose after the gap "
                        "(Extend Clip continues an action past its last key)")
    if not gaps:
        every = "every frame" if usual <= 1 else f"every {usual} frames"
        raise UserError(f"The mapped bones of {name!r} are keyed on {every} from {keys[0]} to {keys[-1]}: "
                        "there is no gap to fill (delete the keys of the frames to fill, or give a Frame Range)")
    return gaps[0]


def check_gap(clip, keys: np.ndarray, start: int, end: int) -> None:
    """A :class:`UserError` unless frames ``start..end`` are a gap the model can fill."""
    name = clip.action.name
    if end - start + 1 < MIN_GAP_FRAMES:
        raise UserError(f"The gap {start}-{end} has {end - start + 1} frame; Fill Gap needs at least "
                        f"{MIN_GAP_FRAMES} (Blender's own interpolation is as good for one frame)")
    if not (keys < start).any():
        raise UserError(f"No key on the mapped bones of {name!r} before frame {start}: key a pose before the gap")
    if not (keys > end).any():
        raise UserError(f"No key on the mapped bones of {name!r} after frame {end}: key a pose after the gap")
    seconds = (end - start + 2) / clip.fps
    if seconds > MAX_GAP_S:
        raise UserError(f"The gap {start}-{end} lasts {seconds:.1f} s, longer than the {MAX_GAP_S:g} s the model "
                        "can bridge: key a pose inside it and fill the two shorter gaps")


def frames_after(fps: float) -> int:
    """Scene frames after the gap the model reads: the target and the frame after it at the model's rate."""
    return int(np.ceil(fps / 30.0)) + 1


def take_ranges(clip, start: int, end: int, follow_take: bool, step: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Scene frames read before and after the gap ``start..end``: what the model needs (its context, the target
    and the frame after it) or, when ``follow_take``, up to :data:`extend.MEMORY_S` seconds either side,
    within the action; every ``step``-th from the gap's edges (an action keyed on twos is read at its keys)."""
    fps = clip.fps / step
    most = int(round(MEMORY_S * fps)) if follow_take else 0
    need_before = max(pipeline.min_scene_frames(fps), most)
    need_after = max(frames_after(fps), most)
    before = start - 1 - step * np.arange(need_before, dtype=np.float64)[::-1]
    after = end + 1 + step * np.arange(need_after, dtype=np.float64)
    return before[before >= clip.first], after[after <= clip.last]


def inbetween_steps(context, obj, *, frame_start: int | None = None, frame_end: int | None = None,
                    from_playhead: bool = True, follow_take: bool = True, foot_lock: bool = True):
    """Fill frames ``frame_start..frame_end`` of ``obj``'s action (default: the gap between keys around
    the current frame when ``from_playhead``, else the first gap) with the model's in-between, leaning on the
    rest of the action where it did what the gap must when ``follow_take``, feet locked when ``foot_lock``.
    A generator like :func:`stages.extend.extend_steps`."""
    clip = pipeline.prepare(context, obj)
    keys = key_frames(clip)
    current = context.scene.frame_current if from_playhead else None
    start, end = find_gap(clip, keys, frame_start, frame_end, current)
    check_gap(clip, keys, start, end)
    step, key = pipeline.key_step(clip, start - 1) if start - 1 in keys and end + 1 in keys else (1, start - 1)
    step = step if key == start - 1 and (end - start + 2) % step == 0 else 1  # keys on twos either side: on twos
    fps = clip.fps / step
    need = pipeline.min_scene_frames(fps)
    read_before, read_after = take_ranges(clip, start, end, follow_take, step)
    gap = np.arange(start - 1 + step, end + 1, step, dtype=np.float64)
    yield "read"
    before = len(read_before) / max(1, len(read_before) + len(read_after))  # each read's share of the stage
    taken_before = yield from share(pipeline.joint_positions_steps(context, clip, read_before), 0.0, before)
    taken_after = yield from share(pipeline.joint_positions_steps(context, clip, read_after), before, 1.0 - before)
    previous = pipeline.raw_rotations(clip, start - 1)
    yield "model"
    new_pos = model_call(engine_bridge.run_inbetween, prefs(context), taken_before, taken_after, fps, len(gap),
                         follow_take)
    # Foot Lock and the familiarity read the frames next to the gap only
    before, after = read_before[-need:], read_after[:frames_after(fps)]
    pos_before, pos_after = taken_before[-need:], taken_after[:len(after)]
    if foot_lock:
        seq = np.concatenate([pos_before, new_pos, pos_after])
        fixed = np.ones(len(seq), bool)
        fixed[len(before):len(before) + len(gap)] = False
        new_pos = lock(seq, fps, fixed=fixed, passes=SETTLE_PASSES)[len(before):len(before) + len(gap)]
    yield "solve"
    loc, rot, joints = yield from pipeline.solve_frames_steps(context, clip, gap, new_pos)
    record = made_by("Fill Gap", clip, engine_bridge.model_used(prefs(context)), key_step=step,
                     frame_start=start, frame_end=end,
                     follow_take_frames=len(read_before) + len(read_after) if follow_take else 0, foot_lock=foot_lock)
    if len(before) >= need:  # how well the model knows the motion before the gap, as Extend reports it
        record.update(familiarity_record(model_call(engine_bridge.run_familiarity, prefs(context), pos_before,
                                                    fps)))
    record.update(pace_record(context, clip))
    yield "write"  # every check and every read done: only the writing is left
    return (yield from write_new(context, clip, "filled", gap, loc, rot, previous, (start - 0.5, end + 0.5), record,
                                 joints=joints))
