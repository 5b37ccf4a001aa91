"""The README's main demo, end to end, on a tiny untrained model (no shipped model needed)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from model_core.bvh import read_bvh
from model_core.checkpoint import save_release
from model_core.dataset import Normaliser
from model_core.features import positions_to_features
from model_core.rigs import canonical_positions
from model_core.synthetic import walking_skeleton

REPO = Path(__file__).resolve().parent.parent


@pytest.fixture
def tiny_model(tmp_path) -> Path:
    """A release folder with random weights of a small STRNN and one seed window."""
    torch = pytest.importorskip("torch")
    from model_core.model import STRNN, STRNNConfig

    torch.manual_seed(0)
    cfg = STRNNConfig(width=64, residual_width=64)
    weights = {k: v.detach().numpy() for k, v in STRNN(cfg).eval().state_dict().items() if v.dtype.is_floating_point}
    feats, _ = positions_to_features(walking_skeleton(100))
    norm = Normaliser.fit(feats)
    return save_release(tmp_path / "model", weights, cfg.to_dict(), norm.mean, norm.std, {},
                        feats[None, : cfg.encode_len], ["walk@0"])


def _demo_module():
    spec = importlib.util.spec_from_file_location("demo", REPO / "scripts" / "demo.py")
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    return demo


def test_demo_writes_bvh_and_png(tiny_model, tmp_path, capsys):
    out = tmp_path / "out"
    assert _demo_module().main(["--model", str(tiny_model), "--out", str(out), "--frames", "90"]) == 0
    printed = capsys.readouterr().out
    assert f"BVH: {out / 'demo.bvh'}" in printed and f"PNG: {out / 'demo.png'}" in printed
    bvh = read_bvh(out / "demo.bvh")
    assert bvh.frames == 20 + 90  # the seed window, then the generated frames
    assert np.all(np.isfinite(canonical_positions(bvh)))
    assert (out / "demo.png").read_bytes().startswith(b"\x89PNG")


def test_demo_rejects_a_seed_out_of_range(tiny_model, tmp_path, capsys):
    assert _demo_module().main(["--model", str(tiny_model), "--out", str(tmp_path), "--seed", "5"]) == 2
    assert "out of range: this model ships 1 seeds" in capsys.readouterr().err
