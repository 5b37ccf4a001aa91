#!/usr/bin/env python3
"""Check Extend Clip as an animator meets it, on takes of your own: the real operator in Blender (bpy workers of
scripts/strnn_batch.py extend), measured on the BVH files it writes.

  cuts  each take cut part way (--at FRAME ..., scene frames counted from 1: the last frame kept; default a
        quarter, half and three quarters of the way) and extended by --seconds (0.5). How far the extension is
        from the take's own continuation at that time, beside holding the last pose: every joint of the file in
        its own units, and the 21 joints the model reads in cm on a standard body (legs 0.87 m) where the rig is
        one the project maps. A cut counts as no further than holding where its error is at most holding's.
  walk  each take extended by --frames (1200). Over the last --last seconds (5): the joints' speed about the hips
        against the clip's (a walk that still walks: 0.4 to 2.5 x), how far the feet swing past each other
        against the clip, the share of seconds that move (hips over 0.3 m/s) in which a foot comes within 3 cm of
        the clip's floor, the lowest foot's median height over that floor, the share of frames with both feet in
        the air (the clip's beside it), and the hips' speed over the ground; and at the cut, the hips' slowest step
        from the take's second-last frame over the first 0.1 s added against their step over the 5 frames before
        (under 0.5: the walk stumbles at the cut).

Examples:
  python scripts/check_extend.py cuts data/mocap/cmu/acrnn-dance/martial/*.bvh --at 600 1200 1800
  python scripts/check_extend.py walk walk_60fps.bvh --frames 1200 --json out/walk.json

The inputs are copied under --out (DIR/.../in; the extended files under DIR/.../out) and never changed. Exit
status: 0 when every take was extended and measured (whatever the figures), 1 when any failed, 2 for bad
arguments.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

if __package__:  # installed with pip: strnn_motion.scripts
    from . import strnn_batch
else:  # run by path from a checkout
    import strnn_batch

from model_core.eval.extend_evaluation import feet_lead, limb_speed
from model_core.eval.metrics import airborne_fraction, feet_report
from model_core.io.bvh import BvhError, forward_kinematics, read_bvh
from model_core.io.files import unwritable, write_json
from model_core.motion.conventions import GROUND_AXES, MODEL_FPS, ROOT, min_scene_frames
from model_core.motion.features import floor_height
from model_core.rig.rigs import RigError, canonical_clip

WALK_BAND = (0.4, 2.5)  # a walk still walks: its joints' speed about the hips against the clip's
SEAM_S = 0.1  # the hips' steps over the cut judged over the take's last step and this many seconds added
FLOOR_S = 3.0  # the clip's floor: its last seconds' (a capture's floor can drift over a long take)
MARK = ".check_extend"  # in each folder this script makes, which a later run may replace; no other folder is touched


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="check", required=True)
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("takes", nargs="+", type=Path, metavar="TAKE.bvh", help="BVH takes of a rig Blender imports")
    common.add_argument("--out", type=Path, default=Path("out/check_extend"), metavar="DIR",
                        help="where the copies and the extended files go (default: out/check_extend)")
    common.add_argument("--json", type=Path, metavar="FILE", help="also write every figure as JSON here")
    common.add_argument("--extension", type=Path, metavar="ZIP",
                        help="the built extension to install (default: built into dist/ as strnn_batch.py does)")
    common.add_argument("--keys-per-second", type=float, default=None, metavar="FPS",
                        help="the rate the takes were captured at where their files say another (passed to "
                             "strnn_batch.py; seconds here are counted at it too)")
    common.add_argument("--jobs", "-j", type=int, default=1, metavar="N", help="Blender workers at a time")
    common.add_argument("--timeout", type=float, default=900.0, metavar="S", help="seconds a take may take")
    cuts = sub.add_parser("cuts", parents=[common], help="takes cut part way and extended: against holding the pose",
                          description="Each take cut at --at frames and extended by --seconds; the extension "
                                      "against the take and against holding the last pose at that time.")
    cuts.add_argument("--at", type=int, nargs="+", metavar="FRAME",
                      help="scene frames to cut at, the last frame kept (default: 1/4, 1/2 and 3/4 of each take)")
    cuts.add_argument("--seconds", type=float, default=0.5, help="how far to extend and where to compare (0.5)")
    walk = sub.add_parser("walk", parents=[common], help="takes extended far: do they still walk at the end?",
                          description="Each take extended by --frames; its last --last seconds against the clip.")
    walk.add_argument("--frames", type=int, default=1200, help="frames to extend each take by (1200)")
    walk.add_argument("--last", type=float, default=5.0, metavar="S", help="seconds at the end to judge (5)")
    args = p.parse_args(argv)
    if args.jobs < 1:
        p.error("--jobs must be at least 1")
    if args.keys_per_second is not None and not 0.0 < args.keys_per_second <= 1000.0:
        p.error("--keys-per-second must be over 0 (frames a second, e.g. 60)")
    if args.check == "cuts" and args.seconds <= 0:
        p.error("--seconds must be over 0")
    if args.check == "walk" and (args.frames < 1 or args.last <= 0):
        p.error("--frames must be at least 1 and --last over 0")
    for take in args.takes:
        if take.suffix.lower() != ".bvh" or not take.is_file():
            p.error(f"{take}: not a BVH file")
    if args.json is not None:
        reason = "it is a folder" if args.json.is_dir() else unwritable(args.json.parent)
        if reason:
            p.error(f"--json {args.json}: cannot write there ({reason})")
    return args


# ------------------------------------------------------------------------------------------ measuring
def context_frames(fps: float) -> int:
    """Frames a take at ``fps`` needs before a cut for Extend Clip to read the model's context (the operator's
    rule, :func:`conventions.min_scene_frames`), and one to spare for how Blender rounds a file's rate."""
    return min_scene_frames(fps) + 1


