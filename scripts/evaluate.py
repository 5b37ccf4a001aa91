#!/usr/bin/env python3
"""Evaluate an STRNN checkpoint on a folder of BVH files (metrics of DESIGN.md).

Prediction MPJPE at 80..1000 ms for STRNN, zero- and constant-velocity always, and for
baseline models (siMLPe, residual GRU, trained by train.py --arch) with --baseline-model;
long-horizon rollouts with --long-horizon FRAMES --seeds K (the model's own open loop, and Extend as it ships,
following each seed's take); denoising against the
best Butterworth filter and the noisy input with --denoise-std S [S ...]; path following
(path error, foot skate and knee pops before/after foot lock, synthesis speed) with --paths.

Example (the model card's figures):
  python scripts/evaluate.py --data data/mocap --split test --long-horizon 20000 --seeds 20 \\
      --denoise-std 3 --json out/eval.json
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matmuls: BLAS threads only spin
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from model_core.eval.evaluation import (  # noqa: E402
    evaluate_denoise,
    evaluate_long_horizon,
    evaluate_pops,
    evaluate_prediction,
    evaluate_rotation_jitter,
    select_clips,
)
from model_core.eval.extend_evaluation import evaluate_long_extend  # noqa: E402
from model_core.eval.feet_evaluation import evaluate_feet  # noqa: E402
from model_core.eval.inbetween_evaluation import evaluate_inbetween  # noqa: E402
from model_core.eval.loop_evaluation import evaluate_loops  # noqa: E402
from model_core.inference.engine import Engine  # noqa: E402
from model_core.io.bvh import BvhError  # noqa: E402
from model_core.io.checkpoint import DEFAULT_MODEL, CheckpointError, default_denoiser  # noqa: E402
from model_core.io.files import unwritable, write_json  # noqa: E402
from model_core.model.dataset import DataError, load_data_config, load_folder  # noqa: E402
from model_core.ops.extend import MEMORY_S  # noqa: E402
from model_core.rig.rigs import RigError  # noqa: E402


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="folder of .bvh files of a supported rig (searched recursively)")
    p.add_argument("--checkpoint", default=str(DEFAULT_MODEL), help="release folder (default: bundled model)")
    clips = p.add_mutually_exclusive_group()
    clips.add_argument("--split", choices=("all", "train", "validation", "test"), default="all",
                       help="which clips of the folder (the project's split rule); 'all' for a foreign folder")
    clips.add_argument("--group", choices=sorted(load_data_config()["held_out"]),
                       help="every clip of this held-out group of configs/data.toml instead of a split")
    p.add_argument("--baseline-model", action="append", default=[], metavar="FOLDER",
                   help="release folder of a baseline (train.py --arch simlpe | residual_gru), scored on "
                        "prediction beside STRNN as prediction.mpjpe_cm.<architecture> (repeatable; needs torch)")
    p.add_argument("--threads", type=int, default=0,
                   help="torch CPU threads for baseline models and path following (0: torch's default)")
    p.add_argument("--json", help="write the results as JSON here")
    p.add_argument("--long-horizon", type=int, metavar="FRAMES",
                   help="rollout length: the model's open loop from each seed, and Extend following each seed's take")
    p.add_argument("--seeds", type=int, default=20, help="number of long-horizon seeds")
    p.add_argument("--reference", help="folder of BVH files for D_1nn and speed (default: --data's clips)")
    p.add_argument("--denoise-std", type=float, nargs="+", metavar="S",
                   help="Gaussian noise std in cm (0: the clean take, to see how much Denoise changes it)")
    p.add_argument("--denoise-rot", type=float, nargs="+", metavar="DEG",
                   help="also score Gaussian jitter of DEG degrees on every joint's rotation channels (a BVH's or "
                        "an armature's jitter), against the best Butterworth")
    p.add_argument("--denoise-pops", type=float, metavar="RATE",
                   help="also score single-frame pops of 10 to 30 cm on this fraction of joint-frames, against "
                        "the best Butterworth and the best median filter")
    p.add_argument("--inbetween", type=int, nargs="+", metavar="N",
                   help="in-betweening over gaps of N frames (e.g. 15 30 60): L2P, error at the target, foot "
                        "skate, beside linear interpolation")
    p.add_argument("--loops", action="store_true",
                   help="also Make Loop's seams: 2 s of each clip that moves over the ground made into a cycle and "
                        "played 3 times, against the seam as it is, an eased offset and a cross-fade")
    p.add_argument("--feet", action="store_true",
                   help="feet of extended motion before and after Foot Lock: skate beside the real takes', sink "
                        "below the take's floor, knees left fully straight")
    p.add_argument("--long-extend", action="store_true",
                   help="long extensions as Extend Clip makes them: each clip's first 10 s extended by 20 s, following "
                        "the clip and with the model alone; the last 5 s' speed, hops and steps against the take")
    p.add_argument("--denoise-fps", type=float, default=30.0, metavar="FPS",
                   help="denoise at this frame rate: clips captured at least this fast are read from their files at "
                        "it, the others upsampled from 30 fps by a cubic")
    p.add_argument("--denoise-checkpoint", default=None, metavar="FOLDER",
                   help="release folder that denoises (default: the bundled denoising model, which Denoise "
                        "uses, if it exists, else --checkpoint)")
    p.add_argument("--cache", default="data/cache", help="folder for cached dataset arrays ('' = none)")
    p.add_argument("--paths", action="store_true",
                   help="path following (NumPy, as Follow Curve): line, circle, S-curve and figure-eight walked by "
                        "walking seeds")
    p.add_argument("--follow-torch", action="store_true",
                   help="with --paths: follow with the paper's run-time control instead (fine-tuning; needs torch)")
    p.add_argument("--path-seeds", type=int, default=3, help="walking seeds per path")
    return p.parse_args(argv)


def print_prediction(result: dict):
    """The prediction table; the ratios are to the best of the baselines (simple ones and models) per horizon."""
    pred, rows = result["prediction"], dict(result["prediction"]["mpjpe_cm"])
    print(f"\nPrediction MPJPE (cm), {result['clips']} clips, {result['windows']} windows")
    print(f"{'horizon ms':<20}" + "".join(f"{h:>8}" for h in pred["horizons_ms"]))
    seam = rows.pop("strnn_as_extend")  # what Extend Clip delivers: the take before as its clip, the seam blend
    alone = rows.pop("strnn_as_extend_context_only", None)
    for name, row in rows.items():
        print(f"{name:<20}" + "".join(f"{v:8.2f}" for v in row))
    best = [min(v) for v in zip(*(row for name, row in rows.items() if name != "strnn"))]
    print(f"{'strnn / best base':<20}" + "".join(f"{s / b:8.2f}" for s, b in zip(rows["strnn"], best)))
    print(f"{'as Extend':<20}" + "".join(f"{v:8.2f}" for v in seam))
    print(f"{'  / best base':<20}" + "".join(f"{s / b:8.2f}" for s, b in zip(seam, best)))
    if alone is not None:
        print(f"{'  context only':<20}" + "".join(f"{v:8.2f}" for v in alone))
    print_against(pred)
    parts = pred.get("as_extend_parts")
    if parts:
        print(f"{'  take track':<20}" + "".join(f"{v:8.2f}" for v in parts["true_track_cm"]))
        print(f"{'  take pose':<20}" + "".join(f"{v:8.2f}" for v in parts["true_pose_cm"]))
        if parts["travel_ratio"] is not None:
            print(f"  as Extend, {parts['moving_windows']} windows that move: "
                  f"{parts['travel_ratio']:.2f} x the take's way in {pred['horizons_ms'][-1]} ms (median)")
        print("  (take track: the take's own hips track under Extend's pose, the pose's error alone; take pose: "
              "the take's pose on Extend's track)")


def print_against(pred: dict):
    """As Extend's gap to every other row with its interval, and at which horizons it is surely ahead or behind."""
    against, iv = pred.get("as_extend_against"), pred.get("intervals")
    if not against:
        return
    print(f"  as Extend - each row (cm), {iv['level']:.0%} interval with the {iv['takes']} takes resampled "
          f"{iv['draws']} times:")
    for name, c in against.items():
        gaps = [f"{g:+.2f} ({lo:+.2f}..{hi:+.2f})" for g, (lo, hi) in zip(c["gap_cm"], c["gap_interval_cm"])]
        ratios = [f"x{r:.2f} ({lo:.2f}..{hi:.2f})" for r, (lo, hi) in zip(c["ratio"], c["ratio_interval"])]
        print(f"    {name:<30}" + "".join(f"{cell:>24}" for cell in gaps))
        print(f"    {'':<30}" + "".join(f"{cell:>24}" for cell in ratios))
        told = {"ahead": [h for h, (_, hi) in zip(pred["horizons_ms"], c["gap_interval_cm"]) if hi < 0],
                "behind": [h for h, (lo, _) in zip(pred["horizons_ms"], c["gap_interval_cm"]) if lo > 0]}
        level = [h for h in pred["horizons_ms"] if h not in told["ahead"] + told["behind"]]
        print(f"    {'':<30}" + "; ".join(f"{word} at {', '.join(map(str, hs))} ms" for word, hs in
                                          (*told.items(), ("not told apart", level)) if hs))


