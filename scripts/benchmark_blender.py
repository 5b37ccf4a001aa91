"""Benchmark Extend Clip (or Denoise Action, Foot Lock, or Fill Gap) in Blender on a 60-bone rig: a
1,000-frame clip extended by 1,000 frames (or denoised or foot-locked whole, or a 30-frame gap in its
middle filled), with the time of each stage and the memory the run takes beyond the scene's own.

Builds the extension, installs it into the bpy module (a temporary user repository, as the
tests do), builds a 60-bone armature with a 1,000-frame keyed action, runs the operator's
worker and prints the time of each stage (read, model, solve, write) beside the floor:
reading and writing the same keys with bulk ``foreach_get`` / ``foreach_set`` and nothing else, and
the peak of the process's resident memory during the run above what it held before (sampled every
5 ms from /proc/self/statm).

    python scripts/benchmark_blender.py
    python scripts/benchmark_blender.py --operator denoise   # with the bundled denoising model
    python scripts/benchmark_blender.py --operator inbetween --gap 30   # Fill Gap of 30 frames
    python scripts/benchmark_blender.py --operator footlock --frames 30000 --repeat 1   # a long take
    python scripts/benchmark_blender.py --operator footlock --ground   # on a ground mesh, beside the flat floor
    python scripts/benchmark_blender.py --rigify --frames 300   # a generated Rigify rig: IK legs beside FK legs
    python scripts/benchmark_blender.py --rigify --skin 30000 --frames 300   # that rig deforming a body mesh
    python scripts/benchmark_blender.py --rigify --operator denoise --frames 600   # Denoise on that rig
    python scripts/benchmark_blender.py --rigify --others 3 --frames 300   # with three more animated characters
    python scripts/benchmark_blender.py --rigify --others 3 --set 2000 --frames 300   # and a set of 2,000 objects
    python scripts/benchmark_blender.py --baked --frames 300 --operator denoise   # that rig baked through FBX:
        # keyed in closed form, beside Blender's visual bake frame by frame in the same run
    python scripts/benchmark_blender.py --model runs/default/release --frames 1000 --repeat 3
    python scripts/benchmark_blender.py --untrained   # timing only: a randomly initialised model
"""

from __future__ import annotations

import argparse
import importlib
import os
import shutil
import sys
import tempfile
import time
from functools import partial
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "scripts"))

import bpy  # noqa: E402
from batch_worker import clear_keys  # noqa: E402

from model_core.motion.conventions import JOINTS, PARENT_NAMES, yup_to_zup  # noqa: E402
from model_core.motion.synthetic import rest_offset  # noqa: E402

FINGERS = ("Thumb", "Index", "Middle", "Ring", "Pinky")


def untrained_release(folder: Path) -> Path:
    """A randomly initialised model of the default size, saved as a release (timing only)."""
    import torch

    from model_core.io.checkpoint import save_release
    from model_core.model.strnn import STRNN, STRNNConfig
    from model_core.motion.conventions import LAYOUT

    torch.manual_seed(0)
    cfg = STRNNConfig()
    model = STRNN(cfg).eval()
    weights = {k: v.detach().numpy() for k, v in model.state_dict().items() if v.dtype.is_floating_point}
    seeds = np.zeros((1, cfg.encode_len, LAYOUT.size), np.float32)
    return save_release(folder, weights, cfg.to_dict(), np.zeros(LAYOUT.size), np.ones(LAYOUT.size),
                        {"licence": "untrained, for benchmarks only"}, seeds, ["zeros"])


def find_model(args, work: Path) -> Path:
    if args.model:
        return args.model
    for candidate in [REPO / "models" / "strnn_default", *sorted(REPO.glob("runs/*/release"))]:
        if (candidate / "model.json").exists():
            return candidate
    if not args.untrained:
        raise SystemExit("no trained model (models/strnn_default or runs/*/release): pass --model or --untrained")
    return untrained_release(work / "untrained")


def install(out: Path) -> str:
    """Build the extension and install it the way the batch CLI does; returns its package name."""
    import batch_worker
    import build_extension

    zip_path = build_extension.main(["--out", str(out), "--no-validate"])
    batch_worker.install_extension(bpy, str(zip_path), out)
    return batch_worker.ADDON


