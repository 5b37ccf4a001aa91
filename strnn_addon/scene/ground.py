"""The ground a character stands on, from a mesh in the scene: stairs, a slope, terrain (Foot Lock's Ground).

Heights are found by casting a ray straight down (the world's -Z) onto the mesh as it stands at the current
frame, from half a leg above each heel and toe, so a foot that sinks a little into a step still finds that
step's top, and a roof or a table further above the foot is not taken for the floor.
"""

from __future__ import annotations

import numpy as np
from mathutils import Vector
from mathutils.bvhtree import BVHTree

from ...model_core.motion.conventions import CONTACT_JOINTS, yup_to_zup
from ...model_core.rig.rigs import leg_length
from .pipeline import UserError


def find_ground(name: str):
    """The mesh object named ``name``; raises :class:`UserError` when there is none or it is no mesh."""
    import bpy

    obj = bpy.data.objects.get(name)
    if obj is None:
        raise UserError(f"No object named {name!r} to stand on: pick the ground mesh (stairs, a slope) in Foot "
                        "Lock > Ground, or leave it empty for one flat floor")
    if obj.type != "MESH":
        kind = obj.type.lower()
        article = "an" if kind[0] in "aeiou" else "a"
        raise UserError(f"{name!r} is {article} {kind}, not a mesh: pick the mesh the feet stand on as Ground")
    return obj


def ground_heights(context, obj, pos: np.ndarray) -> tuple[np.ndarray, int]:
    """Height ``[F, 4]`` (Y-up, scene units, as ``pos``) of ``obj``'s surface under each heel (at the ankle) and
    toe of world-space canonical joints ``pos`` ``[F, 21, 3]`` (Y-up), and how many frames had no surface under a
    heel or toe (there the height is carried over from the nearest frames that had one). Raises
    :class:`UserError` where the mesh is under no foot on any frame."""
    depsgraph = context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(depsgraph)
    tree = BVHTree.FromObject(evaluated, depsgraph)
    to_local = evaluated.matrix_world.inverted()
    down = (to_local.to_3x3() @ Vector((0.0, 0.0, -1.0))).normalized()
    feet = yup_to_zup(np.asarray(pos, np.float64)[:, CONTACT_JOINTS])  # [F, 4, 3], Blender axes
    lift = 0.5 * leg_length(pos)
    heights = np.full(feet.shape[:2], np.nan)
    for f in range(feet.shape[0]):
        for k in range(feet.shape[1]):
            x, y, z = feet[f, k]
            hit, *_ = tree.ray_cast(to_local @ Vector((x, y, z + lift)), down)
            if hit is not None:
                heights[f, k] = (evaluated.matrix_world @ hit).z
    found = np.isfinite(heights)
    if not found.any():
        raise UserError(f"The ground {obj.name!r} is under neither foot on any frame: move it under the character "
                        "(seen from above), or leave Ground empty for one flat floor")
    frames = np.arange(len(heights))
    either = np.where(found, heights, 0.0).sum(axis=1) / np.maximum(found.sum(axis=1), 1)  # a frame's heights' mean
    for k in range(heights.shape[1]):  # Blender's Z is the model's up
        have = found[:, k] if found[:, k].any() else found.any(axis=1)
        source = heights[:, k] if found[:, k].any() else either
        heights[:, k] = np.interp(frames, frames[have], source[have])
    return heights, int((~found).any(axis=1).sum())