def print_table(result: dict, extra: dict):
    print_prediction(result)
    if "long_horizon" in result:
        lh = result["long_horizon"]
        print(f"\nLong horizon: {lh['seeds']} seeds x {lh['frames']} frames: exploded {lh['exploded']}, "
              f"frozen {lh['frozen']} (still for 2 s or more, longer than their take ever is)")
        print_seeds(lh)
        blocks = [sum(b[i] for b in lh["d1nn_per_block"]) / len(lh["d1nn_per_block"])
                  for i in range(len(lh["d1nn_per_block"][0]))]
        print("mean D_1nn per 1000-frame block: " + " ".join(f"{d:.4f}" for d in blocks))
        ax = lh["as_extend"]
        print(f"\nAs Extend delivers it (Follow the Clip on; each seed's take, its first {MEMORY_S:g} s at most, "
              f"extended by {lh['frames']} frames): exploded {ax['exploded']}, frozen {ax['frozen']}; the clip's "
              f"last second / its take: " + " ".join(f"{v:.2f}" for v in ax["clip_end_speed_ratio"]))
        print_seeds(ax)
    if "denoise" in result:
        dn = result["denoise"]
        print(f"\nDenoising MPJPE (cm), model {extra['denoise_checkpoint']}: {dn['clips_captured_at_fps']} of "
              f"{dn['clips']} clips captured at that rate or faster, the others upsampled by a cubic")
        print(f"{'noise std cm':<20}" + "".join(f"{s:>8.1f}" for s in dn["std_cm"]))
        for name, row in dn["mpjpe_cm"].items():
            print(f"{name:<20}" + "".join(f"{v:8.2f}" for v in row))
        print(f"{'best cutoff Hz':<20}" + "".join(f"{v:8.1f}" for v in extra["butterworth_cutoff_hz"]))
        print(f"{'strnn frames/s':<20}" + "".join(f"{v:8.0f}" for v in extra["denoise_fps"]))
    if "denoise_rotation" in result:
        rot = result["denoise_rotation"]
        print(f"\nRotation jitter on every joint's channels, MPJPE (cm), model {extra['denoise_checkpoint']}")
        print(f"{'jitter degrees':<20}" + "".join(f"{s:>8.1f}" for s in rot["deg"]))
        for name, row in rot["mpjpe_cm"].items():
            print(f"{name:<20}" + "".join(f"{v:8.2f}" for v in row))
        print(f"{'best cutoff Hz':<20}" + "".join(f"{v:8.1f}" for v in extra["rotation_cutoff_hz"]))
    if "denoise_pops" in result:
        pops = result["denoise_pops"]
        cutoff, size = extra["pops_filters"]
        print(f"\nSingle-frame pops on {100 * pops['rate']:g} % of joint-frames, MPJPE (cm), model "
              f"{extra['denoise_checkpoint']}: best Butterworth at {cutoff:g} Hz, best median over {size} frames")
        for name, value in pops["mpjpe_cm"].items():
            print(f"{name:<20}{value:8.2f}")
    if "inbetween" in result:
        print_inbetween(result["inbetween"])
    if "loops" in result:
        print_loops(result["loops"])
    if "feet" in result:
        ft = result["feet"]
        print(f"\nFeet of {ft['frames']} extended frames after each of {ft['clips']} clips' first 20, before -> after "
              f"Foot Lock: skate {ft['skate_raw_cm']:.2f} -> {ft['skate_locked_cm']:.3f} cm/frame on contact frames "
              f"(real takes {ft['skate_real_cm']:.2f}), deepest sink below the take's floor {ft['sink_raw_cm']:.1f} "
              f"-> {ft['sink_locked_cm']:.1f} cm, knees left fully straight {100 * ft['straight_knees_locked']:.1f} %")
    if "long_extend" in result:
        print_long_extend(result["long_extend"])
    if "paths" in result:
        print_paths(result["paths"])


