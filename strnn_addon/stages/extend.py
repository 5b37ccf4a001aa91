"""Extend Clip: continue an armature's action with the model, as a stage generator."""

from __future__ import annotations

import numpy as np

from ...model_core.motion.conventions import STANDARD_LEG_LENGTH, UP_AXIS
from ...model_core.ops.extend import FLOOR_S, MEMORY_S, clip_floor, clip_in_place, floor_rise
from ...model_core.ops.footlock import SETTLE_PASSES
from ...model_core.rig.rigs import leg_length
from ...model_core.rig.solve import solve
from .. import engine_bridge
from ..scene import anim, cycles, pipeline
from ..scene.ground import carried, find_ground, flattened, ground_record
from ..scene.pipeline import UserError
from .common import (
    familiarity_record,
    first_window_record,
    following_record,
    lock,
    made_by,
    model_call,
    noop,
    pace_record,
    prefs,
    run,
    stalled_record,
    stalls,
    write_new,
)


def extend_clip(context, obj, *, progress=noop, **options):
    """:func:`extend_steps` run to the end; returns the new action."""
    return run(extend_steps(context, obj, **options), progress)


def context_range(clip, context_frames: int, frames: int, end: int, step: int = 1, back: bool = False) -> np.ndarray:
    """Scene frames ``[C]`` the model reads, in the order it reads them: the ``context_frames`` (0: just enough) up
    to ``end``, every ``step``-th (an action keyed on twos is read at its keys, :func:`pipeline.key_step`); with
    ``back`` (frames before the start) the frames from ``end`` on, read backwards in time from the last."""
    fps = clip.fps / step
    need = pipeline.min_scene_frames(fps)
    n_ctx = max(-(-context_frames // step), need)
    if not clip.first <= end <= clip.last:
        where = "before it" if back else "from there"
        raise UserError(f"Frame {end} lies outside the action {clip.action.name!r} (frames {clip.first}-"
                        f"{clip.last}): move the current frame into it to continue {where}")
    span = ((clip.last - end) if back else (end - clip.first)) // step + 1
    if n_ctx > span:
        before = (f"from frame {end}" if end > clip.first else "frames") if back else \
            (f"up to frame {end}" if end < clip.last else "frames")
        on = f" keys (it is keyed every {step} frames)" if step > 1 else ""
        raise UserError(f"The action {clip.action.name!r} has {span}{on} {before}; extending needs at least "
                        f"{n_ctx} at {fps:g} fps (the model reads {pipeline.MIN_MODEL_FRAMES} "
                        "frames at 30 fps): use a longer action, a later frame or a smaller context")
    if frames < 1:
        raise UserError("Frames to add must be at least 1")
    return end - (-1 if back else 1) * step * np.arange(n_ctx, dtype=np.float64)[::-1]


def memory_range(clip, ctx_frames: np.ndarray, seconds: float = MEMORY_S, step: int = 1,
                 back: bool = False) -> np.ndarray:
    """Scene frames ``[M]`` of the clip's own motion the continuation leans on (:data:`extend.MEMORY_S` seconds
    up to the context's last frame, or ``seconds``, within the action; at least the context's frames), every
    ``step``-th back from the context's last, in the order the model reads them (``back``: backwards in time)."""
    end, sign = int(ctx_frames[-1]), -1 if back else 1
    most = int(round(seconds * clip.fps)) - 1
    far = max(clip.first, end - most) if not back else min(clip.last, end + most)
    reach = max(abs(end - far), abs(end - int(ctx_frames[0])))
    return end - sign * step * np.arange(reach // step + 1, dtype=np.float64)[::-1]


def extend_steps(context, obj, *, frames: int = 120, context_frames: int = 0, follow_clip: bool = True,
                 foot_lock: bool = False, from_frame: int | None = None, scene_range: bool = True,
                 before_start: bool = False, ground: str = ""):
    """Continue ``obj``'s action by ``frames`` scene frames from its last ``context_frames``
    (0: just enough for the model's 20-frame context), leaning after the model's first window on the
    clip's own motion (up to :data:`extend.MEMORY_S` seconds of it) when ``follow_clip``, feet locked on the
    new frames when ``foot_lock``. ``from_frame``: continue after this frame instead of the action's last, the
    written bones' keys after it replaced. ``before_start``: add the frames before the action's first frame (or
    before ``from_frame``, the keys before it replaced) instead, the clip read backwards in time, as a lead-in or a
    simulation's pre-roll. ``scene_range``: widen the scene's range to the new frames. ``ground``: a mesh the clip
    walks on (a slope, terrain): the new frames go up and down with its surface under the hips, their feet locked
    on it. A generator: yields each stage's name before running it (so a caller can report progress or stop),
    returns the new action."""
    surface = find_ground(ground, obj) if ground else None
    clip = pipeline.prepare(context, obj)
    back, sign = before_start, -1 if before_start else 1
    edge = (clip.first if back else clip.last) if from_frame is None else int(from_frame)
    # a walk cycle keyed with Cycles modifiers plays on beyond its keys: the clip is what plays, up to the edge, and
    # the new action has those cycles as keys (and no more repeats), so that the new frames follow them
    cycled = cycles.repeats(clip, back)
    keys_end = clip.first if back else clip.last
    baked = np.arange(edge, keys_end) if back else np.arange(keys_end + 1, edge + 1)
    if cycled:
        clip.first, clip.last = min(clip.first, edge), max(clip.last, edge)
    # keys on twos: read at its keys (the one ``edge`` holds, or the first from it), continued on twos
    step, key = pipeline.key_step(clip, edge, back)
    # an action that ends on a stalled frame (converted mocap often does) goes on from the frame before, the new
    # frames' first in its place, so that the motion does not stop for a frame and stumble at the cut
    at_end = edge == (clip.first if back else clip.last)  # the action's own end, or the playhead on it
    stalled = edge if at_end and not cycled and step == 1 and stalls(context, clip, edge, back) else None
    asked = frames
    if stalled is not None:
        edge, key, frames = edge - sign, edge - sign, frames + 1
    fps, count = clip.fps / step, -(-(frames + sign * (edge - key)) // step)  # the keys' rate, the new keys
    ctx_frames = context_range(clip, context_frames, frames, key, step, back)
    yield "read"
    # following the clip, up to 20 s of it; otherwise what the floor is judged on (extend.FLOOR_S)
    mem_frames = memory_range(clip, ctx_frames, MEMORY_S if follow_clip else FLOOR_S, step, back)
    order = np.argsort(mem_frames)  # read in time order, then as the model reads them
    read = yield from pipeline.joint_positions_steps(context, clip, mem_frames[order])
    memory = np.empty_like(read)
    memory[order] = read
    seen = memory[len(mem_frames) - len(ctx_frames):]  # the context as it is
    rise = None
    if surface is not None:  # read as walked on a flat floor at the edge's height, as the model learnt walks
        memory = flattened(context, surface, memory, fps)
    elif (rise := floor_rise(memory, fps)) is not None:  # up or down something no mesh stands for: on at the edge
        memory = memory.copy()
        memory[..., UP_AXIS] -= rise[:, None]
        seen = memory[len(mem_frames) - len(ctx_frames):]  # the new frames' feet level with the edge's
    pos = memory[len(mem_frames) - len(ctx_frames):]
    held_loc, held_rot = pipeline.reference_pose(context, clip, ctx_frames[-1:])
    previous = pipeline.raw_rotations(clip, edge)
    yield "model"
    followed = memory if follow_clip and len(mem_frames) > len(ctx_frames) else None
    floor = clip_floor(memory, fps)  # the ground the new feet stay out of
    new_pos = model_call(engine_bridge.run_extend, prefs(context), pos, fps, count, followed, floor)
    joined, heights, bare = np.concatenate([seen, new_pos]), None, 0
    if surface is not None:  # the new frames, made on the flat floor, carried over the ground; the feet stand as
        joined, heights, _, bare = carried(context, surface, joined, len(pos), fps)  # high as the clip's over it
    if foot_lock:
        joined = lock(joined, fps, fixed=np.arange(len(pos) + count) < len(pos), passes=SETTLE_PASSES,
                      ground=heights)
    new_pos = joined[len(pos):]
    new_frames = key + sign * step * (1 + np.arange(count, dtype=np.float64))
    yield "solve"
    ref_loc, ref_rot = np.repeat(held_loc, count, 0), np.repeat(held_rot, count, 0)
    arm_world = yield from pipeline.world_at_steps(context, clip, new_frames)
    # a game rig's root carries the travel: on with the body
    root, carry = pipeline.moving_root(context, clip, mem_frames, ctx_frames[-1]), None
    if root is not None:
        carry = np.linalg.inv(arm_world) @ root.track(joined, len(pos), fps, surface)[1:]
        ref_loc, ref_rot = pipeline.root_carried(clip, root.bone, ref_loc, ref_rot, carry)
        previous.update(pipeline.raw_rotations(clip, edge, [root.bone]))
    if back:  # written in time order
        new_frames, new_pos, arm_world = new_frames[::-1], new_pos[::-1], arm_world[::-1]
        ref_loc, ref_rot = ref_loc[::-1], ref_rot[::-1]
        carry = carry[::-1] if carry is not None else None
    targets = pipeline.to_armature(clip, new_pos, arm_world)
    loc, rot = solve(clip.rig, clip.anchors, targets, ref_loc, ref_rot)
    record = made_by("Extend Clip", clip, engine_bridge.model_used(prefs(context)), key_step=step,
                     frames=asked, context_frames=len(ctx_frames),
                     follow_clip_frames=len(mem_frames) if follow_clip else 0,
                     foot_lock=foot_lock, from_frame=from_frame, before_start=before_start or None)
    if surface is not None:
        record.update(ground_record(surface, bare, len(joined)))
    if stalled is not None:
        record.update(stalled_record(stalled, edge, back))
    if rise is not None:  # in cm for a body of the standard leg length, as the rule judges it
        cm = 100 * float(np.ptp(rise)) * STANDARD_LEG_LENGTH / leg_length(seen)
        record["floor_rise"] = {"cm": round(cm, 1), "note": (
            f"The clip's floor rises or falls {cm:.0f} cm (for a standard body) over what Extend read (stairs, a "
            "slope?): the new frames go on level at its height where the clip ends; to carry them over the ground, "
            "name its mesh as Ground")}
    if followed is not None and clip_in_place(followed, fps):  # the new frames kept where the clip walks in place
        record["in_place"] = True
    if cycled:
        record["cycles_baked"] = [int(baked[0]), int(baked[-1])] if len(baked) else []
    if root is not None:
        record["root_motion"] = {"bone": root.bone}
    record.update(familiarity_record(model_call(engine_bridge.run_familiarity, prefs(context), pos, fps)))
    held = model_call(engine_bridge.run_first_window, prefs(context), pos, fps, followed)
    record.update(first_window_record(held, back))
    if followed is not None:
        record.update(following_record(model_call(engine_bridge.run_following, prefs(context), followed, fps, count)))
    record.update(pace_record(context, clip, edge if not back else None))
    # the written bones' keys beyond the edge go: the old tail or head (from a frame), or keys past a manual range
    replace = (-float("inf"), edge - 0.5) if back else (edge + 0.5, float("inf"))
    yield "write"  # every check and every read done: only the writing is left
    unrepeat = (lambda action: cycles.bake_cycles(anim.Channels(action, clip.obj.animation_data), baked)) \
        if cycled else None
    return (yield from write_new(context, clip, "extended", new_frames, loc, rot, previous, replace, record,
                                 scene_range=scene_range, follows=back, first=unrepeat,
                                 root=(root.bone, carry) if root is not None else None, joints=targets))