def cut_frames(frames: int, at: list[int] | None, horizon: int, fps: float = MODEL_FPS) -> list[int]:
    """The cuts (scene frames from 1, the last kept) of a take of ``frames`` frames at ``fps`` that leave
    ``horizon`` frames of the take after them to compare with and the model's context before them."""
    wanted = at if at else [round(frames * q) for q in (0.25, 0.5, 0.75)]
    return sorted({int(f) for f in wanted if context_frames(fps) <= f and f + horizon <= frames})


def _canonical(path: Path) -> np.ndarray | None:
    """The file's canonical joints frame for frame (at its own rate: an exported file's Frame Time is rounded, and
    resampling it to the take's would drop a frame), None where the rig is not one the project maps."""
    try:
        bvh = read_bvh(path)
        return canonical_clip(bvh, bvh.fps)
    except (RigError, BvhError):
        return None


def measure_cut(take: Path, extended: Path, cut: int, horizon: int) -> dict:
    """The extension of ``take`` from scene frame ``cut`` (``extended``) against the take ``horizon`` frames on,
    and holding the pose of frame ``cut`` against it: every joint of the file (its units) and the canonical
    joints (cm on the standard body; None where the rig is not one the project maps). ``before``: the most any
    joint of the extended file is off the take before the cut (0 when the operator kept them)."""
    a, b = read_bvh(take), read_bvh(extended)
    if len(b.motion) < cut + horizon:
        raise BvhError(f"{extended}: {len(b.motion)} frames, fewer than the cut {cut} and {horizon} more")
    ta, tb = forward_kinematics(a)[0], forward_kinematics(b)[0]
    if ta.shape[1] != tb.shape[1]:
        raise BvhError(f"{extended}: {tb.shape[1]} joints, the take {ta.shape[1]}")
    kept, at = cut - 1, cut - 1 + horizon  # indices of the last frame kept and of the one compared
    err = lambda x, y: float(np.linalg.norm(x - y, axis=-1).mean())
    out = {"cut": cut, "extend": err(tb[at], ta[at]), "hold": err(ta[kept], ta[at]),
           "before": float(np.abs(tb[:cut] - ta[:cut]).max()), "canonical_cm": None}
    ca, cb = _canonical(take), _canonical(extended)
    if ca is not None and cb is not None:
        cb = cb - (cb[:cut] - ca[:cut]).mean((0, 1))  # each file is put on its own floor; align on the frames kept
        out["canonical_cm"] = {"extend": 100 * err(cb[at], ca[at]), "hold": 100 * err(ca[kept], ca[at])}
    return out


