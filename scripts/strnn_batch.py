"""Run the STRNN Motion extension headless over many BVH / FBX / glTF / USD / .blend files, one Blender (bpy) per
file.

    python scripts/strnn_batch.py extend   --frames 120 data/clips/ --out out/batch
    python scripts/strnn_batch.py denoise  --strength 0.8 a.bvh b.bvh --jobs 4
    python scripts/strnn_batch.py inbetween --gap 40 70 take.bvh --out out/filled
    python scripts/strnn_batch.py footlock data/clips/ --out out/locked
    python scripts/strnn_batch.py loop     --range 60 120 walk.bvh --no-travel
    python scripts/strnn_batch.py follow   --path figure_eight --frames 300 walk.bvh
    python scripts/strnn_batch.py transfer --target hero.blend data/clips/ --out out/hero
    python scripts/strnn_batch.py transfer --target hero.fbx takes/ --out out/hero   # FBX results
    python scripts/strnn_batch.py extend   --frames 60 game_clips/*.glb --out out/glb   # glTF in, .glb out
    python scripts/strnn_batch.py denoise  shots/*.usd --out out/usd     # USD in, USD out (its axes, units, rate)
    python scripts/strnn_batch.py inspect  library/      # what each file holds and would run on; writes nothing

Each input file runs in its own worker process (``--jobs N`` at a time) that imports the ``bpy``
module, resets to factory settings, installs and enables the built extension zip (built once
here with scripts/build_extension.py into dist/ unless dist/ is up to date, or ``--extension``),
imports the file with Blender's own BVH, FBX, glTF or USD importer (a .blend is opened), runs the extension's real
operator (strnn.extend_clip, strnn.inbetween, strnn.denoise_action, strnn.foot_lock,
strnn.make_loop, strnn.follow_curve) on the armature, and writes the result with Blender's own BVH, FBX, glTF
or USD exporter (or saves a .blend) as ``OUT/NAME.<command>.bvh`` (``.fbx``, ``.glb``, ``.usd``: the file's
armature and meshes, the new action its one take or animation; a .gltf's result is a .glb; a USD result keeps
its input's up axis, units and rate). Folders are searched recursively for *.bvh, *.fbx, *.glb, *.gltf, *.usd,
*.usda, *.usdc, *.usdz and *.blend; their sub-folders are kept under OUT. An input is never overwritten
unless ``--in-place``. ``transfer`` opens the character .blend (--target; an FBX, glTF or USD character is
imported) instead, imports each take (BVH, FBX, glTF or USD) beside its rig, runs strnn.transfer_motion from the
take onto the rig, removes what the take brought and saves a copy of the .blend (an FBX, .glb or USD file of the
character, for a character in one of those). ``--action NAME`` runs on another take of a file than the one it
plays, ``--every-action`` on each of them into one result. ``inspect`` imports each file and says what the others
would run on (the armature, its bone map and controls, its takes and their rate) or why they would refuse it,
writing nothing.

One progress line per finished file, then a summary table (file, status, seconds, and the reason a
file failed or the notes the operator's report warns of for one that did: motion unlike what the model
learnt, keys at another rate than the take's, a first window held near a clip at rest). A file
whose worker runs past ``--timeout`` seconds (default 900) is killed and reported as failed.
Exit status: 0 when every file was processed, 1 when any failed (each failure and its reason
are listed at the end), 2 for bad arguments.
"""

from __future__ import annotations

import argparse
import contextlib
import glob
import importlib.util
import multiprocessing
import multiprocessing.connection as mp_connection
import os
import shutil
import signal
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

if __package__:  # installed with pip: strnn_motion.scripts
    from .batch_worker import USD, process_file
else:  # run by path from a checkout
    from batch_worker import USD, process_file  # noqa: E402

from model_core.io.files import unwritable, write_json  # noqa: E402  (model_core never imports bpy)
from model_core.ops import options as opts  # noqa: E402

EXTENSIONS = (".bvh", ".fbx", ".glb", ".gltf", *USD, ".blend")
CHARACTERS = (".blend", ".fbx", ".glb", ".gltf", *USD)  # what --target may be
NAMED = ".bvh, .fbx, .glb, .gltf, .usd (.usda, .usdc, .usdz) or .blend"  # the inputs, as messages name them
PATHS = ("line", "circle", "s_curve", "figure_eight")
SOURCES = ("strnn_addon", "model_core", "models", "blender_manifest.toml", "__init__.py")


