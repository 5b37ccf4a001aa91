"""The worker side of scripts/strnn_batch.py: input files, one after another, in a process with its own bpy.

The first :func:`process_file` of a worker process starts Blender (the ``bpy`` module) with factory
settings in a user folder of its own and installs and enables the extension zip; every file then
starts from Blender's factory startup file, is imported (Blender's BVH, FBX, glTF or USD importer, or the .blend
is opened), has the extension's operator run on its armature, and its result is written atomically.
It never raises: a failure becomes a one-line reason in the result. :func:`install_extension` is
also used by the README pictures, which install the extension the same way.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import os
import struct
import sys
import tempfile
import time
import traceback
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
REPO_MODULE = "strnn_batch"
ADDON = f"bl_ext.{REPO_MODULE}.strnn_motion"
BOM = b"\xef\xbb\xbf"  # UTF-8's byte-order mark
GLTF = (".glb", ".gltf")
USD = (".usd", ".usda", ".usdc", ".usdz")
# the frame rates a glTF's keys (or a USD stage's time codes) are read at where their spacing says one (within
# RATE_TOLERANCE)
FRAME_RATES = (8, 10, 12, 15, 20, 24, 25, 30, 48, 50, 60, 72, 90, 100, 120, 144, 240)
RATE_TOLERANCE = 0.01


class BatchError(Exception):
    """A per-file failure with a reason meant for the summary (no traceback)."""


def check_bvh_text(path: Path):
    """Fail with a plain reason for files Blender's importer would choke on; the file as the project reads it."""
    try:
        text = path.read_text(encoding="utf-8-sig", errors="strict")  # a byte-order mark is no content
    except UnicodeDecodeError:
        raise BatchError("not a BVH file: it is not text") from None
    words = text.split()
    if not words:
        raise BatchError("not a BVH file: it is empty")
    if words[0].upper() != "HIERARCHY":
        raise BatchError(f"not a BVH file: it starts with {words[0][:30]!r}, not HIERARCHY")
    if "MOTION" not in words:
        raise BatchError("broken BVH: no MOTION section (the file is cut short?)")
    motion = text[text.index("MOTION"):].splitlines()
    try:
        frames = int(next(line.split(":")[1] for line in motion if line.strip().startswith("Frames")))
        float(next(line.split(":")[1] for line in motion if line.strip().startswith("Frame Time")))
    except (StopIteration, IndexError, ValueError):
        raise BatchError("broken BVH: the MOTION section lacks a valid 'Frames:' or 'Frame Time:' line") from None
    rows = [line for line in motion[3:] if line.strip()]
    if frames < 2:
        raise BatchError(f"broken BVH: {frames} frame(s); the operators need at least 2")
    if len(rows) < frames:
        raise BatchError(f"broken BVH: header says {frames} frames but the file has {len(rows)} (cut short?)")
    widths = {len(line.split()) for line in rows[:frames]}
    if len(widths) != 1:
        raise BatchError("broken BVH: frame lines have different numbers of values")
    try:
        [float(v) for line in rows[:frames] for v in line.split()]
    except ValueError as e:
        raise BatchError(f"broken BVH: a frame line holds a non-number ({e})") from None
    return read_checked(path)


def read_checked(path: Path):
    """The project's own BVH reader over the whole file, the one check every entry point shares: a
    Frame Time no capture rate has, non-finite values, a malformed hierarchy (file, line and fix)."""
    if str(REPO) not in sys.path:
        sys.path.insert(0, str(REPO))
    from model_core.io.bvh import BvhError, read_bvh

    try:
        return read_bvh(path)
    except BvhError as e:
        raise BatchError(f"broken BVH: {str(e).removeprefix(str(path) + ':')}") from None


@contextlib.contextmanager
def without_byte_order_mark(path: Path):
    """``path``, or where the file starts with a UTF-8 byte-order mark (some Windows tools write one; Blender's BVH
    importer then calls it 'not a BVH file') a copy without it, of the same name in a temporary folder."""
    with open(path, "rb") as f:
        marked = f.read(len(BOM)) == BOM
    if not marked:
        yield path
        return
    with tempfile.TemporaryDirectory() as folder:
        copy = Path(folder) / path.name
        copy.write_bytes(path.read_bytes()[len(BOM):])
        yield copy


AXES_FRAMES = 600  # at most this many of a take's frames, evenly spread, say which axis its body stands along


