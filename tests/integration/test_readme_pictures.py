"""scripts/readme_pictures.py: the README's pictures, made by the real extension in Blender on
test-split takes, with the figures their captions quote measured in the same run (the pictures these
assertions read; the in-betweening and Rigify pictures have tests of their own operators)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_pictures_of_each_operator(mocap_root, tmp_path):
    pytest.importorskip("bpy")
    done = subprocess.run([sys.executable, str(REPO / "scripts" / "readme_pictures.py"), "--data", str(mocap_root),
                           "--out", str(tmp_path), "--only", "extend", "denoise", "footlock", "follow", "ground",
                           "bonemap"],
                          capture_output=True, text=True, timeout=600, cwd=REPO)
    assert done.returncode == 0, done.stderr[-2000:]
    for name in ("extend", "denoise", "footlock", "follow", "ground", "bonemap"):
        assert (tmp_path / f"{name}.png").read_bytes().startswith(b"\x89PNG")
    figures = json.loads(next(line for line in done.stdout.splitlines() if line.startswith("figures: "))[9:])
    assert figures["denoise"]["denoised_cm"] < 0.5 * figures["denoise"]["noisy_cm"]  # the jitter is more than halved
    assert figures["footlock"]["skate_after_cm"] < 0.5 * figures["footlock"]["skate_before_cm"]
    assert figures["follow"]["frames"] > 300  # one lap of the figure-eight
    low, high = figures["ground"]["hips_over_hill_m"]
    assert 0.7 < low and high < 1.0  # the hips ride over the hill, 30 cm high
    assert all(0.0 < cm < 6.0 for cm in figures["ground"]["lowest_foot_each_second_cm"])  # a foot down on it
    assert set(figures["bonemap"].values()) == {21}  # every joint found on each of the three rigs


def test_missing_data_is_a_clear_error(tmp_path):
    done = subprocess.run([sys.executable, str(REPO / "scripts" / "readme_pictures.py"), "--data", str(tmp_path),
                           "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=120, cwd=REPO)
    assert done.returncode == 2 and "missing clips" in done.stderr and "extract.sh" in done.stderr
    assert not (tmp_path / "out").exists()
