#!/usr/bin/env python3
"""Generate a long motion with the shipped STRNN model, no input file needed.

Takes a 20-frame seed window shipped with the model (models/strnn_default/seeds.npz),
extrapolates it open-loop with the NumPy engine, and writes a BVH file (open it in
Blender: File > Import > Motion Capture (.bvh)) and a PNG contact sheet into --out.

    python scripts/demo.py                     # 600 frames from seed 0 into out/
    python scripts/demo.py --frames 3000 --seed 3 --out out/long
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np

from model_core.bvh_export import write_bvh
from model_core.checkpoint import CheckpointError
from model_core.conventions import MODEL_FPS
from model_core.features import features_to_positions
from model_core.plots import contact_sheet


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--frames", type=int, default=600, help="frames to generate after the seed (30 fps)")
    p.add_argument("--seed", type=int, default=0, help="index of the shipped seed window to start from")
    p.add_argument("--model", default=None, help="model folder (default: models/strnn_default)")
    p.add_argument("--out", default="out", help="output folder for demo.bvh and demo.png")
    p.add_argument("--panels", type=int, default=12, help="stick figures on the contact sheet")
    return p.parse_args(argv)


def generate(model: str | None, seed_index: int, frames: int) -> tuple[np.ndarray, str]:
    """Seed + generated motion as canonical positions ``float32 [m + frames, 21, 3]`` (metres, Y-up),
    and the seed's name. Raises ``CheckpointError`` / ``ValueError`` with a readable message."""
    from model_core.engine import Engine  # the inference engine needs only NumPy

    eng = Engine.load(model)
    seeds = eng.seeds
    if len(seeds) == 0:
        raise CheckpointError("the model folder ships no seed windows (seeds.npz)")
    if not 0 <= seed_index < len(seeds):
        raise ValueError(f"--seed {seed_index} is out of range: this model ships {len(seeds)} seeds, "
                         f"0 to {len(seeds) - 1}")
    seed = seeds[seed_index]
    generated = eng.extrapolate(seed, frames)  # raw features [frames, C]
    feats = np.concatenate([seed, generated], axis=0)
    names = eng.ckpt.seed_names
    return features_to_positions(feats), names[seed_index] if seed_index < len(names) else f"seed {seed_index}"


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.frames < 1:
        print("error: --frames must be at least 1", file=sys.stderr)
        return 2
    started = time.perf_counter()
    try:
        positions, seed_name = generate(args.model, args.seed, args.frames)
    except (CheckpointError, ValueError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    took = time.perf_counter() - started
    if not np.all(np.isfinite(positions)):
        print("error: the model produced non-finite values; nothing written", file=sys.stderr)
        return 1
    out = Path(args.out)
    bvh = write_bvh(out / "demo.bvh", positions, fps=MODEL_FPS)
    title = f"STRNN: {args.frames} frames generated from {seed_name} ({len(positions) / MODEL_FPS:.1f} s)"
    png = contact_sheet(out / "demo.png", positions, count=args.panels, title=title)
    print(f"generated {args.frames} frames from {seed_name} in {took:.2f} s")
    print(f"BVH: {bvh}")
    print(f"PNG: {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