def print_long_extend(le: dict) -> None:
    print(f"\nLong extensions as Extend Clip makes them: each of {len(le['clips'])} clips' first {le['take_s']:g} s "
          f"extended by {le['extend_s']:g} s; the last {le['last_s']:g} s against the take: joint speed, both feet "
          f"off the floor (the take's), feet lead spread / the take's, following the clip | the model alone")
    for i, name in enumerate(le["clips"]):
        cells = " | ".join(f"{le[k]['speed_ratio'][i]:5.2f} {le[k]['airborne_fraction'][i]:5.2f} "
                           f"{le[k]['feet_lead_ratio'][i]:5.2f}" for k in ("follow", "alone"))
        print(f"  {cells}   take: airborne {le['take_airborne_fraction'][i]:4.2f}, feet lead "
              f"{100 * le['take_feet_lead_m'][i]:3.0f} cm  {name}")
    for k, label in (("follow", "following the clip"), ("alone", "the model alone")):
        r = le[k]
        print(f"{label}: slowed under 0.4 x {r['slowed']}, hopping {r['hopping']}, stepping {r['stepping']} of "
              f"{le['walking_takes']} walking takes")


def print_loops(lp: dict) -> None:
    """Make Loop's seams: per method, matched and forced seams."""
    print(f"\nMake Loop: {lp['stretch_s']:g} s of each clip that moves over the ground as a cycle, played "
          f"{lp['cycles']} times, blend {lp['blend_s']:g} s (foot-locked); peak joint acceleration near the seams / "
          "the take's 99th percentile (mean, worst, cycles over 1.5 x), foot skate there (cm a frame), the body's "
          "fastest turn there / the take's 99th percentile (mean, cycles over 1.5 x), foot skate over the cycle")
    for case in ("matched", "forced"):
        r = lp[case]
        print(f"{case} seam ({r['takes']} clips" + ("" if case == "matched" else ", the stretch's last frame")
              + f"; its pose {r['seam_pose_cm']:.1f} cm a joint from the first's; the takes' skate "
              f"{r['take_skate_cm']:.2f} cm a frame)")
        for name in ("none", "offset", "cross_fade", "model", "make_loop"):
            m = r[name]
            print(f"  {name:<12}{m['peak_accel_ratio_mean']:7.2f}{m['peak_accel_ratio_worst']:7.2f}"
                  f"{m['over_1_5']:5d}{m['skate_cm']:8.2f}{m['turn_rate_ratio_mean']:7.2f}{m['turn_rate_over_1_5']:5d}"
                  f"{m['skate_cycle_cm']:8.2f}")