# --------------------------------------------------------------------------------------------
# parent side: arguments, inputs, the extension zip, the pool, the report
# --------------------------------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    common = argparse.ArgumentParser(add_help=False)
    io = common.add_argument_group("inputs and outputs")
    add_inputs(io)
    io.add_argument("--out", type=Path, default=Path("out"), metavar="DIR",
                    help="output folder (default: ./out); results are named NAME.<command>.bvh (.fbx, .glb, "
                         ".usd, .blend)")
    io.add_argument("--format", choices=("auto", "bvh", "fbx", "glb", "usd", "usda", "usdz", "blend"),
                    default="auto",
                    help="what to write: a BVH, an FBX, a binary glTF or a USD file (Blender's exporters; an FBX, "
                         ".glb or USD file with the file's meshes, the new action its one take, animation or "
                         "skeleton animation; usd binary, usda text, usdz a package) or a .blend; auto (default): "
                         "the input's own format (a .glb for a .gltf)")
    io.add_argument("--in-place", action="store_true",
                    help="overwrite each input with its result instead of writing to --out "
                         "(the output format is then the input's; not for .gltf, whose result is a .glb)")
    io.add_argument("--every-armature", action="store_true",
                    help="in a .blend, run on every armature that has an action (a crowd, a cast), as the sidebar "
                         "does with them all selected, instead of the active one alone (a USD stage's every "
                         "skeleton too); the result is a .blend, or a USD file of them all for a USD input or "
                         "--format usd (extend, inbetween, denoise, footlock, loop)")
    io.add_argument("--action", default="", metavar="NAME",
                    help="run on this action of the file's armature instead of the one it plays (a .blend's action, "
                         "an FBX's take, a glTF's animation, by name; an FBX's or glTF's first otherwise); a "
                         "file that has none of that name fails with the names it has")
    io.add_argument("--every-action", action="store_true",
                    help="run on every take of the file's armature, each in turn, into one result that holds them "
                         "all (an FBX's takes, a glTF's animations; for a .blend the action it plays and those "
                         "stashed in its muted NLA tracks): an FBX, .glb or .blend result (a BVH or a USD "
                         "skeleton holds one take), the first new action "
                         "playing and the others in muted NLA tracks")
    motion = common.add_argument_group("motion")
    motion.add_argument("--keys-per-second", type=float, default=None, metavar="FPS",
                        help="how many of each take's frames make one second of its motion, where its file says "
                             "otherwise (a 60 fps capture whose header says 120: 60); sets each armature's Keys per "
                             "Second (STRNN sidebar) before the operator runs (default: the file's own rate, or "
                             "what a .blend's armature has set)")
    add_running(common)

    parser = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0],
        epilog=__doc__.split("\n\n", 2)[2], formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("extend", parents=[common], help="continue each clip (strnn.extend_clip)",
                       description="Continue each clip by --frames frames with the motion model.")
    p.add_argument("--frames", type=int, default=opts.EXTEND_FRAMES.default, help=opts.EXTEND_FRAMES.help())
    p.add_argument("--context-frames", type=int, default=opts.CONTEXT_FRAMES.default,
                   help=opts.CONTEXT_FRAMES.help())
    p.add_argument("--from-frame", type=int, default=None, metavar="FRAME",
                   help="continue after this frame instead of the clip's last, replacing the motion after it (with "
                        "--before-start: before it, replacing the motion before it)")
    p.add_argument("--before-start", action="store_true", help=opts.BEFORE_START.help())
    p.add_argument("--no-follow-clip", dest="follow_clip", action="store_false",
                   help="the model alone: do not lean on the clip's own motion (by default the continuation does, "
                        "wherever it comes back to something the clip did)")
    foot_lock_flag(p, "extend_clip")
    ground_flag(p, "the new frames go up and down with it, their feet locked on it with --foot-lock")

    p = sub.add_parser("denoise", parents=[common], help="clean each clip (strnn.denoise_action)",
                       description="Clean each clip with the motion model.")
    p.add_argument("--strength", type=float, default=opts.STRENGTH.default, help=opts.STRENGTH.help())
    p.add_argument("--denoise-model", type=Path, default=None, metavar="DIR",
                   help="model release folder for the Denoise Model Folder preference (default: the "
                        "denoising model bundled in the zip)")
    foot_lock_flag(p, "denoise_action")

    p = sub.add_parser("inbetween", parents=[common], help="fill a gap with the model's in-between "
                       "(strnn.inbetween)", description="Fill a gap in each clip with the motion model. With --gap, "
                       "the keys of frames START to END are replaced by the model's in-between of the frames "
                       "around them; without it, the first run of frames without keys is filled.")
    p.add_argument("--gap", type=int, nargs=2, default=None, metavar=("START", "END"),
                   help="the frames to fill (their keys are replaced); default: the first gap between keys")
    p.add_argument("--no-follow-take", dest="follow_take", action="store_false",
                   help="the models alone: do not lean on the rest of the take (by default the gap does, where the "
                        "take did what the gap must elsewhere: a walk's other steps, a repeated move)")
    foot_lock_flag(p, "inbetween")

    p = sub.add_parser("footlock", parents=[common], help="pin the feet while they touch the ground "
                       "(strnn.foot_lock)", description="Pin the feet on the ground while they touch it (leg IK).")
    p.add_argument("--blend", type=float, default=opts.LOCK_BLEND.default, help=opts.LOCK_BLEND.help(" s"))
    ground_flag(p, "each heel and toe is pinned on its surface")

    p = sub.add_parser("loop", parents=[common], help="make each clip a cycle that repeats without a seam "
                       "(strnn.make_loop)", description="Make each clip (or frames START to END of it) a cycle: "
                       "from its first frame to the frame where the pose comes round again, the frames before that "
                       "made again so it flows into its start. A .blend keeps the cyclic action (Cycles modifiers); "
                       "a BVH holds the cycle's frames, its last the next cycle's first.")
    p.add_argument("--range", type=int, nargs=2, default=None, metavar=("START", "END"),
                   help="the frames to make a cycle of (default: the whole clip)")
    p.add_argument("--blend", type=float, default=opts.LOOP_BLEND.default, help=opts.LOOP_BLEND.help(" s"))
    p.add_argument("--no-match", dest="match", action="store_false",
                   help="the range's last frame starts the next cycle (by default the cycle ends where the pose comes "
                        "round to the first frame's again)")
    p.add_argument("--no-travel", dest="loop_in_place", action="store_true",
                   help="take the travel off, so the cycle repeats on the spot (In Place in Blender)")
    foot_lock_flag(p, "make_loop")

    p = sub.add_parser("follow", parents=[common], help="walk each character along a path (strnn.follow_curve)",
                       description="Make each character walk along a path with the motion model, from the "
                       "path's start (walking there first when the take ends elsewhere).")
    p.add_argument("--path", choices=PATHS, default="circle",
                   help="built-in ground path starting at the world origin heading -Y: line (10 m), circle "
                        "(radius 2 m), s_curve (8 m), figure_eight (two 2 m loops) (default: circle)")
    p.add_argument("--curve", default="",
                   help="for .blend inputs: name of a curve object in the file to follow instead of --path")
    p.add_argument("--frames", type=int, default=opts.CURVE_FRAMES.default, help=opts.CURVE_FRAMES.help())
    p.add_argument("--speed", type=float, default=opts.CURVE_SPEED.default, help=opts.CURVE_SPEED.help(" m/s"))
    foot_lock_flag(p, "follow_curve")
    ground_flag(p, "the walk goes up and down with it, feet locked on it")
    p = sub.add_parser("transfer", parents=[common], help="move each take onto a character "
                       "(strnn.transfer_motion)", description="Move the motion of each BVH, FBX, glTF or USD take "
                       "onto the rig of a character .blend, FBX, glTF or USD file (its proportions, feet on the "
                       "floor), one new action per take, saved as a copy of that .blend, or for an FBX, glTF or USD "
                       "character as a file of it in its format with the new action its take (--format: bvh, the "
                       "rig exported as BVH; fbx, glb, usd or blend).")
    p.add_argument("--target", type=Path, required=True, metavar="RIG.blend|RIG.fbx|RIG.glb|RIG.usd",
                   help="the .blend, FBX, glTF or USD file holding the character's armature (never changed; each "
                        "result is a copy)")
    p.add_argument("--rig", default="", metavar="NAME",
                   help="the armature object in --target to put the motion on (default: its active armature, "
                        "or its only one)")
    foot_lock_flag(p, "transfer_motion")
    ground_flag(p, "each take is carried up and down with it from where the character stands, feet locked on it",
                "name of a mesh, or of a collection of meshes, in --target's .blend")
    p.add_argument("--root-motion", action="store_true", help=opts.ROOT_MOTION.help())
    p = sub.add_parser("inspect", help="say what each file holds and whether the operators can take it; writes "
                       "nothing", description="Import each file as the other commands do and say, without running "
                       "an operator or writing anything, what they would run on: the armature, how its bones map "
                       "to the model's joints and which controls are keyed, its takes (frames, the rate read, how "
                       "familiar each one's motion is to the model, as Extend's report judges it), or why the "
                       "operators would refuse it (a failure, with the fix).")
    add_inputs(p)
    add_running(p, model=False)
    p.set_defaults(out=None, format="auto", in_place=False, every_armature=False, action="", every_action=False,
                   keys_per_second=None, model=None)
    return parser


