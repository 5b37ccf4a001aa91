"""Foot Lock: pin an armature's feet on the ground while they touch it (leg IK), as a stage generator."""

from __future__ import annotations

import numpy as np

from ...model_core.ops import footlock
from ..scene import pipeline
from ..scene.ground import find_ground, ground_heights, ground_record
from ..scene.pipeline import UserError
from .common import frame_range, lock, made_by, pace_record, write_new

MIN_LOCK_FRAMES = 3


def foot_lock_steps(context, obj, *, frame_start: int | None = None, frame_end: int | None = None,
                    blend: float = footlock.FootLockSettings.blend_s, only_selected: bool = False, ground: str = ""):
    """Pin the feet of ``obj``'s action on the ground while they touch it, over [frame_start,
    frame_end] (default: the whole action), fading locks in and out over ``blend`` seconds.
    Only the leg bones get new keys (with ``only_selected``, only the selected ones). ``ground``: the name of a
    mesh the feet stand on (stairs, a slope), whose surface under each heel and toe is the floor there; empty: one
    flat floor, the take's own. A generator like :func:`.extend.extend_steps`."""
    surface = find_ground(ground, obj) if ground else None
    clip = pipeline.prepare(context, obj)
    legs = pipeline.leg_bones(clip)
    bones = pipeline.only_selected(clip, legs, "Foot Lock writes (the legs)") if only_selected else legs
    a, b = frame_range(clip, frame_start, frame_end, MIN_LOCK_FRAMES, f"foot lock needs at least {MIN_LOCK_FRAMES}")
    step, keys = pipeline.key_grid(clip, a, b)  # keys on twos: read and locked at its keys, written on them
    if step > 1:
        before, after = keys[0] - step, keys[-1] + step  # the keys either side, where the action has them
        frames = np.arange(before if before >= clip.first else keys[0], (after if after <= clip.last else keys[-1]) + 1,
                           step)
    else:
        frames = np.arange(max(a - 1, clip.first), min(b + 1, clip.last) + 1, dtype=np.float64)
    frames = frames.astype(np.float64)
    inside = (frames >= a) & (frames <= b)  # plus one untouched frame (key) either side to continue from
    fps = clip.fps / step
    yield "read"
    pos = yield from pipeline.joint_positions_steps(context, clip, frames)
    previous = pipeline.raw_rotations(clip, a)
    heights, bare = ground_heights(context, surface, pos) if surface is not None else (None, 0)
    yield "model"
    contacts = lock(pos, fps, detect_only=True, ground=heights)
    if not contacts[inside].any():
        where = (f"near the surface of {surface.name!r} under them" if surface is not None else
                 "near their lowest height")
        raise UserError(f"No foot touches the ground in frames {a}-{b} of {clip.action.name!r} (feet {where} and "
                        "slower than 0.6 m/s): nothing to lock")
    locked = lock(pos, fps, contacts=contacts, fixed=~inside, blend=blend, lower_body=False,
                  passes=footlock.SETTLE_PASSES, ground=heights)
    yield "solve"
    loc, rot, joints = yield from pipeline.solve_frames_steps(context, clip, frames, locked)
    record = made_by("Foot Lock", clip, key_step=step, frame_start=a, frame_end=b, blend=float(blend),
                     only_selected=only_selected)
    if surface is not None:
        record.update(ground_record(surface, bare, len(frames)))
    record.update(pace_record(context, clip))
    yield "write"  # every check and every read done: only the writing is left
    return (yield from write_new(context, clip, "footlocked", frames[inside], loc[inside], rot[inside], previous,
                                 (a, b), record, bones=bones, joints=joints[inside]))
