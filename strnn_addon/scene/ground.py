"""The ground a character stands on, from a mesh in the scene: stairs, a slope, terrain (the Ground of Foot Lock,
Extend Clip and Follow Curve).

Heights are found by casting a ray straight down (the world's -Z) onto the mesh as it stands at the current
frame, from half a leg above each heel and toe, so a foot that sinks a little into a step still finds that
step's top, and a roof or a table further above the foot is not taken for the floor.
"""

from __future__ import annotations

import numpy as np
from mathutils import Vector
from mathutils.bvhtree import BVHTree

from ...model_core.motion.conventions import CONTACT_JOINTS, JOINT_INDEX, UP_AXIS, yup_to_zup
from ...model_core.motion.features import gaussian_smooth
from ...model_core.ops import footlock, footsteps
from ...model_core.rig.rigs import leg_length
from .pipeline import UserError


def deforms(armature, obj) -> bool:
    """Whether ``armature`` deforms mesh ``obj`` (an Armature modifier on it names the armature): the character's
    own body, which is no ground to stand on."""
    return armature is not None and any(m.type == "ARMATURE" and m.object == armature
                                        for m in getattr(obj, "modifiers", ()))


class Ground:
    """The meshes a character stands on: one mesh, or every mesh of a collection (a floor and the stairs on it),
    as they stand at the current frame. ``name``: what the user named."""

    def __init__(self, name: str, meshes: list):
        self.name, self.meshes = name, meshes
        self._trees: list | None = None  # each mesh's (BVH tree, world matrix), built on first use
        self.steps: dict | None = None  # how :func:`carried` placed the steps (:func:`footsteps.even_steps`)
        self.lift: np.ndarray | None = None  # how far :func:`carried` carried the body up, frame by frame

    def _surfaces(self, context) -> list:
        if self._trees is None:  # an operation reads the ground two or three times: the trees are built once
            depsgraph = context.evaluated_depsgraph_get()
            evaluated = [obj.evaluated_get(depsgraph) for obj in self.meshes]
            self._trees = [(BVHTree.FromObject(e, depsgraph), e.matrix_world.copy()) for e in evaluated]
        return self._trees

    def under(self, context, points: np.ndarray, lift: float) -> np.ndarray:
        """Height ``[N]`` (Y-up, scene units) of the highest surface under world-space points ``[N, 3]`` (Y-up) that
        a ray cast down from ``lift`` above each meets; NaN where no mesh is under a point."""
        from_above = yup_to_zup(np.asarray(points, np.float64)) + np.array([0.0, 0.0, lift])
        out = np.full(len(from_above), np.nan)
        for tree, world in self._surfaces(context):
            to_local = world.inverted()
            down = (to_local.to_3x3() @ Vector((0.0, 0.0, -1.0))).normalized()
            for i, p in enumerate(from_above):
                hit, *_ = tree.ray_cast(to_local @ Vector(p.tolist()), down)
                if hit is not None:
                    z = (world @ hit).z  # Blender's Z is the model's up
                    out[i] = z if not np.isfinite(out[i]) else max(out[i], z)
        return out