def add_running(p, model: bool = True) -> None:
    """The options of how the batch runs (workers, timeout, the extension, the report), on parser ``p``."""
    run = p.add_argument_group("running")
    run.add_argument("--jobs", "-j", type=int, default=1, metavar="N",
                     help="files processed at the same time, each in its own process (default: 1)")
    run.add_argument("--timeout", type=float, default=900.0, metavar="SECONDS",
                     help="give up on a file whose worker runs longer than this; it is killed, reported "
                          "as failed and nothing is written for it (default: 900; 0: no limit)")
    run.add_argument("--extension", type=Path, default=None, metavar="ZIP",
                     help="the extension zip to install (default: dist/strnn_motion-*.zip, rebuilt with "
                          "scripts/build_extension.py when older than the sources)")
    if model:
        run.add_argument("--model", type=Path, default=None, metavar="DIR",
                         help="model release folder for the extension's Model Folder preference "
                              "(default: the model bundled in the zip)")
    run.add_argument("--report", type=Path, default=None, metavar="FILE",
                     help="also write the results as JSON for pipelines: the command, and per file its "
                          "status (ok / failed), seconds, output, reason and notes (what the operator's report "
                          "warns of)")
    run.add_argument("--verbose", "-v", action="store_true",
                     help="let Blender's own output through (default: hidden; kept in the failure reason)")