def print_inbetween(ib: dict) -> None:
    """The in-betweening table: one column per gap length."""
    print(f"\nIn-betweening, 20 context frames, gap of N frames, the frame after it as the target "
          f"({', '.join(str(w) for w in ib['windows'])} windows)")
    print(f"{'gap frames':<28}" + "".join(f"{n:>8}" for n in ib["gap_frames"]))
    rows = [("L2P cm: strnn", ib["l2p_cm"]["strnn"]), ("  interpolation", ib["l2p_cm"]["interpolation"]),
            ("  interpolation, heading", ib["l2p_cm"]["interpolation_heading"]),
            ("  strnn / interpolation", [a / b for a, b in zip(ib["l2p_cm"]["strnn"], ib["l2p_cm"]["interpolation"])]),
            ("  strnn without the take", ib["l2p_cm"]["strnn_without_take"]),
            ("target error cm: strnn", ib["target_error_cm"]["strnn"])]
    skate = [("foot skate cm: strnn", ib["foot_skate_cm"]["strnn"]),  # fractions of a millimetre: 3 decimals
             ("  strnn, foot-locked", ib["foot_skate_cm"]["strnn_locked"]),
             ("  interpolation", ib["foot_skate_cm"]["interpolation"]), ("  real takes", ib["foot_skate_cm"]["real"])]
    share = {k: [100 * v for v in row] for k, row in ib["foot_contact_share"].items()}
    rows += [(name, row, 3) for name, row in skate]
    rows += [("contact steps %: strnn", share["strnn"]), ("  strnn, foot-locked", share["strnn_locked"]),
             ("  interpolation", share["interpolation"]), ("  real takes", share["real"])]
    for name, row, *digits in rows:
        print(f"{name:<28}" + "".join(f"{v:8.{digits[0] if digits else 2}f}" for v in row))


