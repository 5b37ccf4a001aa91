"""The gap model (Fill Gap's learnt in-betweener) in NumPy: its body terms, its sine series that leaves the
context and reaches the target exactly, the same numbers as the torch model it was trained as, any body size,
and model folders that are refused with a clear error."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch

from model_core.inference import gap_engine as ge
from model_core.inference.engine import Engine
from model_core.io.checkpoint import DEFAULT_MODEL, GAP, CheckpointError
from model_core.model.gap_training import GapNet, GapTrainConfig, positions_torch, save_gap_release
from model_core.motion.synthetic import walking_skeleton
from model_core.ops.inbetween import interpolation


def small_model(tmp_path, seed: int = 0, scale: float = 0.3) -> ge.GapModel:
    """An untrained gap model of the real code whose output layer is random, so that it moves."""
    torch.manual_seed(seed)
    cfg = GapTrainConfig(data="", width=32, blocks=2, sines=6)
    net = GapNet(cfg, np.zeros(ge.INPUTS), np.ones(ge.INPUTS), np.full(ge.TERMS, 0.05))
    with torch.no_grad():
        net.out.weight.normal_(0.0, scale)
    save_gap_release(tmp_path / f"gap{seed}", net, cfg, 0, [], None)
    return ge.GapModel.load(tmp_path / f"gap{seed}")


def test_terms_are_the_body_and_come_back_exactly():
    walk = walking_skeleton(60, radius=2.0).astype(np.float64)
    t = ge.terms(walk)
    np.testing.assert_allclose(ge.positions(t), walk, atol=1e-9)
    origin = t[30]
    rel = ge.relative(t[None], origin[None])[0]
    assert np.abs(rel[30, :3]).max() < 1e-12  # the origin frame stands at 0, facing 0
    np.testing.assert_allclose(rel[:, 3:], t[:, 3:])  # the pose in the body's frame does not move
    np.testing.assert_allclose(ge.absolute(rel[None], origin[None])[0], t, atol=1e-12)
    np.testing.assert_allclose(positions_torch(torch.as_tensor(t)).numpy(), walk, atol=1e-9)


def test_without_its_series_the_fill_is_the_interpolation_in_the_bodys_terms(tmp_path):
    model = small_model(tmp_path)
    model.weights["out_scale"] = model.weights["out_scale"] * 0.0
    walk = walking_skeleton(90, radius=3.0).astype(np.float64)
    out = model.fill(walk[:20], walk[50:51], 30)
    np.testing.assert_allclose(out, interpolation(walk[19], walk[50], 30), atol=1e-5)


def test_the_gap_leaves_the_context_and_reaches_the_target_for_any_length(tmp_path):
    """What the model adds to the interpolation is a sine series over the gap: it fades in from the context and
    out into the target, whatever the gap's length (the length is only an input)."""
    model = small_model(tmp_path)
    walk = walking_skeleton(200, radius=3.0).astype(np.float64)
    for n in (1, 5, 30, 119):
        out = model.fill(walk[:20], walk[20 + n:22 + n], n)
        assert out.shape == (n, 21, 3) and np.isfinite(out).all()
        moved = np.linalg.norm(out - interpolation(walk[19], walk[20 + n], n), axis=-1).max(1)
        assert moved.max() > 0.01  # the series moves the motion off the interpolation
        if n == 119:  # sin(k pi / 120) <= 0.16 for the 6 sines of this model
            assert max(moved[0], moved[-1]) < 0.25 * moved.max()


def test_the_series_is_zero_at_both_ends():
    for n in (1, 7, 60):
        basis = ge.sines(np.array([n]), n + 1, 16)[0]
        assert np.abs(basis[-1]).max() < 1e-12  # the frame after the gap: the target, exactly
        ends = np.sin(np.arange(1, 17) * np.pi * 0.0)
        assert np.abs(ends).max() == 0.0


def test_numpy_and_torch_give_the_same_numbers(tmp_path):
    model = small_model(tmp_path, seed=3)
    cfg = GapTrainConfig(data="", width=32, blocks=2, sines=6)
    w = model.weights
    net = GapNet(cfg, w["in_mean"], w["in_std"], w["out_scale"])
    net.load_state_dict({k: torch.as_tensor(np.asarray(v, np.float32)) for k, v in w.items()})
    x = np.random.default_rng(0).normal(size=(4, ge.INPUTS))
    with torch.no_grad():
        want = net(torch.as_tensor(x, dtype=torch.float32)).numpy()
    np.testing.assert_allclose(model.coefficients(x), want, atol=1e-5, rtol=1e-4)


def test_a_body_of_any_size_gets_the_same_motion_at_its_size(tmp_path):
    model = small_model(tmp_path)
    walk = walking_skeleton(90, radius=3.0).astype(np.float64)
    out = model.fill(walk[:20], walk[50:52], 30)
    np.testing.assert_allclose(model.fill(walk[:20] * 1.7, walk[50:52] * 1.7, 30), out * 1.7, atol=1e-4)


def test_a_damaged_or_foreign_folder_is_refused(tmp_path):
    model = small_model(tmp_path)
    folder = tmp_path / "gap0"
    doc = json.loads((folder / "model.json").read_text())
    (folder / "model.json").write_text(json.dumps({**doc, "format": "strnn-release-1"}))
    with pytest.raises(CheckpointError, match="not a gap model"):
        ge.GapModel.load(folder)
    (folder / "model.json").write_text(json.dumps({**doc, "config": {**doc["config"], "width": 64}}))
    with pytest.raises(CheckpointError, match="do not match"):
        ge.GapModel.load(folder)
    (folder / "model.json").write_text(json.dumps(doc))
    (folder / "model.safetensors").write_bytes(b"\x80\x04pickle")
    with pytest.raises(CheckpointError, match="unreadable|too short"):
        ge.GapModel.load(folder)
    assert model.k == 6


def test_the_gap_model_is_read_when_fill_gap_first_needs_it(tmp_path):
    """A release's gap model is read on first use and kept: Extend and Follow Curve neither wait for it nor fail
    on a damaged copy of it, and Fill Gap gets the damage as a CheckpointError that names the folder."""
    release = tmp_path / "release"
    release.mkdir()
    for name in ("model.json", "model.safetensors", "seeds.npz"):
        shutil.copy(DEFAULT_MODEL / name, release / name)
    shutil.copytree(DEFAULT_MODEL / GAP, release / GAP)
    engine = Engine.load(release)
    assert engine._gap is not None and not isinstance(engine._gap, ge.GapModel)  # not read yet
    assert isinstance(engine.gap, ge.GapModel) and engine.gap is engine.gap  # read once, then kept
    (release / GAP / "model.safetensors").write_bytes(b"\x80\x04pickle")
    damaged = Engine.load(release)
    assert damaged.extrapolate(damaged.seeds[0], 10).shape == (10, damaged.seeds.shape[-1])
    with pytest.raises(CheckpointError, match="gap"):
        _ = damaged.gap
    damaged.gap = None  # the STRNN alone
    assert damaged.gap is None