def add_inputs(p) -> None:
    p.add_argument("inputs", nargs="+", type=Path, metavar="PATH",
                   help="BVH, FBX, glTF (.glb, .gltf), USD (.usd, .usda, .usdc, .usdz) or .blend files, or "
                        "folders searched recursively for them")


def ground_flag(p, what: str, where: str = "for .blend inputs: name of a mesh, or of a collection of meshes, in "
                                            "the file") -> None:
    """``--ground MESH``: a mesh (or a collection of meshes) of a .blend the feet stand on (the operator's
    Ground)."""
    p.add_argument("--ground", default="", metavar="MESH",
                   help=f"{where} the feet stand on (stairs, a slope, terrain): {what} (default: one flat floor, "
                        "the take's own)")


def foot_lock_flag(p, operator: str) -> None:
    """``--foot-lock`` where the operator does not lock the feet by default, ``--no-foot-lock`` where it does
    (:data:`options.FOOT_LOCK`); either way ``args.foot_lock`` says what to do."""
    if opts.FOOT_LOCK[operator]:
        p.add_argument("--no-foot-lock", dest="foot_lock", action="store_false", help="do not lock the feet")
    else:
        p.add_argument("--foot-lock", action="store_true", help=opts.FOOT_LOCK_TIP.replace("Then p", "P"))


def operator_call(args) -> tuple[str, dict]:
    """The operator (``strnn.<name>``) and its keyword arguments for ``args``."""
    if args.command == "extend":
        return "extend_clip", {"frames": args.frames, "context_frames": args.context_frames,
                               "follow_clip": args.follow_clip, "foot_lock": args.foot_lock,
                               "from_current": args.from_frame is not None, "before_start": args.before_start,
                               "ground": args.ground}
    if args.command == "denoise":
        return "denoise_action", {"strength": args.strength, "foot_lock": args.foot_lock}
    if args.command == "footlock":
        return "foot_lock", {"blend": args.blend, "ground": args.ground}
    if args.command == "inbetween":
        start, end = args.gap or (1, 250)
        return "inbetween", {"use_range": args.gap is not None, "frame_start": start, "frame_end": end,
                             "follow_take": args.follow_take, "foot_lock": args.foot_lock}
    if args.command == "inspect":
        return "inspect", {}
    if args.command == "transfer":
        return "transfer_motion", {"foot_lock": args.foot_lock, "ground": args.ground, "root_motion": args.root_motion}
    if args.command == "loop":
        start, end = args.range or (1, 250)
        return "make_loop", {"use_range": args.range is not None, "frame_start": start, "frame_end": end,
                             "blend": args.blend, "match": args.match, "in_place": args.loop_in_place,
                             "foot_lock": args.foot_lock}
    return "follow_curve", {"frames": args.frames, "speed": args.speed, "foot_lock": args.foot_lock,
                            "ground": args.ground}


