"""Read a curve object as the ground path Follow Curve walks: its centre line in world space.

Blender evaluates the spline (Bezier, NURBS or poly, at the curve's own resolution) on a
temporary copy whose bevel, extrusion, offset and taper are switched off, so a curve drawn
as a tube or a ribbon still gives its centre line, not a surface. The copy is removed
again before anything returns; the user's curve is never touched.
"""

from __future__ import annotations

import bpy
import numpy as np

from .pipeline import UserError

TEMP_NAME = "_strnn_curve_sample"


def find_curve(context, name: str = ""):
    """The curve object named ``name``, else the one selected curve; raises :class:`UserError`."""
    if name:
        obj = bpy.data.objects.get(name)
        if obj is None:
            raise UserError(f"No object named {name!r}: pick a curve to follow")
        if obj.type != "CURVE":
            kind = obj.type.lower()
            article = "an" if kind[0] in "aeiou" else "a"
            raise UserError(f"{name!r} is {article} {kind}, not a curve: pick a Bezier, NURBS or poly curve")
        return obj
    curves = [o for o in context.selected_objects if o.type == "CURVE"]
    if len(curves) != 1:
        raise UserError("No curve to follow: pick one in the STRNN sidebar (Follow Curve > Curve), or select "
                        "exactly one curve together with the armature" if not curves else
                        f"{len(curves)} curves are selected: pick the one to follow in the STRNN sidebar")
    return curves[0]


def curve_points(context, obj) -> tuple[np.ndarray, bool]:
    """World-space points ``[P, 3]`` (Blender axes, scene units) along the first spline of curve
    ``obj`` and whether that spline is cyclic. Raises :class:`UserError` for an empty curve."""
    if not obj.data.splines:
        raise UserError(f"The curve {obj.name!r} has no splines: draw a path first")
    co, edges = _centre_line(context, obj)
    if len(co) < 2 or not len(edges):
        raise UserError(f"The curve {obj.name!r} has fewer than two points: draw a longer path")
    chain, cyclic = _first_chain(edges)
    local = co[chain]
    world = np.asarray(obj.matrix_world)
    return local @ world[:3, :3].T + world[:3, 3], cyclic


def _centre_line(context, obj) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``[V, 3]`` (object space) and edges ``[E, 2]`` of the curve evaluated without a profile."""
    data = obj.data.copy()
    tmp = None
    try:
        data.bevel_depth, data.extrude, data.offset = 0.0, 0.0, 0.0
        data.bevel_mode = "ROUND"
        data.bevel_object = data.taper_object = None
        data.dimensions = "3D"  # a 2D curve would be filled
        tmp = bpy.data.objects.new(TEMP_NAME, data)
        context.scene.collection.objects.link(tmp)
        evaluated = tmp.evaluated_get(context.evaluated_depsgraph_get())
        mesh = evaluated.to_mesh()
        try:
            co = np.empty(3 * len(mesh.vertices))
            mesh.vertices.foreach_get("co", co)
            edges = np.empty(2 * len(mesh.edges), dtype=np.int64)
            mesh.edges.foreach_get("vertices", edges)
        finally:
            evaluated.to_mesh_clear()
    finally:
        if tmp is not None:
            bpy.data.objects.remove(tmp)
        bpy.data.curves.remove(data)
    return co.reshape(-1, 3), edges.reshape(-1, 2)


def _first_chain(edges: np.ndarray) -> tuple[np.ndarray, bool]:
    """Vertex indices of the first spline's chain of ``edges`` ``[E, 2]`` and whether it closes."""
    nxt = {int(a): int(b) for a, b in edges}
    start = int(edges[0, 0])
    chain = [start]
    while chain[-1] in nxt and nxt[chain[-1]] != start and len(chain) <= len(edges):
        chain.append(nxt[chain[-1]])
    return np.array(chain), nxt.get(chain[-1]) == start