def rig_bones() -> list[tuple]:
    """(name, parent, head, tail) of a 60-bone Mixamo-style body: 5 fingers and twist bones."""
    j = {}
    for joint in JOINTS:
        parent = PARENT_NAMES[joint]
        j[joint] = (j[parent] if parent else np.array([0.0, 0.95, 0.0])) + rest_offset(joint)
    j = {k: yup_to_zup(v) for k, v in j.items()}
    mid = lambda a, b, t=0.5: a + (b - a) * t
    up = np.array([0, 0, 0.1])
    chest = mid(j["spine"], j["spine1"])
    bones = [("Hips", None, j["hips"], j["spine"]), ("Spine", "Hips", j["spine"], chest),
             ("Spine1", "Spine", chest, j["spine1"]), ("Spine2", "Spine1", j["spine1"], j["neck"]),
             ("Neck", "Spine2", j["neck"], j["head"]), ("Head", "Neck", j["head"], j["head"] + 2 * up)]
    for s, side in (("l", "Left"), ("r", "Right")):
        p = lambda k, s=s: j[f"{s}_{k}"]
        bones += [(f"{side}Shoulder", "Spine2", mid(j["neck"], p("arm"), 0.3) - up, p("arm")),
                  (f"{side}Arm", f"{side}Shoulder", p("arm"), p("elbow")),
                  (f"{side}ArmTwist", f"{side}Arm", mid(p("arm"), p("elbow")), p("elbow")),
                  (f"{side}ForeArm", f"{side}Arm", p("elbow"), p("wrist")),
                  (f"{side}ForeArmTwist", f"{side}ForeArm", mid(p("elbow"), p("wrist")), p("wrist")),
                  (f"{side}Hand", f"{side}ForeArm", p("wrist"), mid(p("wrist"), p("fingertip"), 0.4)),
                  (f"{side}UpLeg", "Hips", p("upleg"), p("knee")),
                  (f"{side}UpLegTwist", f"{side}UpLeg", mid(p("upleg"), p("knee")), p("knee")),
                  (f"{side}Leg", f"{side}UpLeg", p("knee"), p("foot")),
                  (f"{side}LegTwist", f"{side}Leg", mid(p("knee"), p("foot")), p("foot")),
                  (f"{side}Foot", f"{side}Leg", p("foot"), p("toe")),
                  (f"{side}ToeBase", f"{side}Foot", p("toe"), p("toe") + np.array([0, -0.06, 0]))]
        for f, finger in enumerate(FINGERS):
            spread = np.array([0.0, 0.02 * (f - 2), 0.0])
            pts = [mid(p("wrist"), p("fingertip"), t) + spread for t in (0.4, 0.6, 0.8, 1.0)]
            for k in range(3):
                parent = f"{side}Hand" if k == 0 else f"{side}Hand{finger}{k}"
                bones.append((f"{side}Hand{finger}{k + 1}", parent, pts[k], pts[k + 1]))
    return [("mixamorig:" + n, p and "mixamorig:" + p, h, t) for n, p, h, t in bones]


def build_scene(frames: int):
    """The armature with a keyed clip: every bone's quaternion waves, the hips walk forward."""
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.context.scene.render.fps = 30
    arm = bpy.data.armatures.new("Bench")
    obj = bpy.data.objects.new("Bench", arm)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    for name, parent, head, tail in rig_bones():
        eb = arm.edit_bones.new(name)
        eb.head, eb.tail = head, tail
        eb.parent = arm.edit_bones[parent] if parent else None
    bpy.ops.object.mode_set(mode="OBJECT")
    action = bpy.data.actions.new("Walk")
    obj.animation_data_create().action = action
    t = np.arange(1, frames + 1, dtype=np.float64)
    rng = np.random.default_rng(0)
    for pb in obj.pose.bones:
        angle = 0.2 * np.sin(2 * np.pi * t / 30 + rng.uniform(0, 6))
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        quat = np.concatenate([np.cos(angle / 2)[:, None], np.sin(angle / 2)[:, None] * axis], 1)
        channels = [("rotation_quaternion", quat)]
        if pb.parent is None:
            channels.append(("location", np.stack([0 * t, 0.02 * t, 0.02 * np.sin(4 * np.pi * t / 30)], 1)))
        for prop, values in channels:
            for i in range(values.shape[1]):
                fc = fcurve_new(obj, action, f'pose.bones["{pb.name}"].{prop}', i, pb.name)
                key(fc, t, values[:, i])
    return obj