def check_args(parser, args) -> None:
    if args.jobs < 1:
        parser.error("--jobs must be at least 1")
    if args.timeout < 0:
        parser.error("--timeout must not be negative (0: no limit)")
    if args.command == "extend" and args.frames < 1:
        parser.error("--frames must be at least 1")
    if args.command == "denoise" and not 0.0 <= args.strength <= 1.0:
        parser.error("--strength must be between 0 and 1")
    if args.command == "inbetween" and args.gap and args.gap[1] <= args.gap[0]:
        parser.error("--gap START END needs at least 2 frames: END after START")
    if args.command == "footlock" and not 0.0 <= args.blend <= 2.0:
        parser.error("--blend must be between 0 and 2 seconds")
    if args.command == "loop" and not 0.0 <= args.blend <= opts.LOOP_BLEND.max:
        parser.error(f"--blend must be between 0 and {opts.LOOP_BLEND.max:g} seconds")
    if args.command == "loop" and args.range and args.range[1] <= args.range[0]:
        parser.error("--range START END: END must come after START")
    if args.command == "follow" and (args.frames < 0 or args.speed < 0):
        parser.error("--frames and --speed must not be negative")
    if args.command == "transfer" and (args.target.suffix.lower() not in CHARACTERS
                                       or not args.target.is_file()):
        parser.error(f"--target {args.target}: not a .blend, .fbx, .glb, .gltf or USD file")
    if args.command == "transfer" and args.in_place:
        parser.error("--in-place is not for transfer: the results go beside the takes in --out")
    if args.every_armature and args.command in ("transfer", "follow"):
        parser.error(f"--every-armature is not for {args.command}: it moves one character at a time")
    if args.every_armature and (args.action or args.every_action):
        parser.error(f"--{'action' if args.action else 'every-action'} is not for --every-armature: each character "
                     "plays its own action")
    if args.every_action and args.action:
        parser.error("--action picks one take and --every-action runs them all: give one of them")
    if args.every_armature and args.format not in ("auto", "blend") and f".{args.format}" not in USD:
        parser.error(f"--every-armature writes .blend or USD results (a {args.format.upper()} file here holds one "
                     f"armature's take): drop --format {args.format}")
    if args.keys_per_second is not None and not 0.0 < args.keys_per_second <= 1000.0:
        parser.error("--keys-per-second must be over 0 (frames a second, e.g. 60)")
    if args.extension is not None and not args.extension.is_file():
        parser.error(f"--extension {args.extension}: no such file")
    for option in ("model", "denoise_model"):
        folder = getattr(args, option, None)
        if folder is not None and not (folder / "model.json").is_file():
            parser.error(f"--{option.replace('_', '-')} {folder}: no model.json in it")


def check_writable(parser, args) -> None:
    """The output folder and the report's folder can be written (found before the first file, not after)."""
    places = [] if args.in_place or args.out is None else [("--out", args.out)]
    if args.report is not None:
        places.append(("--report", args.report.parent if str(args.report.parent) else Path(".")))
    for option, folder in places:
        if unwritable(folder):
            parser.error(f"{option} {folder}: cannot write there ({unwritable(folder)}); pick a writable folder")
    if args.report is not None and args.report.is_dir():
        parser.error(f"--report {args.report}: is a folder; give a file name")


def collect(inputs: list[Path]) -> tuple[list[tuple[Path, Path]], list[tuple[str, str]]]:
    """(file, path relative to the output folder) for each input file; problems as (name, reason)."""
    found, problems, seen = [], [], set()
    for item in inputs:
        if item.is_dir():
            files = sorted(p for p in item.rglob("*") if p.suffix.lower() in EXTENSIONS and p.is_file())
            if not files:
                problems.append((str(item), f"folder holds no {NAMED} file"))
            pairs = [(p, p.relative_to(item)) for p in files]
        elif item.is_file():
            if item.suffix.lower() not in EXTENSIONS:
                problems.append((str(item), f"not a {NAMED} file "
                                            f"({item.suffix or 'no extension'})"))
                continue
            pairs = [(item, Path(item.name))]
        else:
            problems.append((str(item), "no such file or folder"))
            continue
        for path, rel in pairs:
            if path.resolve() not in seen:
                seen.add(path.resolve())
                found.append((path, rel))
    return found, problems


