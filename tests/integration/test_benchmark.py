"""The roofline cost model (counted by hand on the Temporal variant) and a smoke run of
``scripts/benchmark_core.py`` on a tiny random release."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from model_core.eval.benchmark import model_costs, roofline
from model_core.motion.conventions import LAYOUT

REPO = Path(__file__).resolve().parents[2]


def temporal_weights(c: int, w: int, window: int, r: int) -> dict:
    z = lambda *shape: np.zeros(shape, np.float32)
    weights = {"encode_frame.weight": z(w, c), "decode_frame.weight": z(c, w), "start": z(w)}
    weights.update({f"{p}.weight_{k}{s}": z(4 * w, w) for p, s in (("encoder", "_l0"), ("decoder", ""),
                                                                ("predictor", "")) for k in ("ih", "hh")})
    sizes = [(r, window * c), (r, r), (r, r), (window * c, r)]
    weights.update({f"filter.net.{2 * i}.weight": z(*s) for i, s in enumerate(sizes)})
    return weights


def test_model_costs_by_hand():
    c, w, m, n, r = 70, 16, 4, 6, 8
    costs = model_costs(temporal_weights(c, w, m + n, r), {"encode_len": m, "predict_len": n}, decoded=True)
    lstm, frame, filt = 8 * w * w, c * w, 2 * (m + n) * c * r + 2 * r * r
    macs = m * (frame + lstm) + n * (2 * lstm + 2 * 2 * frame) + filt  # max(m, n) = n steps
    assert costs["flops_per_frame"] == pytest.approx(2 * macs / n)
    entries = frame + 4 * w * w + m * 4 * w * w + n * (2 * lstm + 2 * frame) + filt
    assert costs["weight_bytes_per_frame"] == pytest.approx(4 * entries / n)
    bounds = roofline(100.0, 4, costs, gflops=10.0, bandwidth_gbs=2.0)
    assert bounds["compute_bound_fps"] == pytest.approx(10e9 / costs["flops_per_frame"])
    assert bounds["bandwidth_bound_fps"] == pytest.approx(4 * 2e9 / costs["weight_bytes_per_frame"])
    twice = model_costs(temporal_weights(c, w, m + n, r), {"encode_len": m, "predict_len": n}, readings=2,
                        decoded=True)
    assert twice["flops_per_frame"] == pytest.approx(2 * costs["flops_per_frame"])  # mirrored reading: twice
    assert twice["weight_bytes_per_frame"] == costs["weight_bytes_per_frame"]  # the work, the same weights
    # A later window as the engine runs it: the predictor alone beside the encoder, n steps of one row.
    later = model_costs(temporal_weights(c, w, m + n, r), {"encode_len": m, "predict_len": n})
    macs = m * (frame + lstm) + n * (lstm + 2 * frame) + filt
    assert later["flops_per_frame"] == pytest.approx(2 * macs / n)
    entries = frame + 4 * w * w + m * 4 * w * w + n * (lstm + 2 * frame) + filt
    assert later["weight_bytes_per_frame"] == pytest.approx(4 * entries / n)


def test_benchmark_script_smoke(tmp_path, monkeypatch):
    from releases import random_release

    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.setenv(var, "1")  # restored after the test; the script sets them
    random_release(tmp_path / "model")
    sys.path.insert(0, str(REPO / "scripts"))
    try:
        import benchmark_core
    finally:
        sys.path.remove(str(REPO / "scripts"))
    out = tmp_path / "bench.json"
    args = ["--model", str(tmp_path / "model"), "--engines", "numpy", "numpy-decoded", "--batches", "1", "2",
            "--frames", "15", "--repeats", "1", "--json", str(out)]
    assert benchmark_core.main(args) == 0
    res = json.loads(out.read_text())
    assert [(r["engine"], r["batch"]) for r in res["results"]] == \
        [("numpy", 1), ("numpy", 2), ("numpy-decoded", 1), ("numpy-decoded", 2)]
    assert [r["batch"] for r in res["ratios"]] == [1, 2] and all(r["ratio"] > 0 for r in res["ratios"])
    assert all(r["fps_best"] > 0 and r["pct_of_roofline"] > 0 for r in res["results"])
    assert res["machine"]["sgemm_gflops"] > 0 and res["costs"]["flops_per_frame"] > 0
    assert res["config"]["frame_size"] == LAYOUT.size


@pytest.mark.parametrize("operator", ["extend", "denoise"])
def test_blender_benchmark_smoke(operator):
    """scripts/benchmark_blender.py in its own process (it installs the extension into bpy)."""
    pytest.importorskip("bpy")
    import subprocess

    done = subprocess.run([sys.executable, str(REPO / "scripts" / "benchmark_blender.py"), "--operator", operator,
                           "--frames", "60", "--repeat", "1"], capture_output=True, text=True, timeout=300, cwd=REPO)
    assert done.returncode == 0, done.stderr[-2000:]
    assert f"{operator}, model:" in done.stdout and "60 bones" in done.stdout
    stages = {line.split()[0]: float(line.split()[1]) for line in done.stdout.splitlines()
              if line.strip().split(" ")[0] in ("read", "model", "solve", "write", "total")}
    assert set(stages) == {"read", "model", "solve", "write", "total"} and stages["total"] > 0