def build_rigify(frames: int, ik_legs: bool):
    """A rig generated by Rigify from its human metarig, walking forward for ``frames`` frames: torso moves, the arms
    swing in FK, and the legs either swing in FK or (``ik_legs``, the generated rig's own setting) step on their IK
    feet, planted 60 % of each second-long stride."""
    import addon_utils

    addon_utils.enable("rigify", default_set=True)
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.context.scene.render.fps = 30
    bpy.ops.object.armature_human_metarig_add()
    bpy.ops.pose.rigify_generate()
    obj = bpy.data.objects["rig"]
    bpy.context.view_layer.objects.active = obj
    bones = obj.pose.bones
    for side in "LR":
        bones[f"upper_arm_parent.{side}"]["IK_FK"] = 1.0
        bones[f"thigh_parent.{side}"]["IK_FK"] = 0.0 if ik_legs else 1.0

    def local(name: str, world) -> list:  # a location in the bone's rest space that moves it by ``world``
        return list(np.array(obj.data.bones[name].matrix_local)[:3, :3].T @ np.asarray(world, dtype=np.float64))

    for f in range(1, frames + 1):
        phase = 2 * np.pi * f / 30.0
        bones["torso"].location = local("torso", (0.0, -0.02 * f, 0.01 * np.sin(2 * phase) - 0.08))
        bones["torso"].keyframe_insert("location", frame=f)
        for k, side in enumerate("LR"):
            swing = np.sin(phase + np.pi * k)
            arm = bones[f"upper_arm_fk.{side}"]
            arm.rotation_mode = "XYZ"
            arm.rotation_euler = (0.4 * swing, 0.0, 0.0)
            arm.keyframe_insert("rotation_euler", frame=f)
            if ik_legs:
                t = (f / 30.0 + 0.5 * k) % 1.0
                along = np.floor(f / 30.0 + 0.5 * k) + (0.0 if t < 0.6 else (t - 0.6) / 0.4)
                foot = bones[f"foot_ik.{side}"]
                foot.location = local(foot.name, (0.0, 0.6 * (0.5 * k - 0.3 - along),
                                                  0.0 if t < 0.6 else 0.06 * np.sin(np.pi * (t - 0.6) / 0.4)))
                foot.keyframe_insert("location", frame=f)
            else:
                for name, angle in ((f"thigh_fk.{side}", 0.4 * swing), (f"shin_fk.{side}", 0.5 * max(0.0, swing))):
                    bones[name].rotation_mode = "XYZ"
                    bones[name].rotation_euler = (angle, 0.0, 0.0)
                    bones[name].keyframe_insert("rotation_euler", frame=f)
    return obj


def add_skin(obj, vertices: int) -> str:
    """A body-sized mesh of about ``vertices`` vertices that armature ``obj`` deforms (an Armature modifier, each vertex
    weighted to the deform bone whose head is nearest), as a character's body is; its name."""
    import bmesh

    rings = max(4, int(np.sqrt(vertices)))
    mesh = bpy.data.meshes.new("BenchBody")
    bm = bmesh.new()
    bmesh.ops.create_uvsphere(bm, u_segments=rings, v_segments=rings, radius=0.3)
    bm.to_mesh(mesh)
    bm.free()
    co = np.array([v.co for v in mesh.vertices]) * np.array([1.0, 1.0, 3.0]) + np.array([0.0, 0.0, 1.0])
    mesh.vertices.foreach_set("co", co.astype(np.float32).ravel())
    body = bpy.data.objects.new("BenchBody", mesh)
    bpy.context.scene.collection.objects.link(body)
    deform = [b for b in obj.data.bones if b.use_deform]
    heads = np.array([np.array(obj.matrix_world @ b.head_local) for b in deform])
    nearest = np.argmin(((co[:, None] - heads[None]) ** 2).sum(-1), axis=1)
    for k, b in enumerate(deform):
        if (nearest == k).any():
            body.vertex_groups.new(name=b.name).add(np.flatnonzero(nearest == k).tolist(), 1.0, "REPLACE")
    body.modifiers.new("Armature", "ARMATURE").object = obj
    bpy.context.view_layer.objects.active = obj
    return body.name


