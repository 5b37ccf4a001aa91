#!/usr/bin/env python3
"""Train STRNN, a baseline to score it against (--arch simlpe | residual_gru), or Fill Gap's gap model
(--arch gap), on a folder of BVH files.

Single machine:   python scripts/train.py --data DIR --out runs/NAME
Data-parallel:    torchrun --nproc_per_node N scripts/train.py --data DIR --out runs/NAME
Resume:           the same command with --resume (state in OUT/train_state.pt).
The release checkpoint (safetensors + JSON + seeds) is written to OUT/release.
A baseline's --max-minutes is its time budget: its release is written also when that ends the run.
"""

from __future__ import annotations

import argparse
import logging
import os
import shlex
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

try:
    import torch  # noqa: F401  (training is PyTorch)
except ImportError:
    sys.exit("error: training needs PyTorch: bash scripts/setup.sh installs it; with pip: strnn-motion[torch]")

from model_core.io.checkpoint import COMPANION, PURPOSES, REGULARISED, SIMLPE  # noqa: E402
from model_core.model.dataset import DataError  # noqa: E402
from model_core.model.strnn import STRNNConfig  # noqa: E402
from model_core.model.training import TrainConfig, export_state, train  # noqa: E402

ARCHS = ("strnn", "simlpe", "residual_gru", "gap")
DEFAULT_WIDTH = {"strnn": 128, "residual_gru": 512, "gap": 768}
DEFAULT_LR = {"strnn": 1e-3, "simlpe": 3e-4, "residual_gru": 1e-3, "gap": 1e-3}

