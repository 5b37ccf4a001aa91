"""Make Loop: a stretch of an armature's action made into a cycle that repeats without a seam, as a stage
generator (the cycle: :mod:`model_core.ops.loop`; the action made cyclic: :mod:`..scene.cycles`)."""

from __future__ import annotations

import numpy as np

from ...model_core.motion.geometry import closing_weights
from ...model_core.motion.rotations import closing_turns
from ...model_core.ops.footlock import SETTLE_PASSES
from ...model_core.ops.loop import least_cycle
from .. import engine_bridge
from ..scene import cycles, pipeline
from .common import frame_range, lock, made_by, model_call, noop, pace_record, prefs, run, write_new


def make_loop(context, obj, *, progress=noop, **options):
    """:func:`loop_steps` run to the end; returns the new action."""
    return run(loop_steps(context, obj, **options), progress)


def loop_steps(context, obj, *, frame_start: int | None = None, frame_end: int | None = None, blend: float = 0.4,
               match: bool = True, in_place: bool = False, foot_lock: bool = True):
    """Make frames ``frame_start..frame_end`` of ``obj``'s action (default: the whole action) into a cycle: from
    the first frame to the seam (with ``match`` the frame of the range's second half where the pose comes round to
    the first's again, else the range's last frame; a range that turns unwound so that it repeats straight), the
    last ``blend`` seconds before the seam made again by the model so the motion flows on into the next cycle's
    start, the feet locked there (over the whole cycle where it was unwound) when ``foot_lock``, the travel taken
    off when ``in_place``. The new action holds the cycle, every F-curve repeating it (Cycles modifiers;
    locations with their offset, so a walk walks on), its manual frame range the cycle and marked cyclic. A
    generator like :func:`.extend.extend_steps`."""
    clip = pipeline.prepare(context, obj)
    need = max(least_cycle(clip.fps) + 1, pipeline.min_scene_frames(clip.fps))  # a cycle the model reads whole
    a, b = frame_range(clip, frame_start, frame_end, need, f"a loop needs at least {need} at {clip.fps:g} fps")
    step, keys = pipeline.key_grid(clip, a, b)  # keys on twos: a cycle of its keys, keyed on them
    if len(keys) < max(least_cycle(clip.fps / step) + 1, pipeline.min_scene_frames(clip.fps / step)):
        step, keys = 1, np.arange(a, b + 1)
    frames, fps = keys.astype(np.float64), clip.fps / step
    lead = frames[0] - step * np.arange(pipeline.min_scene_frames(fps), 0, -1, dtype=np.float64)
    lead = lead[lead >= clip.first]  # the take before the range, which the in-between reads as well
    yield "read"
    pos = yield from pipeline.joint_positions_steps(context, clip, frames)
    before = pipeline.joint_positions(context, clip, lead) if len(lead) else None
    previous = pipeline.raw_rotations(clip, frames[0])
    yield "model"
    blend_keys = int(round(max(float(blend), 0.0) * fps))
    loop = model_call(engine_bridge.run_loop, prefs(context), pos, fps, blend_keys, match, before)
    cycle = loop.positions
    if foot_lock and not loop.fixed().all():  # the frames made again (a stretch unwound: all), locked
        cycle = lock(cycle, fps, fixed=loop.fixed(), passes=SETTLE_PASSES)
    if in_place:
        loop = loop.on_the_spot(cycle)
        cycle = loop.positions
    written = frames[0] + step * np.arange(loop.seam + 1, dtype=np.float64)
    yield "solve"
    root = pipeline.moving_root(context, clip, frames, written[0])
    carry, arm_world = None, None
    if root is not None:  # a game rig's root carries the travel: carried with the cycle (in place: it stays)
        arm_world = yield from pipeline.world_at_steps(context, clip, written)
        carry = (root.bone, np.linalg.inv(arm_world) @ root.track(cycle, 1, fps))
    loc, rot, joints = yield from pipeline.solve_frames_steps(context, clip, written, cycle, carry, arm_world)
    # a turn the joints leave free (a head's nod, taken from the take) ends the cycle where it began, as the rest does
    rot = closing_turns(rot, closing_weights(len(written), loop.blend))
    record = made_by("Make Loop", clip, engine_bridge.model_used(prefs(context)), key_step=step,
                     frame_start=a, frame_end=b, blend=float(blend), match=match, in_place=in_place,
                     foot_lock=foot_lock)
    record["cycle"] = {"first": int(written[0]), "seam": int(written[-1]), "frames": int(written[-1] - written[0]),
                       "seconds": round(float(written[-1] - written[0]) / clip.fps, 3),
                       "travel": round(float(np.linalg.norm(loop.travel)), 4), "match_cm": round(loop.match_cm, 2),
                       "blend_keys": loop.blend, "turn_deg": round(float(np.degrees(loop.turn)), 1)}
    record.update(pace_record(context, clip, b))
    if root is not None:
        record["root_motion"] = {"bone": root.bone}
        previous.update(pipeline.raw_rotations(clip, frames[0], [root.bone]))
    yield "write"  # every check and every read done: only the writing is left
    made = pipeline.written_paths(clip, root.bone if root is not None else None)
    return (yield from write_new(context, clip, "loop", written, loc, rot, previous, (-np.inf, np.inf), record,
                                 scene_range=False, root=carry, joints=joints,
                                 shape=lambda action: cycles.make_cyclic(clip, action, written, loop.blend, made)))