def add_others(obj, count: int, frames: int) -> list[str]:
    """``count`` more rigs generated by Rigify beside armature ``obj``, each animated over ``frames`` frames (the
    torso swaying, the arms swinging), as the other characters of a shot are; their names."""
    names = []
    for k in range(count):
        bpy.ops.object.select_all(action="DESELECT")
        bpy.ops.object.armature_human_metarig_add()
        meta = bpy.context.active_object
        bpy.ops.pose.rigify_generate()
        other = bpy.context.active_object
        meta.hide_viewport, other.location.x = True, 1.5 * (k + 1)
        for f in range(1, frames + 1, 5):
            other.pose.bones["torso"].location = (0.0, 0.0, 0.02 * (f % 10))
            other.pose.bones["torso"].keyframe_insert("location", frame=f)
            for side in "LR":
                arm = other.pose.bones[f"upper_arm_fk.{side}"]
                arm.rotation_quaternion = (1.0, 0.1 * (f % 7), 0.0, 0.0)
                arm.keyframe_insert("rotation_quaternion", frame=f)
        names.append(other.name)
    bpy.ops.object.select_all(action="DESELECT")
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    return names


def add_set(count: int) -> None:
    """``count`` still objects (cubes sharing one mesh) in the scene, as the props and pieces of a set are."""
    mesh = bpy.data.meshes.new("BenchSetPiece")
    mesh.from_pydata([(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)], [],
                     [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)])
    for k in range(count):
        piece = bpy.data.objects.new(f"BenchSet{k}", mesh)
        piece.location = (3.0 + k % 50, 3.0 + k // 50, 0.0)
        bpy.context.scene.collection.objects.link(piece)


def through_fbx(obj, folder: Path):
    """``obj`` exported to FBX with every bone (Blender's exporter bakes each bone and drops the constraints) and
    imported into an empty scene at the same frame rate: a control rig an exporter baked, active."""
    fps = bpy.context.scene.render.fps
    for other in bpy.context.view_layer.objects:
        other.select_set(other is obj)
    path = folder / "baked.fbx"
    bpy.ops.export_scene.fbx(filepath=str(path), use_selection=True, add_leaf_bones=False,
                             bake_anim_use_all_actions=False, bake_anim_use_nla_strips=False)
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.context.scene.render.fps = fps
    bpy.ops.import_scene.fbx(filepath=str(path))
    baked = next(o for o in bpy.data.objects if o.type == "ARMATURE")
    for other in bpy.context.view_layer.objects:
        other.select_set(other is baked)
    bpy.context.view_layer.objects.active = baked
    return baked


def evaluated_by_blender(obj) -> None:
    """Make Blender evaluate ``obj`` frame by frame for every read and bake (a bone at an end of the skeleton, outside
    the body the operators key, set not to take its location in its own space), as on a rig with constraints."""
    leaf = next(b for b in obj.data.bones if not b.children and b.name.startswith("MCH-"))
    leaf.use_local_location = False


def add_ground_plane() -> str:
    """A 10 km square plane at the world's origin, for Foot Lock's Ground; its name."""
    mesh = bpy.data.meshes.new("BenchGround")
    mesh.from_pydata([(-5e3, -5e3, 0.0), (5e3, -5e3, 0.0), (5e3, 5e3, 0.0), (-5e3, 5e3, 0.0)], [], [(0, 1, 2, 3)])
    obj = bpy.data.objects.new("BenchGround", mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj.name


def fcurve_new(obj, action, path: str, index: int, group: str):
    """A new F-curve on the legacy (4.2) or layered (4.4+) action API."""
    if not hasattr(action, "slots"):
        return action.fcurves.new(path, index=index, action_group=group)
    from bpy_extras import anim_utils

    ad = obj.animation_data
    if ad.action_slot is None:
        ad.action_slot = action.slots.new(id_type="OBJECT", name=obj.name)
    return anim_utils.action_ensure_channelbag_for_slot(action, ad.action_slot).fcurves.new(path, index=index)


def key(fc, frames: np.ndarray, values: np.ndarray) -> None:
    fc.keyframe_points.add(len(frames))
    fc.keyframe_points.foreach_set("co", np.stack([frames, values], 1).astype(np.float32).ravel())
    fc.keyframe_points.foreach_set("interpolation", np.ones(len(frames), np.int32))  # LINEAR
    fc.update()


def action_copy_mb(obj) -> float:
    """The memory (MB) a copy of the armature's action takes: the floor of any operator, whose result is a
    new action of about that size."""
    with PeakMemory() as memory:
        copy = action_of(obj).copy()
    bpy.data.actions.remove(copy)
    return memory.extra_mb


def action_of(obj):
    return obj.animation_data.action


def floor_time(obj) -> tuple[float, float]:
    """Seconds to read all keys of the action, and to write as many keys into a new action."""
    from bpy_extras import anim_utils

    action = obj.animation_data.action
    bag = anim_utils.action_get_channelbag_for_slot(action, obj.animation_data.action_slot) \
        if hasattr(action, "slots") else action
    t0 = time.perf_counter()
    data = []
    for fc in bag.fcurves:
        buf = np.empty(2 * len(fc.keyframe_points), np.float32)
        fc.keyframe_points.foreach_get("co", buf)
        data.append((fc.data_path, fc.array_index, buf))
    t1 = time.perf_counter()
    new = bpy.data.actions.new("Floor")
    slot_obj = bpy.data.objects.new("FloorTarget", None)
    slot_obj.animation_data_create().action = new
    for path, index, buf in data:
        fc = fcurve_new(slot_obj, new, path, index, "")
        fc.keyframe_points.add(len(buf) // 2)
        fc.keyframe_points.foreach_set("co", buf)
        fc.update()
    t2 = time.perf_counter()
    bpy.data.actions.remove(new)
    bpy.data.objects.remove(slot_obj)
    return t1 - t0, t2 - t1


class PeakMemory:
    """The peak resident memory (MB) of this process above its level at the start, sampled in a thread."""

    def __enter__(self):
        import threading

        self.page = os.sysconf("SC_PAGE_SIZE")
        self.start = self.peak = self.top = self._rss()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)
        self._thread.start()
        return self

    def _rss(self) -> int:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * self.page

    def _watch(self) -> None:
        while not self._stop.wait(0.005):
            self.peak = max(self.peak, self._rss())

    def mark(self) -> float:
        """The peak (MB above the start) since the last mark; the next mark counts from now."""
        rss = self._rss()
        peak, self.peak = max(self.peak, rss), rss
        self.top = max(self.top, peak)
        return max(peak - self.start, 0) / 2**20

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.top = max(self.top, self.peak, self._rss())
        self.extra_mb = (self.top - self.start) / 2**20


def stage_times(worker, *args, **kwargs) -> dict:
    """Seconds of each stage of ``worker(*args, progress=..., **kwargs)`` (a runner of
    ``strnn_addon/stages/``, which calls ``progress(stage)`` as each stage starts): a stage lasts
    until the next starts (the first also covers the checks before it), plus the ``total``; and
    the peak memory of each stage (``mb`` by stage) and of the whole run (``extra_mb``)."""
    marks: list[tuple[str, float]] = []
    peaks: list[float] = []

    def progress(stage):
        peaks.append(memory.mark())
        marks.append((stage, time.perf_counter()))

    with PeakMemory() as memory:
        start = time.perf_counter()
        worker(*args, progress=progress, **kwargs)
        end = time.perf_counter()
        peaks.append(memory.mark())
    bounds = [start] + [t for _, t in marks[1:]] + [end]
    times = {stage: b - a for (stage, _), a, b in zip(marks, bounds, bounds[1:])}
    # The first stage also covers the checks before it, as its time does.
    mb = {stage: max(peaks[i + 1], peaks[0]) if i == 0 else peaks[i + 1] for i, (stage, _) in enumerate(marks)}
    return {**times, "total": end - start, "extra_mb": memory.extra_mb, "mb": mb}


def operation(args, obj, extend, denoise, inbetween, common, footlock, flat: bool = False) -> tuple:
    """(runner, its arguments...) for :func:`stage_times`: the operator ``args`` names on ``obj`` (``flat``: Foot
    Lock on the flat floor, whatever ``--ground`` says)."""
    if args.operator == "extend":
        return partial(extend.extend_clip, frames=args.frames), bpy.context, obj
    if args.operator == "inbetween":
        start = args.frames // 2 - args.gap // 2
        clear_keys(obj, start, start + args.gap - 1)
        return partial(inbetween.fill_gap, frame_start=start, frame_end=start + args.gap - 1), bpy.context, obj
    if args.operator == "footlock":
        ground = add_ground_plane() if args.ground and not flat else ""

        def lock(context, o, progress):
            return common.run(footlock.foot_lock_steps(context, o, ground=ground), progress)

        return lock, bpy.context, obj
    return denoise.denoise_action, bpy.context, obj


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=1000, help="clip length and frames to add (default 1000)")
    parser.add_argument("--model", type=Path, default=None, help="release folder (default: bundled or runs/*)")
    parser.add_argument("--untrained", action="store_true", help="use a random model when none is trained")
    parser.add_argument("--repeat", type=int, default=3, help="runs; the fastest is reported (default 3)")
    parser.add_argument("--operator", choices=("extend", "denoise", "footlock", "inbetween"), default="extend",
                        help="Extend Clip (default), Denoise Action (the extension's denoising model), Foot Lock "
                             "or Fill Gap")
    parser.add_argument("--gap", type=int, default=30, help="Fill Gap: frames cut out of the clip's middle (30)")
    parser.add_argument("--ground", action="store_true",
                        help="Foot Lock: on a ground mesh (a plane under the rig, its surface found by ray casts), "
                             "beside the same lock on the flat floor in the same run")
    parser.add_argument("--rigify", action="store_true",
                        help="on a rig generated by Rigify, its legs stepping on their IK controls (keyed there), "
                             "beside the same rig walking in FK (keyed on its FK controls) in the same run")
    parser.add_argument("--baked", action="store_true",
                        help="on that rig walking in FK baked through FBX (a control rig an exporter baked: read and "
                             "keyed in closed form), beside the same with Blender evaluating it frame by frame and "
                             "its visual bake in the same run")
    parser.add_argument("--skin", type=int, default=0, metavar="VERTICES",
                        help="with --rigify: the rig deforms a mesh of about this many vertices (a character's body), "
                             "beside the same rig without it in the same run")
    parser.add_argument("--others", type=int, default=0, metavar="COUNT",
                        help="with --rigify: COUNT more Rigify rigs, animated, in the scene (the other characters of "
                             "a shot), beside the same rig alone in its scene in the same run")
    parser.add_argument("--set", type=int, default=0, metavar="COUNT",
                        help="with --others: COUNT still objects in the scene too (the pieces of a set)")
    args = parser.parse_args(argv)
    if args.set and not args.others:
        parser.error("--set is for --others")
    if (args.skin or args.others) and not args.rigify:
        parser.error("--skin and --others are for --rigify")
    if args.skin and args.others:
        parser.error("--skin and --others are two benchmarks: choose one")
    if args.ground and args.operator != "footlock":
        parser.error("--ground is for --operator footlock")
    if args.baked and args.rigify:
        parser.error("--baked and --rigify are two benchmarks: choose one")
    work = Path(tempfile.mkdtemp(prefix="strnn_bench_blender_"))
    try:
        return measure(args, work)
    finally:
        shutil.rmtree(work, ignore_errors=True)  # the built extension and any untrained model


def measure(args, work: Path) -> dict:
    model = find_model(args, work)
    package = install(work)
    bpy.context.preferences.addons[package].preferences.model_folder = str(model)
    extend = importlib.import_module(package + ".strnn_addon.stages.extend")
    denoise = importlib.import_module(package + ".strnn_addon.stages.denoise")
    inbetween = importlib.import_module(package + ".strnn_addon.stages.inbetween")
    common = importlib.import_module(package + ".strnn_addon.stages.common")
    footlock = importlib.import_module(package + ".strnn_addon.stages.footlock")
    bridge = importlib.import_module(package + ".strnn_addon.engine_bridge")
    best: dict = {}
    for _ in range(args.repeat):
        bridge.forget_results()  # each run pays for its model call, as a first run on a take does
        if args.rigify:  # the baseline first: the same walk keyed on the FK controls
            obj = build_rigify(args.frames, ik_legs=False)
            bpy.context.preferences.addons[package].preferences.model_folder = str(model)
            fk_total = stage_times(*operation(args, obj, extend, denoise, inbetween, common, footlock))["total"]
            bridge.forget_results()
        if args.baked:  # the baseline first: Blender evaluating the baked rig frame by frame, its visual bake
            obj = through_fbx(build_rigify(args.frames, ik_legs=False), work)
            evaluated_by_blender(obj)
            bpy.context.preferences.addons[package].preferences.model_folder = str(model)
            evaluated_total = stage_times(*operation(args, obj, extend, denoise, inbetween, common, footlock))["total"]
            bridge.forget_results()
            obj = through_fbx(build_rigify(args.frames, ik_legs=False), work)
        elif args.others:  # the baseline first: the same rig alone in its scene
            obj = build_rigify(args.frames, ik_legs=True)
            bpy.context.preferences.addons[package].preferences.model_folder = str(model)
            alone_total = stage_times(*operation(args, obj, extend, denoise, inbetween, common, footlock))["total"]
            bridge.forget_results()
            obj = build_rigify(args.frames, ik_legs=True)
            add_others(obj, args.others, 2 * args.frames)
            add_set(args.set)
        elif args.skin:  # the baseline first: the same rig without its skin
            obj = build_rigify(args.frames, ik_legs=True)
            bpy.context.preferences.addons[package].preferences.model_folder = str(model)
            bare_total = stage_times(*operation(args, obj, extend, denoise, inbetween, common, footlock))["total"]
            bridge.forget_results()
            obj = build_rigify(args.frames, ik_legs=True)
            add_skin(obj, args.skin)
        else:
            obj = build_rigify(args.frames, ik_legs=True) if args.rigify else build_scene(args.frames)
        bpy.context.preferences.addons[package].preferences.model_folder = str(model)
        read_floor, write_floor = floor_time(obj)
        copy_mb = action_copy_mb(obj)
        timings = stage_times(*operation(args, obj, extend, denoise, inbetween, common, footlock))
        if args.operator == "footlock" and args.ground:  # the same lock on the flat floor: the ray casts' baseline
            timings["flat_total"] = stage_times(*operation(args, obj, extend, denoise, inbetween, common, footlock,
                                                           flat=True))["total"]
        timings.update(floor_read=read_floor, floor_write=write_floor, floor_mb=copy_mb)
        if args.rigify:
            timings["fk_total"] = fk_total
        if args.skin:
            timings["bare_total"] = bare_total
        if args.others:
            timings["alone_total"] = alone_total
        if args.baked:
            timings["evaluated_total"] = evaluated_total
        if not best or timings["total"] < best["total"]:
            best = timings
    done = {"extend": f"+ {args.frames} new", "denoise": "denoised", "footlock": "foot-locked",
            "inbetween": f"with a gap of {args.gap} frames filled"}[args.operator]
    if args.operator == "denoise":
        model = bridge.denoiser_folder(bpy.context.preferences.addons[package].preferences)
    print(f"{args.operator}, model: {model}\nrig: {len(obj.data.bones)} bones, clip {args.frames} frames {done}")
    for stage in ("read", "model", "solve", "write"):
        print(f"  {stage:6s} {best[stage]:7.3f} s   peak {best['mb'].get(stage, 0.0):5.0f} MB")
    print(f"  total  {best['total']:7.3f} s")
    if "fk_total" in best:
        print(f"  the rig generated by Rigify, legs keyed on IK (foot_ik, thigh_ik, toe_ik); the same walk keyed on "
              f"FK in the same run: {best['fk_total']:.3f} s; on IK {best['total'] / best['fk_total']:.2f} x")
    if "bare_total" in best:
        vertices = len(bpy.data.objects["BenchBody"].data.vertices)
        print(f"  the rig deforming a mesh of {vertices} vertices; the same rig without it in the same run: "
              f"{best['bare_total']:.3f} s; with the mesh {best['total'] / best['bare_total']:.2f} x")
    if "alone_total" in best:
        also = f" and {args.set} still objects" if args.set else ""
        print(f"  with {args.others} more animated Rigify rigs{also} in the scene; the same rig alone in its scene in "
              f"the same run: {best['alone_total']:.3f} s; with the others {best['total'] / best['alone_total']:.2f} x")
    if "evaluated_total" in best:
        print(f"  the rig generated by Rigify baked through FBX, read and keyed in closed form; with Blender "
              f"evaluating it frame by frame and its visual bake in the same run: {best['evaluated_total']:.3f} s; "
              f"in closed form {best['total'] / best['evaluated_total']:.2f} x")
    if "flat_total" in best:
        print(f"  on the flat floor (no ground) in the same run: {best['flat_total']:.3f} s; with the ground "
              f"{best['total'] / best['flat_total']:.2f} x")
    print(f"  floor: read keys {best['floor_read']:.3f} s, write keys {best['floor_write']:.3f} s")
    print(f"  memory beyond the scene's own: {best['extra_mb']:.0f} MB at the peak, of which a copy of the action "
          f"(the new action's own size) {best['floor_mb']:.0f} MB; the operation's working memory "
          f"{best['extra_mb'] - best['floor_mb']:.0f} MB")
    return best


if __name__ == "__main__":
    main()
