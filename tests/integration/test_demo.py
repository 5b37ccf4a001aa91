"""The README's main demo, end to end, on a tiny untrained model (no shipped model needed)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from model_core.io.bvh import read_bvh
from model_core.io.checkpoint import save_release
from model_core.model.dataset import Normaliser
from model_core.motion.features import positions_to_features
from model_core.motion.synthetic import walking_skeleton
from model_core.rig.rigs import canonical_positions

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def tiny_model(tmp_path) -> Path:
    """A release folder with random weights of a small STRNN and one seed window."""
    torch = pytest.importorskip("torch")
    from model_core.model.strnn import STRNN, STRNNConfig

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


def test_demo_writes_bvh_png_plots_and_blend(tiny_model, tmp_path, capsys):
    out = tmp_path / "out"
    argv = ["--model", str(tiny_model), "--out", str(out), "--frames", "30", "--path-frames", "25", "--renders", "2"]
    assert _demo_module().main(argv) == 0
    printed = capsys.readouterr().out
    for label, name in (("BVH", "demo.bvh"), ("PNG", "demo.png"), ("Plots", "demo_plots.png")):
        assert f"{label}: {out / name}" in printed
    assert "foot skate:" in printed and "25 frames on the figure-eight" in printed
    assert "denoise: 3 cm of jitter on every joint" in printed
    bvh = read_bvh(out / "demo.bvh")
    assert bvh.frames == 20 + 30 + 25  # the seed window, the continuation, the walk
    assert np.all(np.isfinite(canonical_positions(bvh)))
    for name in ("demo.png", "demo_plots.png"):
        assert (out / name).read_bytes().startswith(b"\x89PNG")
    if importlib.util.find_spec("bpy") is None:
        assert "note: the bpy module is not installed" in printed
    else:
        assert f"Blend: {out / 'demo.blend'}" in printed
        head = (out / "demo.blend").read_bytes()[:7]
        assert head == b"BLENDER" or head.startswith(b"\x28\xb5\x2f\xfd")  # plain, or zstd-compressed
        assert f"Render: {out / 'demo_render.png'}" in printed
        assert (out / "demo_render.png").read_bytes().startswith(b"\x89PNG")


def test_demo_walks_without_torch_and_skips_the_blend_without_bpy(tiny_model, tmp_path, capsys, monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name in ("torch", "bpy") else real(name, *a))
    out = tmp_path / "out"
    argv = ["--model", str(tiny_model), "--out", str(out), "--frames", "30", "--path-frames", "25"]
    assert _demo_module().main(argv) == 0
    printed = capsys.readouterr().out
    assert "torch is not installed" not in printed and "walk skipped" not in printed
    assert "note: the bpy module is not installed: .blend skipped" in printed
    assert read_bvh(out / "demo.bvh").frames == 20 + 30 + 25  # the seed, its continuation and the walk
    assert (out / "demo_plots.png").is_file() and not (out / "demo.blend").exists()


def test_demo_rejects_a_seed_out_of_range(tiny_model, tmp_path, capsys):
    assert _demo_module().main(["--model", str(tiny_model), "--out", str(tmp_path), "--seed", "5"]) == 2
    assert "out of range: this model ships 1 seeds" in capsys.readouterr().err


def test_default_seed_is_the_first_walk():
    from model_core.io.checkpoint import walk_seed_index as default_seed

    assert default_seed(["a/x_raise-up_active_002.bvh@24", "a/x_run_active_016.bvh@30",
                         "a/x_walk_active_008.bvh@30", "a/x_walk_normal_001.bvh@30"]) == 2
    assert default_seed(["cmu/dance/04.bvh@30"]) == 0


def test_denoise_check_halves_the_jitter_on_generated_motion():
    """On motion like the demo's (the shipped model continuing a shipped walking seed)."""
    from model_core.eval.demo_pipeline import denoise_check, seed_continuation
    from model_core.io.checkpoint import DEFAULT_MODEL, DENOISE_MODEL

    if not (DEFAULT_MODEL / "model.json").exists() or not (DENOISE_MODEL / "model.json").exists():
        pytest.skip("needs the shipped models")
    motion = seed_continuation(None, None, 200)[0]
    noisy, clean, folder = denoise_check(motion)
    assert folder == str(DENOISE_MODEL)
    assert 4.0 < noisy < 5.6  # |N(0, 3 cm I3)| has mean 4.8 cm
    assert clean < 0.6 * noisy