def find_ground(name: str, armature=None) -> Ground:
    """The mesh named ``name``, else the meshes of the collection named ``name`` (and of those inside it) that
    ``armature`` does not deform; raises :class:`UserError` when there is neither, the object is no mesh, the
    collection holds no mesh, or ``armature`` deforms the mesh (the character's own body)."""
    import bpy

    layer = bpy.context.view_layer

    def shown(o) -> bool:  # Blender evaluates it: in the view layer and not disabled in viewports
        return o.name in layer.objects and not o.hide_viewport

    obj = bpy.data.objects.get(name)
    if obj is None:
        collection = bpy.data.collections.get(name)
        if collection is None:
            raise UserError(f"No object or collection named {name!r} to stand on: pick the ground mesh (stairs, a "
                            "slope) or the collection of them as Ground, or leave it empty for one flat floor")
        meshes = [o for o in collection.all_objects if o.type == "MESH" and not deforms(armature, o)]
        if not meshes:
            raise UserError(f"The collection {name!r} holds no mesh to stand on (but the character's own): pick "
                            "the collection of the ground's meshes as Ground")
        if not any(shown(o) for o in meshes):
            raise UserError(f"No mesh of the collection {name!r} is in the scene's view layer and enabled in "
                            "viewports: Ground is read as Blender shows it; include the collection in the view "
                            "layer and enable its meshes in viewports")
        return Ground(name, [o for o in meshes if shown(o)])
    if obj.type != "MESH":
        kind = obj.type.lower()
        article = "an" if kind[0] in "aeiou" else "a"
        raise UserError(f"{name!r} is {article} {kind}, not a mesh: pick the mesh the feet stand on as Ground")
    if deforms(armature, obj):
        raise UserError(f"{name!r} is the character's own body ({armature.name!r} deforms it): pick the mesh the "
                        "feet stand on as Ground")
    if not shown(obj):
        raise UserError(f"The mesh {name!r} is not in the scene's view layer, or is disabled in viewports: Ground "
                        "is read as Blender shows it; link it to the scene and enable it in viewports")
    return Ground(name, [obj])


def _no_ground(ground) -> UserError:
    return UserError(f"The ground {ground.name!r} is under neither foot on any frame: move it under the character "
                     "(seen from above), or leave Ground empty for one flat floor")


def ground_heights(context, ground, pos: np.ndarray) -> tuple[np.ndarray, int]:
    """Height ``[F, 4]`` (Y-up, scene units, as ``pos``) of the surface of ``ground`` (:class:`Ground`) under each
    heel (at the ankle) and toe of world-space canonical joints ``pos`` ``[F, 21, 3]`` (Y-up), and how many frames
    had no surface under a heel or toe (there the height is carried over from the nearest frames that had one).
    Raises :class:`UserError` where the mesh is under no foot on any frame."""
    pos = np.asarray(pos, np.float64)
    feet = pos[:, CONTACT_JOINTS]
    heights = ground.under(context, feet.reshape(-1, 3), 0.5 * leg_length(pos)).reshape(feet.shape[:2])
    found = np.isfinite(heights)
    if not found.any():
        raise _no_ground(ground)
    frames = np.arange(len(heights))
    either = np.where(found, heights, 0.0).sum(axis=1) / np.maximum(found.sum(axis=1), 1)  # a frame's heights' mean
    for k in range(heights.shape[1]):
        have = found[:, k] if found[:, k].any() else found.any(axis=1)
        source = heights[:, k] if found[:, k].any() else either
        heights[:, k] = np.interp(frames, frames[have], source[have])
    return heights, int((~found).any(axis=1).sum())


def _smoothed_under_hips(context, ground, pos: np.ndarray, fps: float) -> np.ndarray:
    """The height ``[F]`` of the surface of ``ground`` under the hips of ``pos`` ``[F, 21, 3]`` (world, Y-up),
    carried over frames with none under them and smoothed over a quarter second; raises :class:`UserError` where
    there is none at all."""
    under = ground.under(context, pos[:, JOINT_INDEX["hips"]], 0.5 * leg_length(pos))
    found = np.isfinite(under)
    if not found.any():
        raise _no_ground(ground)
    frames = np.arange(len(under))
    return gaussian_smooth(np.interp(frames, frames[found], under[found]), 0.25 * fps)


def flattened(context, ground, pos: np.ndarray, fps: float) -> np.ndarray:
    """``pos`` ``[F, 21, 3]`` (world, Y-up) as if walked on a flat floor at the height of its last frame: each frame
    lowered by how much higher the surface of ``ground`` under its hips is there (smoothed over a quarter second)
    than under the last frame's, so a model that learnt flat floors reads a walk up a slope as a walk."""
    smooth = _smoothed_under_hips(context, ground, pos, fps)
    out = np.array(pos, np.float64)
    out[..., UP_AXIS] -= (smooth - smooth[-1])[:, None]
    return out