def file_axes(bvh) -> tuple[str, str]:
    """(forward, up) axes for Blender's BVH importer of the read file ``bvh``: the default ``("-Z", "Y")``, or the
    axis the take's body stands along where that is another (a Z-up file: ``("Y", "Z")``), so that the armature
    stands in Blender (``rigs.standing_axis``, on :data:`AXES_FRAMES` of its frames). A rig the project cannot
    read by itself keeps the default."""
    import dataclasses

    from model_core.io.bvh import BvhError
    from model_core.rig.rigs import RigError, axis_name, canonical_positions, standing_axis

    step = max(1, -(-bvh.frames // AXES_FRAMES))
    try:
        axis = standing_axis(canonical_positions(dataclasses.replace(bvh, motion=bvh.motion[::step])))
    except (BvhError, RigError):
        axis = None
    if axis is None or axis[1] > 0:
        return "-Z", "Y"
    up = axis_name(axis)
    return ("Y" if up.endswith("Z") else "-Z"), up


def gltf_document(path: Path) -> dict:
    """The JSON of a .gltf file, or of a .glb's first chunk (the binary form's header, then its JSON)."""
    data = path.read_bytes()
    if path.suffix.lower() == ".glb":
        if len(data) < 20 or data[:4] != b"glTF":
            raise BatchError("not a binary glTF file: it does not start with glTF's header")
        length, kind = struct.unpack_from("<I4s", data, 12)
        if kind != b"JSON":
            raise BatchError("broken glTF: its first chunk is not its JSON")
        data = data[20:20 + length]
    try:
        document = json.loads(data)
    except (UnicodeDecodeError, ValueError) as e:
        raise BatchError(f"broken glTF: its JSON cannot be read ({e})") from None
    if not isinstance(document, dict):
        raise BatchError("broken glTF: its JSON is not an object")
    return document


def gltf_animations(document: dict) -> list[str]:
    """The names of the glTF's animations, in the file's order (an unnamed one as glTF numbers it)."""
    animations = document.get("animations")
    if not isinstance(animations, list):
        return []
    return [a.get("name") or f"animation {i}" if isinstance(a, dict) else f"animation {i}"
            for i, a in enumerate(animations)]


def gltf_frame_rate(document: dict) -> int | None:
    """The frame rate a glTF's keys were made at, or None where their spacing says none.

    glTF keeps time in seconds, and Blender's importer puts a key at the scene's frame rate times its time: at the
    factory 24 fps a 30 fps take's keys land 0.8 frames apart. Read from the animation sampler with the most keys
    (its times' count, first and last, which glTF's accessors must state), as (count - 1) / (last - first), and
    kept where that is within :data:`RATE_TOLERANCE` of one of :data:`FRAME_RATES` (keys set by hand at a few
    poses say no rate)."""
    densest = None
    try:
        for animation in document.get("animations") or []:
            for sampler in animation.get("samplers") or []:
                times = document["accessors"][sampler["input"]]
                count, first, last = int(times["count"]), float(times["min"][0]), float(times["max"][0])
                if count >= 3 and last > first and (densest is None or count > densest[0]):
                    densest = (count, first, last)
    except (AttributeError, KeyError, IndexError, TypeError, ValueError):  # the importer says what is wrong
        return None
    if densest is None:
        return None
    count, first, last = densest
    spacing = (count - 1) / (last - first)
    rate = min(FRAME_RATES, key=lambda r: abs(spacing - r))
    return rate if abs(spacing - rate) <= RATE_TOLERANCE * rate else None


def import_gltf(bpy, path: Path) -> list[str]:
    """Import a .glb or .gltf with Blender's glTF importer, the scene first set to the rate its keys were made at
    (:func:`gltf_frame_rate`: each key on a frame, as a BVH's or an FBX's are); its first animation is the one
    Blender makes active (the others go to NLA tracks). No bone shape is made (the importer's icosphere object).
    Returns the notes a batch reports: keys at no rate."""
    document = gltf_document(path)
    rate = gltf_frame_rate(document)
    scene = bpy.context.scene
    if rate is not None:
        scene.render.fps, scene.render.fps_base = rate, 1.0
    there = set(bpy.data.objects)
    try:
        bpy.ops.import_scene.gltf(filepath=str(path), disable_bone_shape=True)
    except RuntimeError as e:
        raise BatchError(f"Blender's glTF importer could not read it: {blender_error(e)}") from None
    if not document.get("skins") and not any(o.type == "ARMATURE" for o in set(bpy.data.objects) - there):
        raise BatchError("the glTF has no skin, and Blender's importer makes an armature of a skin's joints alone "
                         "(its nodes came in as empties): export the character with its skinned mesh")
    notes = []
    animations = gltf_animations(document)
    if animations and rate is None:
        notes.append(f"the glTF's keys are not spaced at a frame rate: read at the scene's {scene.render.fps} "
                     "frames a second (its keys between frames)")
    return notes


def usd_stage(path: Path) -> dict:
    """What Blender's USD importer and exporter leave to the caller, read from the stage with Pixar's own library
    (``pxr``, the usd-core package): its time codes a second (``rate``; USD's 24 where the file says none, its
    ``framesPerSecond`` where it gives that alone), its up axis (``up``, "Y" or "Z"), its metres per unit
    (``meters``) and its default prim's name (``root``, or "")."""
    try:
        from pxr import Usd, UsdGeom
    except ImportError:
        raise BatchError("reading a USD file needs Pixar's USD library for Python: pip install usd-core "
                         "(scripts/setup.sh installs it)") from None
    try:
        stage = Usd.Stage.Open(str(path), Usd.Stage.LoadNone)
    except Exception as e:  # pxr.Tf.ErrorException: a file USD cannot read
        reason = " ".join(str(e).split())
        raise BatchError(f"broken USD: Pixar's library cannot open it ({reason[:200]})") from None
    default = stage.GetDefaultPrim()
    return {"rate": float(stage.GetTimeCodesPerSecond()), "up": str(UsdGeom.GetStageUpAxis(stage)),
            "meters": float(UsdGeom.GetStageMetersPerUnit(stage)), "root": default.GetName() if default else ""}


def set_frame_rate(scene, rate: float) -> None:
    """Set ``scene`` to play ``rate`` frames a second: a frame rate of :data:`FRAME_RATES` where ``rate`` is within
    :data:`RATE_TOLERANCE` of it (a take exported at 1 / 0.0333333 s is 30), else as Blender writes an odd rate
    (the nearest whole number over a base)."""
    near = min(FRAME_RATES, key=lambda r: abs(rate - r))
    if abs(rate - near) <= RATE_TOLERANCE * near:
        rate = near
    scene.render.fps = max(1, round(rate))
    scene.render.fps_base = scene.render.fps / rate


def import_usd(bpy, path: Path) -> dict:
    """Import a USD file (.usd, .usda, .usdc, .usdz) with Blender's USD importer, the scene first set to the stage's
    time codes a second (:func:`usd_stage`: Blender's importer puts time code t on frame t but leaves the scene's
    rate as it was, so a 30 fps take would play at the factory 24). Returns the stage's settings, which the result
    is written back with (:func:`export_usd`)."""
    stage = usd_stage(path)
    set_frame_rate(bpy.context.scene, stage["rate"])
    there = set(bpy.data.objects)
    try:
        bpy.ops.wm.usd_import(filepath=str(path))
    except RuntimeError as e:
        raise BatchError(f"Blender's USD importer could not read it: {blender_error(e)}") from None
    if not any(o.type == "ARMATURE" for o in set(bpy.data.objects) - there):
        raise BatchError("the USD has no skeleton (UsdSkel) for Blender's importer to make an armature of: export "
                         "the character with its skeleton and skinned mesh")
    return stage


def fbx_takes(bpy, obj, before: set) -> list:
    """The takes Blender's FBX importer made for ``obj``: an action of each named ``ARMATURE|...|TAKE``, which it
    leaves unassigned but the first; renamed ``TAKE`` (the exporter writes ``ARMATURE|ACTION`` again, and the name
    would grow by a prefix at each round trip). ``before``: the actions there were before the import."""
    takes = sorted((a for a in bpy.data.actions if a not in before and a.name.startswith(obj.name + "|")),
                   key=lambda a: a.name)
    for action in takes:
        action.name = action.name.rsplit("|", 1)[1]
    return takes


def every_take(obj, fbx: list) -> list:
    """``--every-action``: the actions of ``obj`` to run on, each in turn, the one it plays first: an FBX's takes
    (``fbx``, from :func:`fbx_takes`), else those of its muted NLA tracks (a glTF's other animations, which
    Blender's importer puts there, a .blend's stashed actions; a track that plays is a layer of the motion, not a
    take)."""
    ad = obj.animation_data
    tracks = [t for t in ad.nla_tracks if t.mute] if ad else []
    found = ([ad.action] if ad else []) + (fbx or [s.action for t in tracks for s in t.strips])
    takes = list(dict.fromkeys(a for a in found if a is not None))
    if not takes:
        raise BatchError(f"--every-action: {obj.name!r} has no action")
    return takes


def inspect(bpy, obj, fbx: list, imported: list[str]) -> list[str]:
    """``inspect``: what the operators would run on in the imported file, as notes (the armature, how its bones map
    and which controls are keyed, or which bones go with the bones they follow, its takes and their rate), or a
    :class:`BatchError` with the reason they would refuse it (the sidebar's own check, ``pipeline.prepare``)."""
    pipeline = importlib.import_module(f"{ADDON}.strnn_addon.scene.pipeline")
    try:
        clip = pipeline.prepare(bpy.context, obj)
    except pipeline.UserError as e:
        raise BatchError(f"the operators would refuse it: {e}") from None
    mapping = pipeline.mapping
    stored = len(mapping.stored_map(obj)) == len(mapping.bonemap.JOINTS)
    how = "the bone map stored with it" if stored else f"its {mapping.auto_map(obj)[0]} bone names"
    others = sorted(o.name for o in bpy.context.scene.objects if o.type == "ARMATURE" and o is not obj)
    beside = f", beside {', '.join(map(repr, others))}" if others else ""
    notes = [f"armature {obj.name!r} ({len(obj.data.bones)} bones{beside}): the model's 21 joints mapped from {how}"]
    if clip.controls is not None:
        baked = (f"a control rig an exporter baked (its controls drive nothing): results keyed on its deform bones, "
                 f"{len(clip.carried)} more carried with them so that none of its skin is left behind")
        notes.append({pipeline.OWN_BONES: "results keyed on its bones by a visual bake", pipeline.BAKED_BONES: baked}
                     .get(clip.controls.name, f"results keyed on its {clip.controls.name} controls"))
    elif clip.carried:  # a game rig's IK bones, keyed on the feet and hands they follow
        pairs = ", ".join(f"{bone} on {carrier}" for bone, carrier in sorted(clip.carried.items()))
        notes.append(f"{len(clip.carried)} bones outside the bone map keyed with the bones they follow ({pairs})")
    takes = every_take(obj, fbx)
    notes.append(f"{len(takes)} takes, the first plays" if len(takes) > 1 else "1 take")
    notes[-1] += f", at {clip.fps:g} keys a second"
    for take in takes:
        obj.animation_data.action = take
        notes.append(f"{take.name!r} frames {round(take.frame_range[0])}-{round(take.frame_range[1])}: "
                     + take_familiarity(bpy, pipeline, obj))
    obj.animation_data.action = takes[0]
    return imported + notes


def take_familiarity(bpy, pipeline, obj) -> str:
    """How familiar the motion of the action ``obj`` plays is to the model, as the sidebar's Check Motion says it
    (``stages.check``: its last 10 s rebuilt by the model, against the motion it knows), or why it cannot say."""
    check = importlib.import_module(f"{ADDON}.strnn_addon.stages.check")
    try:
        checked = check.check_motion(bpy.context, obj)
    except pipeline.UserError as e:
        return f"not judged ({e})"
    rate = checked.suggested_rate
    return checked.message() + (f" (in a batch: --keys-per-second {rate:g})" if rate else "")


def stash(obj, action) -> None:
    """Keep ``action`` on ``obj`` in a muted NLA track of its own (as Blender's Stash does: saved with the file, and
    each such action an animation of a glTF)."""
    track = obj.animation_data.nla_tracks.new()
    track.name = action.name
    track.strips.new(action.name, int(action.frame_range[0]), action)
    track.mute = True


def run_operator(bpy, job: dict, obj, kwargs: dict):
    """Run the job's operator on ``obj`` (and the selection) for the action it plays now; returns ``obj``'s new
    action."""
    if job["operator"] == "inbetween" and kwargs.get("use_range"):
        clear_keys(obj, kwargs["frame_start"], kwargs["frame_end"])
    if kwargs.get("from_current"):
        bpy.context.scene.frame_set(job["from_frame"])
    bpy.context.view_layer.objects.active = obj
    try:
        getattr(bpy.ops.strnn, job["operator"])(**kwargs)
    except RuntimeError as e:
        raise BatchError(f"strnn.{job['operator']} refused: {blender_error(e)}") from None
    action = obj.animation_data.action if obj.animation_data else None
    if action is None:
        raise BatchError(f"strnn.{job['operator']} left the armature without an action")
    return action


def use_action(bpy, obj, name: str) -> None:
    """Play the action ``name`` on ``obj`` (``--action``): an action of that name, or an FBX take of it (named by
    Blender's importer ``ARMATURE|...|TAKE``, as a .blend that imported one keeps it; this armature's first); a
    :class:`BatchError` naming the file's actions where none is."""
    found = bpy.data.actions.get(name)
    if found is None:
        takes = [a for a in bpy.data.actions if "|" in a.name and a.name.rsplit("|", 1)[1] == name]
        found = next((a for a in takes if a.name.startswith(obj.name + "|")), takes[0] if takes else None)
    if found is None:
        names = sorted(a.name.rsplit("|", 1)[-1] for a in bpy.data.actions)
        raise BatchError(f"no action named {name!r} for --action; the file has {', '.join(map(repr, names))}"
                         if names else f"no action named {name!r} for --action; the file has no action")
    (obj.animation_data or obj.animation_data_create()).action = found


def blender_error(e: Exception) -> str:
    """The last meaningful line of a bpy.ops RuntimeError (Blender packs tracebacks in the message)."""
    lines = [line.strip() for line in str(e).splitlines() if line.strip() and not line.strip().startswith(
        ("Location:", "File ", "Traceback", "^", "~"))]
    msg = lines[-1] if lines else type(e).__name__
    return msg.removeprefix("Error: ")


def install_extension(bpy, zip_path: str, user_dir: Path):
    prefs = bpy.context.preferences
    directory = user_dir / "extensions"
    directory.mkdir(parents=True, exist_ok=True)
    if prefs.extensions.repos.get(REPO_MODULE) is None:
        prefs.extensions.repos.new(name=REPO_MODULE, module=REPO_MODULE, custom_directory=str(directory),
                                   source="USER")
    result = bpy.ops.extensions.package_install_files(filepath=zip_path, repo=REPO_MODULE, enable_on_install=True)
    if result != {"FINISHED"} or ADDON not in prefs.addons:
        raise BatchError(f"could not install and enable the extension {zip_path}")


def add_path_curve(bpy, name: str):
    """A poly curve object of the built-in ground path ``name`` (model (x, z) -> Blender (x, -z, 0))."""
    from model_core.ops.paths import evaluation_paths

    points, cyclic = evaluation_paths()[name]
    data = bpy.data.curves.new(f"path_{name}", "CURVE")
    spline = data.splines.new("POLY")
    spline.points.add(len(points) - 1)
    for p, (x, z) in zip(spline.points, points):
        p.co = (float(x), float(-z), 0.0, 1.0)
    spline.use_cyclic_u = bool(cyclic)
    obj = bpy.data.objects.new(f"path_{name}", data)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def pick_armature(bpy, any_animated: bool = False):
    """The armature to process: the active one, else the only one (or the only one with an action); with
    ``any_animated`` (``--every-armature``: all of them run) else the first by name with an action whose bones the
    extension maps (a character rather than a prop), or with an action at all."""
    active = bpy.context.view_layer.objects.active
    if active is not None and active.type == "ARMATURE":
        return active
    arms = [o for o in bpy.context.scene.objects if o.type == "ARMATURE"]
    animated = sorted((o for o in arms if o.animation_data and o.animation_data.action), key=lambda o: o.name)
    if len(arms) == 1:
        return arms[0]
    if len(animated) == 1:
        return animated[0]
    if any_animated and animated:
        mapping = importlib.import_module(f"{ADDON}.strnn_addon.scene.mapping")
        return next((o for o in animated if not mapping.bonemap.missing(mapping.effective_map(o))), animated[0])
    if not arms:
        raise BatchError("the file has no armature")
    raise BatchError(f"{len(arms)} armatures and none active; make the one to process active and save")


POSE_CHANNELS = ("location", "rotation_euler", "rotation_quaternion", "rotation_axis_angle", "scale")


def clear_keys(obj, start: int, end: int) -> None:
    """Delete the pose bones' keys on frames ``start`` to ``end`` (a gap for Fill Gap to fill)."""
    for pb in obj.pose.bones:
        for prop in POSE_CHANNELS:
            for frame in range(start, end + 1):
                try:
                    pb.keyframe_delete(prop, frame=frame)
                except RuntimeError:  # no key there
                    pass


def open_target(bpy, job: dict) -> tuple:
    """For ``transfer``: open the character .blend (or import the character FBX, glTF or USD file into Blender's
    factory startup file); (its rig: ``--rig``, or the one to pick; a USD character's stage, which the result is
    written back in, else None)."""
    stage = None
    try:
        if job["target"].lower().endswith(".fbx"):
            bpy.ops.import_scene.fbx(filepath=job["target"])
        elif job["target"].lower().endswith(GLTF):
            import_gltf(bpy, Path(job["target"]))
        elif job["target"].lower().endswith(USD):
            stage = import_usd(bpy, Path(job["target"]))
        else:
            bpy.ops.wm.open_mainfile(filepath=job["target"], load_ui=False)
    except (RuntimeError, BatchError) as e:
        raise BatchError(f"Blender could not open --target {job['target']}: {blender_error(e)}") from None
    if job["rig"]:
        rig = bpy.data.objects.get(job["rig"])
        if rig is None or rig.type != "ARMATURE":
            raise BatchError(f"no armature named {job['rig']!r} in --target for --rig")
        return rig, stage
    return pick_armature(bpy), stage


def run_file(bpy, job: dict) -> list[str]:
    """Import the job's input, run its operator, write the result; returns the notes of the new action's
    record (what the operator's report would warn of: the motion is unfamiliar, the keys' rate, ...)."""
    src, dst = Path(job["input"]), Path(job["output"])
    target = stage = None  # stage: the USD stage the result is written back in (the character's)
    if job["operator"] == "transfer_motion":
        if src.suffix.lower() not in (".bvh", ".fbx", *GLTF, *USD):
            raise BatchError("transfer takes BVH, FBX, glTF or USD takes; a .blend is a target (--target), not a "
                             "take")
        target, stage = open_target(bpy, job)
    if dst.suffix.lower() == ".gltf":  # (--in-place on a .gltf)
        raise BatchError("a .gltf result is two files (the .gltf and its .bin), which cannot be replaced at once: "
                         "write .glb results to --out (leave out --in-place)")
    axes = ("-Z", "Y")
    there, there_collections = set(bpy.data.objects), set(bpy.data.collections)
    actions = set(bpy.data.actions)
    imported = []
    if src.suffix.lower() in GLTF:
        imported = import_gltf(bpy, src)
    elif src.suffix.lower() in USD:
        read = import_usd(bpy, src)
        if target is None:  # the result is this file's character, written back in its axes and units
            stage = read
        if job["operator"] == "inspect":
            root = f", default prim /{read['root']}" if read["root"] else ""
            imported.append(f"USD stage at {read['rate']:g} time codes a second, {read['up']} up, "
                            f"{read['meters']:g} m a unit{root}: results are written back so")
    elif src.suffix.lower() == ".fbx":
        try:  # as File > Import > FBX does it: the scene takes the file's frame rate
            bpy.ops.import_scene.fbx(filepath=str(src))
        except RuntimeError as e:
            raise BatchError(f"Blender's FBX importer could not read it: {blender_error(e)}") from None
    elif src.suffix.lower() == ".bvh":
        axes = file_axes(check_bvh_text(src))
        with without_byte_order_mark(src) as readable:
            try:
                bpy.ops.import_anim.bvh(filepath=str(readable), update_scene_fps=True, update_scene_duration=True,
                                        axis_forward=axes[0], axis_up=axes[1])
            except RuntimeError as e:
                raise BatchError(f"Blender's BVH importer could not read it: {blender_error(e)}") from None
    else:
        try:
            bpy.ops.wm.open_mainfile(filepath=str(src), load_ui=False)
        except RuntimeError as e:
            raise BatchError(f"Blender could not open it: {blender_error(e)}") from None
    if src.suffix.lower() != ".blend":  # the imported armature (an FBX's or glTF's animated one first) runs
        brought = sorted((o for o in set(bpy.data.objects) - there if o.type == "ARMATURE"),
                         key=lambda o: (not (o.animation_data and o.animation_data.action), o.name))
        if not brought:
            raise BatchError("the file has no armature")
        bpy.context.view_layer.objects.active = brought[0]
    obj = pick_armature(bpy, bool(job.get("every_armature")) and target is None)
    fbx = fbx_takes(bpy, obj, actions) if src.suffix.lower() == ".fbx" else []
    if job["operator"] == "inspect":
        return inspect(bpy, obj, fbx, imported)
    if job.get("action"):  # another take than the one the file plays
        use_action(bpy, obj, job["action"])
    elif not job.get("every_action") and src.suffix.lower() in (".fbx", *GLTF) and obj.animation_data \
            and obj.animation_data.action and len(held := every_take(obj, fbx)) > 1:  # the others left: say so
        kind, what = ("FBX", "takes") if src.suffix.lower() == ".fbx" else ("glTF", "animations")
        imported.append(f"the {kind} holds {len(held)} {what}: ran on {held[0].name!r} (the one Blender's importer "
                        "plays; --action NAME for another); the result holds the new one alone")
    takes = every_take(obj, fbx) if job.get("every_action") else [obj.animation_data.action]
    if len(takes) > 1 and dst.suffix.lower() in (".bvh", *USD):
        kind = "BVH" if dst.suffix.lower() == ".bvh" else "USD skeleton"
        raise BatchError(f"--every-action found {len(takes)} takes, and a {kind} holds one: write FBX, .glb or "
                         ".blend results (--format)")
    view_layer = bpy.context.view_layer
    for other in view_layer.objects:
        other.select_set(False)
    source = None
    if target is not None:  # the import is the source, selected; the rig is the active target
        source, obj = obj, target
        source.select_set(True)
    view_layer.objects.active = obj
    obj.select_set(True)
    crowd = every_armature(bpy, obj) if job.get("every_armature") and target is None else []
    if crowd and dst.suffix.lower() not in (".blend", *USD):  # (--in-place on an FBX: it would keep one of them)
        raise BatchError(f"--every-armature found {len(crowd) + 1} animated armatures, and a {dst.suffix} result "
                         "holds one: write .blend or USD results (leave out --in-place)")
    before = {o.name: o.animation_data.action for o in crowd}
    if job.get("keys_per_second"):  # the take's own pace where its file says another rate (--keys-per-second)
        for each in [obj if source is None else source, *crowd]:
            each.strnn_keys_per_second = job["keys_per_second"]
    kwargs = dict(job["kwargs"])
    if job["operator"] == "follow_curve":
        if job["curve"]:
            if bpy.data.objects.get(job["curve"]) is None:
                raise BatchError(f"no object named {job['curve']!r} in the file for --curve")
            kwargs["curve"] = job["curve"]
        else:
            kwargs["curve"] = add_path_curve(bpy, job["path"]).name
        view_layer.objects.active = obj
    if kwargs.get("ground") and bpy.data.objects.get(kwargs["ground"]) is None \
            and bpy.data.collections.get(kwargs["ground"]) is None:
        raise BatchError(f"no object or collection named {kwargs['ground']!r} in the file for --ground")
    common = importlib.import_module(f"{ADDON}.strnn_addon.stages.common")
    results, notes = [], list(imported)
    for take in takes:  # the take the file plays, or with --every-action each in turn
        player = obj if source is None else source
        if len(takes) > 1:
            player.animation_data.action = take
        action = run_operator(bpy, job, obj, kwargs)
        results.append(action)
        named = batch_notes(common, action)
        notes += [f"{take.name}: {n}" for n in named] if len(takes) > 1 else named
    if len(results) > 1:  # the first plays; the others are kept in muted NLA tracks (saved, and exported as takes)
        obj.animation_data.action = results[0]
        for action in results[1:]:
            stash(obj, action)
    if source is not None:  # the result file holds the character alone: what the take brought goes
        for brought in set(bpy.data.objects) - there:
            bpy.data.objects.remove(brought)
        for brought in set(bpy.data.collections) - there_collections:  # (the glTF importer's scene collection)
            bpy.data.collections.remove(brought)
    if crowd:
        notes = [f"{obj.name}: {n}" for n in notes] + crowd_notes(common, crowd, before)
    if axes[1] != "Y":
        notes.append(f"the take stands along its file's {axes[1]} axis, not Y: read with Up {axes[1]} so that it "
                     "stands, and written back in the file's own axes")
    cast = [obj, *crowd]  # what the result holds: the character, or every one of a crowd with its action
    kept = results + [o.animation_data.action for o in crowd if o.animation_data and o.animation_data.action]
    start = min(int(round(a.frame_range[0])) for a in kept)
    end = max(int(round(a.frame_range[1])) for a in kept)
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = start, end
    # a rate near a frame rate written as it: a BVH's 1 / 0.0333333 s as 30, not 30.00003, which an FBX would carry
    # as a custom rate and a USD stage referencing the result would scale its time by
    set_frame_rate(scene, scene.render.fps / scene.render.fps_base)
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_name(dst.stem + ".tmp" + dst.suffix)  # write beside, then replace: no half-written outputs
    try:
        if dst.suffix.lower() == ".bvh":
            view_layer.objects.active = obj
            if src.suffix.lower() == ".bvh":
                to_file_axes(bpy, obj, *axes)
            bpy.ops.export_anim.bvh(filepath=str(tmp), frame_start=start, frame_end=end,
                                    check_existing=False)
        elif dst.suffix.lower() == ".fbx":
            export_fbx(bpy, obj, results, tmp)
        elif dst.suffix.lower() == ".glb":
            export_gltf(bpy, obj, results, tmp)
        elif dst.suffix.lower() in USD:
            export_usd(bpy, cast, kept, tmp, stage)
        else:
            bpy.ops.wm.save_as_mainfile(filepath=str(tmp), copy=True, compress=True)
    except RuntimeError as e:
        tmp.unlink(missing_ok=True)
        raise BatchError(f"Blender could not write {dst.name}: {blender_error(e)}") from None
    os.replace(tmp, dst)
    return notes


def select_character(bpy, obj, results: list) -> None:
    """Select ``obj`` (an armature, or a list of them: a crowd, the first made active), the objects it hangs from (a
    root null) and the meshes it deforms (or that hang from it), and drop every action but ``results`` (an exporter
    writes a take or an animation for each action; the worker's others, the input's own among them, are not the
    result)."""
    rigs = obj if isinstance(obj, list) else [obj]
    keep = set(rigs) | {o for o in bpy.data.objects if o.type == "MESH" and (
        o.parent in rigs or any(m.type == "ARMATURE" and m.object in rigs for m in o.modifiers))}
    for rig in rigs:
        above = rig.parent
        while above is not None:
            keep.add(above)
            above = above.parent
    for action in [a for a in bpy.data.actions if a not in results]:
        bpy.data.actions.remove(action)
    for o in bpy.context.view_layer.objects:
        o.select_set(o in keep)
    bpy.context.view_layer.objects.active = rigs[0]


def export_fbx(bpy, obj, results: list, path: Path) -> None:
    """Write ``obj`` with what :func:`select_character` selects to an FBX at ``path`` with Blender's exporter, each
    of ``results`` (its new actions) a take of the file (named as the action), every frame keyed (no curve
    simplification) and no leaf bones added, so that it imports again as it was written. (The exporter's take of
    the scene instead of the actions imports one frame late.)"""
    select_character(bpy, obj, results)
    bpy.ops.export_scene.fbx(filepath=str(path), check_existing=False, use_selection=True,
                             object_types={"ARMATURE", "MESH", "EMPTY"}, add_leaf_bones=False, bake_anim=True,
                             bake_anim_use_all_actions=True, bake_anim_use_nla_strips=False,
                             bake_anim_force_startend_keying=True, bake_anim_simplify_factor=0.0)


def export_gltf(bpy, obj, results: list, path: Path) -> None:
    """Write ``obj`` with what :func:`select_character` selects to a binary glTF (.glb) at ``path`` with Blender's
    exporter, each of ``results`` (its new actions: the one it plays and those in its NLA tracks) an animation of
    the file (named as the action), sampled at every frame of the
    action at the scene's rate (glTF's times in seconds: a key at frame f at f / fps), so that it imports again as
    it was written; the bones' rest as Blender has it (the importer's, for a glTF input)."""
    select_character(bpy, obj, results)
    bpy.ops.export_scene.gltf(filepath=str(path), check_existing=False, export_format="GLB", use_selection=True,
                              export_animations=True, export_animation_mode="ACTIONS", export_force_sampling=True,
                              export_frame_range=False, export_anim_slide_to_zero=False)


# USD's metres per unit that Blender's USD exporter names (any other is written as its own figure)
USD_UNITS = {1.0: "METERS", 1000.0: "KILOMETERS", 0.01: "CENTIMETERS", 0.001: "MILLIMETERS", 0.0254: "INCHES",
             0.3048: "FEET", 0.9144: "YARDS"}


def export_usd(bpy, obj, results: list, path: Path, stage: dict | None) -> None:
    """Write ``obj`` (or a list of armatures, with ``--every-armature``) with what :func:`select_character` selects to
    a USD file at ``path`` with Blender's exporter (its suffix says which: .usd and .usdc binary, .usda text, .usdz a
    package), each armature's action (the new one) as its skeleton's animation over the scene's frames at the
    scene's rate. A USD input's result keeps the input stage's up axis,
    units and default prim (``stage``, from :func:`usd_stage`), so that it drops into the pipeline it came from;
    any other is written as Blender writes USD (Z up, metres, ``/root``)."""
    select_character(bpy, obj, results)
    options = {}
    if stage is not None:
        units = USD_UNITS.get(round(stage["meters"], 6), "CUSTOM")
        options = {"convert_orientation": stage["up"] != "Z", "export_global_up_selection": "Y",
                   "export_global_forward_selection": "NEGATIVE_Z", "convert_scene_units": units,
                   "meters_per_unit": stage["meters"]}
        if stage["root"]:  # the default prim: one Blender made (and left out on import) again, or its object's
            options["root_prim_path"] = "" if bpy.data.objects.get(stage["root"]) else "/" + stage["root"]
    bpy.ops.wm.usd_export(filepath=str(path), check_existing=False, selected_objects_only=True,
                          export_animation=True, export_armatures=True, **options)


def every_armature(bpy, obj) -> list:
    """The armatures with an action in the file's view layer other than ``obj``, selected with it so that the
    operator runs on each (``--every-armature``)."""
    crowd = [o for o in bpy.context.view_layer.objects if o.type == "ARMATURE" and o is not obj
             and o.animation_data and o.animation_data.action]
    for o in crowd:
        o.select_set(True)
    return crowd


def crowd_notes(common, crowd: list, before: dict) -> list[str]:
    """Each of ``crowd``'s notes (its name first), and which of them the operator left as they were (their action
    the one they had, ``before``: it could not take them)."""
    notes = []
    for o in crowd:
        action = o.animation_data.action if o.animation_data else None
        if action is None or action is before[o.name]:
            notes.append(f"{o.name}: left as it was (the operator could not take it; run it on that armature alone "
                         "to see why)")
        else:
            notes += [f"{o.name}: {n}" for n in batch_notes(common, action)]
    return notes


def batch_notes(common, action) -> list[str]:
    """The notes of the new action's record (``common.record_notes``) as a batch reports them: the pace's, where it
    says to set Keys per Second (the sidebar's), also says how in a batch, from the rate the record suggests."""
    pace = action.get(common.RECORD, {}).get("pace", {})
    rate = pace.get("suggested_keys_per_second")
    return [f"{note} (in a batch: --keys-per-second {rate:g})" if rate and note == pace.get("note") else note
            for note in common.record_notes(action)]


def to_file_axes(bpy, obj, forward: str = "-Z", up: str = "Y") -> None:
    """Turn the armature back into the BVH file's axes (``forward`` and ``up`` as it was imported with:
    Y up by default) before Blender's exporter writes it.

    The importer turned the file's axes into Blender's (Y-up into Z-up), and the exporter writes armature
    space with no axis option, so without this a take comes back lying on its back. The turn goes into the
    armature's rest (its keys are relative to the bones, so the motion turns with them)."""
    from bpy_extras.io_utils import axis_conversion

    turn = axis_conversion(from_forward=forward, from_up=up).to_4x4().inverted()
    obj.matrix_world = turn @ obj.matrix_world
    for other in bpy.context.view_layer.objects:
        other.select_set(other is obj)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.transform_apply(location=False, rotation=True, scale=False)


_STARTED: dict = {}  # this process's Blender: the bpy module, once the extension is installed


def start_blender(job: dict):
    """The bpy module of this process with the extension installed from ``job["zip"]`` in the user folder
    ``job["user_dir"]`` (made, and removed again, by the batch): done on the first file, kept after."""
    if "bpy" not in _STARTED:
        user_dir = Path(job["user_dir"])
        os.environ["BLENDER_USER_RESOURCES"] = str(user_dir / "user")  # keep the user's own Blender untouched
        # Blender's own temporary folder (blender_*) inside the user folder too, so that a worker killed at a
        # timeout or an interrupt leaves nothing behind when the batch removes that folder
        scratch = user_dir / "tmp"
        scratch.mkdir(parents=True, exist_ok=True)
        os.environ["TMPDIR"] = str(scratch)
        tempfile.tempdir = None  # read again from TMPDIR
        # a parent that imported bpy passes on Blender's scripts/modules in sys.path, whose pure-Python
        # bpy package would shadow the bpy module itself
        sys.path[:] = [p for p in sys.path if not (Path(p or ".") / "bpy" / "__init__.py").is_file()]
        sys.path.insert(0, str(REPO))
        import bpy

        bpy.ops.wm.read_factory_settings(use_empty=True)
        install_extension(bpy, job["zip"], user_dir)
        _STARTED["bpy"] = bpy
    return _STARTED["bpy"]


@contextlib.contextmanager
def output_to(log: Path | None):
    """Blender prints from C as well as Python: with ``log``, the process's stdout and stderr descriptors
    go to that file for the length of the block."""
    if log is None:
        yield
        return
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_APPEND)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    try:
        yield
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        os.close(saved[0])
        os.close(saved[1])


def process_file(job: dict) -> dict:
    """Worker entry point: process one file in this process (Blender started on its first file); never raises."""
    start = time.perf_counter()
    result = {"file": job["display"], "status": "failed", "output": "", "reason": "", "notes": []}
    log = None if job["verbose"] else Path(job["user_dir"]) / "blender.log"
    with output_to(log):
        try:
            bpy = start_blender(job)
            bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)  # nothing of the last file stays
            prefs = bpy.context.preferences.addons[ADDON].preferences
            prefs.model_folder, prefs.denoise_model_folder = job["model"], job["denoise_model"]
            notes = run_file(bpy, job)
            result.update(status="ok", output=job["shown_output"], notes=notes)
        except BatchError as e:
            result["reason"] = str(e)
        except Exception as e:  # an unexpected failure: still one line, with where it happened
            frame = traceback.extract_tb(e.__traceback__)[-1]
            where = f"{Path(frame.filename).name}:{frame.lineno}"
            result["reason"] = f"{type(e).__name__}: {e} ({where})".replace("\n", " ")
    result["seconds"] = time.perf_counter() - start
    return result
