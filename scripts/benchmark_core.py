#!/usr/bin/env python3
"""Benchmark open-loop extrapolation: generated frames per second of the NumPy and the torch
engine at batch 1 and 64, beside this machine's SGEMM GFLOP/s and memory bandwidth and the
model's FLOPs and weight bytes per generated frame, each as a share of its roofline bound.

    python scripts/benchmark_core.py                      # bundled model, 1 BLAS thread
    python scripts/benchmark_core.py --model runs/default/release --frames 4000 --json out/bench.json

BLAS and OpenMP threads are set (--threads, default 1) before NumPy is imported: on a busy
machine spinning BLAS threads make every timing many times worse.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", type=Path, default=None,
                   help="release folder (default: models/strnn_default, else the newest runs/*/release)")
    p.add_argument("--frames", type=int, default=1000, help="frames generated per sequence and call")
    p.add_argument("--batches", type=int, nargs="+", default=[1, 64], help="sequences generated together")
    p.add_argument("--repeats", type=int, default=3, help="timed calls per engine and batch (best is kept)")
    p.add_argument("--threads", type=int, default=1, help="BLAS / OpenMP / torch threads")
    p.add_argument("--engines", nargs="+", choices=("numpy", "torch"), default=["numpy", "torch"])
    p.add_argument("--device", default="cpu", help="torch device for the torch engine (cpu, cuda)")
    p.add_argument("--json", type=Path, default=None, help="also write the results here")
    return p.parse_args(argv)


def find_model(given: Path | None) -> Path:
    from model_core.io.checkpoint import DEFAULT_MODEL

    if given is not None:
        return given
    if (DEFAULT_MODEL / "model.json").exists():
        return DEFAULT_MODEL
    runs = sorted(REPO.glob("runs/*/release/model.json"), key=lambda p: p.stat().st_mtime)
    if not runs:
        sys.exit(f"error: no bundled model at {DEFAULT_MODEL} and no runs/*/release; pass --model FOLDER")
    print(f"note: no bundled model at {DEFAULT_MODEL}; using the newest training release {runs[-1].parent}")
    return runs[-1].parent


def load_engine(kind: str, folder: Path, device: str):
    if kind == "numpy":
        from model_core.inference.engine import Engine

        return Engine.load(folder)
    from model_core.inference.torch_engine import TorchEngine

    return TorchEngine.load(folder, device)


def cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine(weights: dict, threads: int) -> dict:
    import numpy as np

    from model_core.eval.benchmark import measure_bandwidth, measure_gemv, measure_sgemm

    print("measuring the machine (SGEMM, memory copy) ...", flush=True)
    return {"cpu": cpu_name(), "cores": os.cpu_count(), "threads": threads,
            "numpy": np.__version__, "sgemm_gflops": measure_sgemm(), "bandwidth_gbs": measure_bandwidth(),
            "gemv_stream_gbs": measure_gemv(weights)}


def run(args: argparse.Namespace) -> dict:
    from model_core.eval.benchmark import model_costs, roofline, time_extrapolate
    from model_core.inference.engine import Engine
    from model_core.io.checkpoint import load_release

    folder = find_model(args.model)
    ckpt = load_release(folder)
    costs = model_costs(ckpt.weights, ckpt.config, readings=2 if Engine.mirrored_reading else 1)
    mach = machine(ckpt.weights, args.threads)
    results = []
    for kind in args.engines:
        try:
            engine = load_engine(kind, folder, args.device)
        except ImportError as err:  # torch is optional
            print(f"skipping the {kind} engine: {err}")
            continue
        for batch in args.batches:
            r = time_extrapolate(engine, batch, args.frames, args.repeats)
            r.update(engine=kind, **roofline(r["fps_best"], batch, costs, mach["sgemm_gflops"], mach["bandwidth_gbs"]))
            results.append(r)
            print(f"  {kind:5s} batch {batch:3d}: {r['fps_best']:9,.0f} frames/s", flush=True)
    return {"model": str(folder), "config": ckpt.config, "costs": costs, "machine": mach, "results": results}


def report(res: dict) -> str:
    m, c = res["machine"], res["costs"]
    cfg = res["config"]
    lines = [
        f"Model   {res['model']}  (width {cfg['width']}, m={cfg['encode_len']}, n={cfg['predict_len']}, "
        f"spatial={cfg['spatial']}, residual={cfg['residual']}; {c['weight_bytes_total'] / 1e6:.1f} MB of weights)",
        f"        {c['flops_per_frame'] / 1e6:.2f} MFLOP and {c['weight_bytes_per_frame'] / 1e6:.2f} MB of weight "
        f"reads per generated frame (batch 1; the context read {c['readings']} x: as it is and mirrored)",
        f"Machine {m['cpu']}, {m['cores']} cores, {m['threads']} BLAS thread(s): "
        f"SGEMM {m['sgemm_gflops']:.1f} GFLOP/s, memory copy {m['bandwidth_gbs']:.1f} GB/s",
        f"        (a batch-1 matmul streams the largest weight matrix at {m['gemv_stream_gbs']:.1f} GB/s)",
        "",
        f"{'engine':7s}{'batch':>6s}{'frames/s':>11s}{'median':>11s}{'compute bound':>15s}{'%':>7s}"
        f"{'bandwidth bound':>17s}{'%':>7s}{'% roofline':>12s}",
    ]
    for r in res["results"]:
        lines.append(f"{r['engine']:7s}{r['batch']:6d}{r['fps_best']:11,.0f}{r['fps_median']:11,.0f}"
                     f"{r['compute_bound_fps']:15,.0f}{r['pct_of_compute_bound']:6.1f}%"
                     f"{r['bandwidth_bound_fps']:17,.0f}{r['pct_of_bandwidth_bound']:6.1f}%"
                     f"{r['pct_of_roofline']:11.1f}%")
    lines.append("frames/s: best of the timed calls (median beside it); bounds: GFLOP/s / FLOPs per frame and "
                 "batch x bandwidth / weight bytes per frame; % roofline: of the smaller bound.")
    return "\n".join(lines)


def main(argv=None) -> int:
    args = parse_args(argv)
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(args.threads)  # before NumPy (and torch) load their BLAS
    if "torch" in args.engines:
        try:
            import torch

            torch.set_num_threads(args.threads)
        except ImportError:
            pass
    res = run(args)
    print()
    print(report(res))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(res, indent=1))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