def own_format(path: Path) -> str:
    """The format a file's result is written in by default: its own, a .glb for a .gltf (glTF's one-file form,
    which is written whole; a .gltf's .bin beside it could not be replaced with it at once)."""
    own = path.suffix.lower().lstrip(".")
    return "glb" if own == "gltf" else own


def output_path(path: Path, rel: Path, args) -> Path:
    if args.in_place:
        return path
    own = own_format(path)
    if args.command == "transfer":  # the character's format
        own = own_format(args.target)
    elif args.every_armature and f".{own}" not in USD:  # every character of the file, which a BVH, FBX or glTF
        own = "blend"  # result would not hold (a USD stage holds several skeletons)
    fmt = args.format if args.format != "auto" else own
    return args.out / rel.parent / f"{rel.stem}.{args.command}.{fmt}"


def newest_source_time() -> float:
    newest = 0.0
    for name in SOURCES:
        root = REPO / name
        paths = [root] if root.is_file() else root.rglob("*") if root.is_dir() else []
        for p in paths:
            if p.is_file() and "__pycache__" not in p.parts:
                newest = max(newest, p.stat().st_mtime)
    return newest


def extension_zip(given: Path | None) -> Path:
    """``given``, or dist/'s zip when newer than every source file, else a fresh build into dist/."""
    if given is not None:
        return given.resolve()
    dist = REPO / "dist"
    zips = sorted(dist.glob("strnn_motion-*.zip"), key=lambda p: p.stat().st_mtime)
    if zips and zips[-1].stat().st_mtime >= newest_source_time():
        return zips[-1]
    print("building the extension zip (scripts/build_extension.py) ...", flush=True)
    sys.path.insert(0, str(REPO / "scripts"))
    import build_extension

    return Path(build_extension.main(["--out", str(dist)])).resolve()


def progress_line(done: int, total: int, result: dict) -> str:
    width = 20
    filled = round(width * done / total)
    bar = "#" * filled + "-" * (width - filled)
    tail = (f"-> {result['output']}" if result["output"] else "") if result["status"] == "ok" else result["reason"]
    if result.get("notes"):
        tail += f"  (note: {'; '.join(result['notes'])})"
    return f"[{bar}] {done}/{total} {result['status']:6s} {result['seconds']:6.1f}s  {result['file']}  {tail}"


def summary(results: list[dict]) -> str:
    rows = [("file", "status", "seconds", "reason / note")]
    rows += [(r["file"], r["status"], f"{r['seconds']:.1f}", r["reason"] or "; ".join(r.get("notes") or []) or "-")
             for r in results]
    widths = [max(len(row[i]) for row in rows) for i in range(3)]
    lines = []
    for n, row in enumerate(rows):
        lines.append("  ".join([row[0].ljust(widths[0]), row[1].ljust(widths[1]), row[2].rjust(widths[2]), row[3]]))
        if n == 0:
            lines.append("  ".join("-" * w for w in widths) + "  ------")
    return "\n".join(lines)


class Interrupted(Exception):
    """The batch was asked to stop (Ctrl-C or SIGTERM); ``signum`` says which."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def _raise_interrupted(signum, frame):
    raise Interrupted(signum)


def _serve(conn) -> None:
    """A worker process: file after file from ``conn`` (its Blender started on the first and kept), each
    result sent back, until told to stop (None) or the batch goes away. Ctrl-C in the terminal reaches every
    process of the group: the parent alone decides, and stops the workers itself. The process ends without
    Python's teardown, which bpy can hang in."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    while True:
        try:
            job = conn.recv()
        except EOFError:
            break
        if job is None:
            break
        conn.send(process_file(job))
    conn.close()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


class _Worker:
    """A worker process with its own Blender and user folder, and the job it is on (None: idle)."""

    def __init__(self, ctx):
        self.user_dir = tempfile.mkdtemp(prefix="strnn_batch_")
        self.conn, theirs = ctx.Pipe()
        self.proc = ctx.Process(target=_serve, args=(theirs,), daemon=True)
        self.proc.start()
        theirs.close()
        self.job, self.started = None, 0.0

    def give(self, job: dict) -> None:
        job["user_dir"] = self.user_dir
        self.job, self.started = job, time.perf_counter()
        self.conn.send(job)

    def stop(self, kill: bool = False) -> None:
        """End the process (asked to, or killed), and remove its user folder."""
        if not kill and self.proc.is_alive():
            try:
                self.conn.send(None)
            except (BrokenPipeError, OSError):
                pass
            self.proc.join(timeout=10)
        if self.proc.is_alive():
            self.proc.kill()
        self.proc.join()
        self.conn.close()
        shutil.rmtree(self.user_dir, ignore_errors=True)