def measure_walk(take: Path, extended: Path, last_s: float, fps: float | None = None) -> dict:
    """The last ``last_s`` seconds of ``extended`` (``take`` extended) against the clip, on the canonical joints;
    ``fps``: the take's frames a second (default: its file's)."""
    fps = fps or read_bvh(take).fps
    clip, ext = _canonical(take), _canonical(extended)
    if clip is None or ext is None:
        raise RigError(f"{take}: its rig is not one the project maps to the model's joints; the walk check needs "
                       "its feet and hips")
    if len(ext) <= len(clip):
        raise BvhError(f"{extended}: {len(ext)} frames, no more than the take's {len(clip)}")
    ext = ext - (ext[:len(clip)] - clip).mean((0, 1))  # each file is put on its own floor; align on the clip
    last = ext[-max(2, int(round(last_s * fps))):]
    floor = floor_height(clip[-int(round(FLOOR_S * fps)):])
    feet = feet_report(last, floor, fps)
    ground = list(GROUND_AXES)
    hips = lambda p: float(np.linalg.norm(np.diff(p[:, ROOT][:, ground], axis=0), axis=-1).mean() * fps)
    ratio = lambda a, b: a / b if b > 1e-9 else float("nan")  # a clip standing stock-still has no pace to keep
    speed = ratio(limb_speed(last), limb_speed(clip))
    return {"frames": len(ext) - len(clip), "speed_ratio": speed, "seam_step_ratio": seam_step(clip, ext, fps),
            "feet_swing_ratio": ratio(feet_lead(last), feet_lead(clip)),
            "touch_fraction": feet.touch_fraction, "floor_offset_cm": feet.floor_offset_cm,
            "airborne_fraction": feet.airborne_fraction, "clip_airborne_fraction": airborne_fraction(clip, floor),
            "hips_m_per_s": hips(last), "clip_hips_m_per_s": hips(clip),
            "moves_on": bool(WALK_BAND[0] <= speed <= WALK_BAND[1]),
            "walks": bool(WALK_BAND[0] <= speed <= WALK_BAND[1] and feet.touch_fraction == 1)}


def seam_step(clip: np.ndarray, ext: np.ndarray, fps: float) -> float | None:
    """The hips' slowest step over the ground from the clip's ``[F, 21, 3]`` second-last frame over the first
    :data:`SEAM_S` seconds of ``ext`` (the clip extended) against their mean step over the 5 before (a walk that
    stumbles at the cut: under 0.5); None where those moved under 0.1 m/s or the clip is too short."""
    n, ground = len(clip), list(GROUND_AXES)
    if n < 8:
        return None
    step = np.linalg.norm(np.diff(ext[:, ROOT][:, ground], axis=0), axis=-1)
    pace = float(step[n - 7:n - 2].mean())
    if pace * fps < 0.1:
        return None
    return float(step[n - 2:n - 1 + max(1, int(round(SEAM_S * fps)))].min() / pace)


# ------------------------------------------------------------------------------------------ running
def extend(args, takes: list[Path], frames: int, from_frame: int | None, folder: Path) -> list[Path | None]:
    """Each of ``takes`` copied to ``folder``/in/NN/ and extended in Blender (:mod:`strnn_batch`, ``--jobs`` at a
    time) into ``folder``/out/NN/NAME.extend.bvh: those files, None for a take whose extension failed."""
    if folder.exists() and not (folder / MARK).is_file():
        raise FileExistsError(f"{folder} is there and was not made by check_extend.py: choose another --out")
    shutil.rmtree(folder, ignore_errors=True)  # an earlier run's own folder: none of its files is read as this one's
    folder.mkdir(parents=True)
    (folder / MARK).write_text("made by scripts/check_extend.py; it replaces this folder on its next run\n")
    for i, take in enumerate(takes):
        (folder / "in" / f"{i:02d}").mkdir(parents=True)
        shutil.copyfile(take, folder / "in" / f"{i:02d}" / take.name)
    argv = ["extend", "--frames", str(frames), "--out", str(folder / "out"), "--jobs", str(args.jobs),
            "--timeout", str(args.timeout)]
    argv += ["--from-frame", str(from_frame)] if from_frame is not None else []
    argv += ["--extension", str(args.extension)] if args.extension else []
    argv += ["--keys-per-second", str(args.keys_per_second)] if args.keys_per_second else []
    strnn_batch.main(argv + [str(folder / "in")])
    made = [folder / "out" / f"{i:02d}" / f"{take.stem}.extend.bvh" for i, take in enumerate(takes)]
    return [path if path.is_file() else None for path in made]


def run_cuts(args) -> tuple[list[dict], list[str]]:
    rows, failed, by_cut = [], [], {}
    for take in args.takes:  # --from-frame is one frame for a whole run: the takes are extended cut by cut
        bvh = read_bvh(take)
        fps = args.keys_per_second or bvh.fps
        horizon = int(round(args.seconds * fps))
        cuts = cut_frames(len(bvh.motion), args.at, horizon, fps)
        if not cuts:
            failed.append(f"{take}: no cut has the {context_frames(fps)} frames Extend reads before it and "
                          f"{horizon} of the take's {len(bvh.motion)} after it to compare with")
        for cut in cuts:
            by_cut.setdefault((cut, horizon), []).append((take, fps))
    for (cut, horizon), takes in sorted(by_cut.items()):
        made = extend(args, [t for t, _ in takes], horizon, cut, args.out / f"cut_{cut}_{horizon}")
        for (take, fps), extended in zip(takes, made):
            if extended is None:
                failed.append(f"{take} cut at {cut}: the extension failed (see above)")
                continue
            rows.append({"take": str(take), "fps": fps, "horizon_frames": horizon,
                         **measure_cut(take, extended, cut, horizon)})
    rows.sort(key=lambda r: (r["take"], r["cut"]))
    return rows, failed


