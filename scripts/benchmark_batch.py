#!/usr/bin/env python3
"""Batch throughput: `strnn_batch.py extend --frames 120 --jobs 2` over 1 short take and over 20, in
the same run, with the ratio of the two times (the workers start Blender and install the extension
once each, then take file after file, so 20 files should cost far less than 20 times one).

The takes are 90-frame procedural walks written as BVH (nothing to download); the extension zip is
built once beforehand and its build is not timed.

  python scripts/benchmark_batch.py [--files 20] [--jobs 2] [--frames 120]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import strnn_batch  # noqa: E402  (scripts/ is on sys.path when run by path)

from model_core.io.bvh_export import write_bvh  # noqa: E402
from model_core.motion.synthetic import walking_skeleton  # noqa: E402


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--files", type=int, default=20, help="takes in the large batch (default 20)")
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    p.add_argument("--frames", type=int, default=120, help="frames Extend adds to each take (default 120)")
    return p.parse_args(argv)


def batch_seconds(takes: list[Path], out: Path, zip_path: Path, jobs: int, frames: int) -> float:
    """Wall time of one batch run over ``takes`` (its own output is kept quiet)."""
    argv = ["extend", "--frames", str(frames), "--jobs", str(jobs), *map(str, takes), "--out", str(out),
            "--extension", str(zip_path)]
    started = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()):
        code = strnn_batch.main(argv)
    seconds = time.perf_counter() - started
    if code != 0:
        raise SystemExit(f"the batch failed (exit {code}) on {len(takes)} file(s)")
    return seconds


def main(argv=None) -> int:
    args = parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="strnn_bench_batch_") as tmp:
        root = Path(tmp)
        takes = [write_bvh(root / "takes" / f"walk{i:02d}.bvh", walking_skeleton(90, cadence=0.8 + 0.02 * i))
                 for i in range(args.files)]
        zip_path = strnn_batch.extension_zip(None)
        one = batch_seconds(takes[:1], root / "out1", zip_path, args.jobs, args.frames)
        many = batch_seconds(takes, root / "outN", zip_path, args.jobs, args.frames)
    print(f"strnn_batch.py extend --frames {args.frames} --jobs {args.jobs} (90-frame takes)")
    print(f"{'files':>6}{'seconds':>10}{'per file':>10}")
    print(f"{1:>6}{one:10.1f}{one:10.2f}")
    print(f"{args.files:>6}{many:10.1f}{many / args.files:10.2f}")
    print(f"{args.files} files / 1 file: {many / one:.2f} x the time")
    return 0


if __name__ == "__main__":
    sys.exit(main())