def _failed(file: str, reason: str, seconds: float = 0.0) -> dict:
    """The result row of a file that was not processed."""
    return {"file": file, "status": "failed", "output": "", "seconds": seconds, "reason": reason, "notes": []}


def _discard_partial(job: dict) -> None:
    """Remove what a killed worker may have left of its file: its half-written output, under the worker's temporary
    name or under the writer's own beside it (Blender's while saving a .blend, ``NAME.tmp.blend@``; USD's while
    writing a layer or a package, ``NAME.tmp.`` and six letters or digits)."""
    dst = Path(job["output"])
    tmp = dst.with_name(dst.stem + ".tmp" + dst.suffix)
    tmp.unlink(missing_ok=True)
    tmp.with_name(tmp.name + "@").unlink(missing_ok=True)
    for sibling in tmp.parent.glob(glob.escape(tmp.stem) + ".??????"):
        if sibling.suffix[1:].isalnum() and sibling.is_file():
            sibling.unlink(missing_ok=True)


BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


@contextlib.contextmanager
def one_blas_thread_per_worker():
    """Workers run side by side, one file each: their NumPy gets one BLAS thread (unless the environment
    says otherwise), since threads of small matrix products only spin against each other. Spawned workers
    inherit the environment, which is restored after."""
    before = {var: os.environ.get(var) for var in BLAS_THREADS}
    for var in BLAS_THREADS:
        os.environ.setdefault(var, "1")
    try:
        yield
    finally:
        for var, value in before.items():
            if value is None:
                os.environ.pop(var, None)
            else:
                os.environ[var] = value


def run_pool(jobs: list[dict], workers: int, report, timeout: float = 0.0) -> tuple[list[dict], int]:
    """Run ``jobs`` on at most ``workers`` worker processes, each starting Blender and installing the
    extension once and then taking file after file (from Blender's factory startup file each time).

    A file that runs past ``timeout`` seconds (0: no limit) has its worker killed and is reported as
    failed, as is one whose worker dies; a new worker takes the next file, and no other file is
    affected. On Ctrl-C or SIGTERM the workers are killed and their partial files removed, and every
    file not done is reported as interrupted. Returns (the results in job order, the signal that stopped
    the batch or 0)."""
    ctx = multiprocessing.get_context("spawn")
    pending, pool, results = list(jobs), [], {}
    try:
        with one_blas_thread_per_worker():
            _loop(ctx, pending, pool, results, workers, report, timeout)
        stopped = 0
    except (Interrupted, KeyboardInterrupt) as e:
        stopped = getattr(e, "signum", signal.SIGINT)
        now = time.perf_counter()
        for worker in pool:
            worker.stop(kill=True)
            if worker.job is not None:
                _discard_partial(worker.job)
                results[worker.job["index"]] = _failed(worker.job["display"], "interrupted while it ran; nothing "
                                                       "written for it", now - worker.started)
        pool.clear()
        for job in pending:
            results[job["index"]] = _failed(job["display"], "interrupted before it started")
    finally:
        for worker in pool:
            worker.stop()
    return [results[i] for i in sorted(results)], stopped


def _loop(ctx, pending: list, pool: list, results: dict, workers: int, report, timeout: float) -> None:
    """The body of :func:`run_pool`: hand out files, collect results, replace dead or timed-out workers."""

    def finish(worker, result, dead: bool = False):
        job = worker.job
        worker.job = None
        if dead:
            pool.remove(worker)
            worker.stop(kill=True)
            _discard_partial(job)
        results[job["index"]] = result
        report(result)

    while pending or any(w.job is not None for w in pool):
        for worker in pool:
            if worker.job is None and pending:
                worker.give(pending.pop(0))
        while pending and len(pool) < workers:
            pool.append(_Worker(ctx))
            pool[-1].give(pending.pop(0))
        busy = {w.conn: w for w in pool if w.job is not None}
        for conn in mp_connection.wait(list(busy), timeout=0.2):
            worker = busy[conn]
            try:
                finish(worker, conn.recv())
            except EOFError:  # the process died without an answer
                worker.proc.join()
                finish(worker, _failed(worker.job["display"], f"the Blender worker process crashed on this file "
                                                              f"(exit code {worker.proc.exitcode})",
                                       time.perf_counter() - worker.started), dead=True)
        now = time.perf_counter()
        for worker in [w for w in pool if w.job is not None]:
            if timeout and now - worker.started > timeout:
                finish(worker, _failed(worker.job["display"], f"timed out after {timeout:g} s (--timeout); nothing "
                                                              "written for it", now - worker.started), dead=True)


