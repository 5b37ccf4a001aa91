#!/usr/bin/env python3
"""Curve-synthesis speed: generated frames per second for a 1,000-frame path (a circle of
radius 2 m) with Follow Curve's NumPy follower and with the paper's run-time control (predict,
fine-tune a copy with torch, restore), beside plain open-loop generation with the NumPy and torch
engines, all in the same run; the NumPy rows also with every window through the backward decoder, as
before a rollout's later windows left it out (Engine.decode_later_windows).

  python scripts/benchmark_curve.py [--model FOLDER] [--frames 1000] [--threads 1]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", default=None, help="release folder (default: the bundled model)")
    p.add_argument("--frames", type=int, default=1000, help="frames generated along the path")
    p.add_argument("--threads", type=int, default=1, help="BLAS / OpenMP / torch threads")
    return p.parse_args(argv)


def timed(fn) -> float:
    fn()  # warm up
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def main(argv=None) -> int:
    args = parse_args(argv)
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(args.threads)
    import torch

    from model_core.inference.engine import Engine
    from model_core.inference.torch_engine import TorchEngine
    from model_core.motion.features import features_to_positions
    from model_core.ops.follow import PathFollower, follow_path
    from model_core.ops.follow_torch import TorchPathFollower
    from model_core.ops.paths import Path as CurvePath, evaluation_paths

    torch.set_num_threads(args.threads)
    follower, tuned = PathFollower.load(args.model), TorchPathFollower.load(args.model)
    engine, torch_engine = Engine.load(args.model), TorchEngine.load(args.model)
    walk = next((i for i, n in enumerate(engine.ckpt.seed_names) if "walk" in n), 0)
    seed_feats = engine.seeds[walk]
    seed = features_to_positions(seed_feats)
    points, cyclic = evaluation_paths()["circle"]
    path = CurvePath(points, cyclic)
    decoded, decoded_engine = PathFollower.load(args.model), Engine.load(args.model)
    decoded.engine.decode_later_windows = decoded_engine.decode_later_windows = True  # every window, as before
    rows = [
        ("Follow Curve (NumPy)", timed(lambda: follow_path(follower, seed, path, frames=args.frames))),
        ("Follow Curve, every window decoded", timed(lambda: follow_path(decoded, seed, path, frames=args.frames))),
        ("run-time control (torch, fine-tuned)", timed(lambda: follow_path(tuned, seed, path, frames=args.frames))),
        ("open loop (torch engine)", timed(lambda: torch_engine.extrapolate(seed_feats, args.frames))),
        ("open loop (NumPy engine)", timed(lambda: engine.extrapolate(seed_feats, args.frames))),
        ("open loop (NumPy), every window decoded", timed(lambda: decoded_engine.extrapolate(seed_feats, args.frames))),
    ]
    base = rows[0][1]
    print(f"seed: {engine.ckpt.seed_names[walk]}; {args.frames} frames; {args.threads} thread(s)")
    print(f"{'':<42}{'frames/s':>10}{'x Follow Curve':>16}")
    for name, seconds in rows:
        print(f"{name:<42}{args.frames / seconds:10,.0f}{base / seconds:16.2f}")
    print("paper: 1,200 frames/s of curve synthesis on a GTX 1080")
    return 0


if __name__ == "__main__":
    sys.exit(main())