def run_walk(args) -> tuple[list[dict], list[str]]:
    rows, failed = [], []
    for take, extended in zip(args.takes, extend(args, args.takes, args.frames, None, args.out / "walk")):
        if extended is None:
            failed.append(f"{take}: the extension failed (see above)")
            continue
        try:
            rows.append({"take": str(take), **measure_walk(take, extended, args.last, args.keys_per_second)})
        except (RigError, BvhError) as e:
            failed.append(str(e))
    return rows, failed


def print_cuts(rows: list[dict], seconds: float):
    print(f"\nExtended {seconds:g} s from each cut: distance from the take at that time, every joint (the file's "
          f"units) and the model's 21 (cm, standard body), beside holding the last pose")
    for r in rows:
        c = r["canonical_cm"]
        canon = f"   21 joints {c['extend']:7.2f} cm, hold {c['hold']:7.2f}" if c else ""
        mark = "no further" if r["extend"] <= r["hold"] else "further"
        print(f"  {Path(r['take']).name} cut at {r['cut']}: {r['extend']:8.3f}, hold {r['hold']:8.3f}  {mark:10s}"
              f"{canon}   (frames before the cut off by {r['before']:.3g})")
    if rows:
        ext, hold = np.array([r["extend"] for r in rows]), np.array([r["hold"] for r in rows])
        print(f"{len(rows)} cuts: no further than holding in {(ext <= hold).sum()} of {len(rows)} (every joint; mean "
              f"{ext.mean():.2f} against holding {hold.mean():.2f})", end="")
        canon = [r["canonical_cm"] for r in rows if r["canonical_cm"]]
        if canon:
            n = sum(c["extend"] <= c["hold"] for c in canon)
            print(f", {n} of {len(canon)} (the 21 joints; mean {np.mean([c['extend'] for c in canon]):.2f} cm against "
                  f"holding {np.mean([c['hold'] for c in canon]):.2f})", end="")
        print()


def print_walk(rows: list[dict], last_s: float):
    lo, hi = WALK_BAND
    print(f"\nThe last {last_s:g} s of each extension against its clip (walks: joints' speed {lo} to {hi} x the "
          f"clip's and a foot within 3 cm of the floor in every second that moves)")
    for r in rows:
        touch = "no second moves" if np.isnan(r["touch_fraction"]) else f"{r['touch_fraction']:.2f}"
        print(f"  {Path(r['take']).name} + {r['frames']}: speed {r['speed_ratio']:.2f} x, feet swing "
              f"{r['feet_swing_ratio']:.2f} x, seconds touching {touch}, lowest foot {r['floor_offset_cm']:.1f} cm "
              f"over the floor, both feet up {r['airborne_fraction']:.2f} (clip {r['clip_airborne_fraction']:.2f}), "
              f"hips {r['hips_m_per_s']:.2f} m/s (clip {r['clip_hips_m_per_s']:.2f}), "
              f"{seam_words(r.get('seam_step_ratio'))}: {verdict(r)}")


def seam_words(ratio: float | None) -> str:
    """The hips' slowest step over the cut in words (:func:`seam_step`)."""
    return "at rest at the cut" if ratio is None else f"slowest step over the cut {ratio:.2f} x the take's"


def verdict(row: dict) -> str:
    """A walk check's row in words: it walks (the joints at 0.4 to 2.5 x the clip's speed, a foot down in every second
    that moves), or why not."""
    if row["walks"]:
        return "walks"
    pace = row["speed_ratio"]
    why = [] if row["moves_on"] else ["the clip stands still" if pace is None or np.isnan(pace) else
                                      "slows down" if pace < WALK_BAND[0] else "speeds up"]
    touch = row["touch_fraction"]
    if touch is None or np.isnan(touch):
        why.append("no second moves")
    elif touch < 1:
        why.append(f"a foot down in {touch:.0%} of the seconds that move")
    return f"does not walk ({'; '.join(why)})"


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    try:
        if args.check == "cuts":
            rows, failed = run_cuts(args)
            print_cuts(rows, args.seconds)
        else:
            rows, failed = run_walk(args)
            print_walk(rows, args.last)
    except FileExistsError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    for f in failed:
        print(f"failed: {f}", file=sys.stderr)
    if args.json is not None:
        doc = {"check": args.check, "rows": rows, "failed": failed}
        doc |= {"seconds": args.seconds} if args.check == "cuts" else {"frames": args.frames, "last_s": args.last}
        print(f"wrote {write_json(args.json, doc)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