def print_seeds(lh: dict) -> None:
    """One line per long-horizon seed: speed against its own take and the data, grounding, drift."""
    feet = lh["feet"]
    print("per seed, over the last 1000 frames: speed / its take, speed / data mean, share of locomotion seconds "
          "with a foot on the floor, median lowest-foot height over the floor (cm), 99th-percentile sink (cm), "
          "share of frames with both feet in the air / the same in its take, slide of the feet it says are down "
          "(cm/frame), D_1nn last block / first")
    for i, name in enumerate(lh["seed_clips"]):
        print(f"  {lh['seed_take_speed_ratio'][i]:6.2f} {lh['speed_ratio_last_1000'][i]:6.2f} "
              f"{feet['touch_fraction'][i]:6.2f} {feet['floor_offset_cm'][i]:7.1f} {feet['sink_cm'][i]:6.1f} "
              f"{feet['airborne_fraction'][i]:6.2f} / {feet['take_airborne_fraction'][i]:4.2f} "
              f"{feet['skate_cm'][i]:6.2f} "
              f"{lh['d1nn_drift'][i]:6.2f}  {name}")


def run(args) -> dict:
    # every model and the output path are checked before any work
    engine = Engine.load(args.checkpoint)
    if engine.ckpt.purpose == "denoise":
        raise CheckpointError(f"{args.checkpoint} is a denoise-only model, which cannot be scored on prediction: "
                              f"pass it as --denoise-checkpoint (with --denoise-std) and leave --checkpoint "
                              f"at a generating model")
    denoiser, denoise_folder = None, None
    if args.denoise_std or args.denoise_pops or args.denoise_rot:
        denoise_folder = args.denoise_checkpoint or default_denoiser(args.checkpoint)
        denoiser = Engine.load(denoise_folder)
    baselines = load_baselines(args)
    if args.json:
        reason = "it is a folder" if Path(args.json).is_dir() else unwritable(Path(args.json).parent)
        if reason:
            raise ValueError(f"--json {args.json}: cannot write there ({reason}); choose another path")
    data = load_folder(args.data, cache_dir=args.cache or None)
    for failure in data.failures:
        print(f"skipped: {failure}", file=sys.stderr)
    clips = select_clips(data, args.split, args.group)
    print(f"evaluating {args.checkpoint} on {len(clips)} clips of {args.data} ({args.group or args.split})",
          file=sys.stderr)
    pred = evaluate_prediction(engine, clips, {name: b for name, (b, _) in baselines.items()})
    result = {"checkpoint": str(args.checkpoint), "data": str(args.data), "clips": len(clips),
              "windows": pred.pop("windows"), "prediction": pred}
    result |= {"group": args.group} if args.group else {}
    result |= {"baseline_models": {name: folder for name, (_, folder) in baselines.items()}} if baselines else {}
    extra = {}
    if args.long_horizon:
        reference = select_clips(load_folder(args.reference, cache_dir=args.cache or None), "all") \
            if args.reference else None
        lh = evaluate_long_horizon(engine, clips, args.long_horizon, args.seeds, reference,
                                   log=lambda m: print(m, file=sys.stderr))
        result["long_horizon"] = lh
    if denoiser is not None:
        extra["denoise_checkpoint"] = f"{denoise_folder} at {args.denoise_fps:g} fps"
    if args.denoise_std:
        dn = evaluate_denoise(denoiser, clips, args.denoise_std, fps=args.denoise_fps, root=args.data)
        extra["butterworth_cutoff_hz"] = dn.pop("butterworth_cutoff_hz")
        extra["denoise_fps"] = dn.pop("strnn_frames_per_s")
        result["denoise"] = dn
    if args.denoise_rot:
        rot = evaluate_rotation_jitter(denoiser, clips, args.denoise_rot, fps=args.denoise_fps, root=args.data)
        extra["rotation_cutoff_hz"] = rot.pop("butterworth_cutoff_hz")
        rot.pop("strnn_frames_per_s")
        result["denoise_rotation"] = rot
    if args.denoise_pops:
        pops = evaluate_pops(denoiser, clips, args.denoise_pops, fps=args.denoise_fps, root=args.data)
        extra["pops_filters"] = (pops.pop("butterworth_cutoff_hz")[0], pops.pop("median_frames")[0])
        pops.pop("strnn_frames_per_s")
        result["denoise_pops"] = pops
    if args.inbetween:
        result["inbetween"] = evaluate_inbetween(engine, clips, args.inbetween)
    if args.loops:
        result["loops"] = evaluate_loops(engine, clips)
    if args.feet:
        result["feet"] = evaluate_feet(engine, clips)
    if args.long_extend:
        result["long_extend"] = evaluate_long_extend(engine, clips)
    if args.paths:
        result["paths"] = run_paths(args, clips)
    print_table(result, extra)
    return result


