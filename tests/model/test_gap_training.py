"""Training the gap model through scripts/train.py --arch gap: a release the NumPy gap model loads and fills
with, the validation figures in the log, and a run that goes on from its saved state."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("torch")

from model_core.inference.gap_engine import FORMAT, GapModel  # noqa: E402
from model_core.motion.synthetic import walking_skeleton  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "scripts"))

import train as train_script  # noqa: E402


def test_train_py_writes_a_gap_model_that_fills_a_gap_and_resumes(walk_folder, tmp_path):
    out = tmp_path / "gap"
    argv = ["--arch", "gap", "--data", str(walk_folder), "--out", str(out), "--steps", "6", "--batch", "8",
            "--width", "32", "--blocks", "1", "--cache", "", "--threads", "1", "--mirror", "0.5", "--hold-out"]
    assert train_script.main(argv) == 0
    doc = json.loads((out / "release" / "model.json").read_text())
    assert doc["format"] == FORMAT and doc["steps"] == 6 and "other training data" in doc["licence"]
    assert doc["config"] == {"sines": 16, "blocks": 1, "width": 32, "context": 10, "max_gap": 120}
    assert doc["training"]["command"].startswith("python scripts/train.py --arch gap")
    assert "val L2P 15/30/60" in (out / "train.log").read_text()
    model = GapModel.load(out / "release")
    walk = walking_skeleton(90, radius=3.0)
    gap = model.fill(walk[:20], walk[50:52], 30)
    assert gap.shape == (30, 21, 3) and np.isfinite(gap).all()
    assert train_script.main([*argv[:7], "9", *argv[8:], "--resume"]) == 0  # on from step 6 to 9
    assert json.loads((out / "release" / "model.json").read_text())["steps"] == 9


def test_a_gap_run_takes_dropout_and_capture_phases(walk_folder, tmp_path):
    out = tmp_path / "gap_do"
    argv = ["--arch", "gap", "--data", str(walk_folder), "--out", str(out), "--steps", "2", "--batch", "4",
            "--width", "16", "--blocks", "1", "--cache", "", "--threads", "1", "--dropout", "0.1", "--capture-phases"]
    assert train_script.main(argv) == 0
    training = json.loads((out / "release" / "model.json").read_text())["training"]
    assert training["dropout"] == 0.1 and training["capture_phases"] is True


def test_a_gap_run_refuses_strnn_only_options(walk_folder, tmp_path, capsys):
    argv = ["--arch", "gap", "--data", str(walk_folder), "--out", str(tmp_path / "g"), "--init", str(tmp_path)]
    assert train_script.main(argv) == 2
    assert "--init" in capsys.readouterr().err
