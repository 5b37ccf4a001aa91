"""Transfer Motion: move another armature's motion onto the active one, as a stage generator."""

from __future__ import annotations

import numpy as np

from ...model_core.motion.conventions import JOINT_INDEX
from ...model_core.ops.transfer import retarget
from ...model_core.rig.solve import solve
from ..scene import pipeline
from ..scene.ground import carried, find_ground, ground_record
from ..scene.pipeline import UserError
from .common import lock, made_by, noop, run, write_fresh


def transfer_motion(context, obj, *, progress=noop, **options):
    """:func:`transfer_steps` run to the end; returns the new action."""
    return run(transfer_steps(context, obj, **options), progress)


def find_source(context, target, name: str = ""):
    """The armature to take the motion from: the one named ``name``, else the other selected armature
    with an action; a :class:`UserError` saying what to select otherwise."""
    if name:
        obj = context.scene.objects.get(name)
        if obj is None or obj.type != "ARMATURE":
            raise UserError(f"No armature named {name!r} in the scene: give the name of the armature to take the "
                            "motion from")
    else:
        others = [o for o in context.selected_objects if o is not target and o.type == "ARMATURE"]
        if len(others) != 1:
            found = "none" if not others else ", ".join(repr(o.name) for o in others)
            raise UserError("Select the armature to take the motion from, then the one to put it on (active); "
                            f"other selected armatures: {found}")
        obj = others[0]
    if obj is target:
        raise UserError(f"{obj.name!r} is both source and target: the motion comes from another armature")
    return obj


def transfer_steps(context, obj, *, source: str = "", foot_lock: bool = True, scene_range: bool = True,
                   ground: str = "", root_motion: bool = False):
    """Put the motion of ``source`` (default: the other selected armature) on armature ``obj`` over the
    source action's frames: the target's proportions, the source's root path scaled from where the target
    stands, feet on the floor (locked during contacts with ``foot_lock``), into a new action on ``obj``
    (its own action, if any, is kept); over the mesh (or collection) named ``ground``, carried up and down with its
    surface from where the target stands, the feet locked on it; with ``root_motion``, the travel and heading keyed
    on the bone above the hips (:func:`root_motion.carried_root`). A generator like :func:`.extend.extend_steps`."""
    surface = find_ground(ground, obj) if ground else None
    target = pipeline.prepare_any(context, obj)
    root = _root_of(context, target) if root_motion else None
    src = pipeline.prepare(context, find_source(context, obj, source))
    if abs(src.fps - target.fps) > 1e-6:  # one scene: never
        raise UserError("Source and target play at different frame rates")
    frames = np.arange(src.first, src.last + 1, dtype=np.float64)
    if len(frames) < 2:
        raise UserError(f"The action {src.action.name!r} has {len(frames)} frame: transfer needs at least 2")
    step, keys = pipeline.key_grid(src, src.first, src.last)  # a source on twos: moved on twos, held by Constant keys
    if step > 1:
        frames = keys.astype(np.float64)
    yield "read"
    pos = yield from pipeline.joint_positions_steps(context, src, frames)
    ref_loc, ref_rot = pipeline.reference_pose(context, target, np.array([float(context.scene.frame_current)]))
    rest = pipeline.pose_joints(target, ref_loc, ref_rot)
    yield "model"
    new_pos = retarget(pos, rest)
    heights, standing, bare = None, None, 0
    if surface is not None:  # the take, on a flat floor, carried over the ground from where the target stands
        new_pos, heights, standing, bare = carried(context, surface, new_pos, 0, src.fps / step, rest[0])
    if foot_lock:
        new_pos = lock(new_pos, src.fps / step, ground=heights, standing=standing)
    yield "solve"
    n = len(frames)
    arm_world = yield from pipeline.world_at_steps(context, target, frames)
    ref_loc, ref_rot = np.repeat(ref_loc, n, 0), np.repeat(ref_rot, n, 0)
    carry = None
    if root is not None:  # the root, where it stands now under the body, carried with it from the first frame on
        carry = np.linalg.inv(arm_world) @ root.track(new_pos, 1, src.fps / step, surface)
        ref_loc, ref_rot = pipeline.root_carried(target, root.bone, ref_loc, ref_rot, carry)
    joints = pipeline.to_armature(target, new_pos, arm_world)
    loc, rot = solve(target.rig, target.anchors, joints, ref_loc, ref_rot)
    yield "write"
    record = made_by("Transfer Motion", src, key_step=step, source=src.obj.name, target=obj.name, foot_lock=foot_lock,
                     root_motion=root_motion or None)
    if surface is not None:
        record.update(ground_record(surface, bare, n))
    if root is not None:
        record["root_motion"] = {"bone": root.bone}
    return (yield from write_fresh(context, target, f"{src.action.name}.transfer", frames, loc, rot, record,
                                   scene_range, "CONSTANT" if step > 1 else "",
                                   (root.bone, carry) if root is not None else None, joints))


def _root_of(context, target) -> pipeline.Root:
    """The bone above the target's hips that Root Motion keys, where it stands now; a :class:`UserError` where there
    is none."""
    above = pipeline.above_hips(target)
    if not above:
        hips = target.rig.names[int(target.anchors.bone[JOINT_INDEX["hips"]])]
        if target.controls is not None:
            body = next((c.bone for c in target.controls.controls if c.drives == hips), hips)
            raise UserError(f"Root Motion keys the control above the one that carries the body, and "
                            f"{target.obj.name!r}'s {body!r} hangs from none an animator keys (a generated Rigify "
                            "rig's torso follows root by a constraint): turn Root Motion off and key the root "
                            "control by hand")
        raise UserError(f"Root Motion keys the bone above the hips, and {target.obj.name!r}'s hips bone {hips!r} has "
                        "none: add a root bone on the floor as the hips' parent (as a game rig has), or turn Root "
                        "Motion off")
    now = np.array([float(context.scene.frame_current)])
    return pipeline.Root(above[0], pipeline.world_matrices(context, target.obj, above[:1], now)[0, 0])
