"""Follow Curve: walk an armature along a curve with the model, as a stage generator (see :mod:`.common`).

With an action, the new frames continue it from its last frames: a character away from the
curve's start walks there first, then along the curve from its start; without one, the walk
starts on the curve's start from a seed shipped with the model, sized like the rig, at the
scene's start frame. Everything is read, checked and computed before
the new action is made, so a failure or a cancel changes nothing.
"""

from __future__ import annotations

import numpy as np

from ...model_core.motion.conventions import zup_to_yup
from ...model_core.rig.solve import solve
from .. import engine_bridge
from ..scene import anim, curves, cycles, pipeline
from ..scene.ground import carried, find_ground, ground_record
from ..scene.pipeline import UserError
from .common import (
    familiarity_record,
    lock,
    made_by,
    model_steps,
    pace_record,
    prefs,
    stalled_record,
    stalls,
    write_fresh,
    write_new,
)


def follow_curve_steps(context, obj, *, curve: str = "", frames: int = 0, speed: float = 0.0, foot_lock: bool = True,
                       scene_range: bool = True, ground: str = ""):
    """Walk ``obj`` along a curve object (``curve``: its name; '' = the selected curve) for ``frames``
    scene frames (0: until the curve ends) at ``speed`` scene units per second (0: the motion's
    own), feet locked when ``foot_lock``; over the mesh named ``ground`` (stairs, a slope, terrain), the body
    carried up and down with its surface and the feet locked on it, where one is named.
    A generator: yields each stage's name before running it, and the fraction of the model
    stage done after each model window; returns the new action."""
    surface = find_ground(ground, obj) if ground else None
    clip = pipeline.prepare_any(context, obj)
    curve_obj = curves.find_curve(context, curve)
    points, cyclic = curves.curve_points(context, curve_obj)
    points = zup_to_yup(points)
    if np.linalg.norm(np.diff(points[:, [0, 2]], axis=0), axis=-1).sum() < 1e-6:
        raise UserError(f"The curve {curve_obj.name!r} has zero length on the ground: draw a path across the floor")
    yield "read"
    stalled = None
    if clip.action is not None:
        need = pipeline.min_scene_frames(clip.fps)
        if clip.last - clip.first + 1 < need:
            raise UserError(f"The action {clip.action.name!r} has {clip.last - clip.first + 1} frames; Follow Curve "
                            f"needs at least {need} at {clip.fps:g} fps to continue it (or remove the action to "
                            "start from the model's own walk)")
        # an action that ends on a stalled frame (converted mocap often does) walks on from the frame before, the
        # walk's first frame in its place, so that it does not start from rest
        edge = clip.last
        if clip.last - clip.first >= need and not cycles.repeats(clip) and stalls(context, clip, edge):
            stalled, edge = edge, edge - 1
        ctx = np.arange(edge - need + 1, edge + 1, dtype=np.float64)
        context_pos, rest = (yield from pipeline.joint_positions_steps(context, clip, ctx)), None
        held_loc, held_rot = pipeline.reference_pose(context, clip, ctx[-1:])
        previous = pipeline.raw_rotations(clip, edge)
    else:
        edge = None
        held_loc, held_rot = pipeline.reference_pose(context, clip, np.array([float(context.scene.frame_current)]))
        context_pos, rest, previous = None, pipeline.pose_joints(clip, held_loc, held_rot)[0], {}
    yield "model"
    new_pos = yield from model_steps(engine_bridge.run_follow_curve(
        prefs(context), points, cyclic, clip.fps, frames or None, speed or None, context_pos, rest))
    known = 0 if context_pos is None else len(context_pos)
    joined = new_pos if context_pos is None else np.concatenate([context_pos, new_pos])
    heights, standing, bare = None, None, 0
    if surface is not None:  # the walk, made on a flat floor, carried over the ground
        joined, heights, standing, bare = carried(context, surface, joined, known, clip.fps, rest)
    if foot_lock:
        joined = lock(joined, clip.fps, fixed=np.arange(len(joined)) < known, ground=heights, standing=standing)
    new_pos = joined[known:]
    yield "solve"
    n = len(new_pos)
    start = edge + 1 if edge is not None else context.scene.frame_start
    new_frames = start + np.arange(n, dtype=np.float64)
    arm_world = yield from pipeline.world_at_steps(context, clip, new_frames)
    ref_loc, ref_rot = np.repeat(held_loc, n, 0), np.repeat(held_rot, n, 0)
    root = pipeline.moving_root(context, clip, ctx, edge) if context_pos is not None else None
    carry = None
    if root is not None:  # a game rig's root carries the travel: along the curve with the body
        carry = np.linalg.inv(arm_world) @ root.track(joined, known, clip.fps, surface)[1:]
        ref_loc, ref_rot = pipeline.root_carried(clip, root.bone, ref_loc, ref_rot, carry)
        previous.update(pipeline.raw_rotations(clip, edge, [root.bone]))
    targets = pipeline.to_armature(clip, new_pos, arm_world)
    loc, rot = solve(clip.rig, clip.anchors, targets, ref_loc, ref_rot)
    record = made_by("Follow Curve", clip, engine_bridge.model_used(prefs(context)), curve=curve_obj.name,
                     frames=n, speed=float(speed), foot_lock=foot_lock)
    if surface is not None:
        record.update(ground_record(surface, bare, len(joined)))
    if stalled is not None:
        record.update(stalled_record(stalled, edge))
    if root is not None:
        record["root_motion"] = {"bone": root.bone}
    if context_pos is not None:
        record.update(familiarity_record(engine_bridge.run_familiarity(prefs(context), context_pos, clip.fps)))
        record.update(pace_record(context, clip))
    yield "write"  # every check and every read done: only the writing is left
    if clip.action is not None:
        # a walk cycle keyed with Cycles modifiers: the new action plays it once and repeats no more, the walk
        # along the curve following it
        unrepeat = (lambda action: cycles.bake_cycles(anim.Channels(action, clip.obj.animation_data), [])) \
            if cycles.repeats(clip) else None
        # keys past a manual range's end go
        return (yield from write_new(context, clip, "curve", new_frames, loc, rot, previous, (edge + 0.5, float("inf")),
                                     record, scene_range=scene_range, first=unrepeat,
                                     root=(root.bone, carry) if root is not None else None, joints=targets))
    return (yield from write_fresh(context, clip, f"{clip.obj.name}.curve", new_frames, loc, rot, record, scene_range,
                                   joints=targets))