def load_baselines(args) -> dict:
    """``{architecture: (engine, folder)}`` of the --baseline-model folders (torch imported only for them)."""
    if not args.baseline_model:
        return {}
    from model_core.model.baselines import BaselineEngine

    out = {}
    for folder in args.baseline_model:
        engine = BaselineEngine.load(folder)
        if engine.name in out:
            raise ValueError(f"two --baseline-model folders hold a {engine.name} model ({out[engine.name][1]}, "
                             f"{folder}): score one per architecture at a time")
        out[engine.name] = (engine, str(folder))
    return out


def run_paths(args, clips) -> dict:
    from model_core.eval.path_evaluation import evaluate_paths, synthesis_speed, walking_seeds
    if args.follow_torch:
        from model_core.ops.follow_torch import TorchPathFollower as follower_class
    else:
        from model_core.ops.follow import PathFollower as follower_class
    follower = follower_class.load(args.checkpoint)
    paths = evaluate_paths(follower, clips, args.path_seeds, log=lambda m: print(m, file=sys.stderr))
    paths["synthesis_fps_1000"] = synthesis_speed(follower, walking_seeds(clips, 1)[0][1])
    return paths


def print_paths(pt: dict) -> None:
    print(f"\nPath following ({len(pt['seed_clips'])} walking seeds; skate on detected contact frames)")
    print(f"{'path':<14}{'mean cm':>9}{'max cm':>9}{'skate raw':>11}{'locked':>8}{'bone err':>10}{'pops raw':>10}"
          f"{'locked':>8}{'speed':>7}{'reached':>9}")
    for i, name in enumerate(pt["names"]):
        print(f"{name:<14}{pt['mean_cm'][i]:9.1f}{pt['max_cm'][i]:9.1f}{pt['foot_skate_cm']['raw'][i]:11.2f}"
              f"{pt['foot_skate_cm']['locked'][i]:8.2f}{pt['bone_error'][i]:10.4f}{pt['knee_pops']['raw'][i]:10d}"
              f"{pt['knee_pops']['locked'][i]:8d}{pt['speed_ratio'][i]:7.2f}{pt['end_reached'][i]:9.2f}")
    print("speed: the walk's mean ground speed / its seed's; reached: share of the path walked (1 = its end)")
    claimed = pt["foot_skate_model_contacts_cm"]
    print("skate on the model's own contact channels, raw -> locked: "
          + ", ".join(f"{r:.2f} -> {k:.2f}" for r, k in zip(claimed["raw"], claimed["locked"])))
    print(f"curve synthesis: {pt['synthesis_fps_1000']:.0f} frames/s for a 1000-frame path")


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.threads:
        import torch

        torch.set_num_threads(args.threads)
    try:
        result = run(args)
    except (BvhError, RigError, DataError, CheckpointError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(f"\nwrote {write_json(args.json, result)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