def body_lift(context, ground, pos: np.ndarray, known: int, fps: float,
              rest: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """How far up ``[F]`` to carry the frames of ``pos`` ``[F, 21, 3]`` (world, Y-up) from ``known`` on, so a walk
    made on a flat floor goes up and down with the surface of ``ground`` under its hips: the surface's height there,
    smoothed over a quarter second (steps become a slope the hips ride), less its height under the hips where the
    walk starts (the last of the ``known`` frames, else the ``rest`` pose ``[21, 3]`` the walk starts from); 0 on
    the known frames. Also that starting height: the flat floor's, over which the walk stands as high as it will
    over the surface."""
    smooth = _smoothed_under_hips(context, ground, pos, fps)
    if known:
        start = smooth[known - 1]
    else:
        start = ground.under(context, np.asarray(rest, np.float64)[None, JOINT_INDEX["hips"]],
                             0.5 * leg_length(np.asarray(rest)[None]))[0] if rest is not None else np.nan
        start = smooth[0] if not np.isfinite(start) else start
    lift = smooth - start
    lift[:known] = 0.0
    return lift, float(start)


def carried(context, ground, pos: np.ndarray, known: int, fps: float,
            rest: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, int]:
    """Motion ``pos`` ``[F, 21, 3]`` (world, Y-up, ``fps``) made on a flat floor from ``known`` on, carried over
    ``ground`` (:func:`body_lift`, kept in ``ground.lift``; ``rest``: the pose a walk with nothing known starts from),
    each of its steps moved along its foot off the surface's edges (:func:`footsteps.even_steps`, what it did in
    ``ground.steps``), each foot raised clear of the surface (:func:`footsteps.clear_of_surface`), with what Foot Lock
    needs to lock it there: (the carried motion, the surface's height under each heel and toe ``[F, 4]``
    (:func:`ground_heights`), how high each stood over the flat floor ``[4]`` (None: no contacts), frames with no
    surface under a foot)."""
    lift, floor = body_lift(context, ground, pos, known, fps, rest)
    ground.lift = lift
    contacts = footlock.detect_foot_contacts(pos, fps)
    standing = footlock.rest_heights(pos, contacts, np.arange(len(pos)) < known if known else None)
    out = np.array(pos, np.float64)
    out[..., UP_AXIS] += lift[:, None]
    reach = 0.5 * leg_length(pos)  # rays cast from half a leg over each point, as for the feet
    out, ground.steps = footsteps.even_steps(
        out, contacts, lambda points: ground.under(context, points, reach),
        int(round(footlock.FootLockSettings().min_gap_s * fps)), np.arange(len(out)) < known)
    heights, bare = ground_heights(context, ground, out)
    if standing is not None:  # no foot passes through the surface it is carried over (a stair's nose on the way down)
        out, ground.steps["raised"] = footsteps.clear_of_surface(out, heights, standing - floor, fps,
                                                                 np.arange(len(out)) < known)
    return out, heights, None if standing is None else standing - floor, bare


def ground_record(ground, bare: int, frames: int) -> dict:
    """The new action's record of the ground (``ground``: the mesh's or the collection's name, how many frames had no
    surface under a heel or toe and, where some had none, a note saying so)."""
    record = {"object": ground.name, "frames_without": bare}
    if ground.steps is not None:  # steps of motion made on a flat floor, moved off edges
        record["steps"] = {**ground.steps, "largest": round(float(ground.steps["largest"]), 4)}
    if bare:
        record["note"] = (f"The ground {ground.name!r} is under no foot on {bare} of {frames} frames: there the feet "
                          "stand as high as on the nearest frames over it")
    return {"ground": record}