def job_of(args, op: str, kwargs: dict, path: Path, display: str, out: Path | None) -> dict:
    """A worker's job: one input file, its output (None: nothing is written) and what to run on it."""
    return {"input": str(path.resolve()), "display": display, "output": str(out.resolve()) if out else "",
            "shown_output": str(out or ""), "operator": op, "kwargs": kwargs,
            "path": getattr(args, "path", None), "curve": getattr(args, "curve", ""),
            "from_frame": getattr(args, "from_frame", None), "keys_per_second": args.keys_per_second,
            "target": str(args.target.resolve()) if getattr(args, "target", None) else "",
            "rig": getattr(args, "rig", ""),
            "model": str(args.model.resolve()) if args.model else "",
            "denoise_model": str(args.denoise_model.resolve()) if getattr(args, "denoise_model", None) else "",
            "verbose": args.verbose, "every_armature": args.every_armature,
            "action": args.action, "every_action": args.every_action}


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if importlib.util.find_spec("bpy") is None:
        parser.error("the batch runs the extension in Blender's bpy module, which is not installed: bash "
                     "scripts/setup.sh installs it; with pip: strnn-motion[blender]")
    check_args(parser, args)
    check_writable(parser, args)
    files, problems = collect(args.inputs)
    op, kwargs = operator_call(args)
    results: list[dict] = [_failed(name, reason) for name, reason in problems]
    jobs, claimed = [], {}
    inputs = {p.resolve() for p, _ in files}
    for path, rel in files:
        display = str(path)
        if args.out is None:  # inspect: nothing is written
            jobs.append(job_of(args, op, kwargs, path, display, None))
            continue
        out = output_path(path, rel, args)
        if not args.in_place and out.resolve() in inputs:
            results.append(_failed(display, f"output {out} is an input; pass --in-place to overwrite inputs"))
            continue
        if out.resolve() in claimed:
            results.append(_failed(display, f"output {out} would also be written for {claimed[out.resolve()]}"))
            continue
        claimed[out.resolve()] = display
        jobs.append(job_of(args, op, kwargs, path, display, out))
    for n, job in enumerate(jobs):
        job["index"] = n
    total = len(jobs) + len(results)
    if not total:
        parser.error("no input files")
    for n, r in enumerate(results, 1):
        print(progress_line(n, total, r), flush=True)
    start = time.perf_counter()
    stopped = 0
    if jobs:
        try:
            zip_path = extension_zip(args.extension)
        except SystemExit as e:  # build_extension reports its failures this way
            print(f"error: could not build the extension: {e}", file=sys.stderr)
            return 1
        for job in jobs:
            job["zip"] = str(zip_path)
        done = len(results)

        def report(result):
            nonlocal done
            done += 1
            print(progress_line(done, total, result), flush=True)

        order = {job["display"]: job["index"] for job in jobs}
        handlers = {sig: signal.signal(sig, _raise_interrupted) for sig in (signal.SIGINT, signal.SIGTERM)}
        try:
            processed, stopped = run_pool(jobs, min(args.jobs, len(jobs)), report, args.timeout)
        finally:
            for sig, handler in handlers.items():
                signal.signal(sig, handler)
        results += sorted(processed, key=lambda r: order.get(r["file"], 0))
    wall = time.perf_counter() - start
    failed = [r for r in results if r["status"] != "ok"]
    if args.report:
        write_json(args.report, {"command": args.command, "seconds": wall, "processed": len(results) - len(failed),
                                 "failed": len(failed), "interrupted": bool(stopped), "files": results})
    print()
    print(summary(results))
    print(f"\n{len(results) - len(failed)} of {len(results)} files processed in {wall:.1f} s "
          f"with --jobs {args.jobs}; {len(failed)} failed")
    if failed:
        print("\nfailures:", file=sys.stderr)
        for r in failed:
            print(f"  {r['file']}: {r['reason']}", file=sys.stderr)
    if stopped:
        print(f"\nstopped by {signal.Signals(stopped).name}: the files above marked interrupted were not processed",
              file=sys.stderr)
        return 128 + int(stopped)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