VARIANTS = {
    "composite": dict(spatial=True, residual=True),  # the full model (paper: Composite)
    "spatiotemp": dict(spatial=True, residual=False),  # no residual filter (SpatioTemp)
    "temporal": dict(spatial=False, residual=False),  # no spatial network (Temporal)
    # Temporal with the residual filter (a denoiser's: with --filter-context it reads the input window)
    "temporal-filter": dict(spatial=False, residual=True),
}


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="folder of .bvh files (searched recursively)")
    p.add_argument("--out", default=TrainConfig.out, help="output folder (state, log, release)")
    p.add_argument("--arch", choices=ARCHS, default="strnn",
                   help="STRNN, a baseline: siMLPe (Guo et al. 2023) or the residual GRU (Martinez et al. "
                        "2017), or the gap model Fill Gap uses (its release goes into a release folder as gap/); "
                        "the STRNN-only options below are ignored for the others")
    p.add_argument("--variant", choices=VARIANTS, default="composite", help="architecture (paper's ablations)")
    p.add_argument("--width", type=int, default=None,
                   help="STRNN: L4 width and LSTM size (default 128, paper: 512); residual GRU: units (default 512); "
                        "gap model: width of its residual MLP (default 768)")
    p.add_argument("--blocks", type=int, default=None, help="siMLPe: temporal MLP blocks (default 48); gap model: "
                                                            "residual blocks (default 4)")
    p.add_argument("--encode-len", type=int, default=STRNNConfig.encode_len, help="context frames m")
    p.add_argument("--predict-len", type=int, default=STRNNConfig.predict_len, help="predicted frames n")
    p.add_argument("--decode-len", type=int, default=None, metavar="R",
                   help="STRNN: the backward decoder reconstructs only the context's last R frames (default: all m); "
                        "a long --encode-len then costs little more per window")
    p.add_argument("--residual-width", type=int, default=STRNNConfig.residual_width,
                   help="hidden units of the residual filter")
    p.add_argument("--dropout", type=float, default=STRNNConfig.dropout,
                   help="dropout after each spatial layer (paper: 0.1)")
    p.add_argument("--spatial-norm", choices=("batch", "none"), default=STRNNConfig.spatial_norm,
                   help="normalisation after each spatial layer: the paper's batch norm, or none (trains and "
                        "runs alike; see the model card)")
    p.add_argument("--steps", type=int, default=TrainConfig.steps, help="optimiser steps over all phases")
    p.add_argument("--recalibrate-batches", type=int, default=TrainConfig.recalibrate_batches, metavar="N",
                   help="before writing the release, recompute the batch norms' running statistics over N "
                        "training batches (with --init and --steps 0: fix a trained model's statistics)")
    p.add_argument("--phase-split", type=float, nargs=3, default=TrainConfig.phase_split,
                   metavar=("NET", "FILTER_PRETRAIN", "FILTER_FINETUNE"),
                   help="share of the steps for the spatio-temporal net, the residual filter's pre-training on "
                        "ground truth and its fine-tuning on the frozen net's output (e.g. 0 0 1 after --init: "
                        "only the filter, which starts afresh where --residual-width differs)")
    p.add_argument("--batch", type=int, default=TrainConfig.batch, help="windows per step")
    p.add_argument("--optimizer", choices=("adam", "adadelta"), default=TrainConfig.optimizer)
    p.add_argument("--lr", type=float, default=None,
                   help="learning rate (default: 1e-3; siMLPe 3e-4, the paper's)")
    p.add_argument("--weight-decay", type=float, default=TrainConfig.weight_decay,
                   help="decoupled weight decay of the optimiser (AdamW; STRNN runs)")
    p.add_argument("--smooth-weight", type=float, default=TrainConfig.smooth_weight,
                   help="weight of the long-horizon cost")
    p.add_argument("--recon-weight", type=float, default=TrainConfig.recon_weight,
                   help="weight of the reconstructed context frames against the predicted frames in the MSE")
    p.add_argument("--velocity-weight", type=float, default=TrainConfig.velocity_weight,
                   help="weight of the error of the joints' frame-to-frame motion from the context's last frame "
                        "through the prediction (0: off)")
    p.add_argument("--world-weight", type=float, default=TrainConfig.world_weight,
                   help="weight of the error (m^2) of the joints' world positions over the predicted frames, the "
                        "root's track and heading integrated as the motion is played (0: off)")
    p.add_argument("--rollout-windows", type=int, default=TrainConfig.rollout_windows,
                   help="train on contexts the model generated itself, open loop for up to this many windows "
                        "(0: off)")
    p.add_argument("--rollout-fraction", type=float, default=TrainConfig.rollout_fraction,
                   help="share of the first phase's steps that use such contexts")
    p.add_argument("--denoise-fraction", type=float, default=TrainConfig.denoise_fraction,
                   help="share of each batch whose context is re-derived from positions with noise (denoising)")
    p.add_argument("--denoise-rotation-deg", type=float, default=TrainConfig.denoise_rotation_deg,
                   help="above 0: half of those contexts get jitter of the joints' rotations instead, of a std "
                        "drawn from 0 to this many degrees")
    p.add_argument("--init", default=TrainConfig.init,
                   help="start from the weights of a train_state.pt or release folder")
    p.add_argument("--noise-start", type=float, default=TrainConfig.noise_start, help="initial input-noise std")
    p.add_argument("--seed", type=int, default=TrainConfig.seed)
    p.add_argument("--threads", type=int, default=0, help="torch CPU threads (0: torch's default)")
    p.add_argument("--cache", default=TrainConfig.cache, help="folder for cached dataset arrays")
    p.add_argument("--max-minutes", type=float, default=TrainConfig.max_minutes,
                   help="stop with a checkpoint after this long")
    p.add_argument("--checkpoint-seconds", type=float, default=TrainConfig.checkpoint_seconds,
                   help="seconds between checkpoints")
    p.add_argument("--resume", action="store_true", help="continue from OUT/train_state.pt")
    p.add_argument("--export", action="store_true",
                   help="only write OUT/release_stepN from OUT/train_state.pt (try a model mid-training)")
    p.add_argument("--purpose", choices=PURPOSES, default=TrainConfig.purpose,
                   help="recorded in the release: 'denoise' marks a model trained for Denoise alone (its "
                        "predictions are not for Extend or Follow Curve, which then refuse it)")
    p.add_argument("--offsets", action="store_true",
                   help="the frame decoder outputs offsets from the last context frame (a residual connection)")
    p.add_argument("--offset-keep", type=int, default=None, metavar="K",
                   help="with --offsets: the predicted frames from the K-th on let go of the last context frame, "
                        "linearly, to absolute frames at the window's end (no offset carried from window to window)")
    p.add_argument("--filter-context", action="store_true",
                   help="the residual filter also reads the true context frames, not only the decoded window "
                        "(with --init from a model without: it starts as that model's filter)")
    p.add_argument("--predictor-context", action="store_true",
                   help="every input of the forward predictor also gets a learnt linear map of the context's "
                        "frames less its last frame (with --init from a model without: it starts at zero)")
    p.add_argument("--temporal-skip", action="store_true",
                   help="each predicted frame also gets a learnt linear extrapolation of the context's motion "
                        "(an n x m map shared by all channels; with --init from a model without: it starts at zero)")
    p.add_argument("--decoder-skip", action="store_true",
                   help="the backward decoder also reads a learnt linear map of the encoder's state at the frame it "
                        "reconstructs (with --init from a model without: it starts at zero)")
    p.add_argument("--mirror", type=float, default=TrainConfig.mirror,
                   help="share of training windows mirrored left to right")
    p.add_argument("--proportions", type=float, default=TrainConfig.proportions, metavar="P",
                   help="body-proportion augmentation: each training window's torso and arms made longer or "
                        "shorter by factors drawn from [1-P, 1+P] (0: off; the legs keep the standard length)")
    p.add_argument("--time-warp", type=float, default=TrainConfig.time_warp, metavar="W",
                   help="time-warp augmentation: play each training window at a speed drawn log-uniformly "
                        "from [1/(1+W), 1+W] times the capture's (0: off)")
    p.add_argument("--capture-phases", action="store_true",
                   help="train on every phase of takes captured at a whole multiple of 30 fps (60 fps: frames "
                        "0, 2, 4... and 1, 3, 5...), not only on the first")
    p.add_argument("--hold-out", action="store_true",
                   help="keep the held-out groups of configs/data.toml out of training and validation")
    p.add_argument("--device", default=TrainConfig.device,
                   help="torch device to train STRNN on: cpu, cuda or cuda:N (windows are drawn on the CPU)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p.parse_args(argv)


def command_line(argv) -> str:
    return "python scripts/train.py " + " ".join(shlex.quote(a) for a in (argv or sys.argv[1:]) if a != "--export")


def baseline_run(args, argv):
    """Train a baseline (imported here: STRNN runs never load its module)."""
    from model_core.model.baseline_training import BaselineTrainConfig, train_baseline
    from model_core.model.baselines import MODELS

    if args.export or args.init or args.time_warp or args.proportions or args.capture_phases or args.device != "cpu":
        raise ValueError("--export, --init, --time-warp, --proportions, --capture-phases and --device are for "
                         "STRNN runs")
    shape = dict(encode_len=args.encode_len, predict_len=args.predict_len)
    if args.arch == "simlpe":
        shape |= {"blocks": args.blocks or 48}
    else:
        shape |= {"width": args.width or DEFAULT_WIDTH[args.arch]}
    cfg = BaselineTrainConfig(data=args.data, out=args.out, model=MODELS[args.arch][1](**shape), steps=args.steps,
                              batch=args.batch, lr=learning_rate(args), seed=args.seed, cache=args.cache,
                              max_minutes=args.max_minutes, checkpoint_seconds=args.checkpoint_seconds,
                              command=command_line(argv), mirror=args.mirror, hold_out=args.hold_out)
    return train_baseline(cfg, resume=args.resume, progress=not args.quiet)


def gap_run(args, argv):
    """Train the gap model (imported here: other runs never load its module)."""
    from model_core.model.gap_training import GapTrainConfig, train_gap

    if args.export or args.init or args.device != "cpu":
        raise ValueError("--export, --init and --device are for STRNN runs")
    cfg = GapTrainConfig(data=args.data, out=args.out, width=args.width or DEFAULT_WIDTH["gap"],
                         blocks=args.blocks or 4, steps=args.steps, batch=args.batch, lr=learning_rate(args),
                         dropout=args.dropout, capture_phases=args.capture_phases,
                         seed=args.seed, mirror=args.mirror > 0, hold_out=args.hold_out, cache=args.cache,
                         max_minutes=args.max_minutes, checkpoint_seconds=args.checkpoint_seconds,
                         command=command_line(argv))
    return train_gap(cfg, resume=args.resume)


def strnn_run(args, argv):
    if args.time_warp < 0:
        raise ValueError(f"--time-warp {args.time_warp:g}: the speed range must be 0 (off) or more, e.g. 0.25")
    device_problem = unusable_device(args.device)
    if device_problem:
        raise ValueError(f"--device {args.device}: {device_problem}")
    if not 0 <= args.proportions < 1:
        raise ValueError(f"--proportions {args.proportions:g}: the range must be from 0 (off) to below 1, e.g. 0.1")
    model = STRNNConfig(width=args.width or DEFAULT_WIDTH["strnn"], encode_len=args.encode_len,
                        predict_len=args.predict_len, decode_len=args.decode_len, residual_width=args.residual_width,
                        dropout=args.dropout,
                        offsets=args.offsets, offset_keep=args.offset_keep, spatial_norm=args.spatial_norm,
                        filter_context=args.filter_context,
                        predictor_context=args.predictor_context, temporal_skip=args.temporal_skip,
                        decoder_skip=args.decoder_skip,
                        **VARIANTS[args.variant])
    cfg = TrainConfig(data=args.data, out=args.out, model=model, steps=args.steps, batch=args.batch,
                      phase_split=tuple(args.phase_split), recalibrate_batches=args.recalibrate_batches,
                      optimizer=args.optimizer, lr=learning_rate(args), weight_decay=args.weight_decay,
                      smooth_weight=args.smooth_weight,
                      recon_weight=args.recon_weight, velocity_weight=args.velocity_weight,
                      world_weight=args.world_weight, init=args.init,
                      rollout_windows=args.rollout_windows, rollout_fraction=args.rollout_fraction,
                      denoise_fraction=args.denoise_fraction, denoise_rotation_deg=args.denoise_rotation_deg,
                      noise_start=args.noise_start, seed=args.seed, cache=args.cache, max_minutes=args.max_minutes,
                      checkpoint_seconds=args.checkpoint_seconds, purpose=args.purpose,
                      mirror=args.mirror, time_warp=args.time_warp, proportions=args.proportions,
                      capture_phases=args.capture_phases, hold_out=args.hold_out, device=args.device,
                      command=command_line(argv))
    if args.export:
        return export_state(cfg)
    release = train(cfg, resume=args.resume, progress=not args.quiet)
    if args.init and (Path(args.init) / COMPANION / "model.json").exists():
        print(f"note: {args.init} has a companion model ({COMPANION}/) that averages the first predicted window "
              f"with it; this run did not train it. Fine-tune it the same way (--init {Path(args.init) / COMPANION}) "
              f"and copy that run's release folder to {Path(release) / COMPANION}, or the new release predicts "
              "alone.", file=sys.stderr)
    if args.init and (Path(args.init) / SIMLPE / "model.json").exists():
        print(f"note: {args.init} has a siMLPe ({SIMLPE}/) that shares the first predicted window; this run did not "
              f"train it. Copy it to {Path(release) / SIMLPE} (or train one on this run's data with --arch simlpe), "
              "or the new release predicts without it.", file=sys.stderr)
    if args.init and (Path(args.init) / REGULARISED / "model.json").exists():
        print(f"note: {args.init} has a regularised model ({REGULARISED}/) that the first two windows of unfamiliar "
              f"motion lean on; this run did not train it. Fine-tune this run's release the same way with "
              f"--dropout 0.2 (--init {release}) and copy that run's release folder to {Path(release) / REGULARISED}, "
              "or Extend continues unfamiliar motion without it.", file=sys.stderr)
    return release


def unusable_device(name: str) -> str:
    """Why torch cannot train on device ``name`` here, or "" when it can."""
    import torch

    try:
        device = torch.device(name)
    except RuntimeError as e:
        return f"not a torch device ({e}); use cpu, cuda or cuda:N"
    if device.type == "cpu":
        return ""
    if device.type != "cuda":
        return "only cpu and cuda devices are supported"
    if not torch.cuda.is_available():
        return "this torch build or machine has no CUDA device; train on the CPU (--device cpu)"
    if (device.index or 0) >= torch.cuda.device_count():
        return f"this machine has {torch.cuda.device_count()} CUDA device(s)"
    return ""


def learning_rate(args) -> float:
    return DEFAULT_LR[args.arch] if args.lr is None else args.lr


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.threads:
        import torch

        torch.set_num_threads(args.threads)
    try:
        run = {"strnn": strnn_run, "gap": gap_run}.get(args.arch, baseline_run)
        release = run(args, argv)
    except (DataError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return leave(2)
    print(f"release checkpoint: {release}")
    return leave(0)


def leave(code: int) -> int:
    """``code``, for ``sys.exit``; a torchrun worker (WORLD_SIZE over 1) instead exits here, its output flushed,
    without the interpreter's teardown. Its work is written and its process group destroyed by now, but torch's
    gloo backend can abort that teardown ("terminate called without an active exception", once in about 60
    two-process runs on this project's machines), which torchrun reports as a failed run."""
    if int(os.environ.get("WORLD_SIZE", "1")) <= 1:
        return code
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":
    sys.exit(main())
