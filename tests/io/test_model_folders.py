"""A damaged model folder gets one message naming the file, what is wrong and what to do: never a traceback
from the safetensors, JSON or NumPy readers. Checked on copies of the bundled model."""

from __future__ import annotations

import json
import shutil

import pytest

from model_core.io.checkpoint import DEFAULT_MODEL, CheckpointError, load_release


@pytest.fixture
def copy(tmp_path):
    folder = tmp_path / "model"
    shutil.copytree(DEFAULT_MODEL, folder)
    return folder


def test_truncated_weights(copy):
    data = (copy / "model.safetensors").read_bytes()
    (copy / "model.safetensors").write_bytes(data[: len(data) // 3])
    with pytest.raises(CheckpointError, match=r"model\.safetensors is damaged or incomplete .*copy the model folder"):
        load_release(copy)


def test_malformed_model_json(copy):
    (copy / "model.json").write_text('{"format": "strnn-release-1", ')
    with pytest.raises(CheckpointError, match=r"model\.json is not valid JSON"):
        load_release(copy)


@pytest.mark.parametrize("section", ["config", "normalisation", "layout"])
def test_incomplete_model_json(copy, section):
    doc = json.loads((copy / "model.json").read_text())
    del doc[section]
    (copy / "model.json").write_text(json.dumps(doc))
    with pytest.raises(CheckpointError, match=f"no '{section}' section; the file is incomplete"):
        load_release(copy)


def test_damaged_seeds(copy):
    (copy / "seeds.npz").write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(CheckpointError, match=r"seeds\.npz is unreadable"):
        load_release(copy)


def test_weights_of_another_model(copy):
    doc = json.loads((copy / "model.json").read_text())
    doc["config"]["width"] = 2 * doc["config"]["width"]
    (copy / "model.json").write_text(json.dumps(doc))
    with pytest.raises(CheckpointError, match="the two files come from different models"):
        load_release(copy)
