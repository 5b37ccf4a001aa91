#!/usr/bin/env python3
"""Import a BVH into a fresh Blender scene (the ``bpy`` module), give the armature a simple body,
a floor and a camera that follows it, save a .blend and render a few frames with Workbench.

scripts/demo.py runs it in a child process (so bpy's state never touches the demo's process):

    python scripts/demo_blend.py out/demo.bvh out/demo.blend --render-dir out/frames --frames 8

Prints one line per rendered frame: ``frame <number> <png path>``.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import bpy
from mathutils import Matrix
from matplotlib.colors import to_rgba

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from model_core.eval.plots import SIDE_COLOURS  # noqa: E402
from model_core.rig.bonemap import split_side  # noqa: E402


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("bvh", help="BVH file to import")
    p.add_argument("blend", help=".blend file to save")
    p.add_argument("--fps", type=int, default=30, help="scene frame rate (default: 30)")
    p.add_argument("--render-dir", default="", help="render --frames frames here as PNG (default: no render)")
    p.add_argument("--frames", type=int, default=8, help="frames to render, spread over the action (default: 8)")
    p.add_argument("--size", type=int, nargs=2, default=(480, 400), metavar=("W", "H"), help="render size")
    return p.parse_args(argv)


def side(name: str) -> str:
    """``"l"``, ``"r"`` or ``"c"`` (centre) of a bone name, by the bone map's own parsing."""
    return split_side(name)[0] or "c"


def material(name: str, colour) -> bpy.types.Material:
    mat = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    mat.diffuse_color = colour
    return mat


def limb_mesh(name: str, length: float, radius: float, head: bool) -> bpy.types.Mesh:
    """A capsule-like limb from the bone's head (y = -length) to its tail (y = 0), the frame a
    bone-parented object lives in; a head bone gets a ball instead."""
    import bmesh  # Blender's own module, importable once bpy is

    bm = bmesh.new()
    if head:
        bmesh.ops.create_uvsphere(bm, u_segments=16, v_segments=10, radius=max(length * 0.6, 0.09),
                                  matrix=Matrix.Translation((0.0, -length * 0.4, 0.0)))
    else:
        rot = Matrix.Rotation(math.radians(90.0), 4, "X")  # cone axis (z) along the bone (y)
        bmesh.ops.create_cone(bm, cap_ends=True, segments=12, radius1=radius, radius2=radius * 0.8, depth=length,
                              matrix=Matrix.Translation((0.0, -length / 2, 0.0)) @ rot)
        bmesh.ops.create_uvsphere(bm, u_segments=12, v_segments=8, radius=radius * 1.15,
                                  matrix=Matrix.Translation((0.0, -length, 0.0)))
    mesh = bpy.data.meshes.new(name)
    bm.to_mesh(mesh)
    bm.free()
    for poly in mesh.polygons:
        poly.use_smooth = True
    return mesh


def add_body(arm: bpy.types.Object) -> None:
    """One mesh object per bone, parented to it, coloured by side (``plots.SIDE_COLOURS``: left blue,
    right red)."""
    zs = [(arm.matrix_world @ p).z for b in arm.data.bones for p in (b.head_local, b.tail_local)]
    height = (max(zs) - min(zs)) or 1.7  # of the rest pose: the body's thickness scales with it
    for bone in arm.data.bones:
        if bone.length < 1e-4 * height:
            continue
        torso = side(bone.name) == "c"
        mesh = limb_mesh(f"body_{bone.name}", bone.length, (0.06 if torso else 0.032) * height / 1.7,
                         "head" in bone.name.lower())
        mesh.materials.append(material(f"body_{side(bone.name)}", to_rgba(SIDE_COLOURS[side(bone.name)])))
        obj = bpy.data.objects.new(f"body_{bone.name}", mesh)
        bpy.context.scene.collection.objects.link(obj)
        obj.parent, obj.parent_type, obj.parent_bone = arm, "BONE", bone.name


def add_floor_and_camera(arm: bpy.types.Object, root: str):
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_plane_add(size=200.0, location=(0.0, 0.0, 0.0))
    floor = bpy.context.object
    floor.name = "floor"
    floor.data.materials.append(material("floor", (0.62, 0.63, 0.62, 1.0)))
    scene.world = bpy.data.worlds.new("sky")
    scene.world.color = (0.78, 0.84, 0.9)
    cam_data = bpy.data.cameras.new("camera")
    cam_data.lens = 50
    cam = bpy.data.objects.new("camera", cam_data)
    scene.collection.objects.link(cam)
    cam.location = (2.0, -3.4, 1.1)  # offset from the hips, kept by the constraint below
    follow = cam.constraints.new("COPY_LOCATION")
    follow.target, follow.subtarget, follow.use_offset, follow.use_z = arm, root, True, False
    aim = cam.constraints.new("TRACK_TO")
    aim.target, aim.subtarget = arm, root
    aim.track_axis, aim.up_axis = "TRACK_NEGATIVE_Z", "UP_Y"
    scene.camera = cam
    shading = scene.display.shading
    shading.light, shading.color_type = "STUDIO", "MATERIAL"
    shading.show_shadows, shading.show_cavity = True, True
    scene.display.shadow_focus = 0.5
    scene.render.engine = "BLENDER_WORKBENCH"


def main(argv=None) -> int:
    args = parse_args(argv)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = args.fps
    bpy.ops.import_anim.bvh(filepath=args.bvh, update_scene_fps=True, update_scene_duration=True)
    arm = bpy.context.view_layer.objects.active
    root = arm.data.bones[0].name
    add_body(arm)
    add_floor_and_camera(arm, root)
    start, end = (int(round(f)) for f in arm.animation_data.action.frame_range)
    scene.frame_start, scene.frame_end = start, end
    bpy.ops.wm.save_as_mainfile(filepath=str(Path(args.blend).resolve()))
    if args.render_dir:
        out = Path(args.render_dir)
        out.mkdir(parents=True, exist_ok=True)
        scene.render.resolution_x, scene.render.resolution_y = args.size
        scene.render.resolution_percentage = 100
        count = max(1, args.frames)
        for i in range(count):
            frame = start + round(i * (end - start) / max(count - 1, 1))
            scene.frame_set(frame)
            scene.render.filepath = str((out / f"frame_{frame:05d}.png").resolve())
            bpy.ops.render.render(write_still=True)
            print(f"frame {frame} {scene.render.filepath}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else None))
