#!/usr/bin/env python3
"""Benchmark open-loop extrapolation: generated frames per second of the NumPy and the torch
engine at batch 1 and 64, beside this machine's SGEMM GFLOP/s and memory bandwidth and the
model's FLOPs and weight bytes per generated frame, each as a share of its roofline bound. The
baseline in the same run, ``numpy-decoded``, is the NumPy engine running every window through the
backward decoder, as it did before later windows left it out (Engine.decode_later_windows): the
report gives the NumPy engine's frames/s as a ratio of it.

    python scripts/benchmark_core.py                      # bundled model, 1 BLAS thread
    python scripts/benchmark_core.py --model runs/default/release --frames 4000 --json out/bench.json

BLAS and OpenMP threads are set (--threads, default 1) before NumPy is imported: on a busy
machine spinning BLAS threads make every timing many times worse.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
ENGINES = ("numpy", "numpy-decoded", "torch")


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--model", type=Path, default=None,
                   help="release folder (default: models/strnn_default, else the newest runs/*/release)")
    p.add_argument("--frames", type=int, default=1000, help="frames generated per sequence and call")
    p.add_argument("--batches", type=int, nargs="+", default=[1, 64], help="sequences generated together")
    p.add_argument("--repeats", type=int, default=3, help="timed calls per engine and batch (best is kept)")
    p.add_argument("--threads", type=int, default=1, help="BLAS / OpenMP / torch threads")
    p.add_argument("--engines", nargs="+", choices=ENGINES, default=list(ENGINES),
                   help="numpy-decoded: the NumPy engine with every window through the backward decoder (the "
                        "baseline the NumPy engine's ratio is given against)")
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
    if kind.startswith("numpy"):
        from model_core.inference.engine import Engine

        engine = Engine.load(folder)
        engine.decode_later_windows = kind == "numpy-decoded"
        return engine
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
    readings = 2 if Engine.mirrored_reading else 1
    costs = {decoded: model_costs(ckpt.weights, ckpt.config, readings, decoded) for decoded in (False, True)}
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
            cost = costs[kind == "numpy-decoded"]
            r.update(engine=kind, **roofline(r["fps_best"], batch, cost, mach["sgemm_gflops"], mach["bandwidth_gbs"]))
            results.append(r)
            print(f"  {kind:13s} batch {batch:3d}: {r['fps_best']:9,.0f} frames/s", flush=True)
    fps = {(r["engine"], r["batch"]): r["fps_best"] for r in results}
    ratios = [{"batch": b, "ratio": fps["numpy", b] / fps["numpy-decoded", b]} for b in args.batches
              if ("numpy", b) in fps and ("numpy-decoded", b) in fps]
    return {"model": str(folder), "config": ckpt.config, "costs": costs[False], "costs_decoded": costs[True],
            "machine": mach, "results": results, "ratios": ratios}


def report(res: dict) -> str:
    m, c = res["machine"], res["costs"]
    cfg = res["config"]
    lines = [
        f"Model   {res['model']}  (width {cfg['width']}, m={cfg['encode_len']}, n={cfg['predict_len']}, "
        f"spatial={cfg['spatial']}, residual={cfg['residual']}; {c['weight_bytes_total'] / 1e6:.1f} MB of weights)",
        f"        {c['flops_per_frame'] / 1e6:.2f} MFLOP and {c['weight_bytes_per_frame'] / 1e6:.2f} MB of weight "
        f"reads per generated frame (batch 1; the context read {c['readings']} x: as it is and mirrored; a later "
        f"window, the predictor alone; numpy-decoded: {res['costs_decoded']['weight_bytes_per_frame'] / 1e6:.2f} MB)",
        f"Machine {m['cpu']}, {m['cores']} cores, {m['threads']} BLAS thread(s): "
        f"SGEMM {m['sgemm_gflops']:.1f} GFLOP/s, memory copy {m['bandwidth_gbs']:.1f} GB/s",
        f"        (a batch-1 matmul streams the largest weight matrix at {m['gemv_stream_gbs']:.1f} GB/s)",
        "",
        f"{'engine':14s}{'batch':>6s}{'frames/s':>11s}{'median':>11s}{'compute bound':>15s}{'%':>7s}"
        f"{'bandwidth bound':>17s}{'%':>7s}{'% roofline':>12s}",
    ]
    for r in res["results"]:
        lines.append(f"{r['engine']:14s}{r['batch']:6d}{r['fps_best']:11,.0f}{r['fps_median']:11,.0f}"
                     f"{r['compute_bound_fps']:15,.0f}{r['pct_of_compute_bound']:6.1f}%"
                     f"{r['bandwidth_bound_fps']:17,.0f}{r['pct_of_bandwidth_bound']:6.1f}%"
                     f"{r['pct_of_roofline']:11.1f}%")
    lines.append("frames/s: best of the timed calls (median beside it); bounds: GFLOP/s / FLOPs per frame and "
                 "batch x bandwidth / weight bytes per frame; % roofline: of the smaller bound.")
    for r in res.get("ratios", []):
        lines.append(f"numpy against numpy-decoded (every window through the backward decoder) at batch "
                     f"{r['batch']}: {r['ratio']:.2f} x the frames/s")
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
        from model_core.io.files import write_json

        print(f"wrote {write_json(args.json, res)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
