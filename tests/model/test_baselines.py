"""The baselines (siMLPe, residual GRU): the models, their training through scripts/train.py,
their release folders, the engine that evaluate.py runs them with, and the STRNN engines'
refusal of those folders."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from model_core.inference.engine import Engine  # noqa: E402
from model_core.inference.torch_engine import TorchEngine  # noqa: E402
from model_core.io.checkpoint import DEFAULT_MODEL, CheckpointError  # noqa: E402
from model_core.model.baseline_training import BaselineTrainConfig, lr_scale, train_baseline  # noqa: E402
from model_core.model.baselines import (  # noqa: E402
    MODELS,
    BaselineEngine,
    ResidualGRU,
    ResidualGRUConfig,
    SiMLPe,
    SiMLPeConfig,
    dct_matrix,
)
from model_core.motion.conventions import LAYOUT  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "scripts"))

import train as train_script  # noqa: E402

C = LAYOUT.size
TINY = {"simlpe": ["--blocks", "2"], "residual_gru": ["--width", "16"]}


def test_dct_is_orthonormal():
    d = dct_matrix(20)  # the NumPy engine's (inference/simlpe_engine.py), which the torch siMLPe takes as a buffer
    np.testing.assert_allclose(d @ d.T, np.eye(20), atol=1e-5, rtol=0)
    ramp = np.arange(20.0)
    assert np.abs(d @ np.ones(20))[1:].max() < 1e-5 and np.abs(d @ ramp)[1:].max() > 1  # a constant is all DC


@pytest.mark.parametrize("model", [SiMLPe(SiMLPeConfig()), ResidualGRU(ResidualGRUConfig(width=32))])
def test_at_initialisation_the_prediction_is_the_last_frame(model):
    torch.manual_seed(0)
    context = torch.randn(3, 20, C)
    with torch.no_grad():
        out = model(context)
    assert out.shape == (3, 20, C)
    torch.testing.assert_close(out, context[:, -1:].expand(-1, 20, -1), atol=1e-5, rtol=0)


def test_simlpe_has_the_papers_size():
    model = SiMLPe(SiMLPeConfig())
    assert sum(p.numel() for p in model.parameters()) == 2 * (C * C + C) + 48 * (20 * 20 + 20 + 2 * C)


@pytest.mark.parametrize("model", [SiMLPe(SiMLPeConfig(blocks=4)), ResidualGRU(ResidualGRUConfig(width=32))])
def test_overfits_one_batch(model):
    torch.manual_seed(0)
    x = torch.cumsum(0.1 * torch.randn(8, 40, C), 1)  # smooth-ish trajectories
    opt = torch.optim.Adam(model.parameters(), 3e-3)
    losses = []
    for _ in range(120):
        loss = model.loss(model(x[:, :20]), x[:, 20:])
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.6 * losses[0]


@pytest.mark.parametrize("arch", list(MODELS))
def test_train_py_writes_a_release_the_engine_loads(walk_folder, tmp_path, arch):
    out = tmp_path / arch
    argv = ["--arch", arch, "--data", str(walk_folder), "--out", str(out), "--steps", "6", "--batch", "8",
            "--cache", "", "--quiet", "--threads", "1", "--mirror", "0.5", "--hold-out", *TINY[arch]]
    assert train_script.main(argv) == 0
    doc = json.loads((out / "release" / "model.json").read_text())
    assert doc["architecture"] == arch and doc["purpose"] == "generate" and "other training data" in doc["licence"]
    assert doc["training"]["steps_done"] == 6 and doc["training"]["command"].startswith("python scripts/train.py")
    assert len(doc["normalisation"]["mean"]) == C and doc["data"]["clips"]["train"] > 0
    log = (out / "train.log").read_text()
    assert "val_mse" in log or doc["data"]["clips"]["validation"] == 0
    engine = BaselineEngine.load(out / "release")
    assert engine.name == arch and (engine.m, engine.n) == (20, 20) and engine.ckpt.purpose == "generate"
    assert engine.extrapolate(engine.seeds[0], 25).shape == (25, C)


def test_a_run_stopped_by_the_time_budget_writes_a_release_and_resumes_exactly(walk_folder, tmp_path):
    def cfg(out, **kw):
        return BaselineTrainConfig(data=str(walk_folder), out=str(tmp_path / out), model=SiMLPeConfig(blocks=2),
                                   steps=8, batch=8, cache="", val_every=4, checkpoint_seconds=1e9, mirror=0.5, **kw)

    whole = train_baseline(cfg("whole"), progress=False)
    cut = train_baseline(cfg("cut", max_minutes=1e-9), progress=False)  # the budget ends it after one step
    assert json.loads((cut / "model.json").read_text())["training"]["steps_done"] == 1
    assert "--max-minutes reached at step 1 of 8" in (tmp_path / "cut" / "train.log").read_text()
    resumed = train_baseline(cfg("cut"), resume=True, progress=False)
    assert "resumed at step 1" in (tmp_path / "cut" / "train.log").read_text()
    a, b = BaselineEngine.load(whole).model.state_dict(), BaselineEngine.load(resumed).model.state_dict()
    for k in a:
        torch.testing.assert_close(a[k], b[k], atol=1e-6, rtol=0, msg=k)


def test_cosine_schedule_runs_over_the_steps():
    cfg = BaselineTrainConfig(data="", steps=100, lr_final=0.01)
    assert lr_scale(cfg, 0) == pytest.approx(1.0) and lr_scale(cfg, 100) == pytest.approx(0.01)
    assert lr_scale(cfg, 50) == pytest.approx(0.505)


@pytest.mark.parametrize("arch", list(MODELS))
def test_extrapolate_shapes_and_batch_equals_single(baseline_release, arch):
    engine = BaselineEngine.load(baseline_release(arch, **({"width": 16} if arch == "residual_gru" else {})))
    seeds = engine.seeds
    batch = engine.extrapolate(seeds, 45)
    assert batch.shape == (2, 45, C) and np.isfinite(batch).all()
    for i in range(2):
        np.testing.assert_allclose(engine.extrapolate(seeds[i], 45), batch[i], atol=1e-4, rtol=0)
    assert set(np.unique(batch[..., LAYOUT.contacts])) <= {0.0, 1.0}  # rounded as STRNN's rollout does
    assert engine.predict(seeds).shape == (2, 20, C)


def test_the_strnn_engines_refuse_a_baseline_folder(baseline_release):
    folder = baseline_release("simlpe")
    for load in (Engine.load, TorchEngine.load):
        with pytest.raises(CheckpointError, match="simlpe baseline .*--baseline-model"):
            load(folder)
    with pytest.raises(CheckpointError, match="not a baseline"):
        BaselineEngine.load(DEFAULT_MODEL)


def test_an_unknown_architecture_is_refused(baseline_release):
    folder = baseline_release("simlpe")
    doc = json.loads((folder / "model.json").read_text())
    (folder / "model.json").write_text(json.dumps(doc | {"architecture": "transformer"}))
    with pytest.raises(CheckpointError, match="unknown architecture 'transformer'"):
        BaselineEngine.load(folder)
