"""scripts/evaluate.py end to end on a small folder of BVH files with the bundled model:
one run, the table printed, and JSON with exactly the keys the metrics define."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from model_core.bvh_export import write_bvh
from model_core.synthetic import walking_skeleton

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "scripts"))

import evaluate  # noqa: E402


@pytest.fixture(scope="module")
def walks(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("walks")
    for i in range(3):
        write_bvh(root / f"walk_{i}.bvh", walking_skeleton(frames=150, speed=1.0 + 0.2 * i, radius=4.0 + i))
    return root


def test_one_run_writes_exactly_the_metric_keys(walks, tmp_path, capsys):
    out = tmp_path / "eval.json"
    evaluate.main(["--data", str(walks), "--cache", "", "--long-horizon", "1000", "--seeds", "2",
                   "--denoise-std", "3", "--json", str(out)])
    printed = capsys.readouterr().out
    doc = json.loads(out.read_text())
    assert set(doc) == {"checkpoint", "data", "clips", "windows", "prediction", "long_horizon", "denoise"}
    assert doc["clips"] == 3 and doc["windows"] > 0
    assert doc["prediction"]["horizons_ms"] == [80, 160, 320, 400, 560, 1000]
    assert set(doc["prediction"]["mpjpe_cm"]) == {"strnn", "zero_velocity", "constant_velocity"}
    assert all(len(v) == 6 for v in doc["prediction"]["mpjpe_cm"].values())
    zero, const = doc["prediction"]["mpjpe_cm"]["zero_velocity"], doc["prediction"]["mpjpe_cm"]["constant_velocity"]
    assert zero[-1] > zero[0] and const[-1] > const[0]  # errors grow with the horizon
    lh = doc["long_horizon"]
    assert set(lh) == {"frames", "seeds", "exploded", "frozen", "speed_ratio_last_1000", "d1nn_per_block",
                       "seed_clips", "seed_take_speed_ratio", "d1nn_drift", "feet"}
    assert lh["frames"] == 1000 and lh["seeds"] == 2 and len(lh["speed_ratio_last_1000"]) == 2
    assert len(lh["seed_clips"]) == len(lh["seed_take_speed_ratio"]) == 2
    assert set(lh["feet"]) == {"touch_fraction", "floor_offset_cm", "sink_cm"}
    assert [len(b) for b in lh["d1nn_per_block"]] == [1, 1]
    dn = doc["denoise"]
    assert set(dn) == {"std_cm", "mpjpe_cm"} and set(dn["mpjpe_cm"]) == {"strnn", "butterworth_best", "noisy"}
    assert dn["mpjpe_cm"]["butterworth_best"][0] < dn["mpjpe_cm"]["noisy"][0]  # the filter removes noise
    assert 4.0 < dn["mpjpe_cm"]["noisy"][0] < 5.6  # |N(0, 3 cm I3)| has mean 4.8 cm
    for heading in ("Long horizon", "Denoising", "speed / its take", "walk_0.bvh", "as Extend (seam)"):
        assert heading in printed


def test_without_options_only_prediction(walks, tmp_path):
    out = tmp_path / "eval.json"
    evaluate.main(["--data", str(walks), "--cache", "", "--json", str(out)])
    assert set(json.loads(out.read_text())) == {"checkpoint", "data", "clips", "windows", "prediction"}


def test_a_denoise_only_checkpoint_is_pointed_to_denoise_checkpoint(walks, tmp_path, capsys):
    from test_engine import random_release

    random_release(tmp_path / "dn", m=20, n=1, purpose="denoise")
    assert evaluate.main(["--data", str(walks), "--cache", "", "--checkpoint", str(tmp_path / "dn")]) == 2
    assert "pass it as --denoise-checkpoint" in capsys.readouterr().err
    out = tmp_path / "eval.json"
    assert evaluate.main(["--data", str(walks), "--cache", "", "--denoise-std", "3", "--denoise-checkpoint",
                          str(tmp_path / "dn"), "--json", str(out)]) == 0
    assert f"model {tmp_path / 'dn'}" in capsys.readouterr().out
    assert set(json.loads(out.read_text())["denoise"]["mpjpe_cm"]) == {"strnn", "butterworth_best", "noisy"}
