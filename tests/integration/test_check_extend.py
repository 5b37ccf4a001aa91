"""scripts/check_extend.py: Extend Clip checked on the user's own takes, the real operator in Blender's bpy workers;
its measures on BVH files made here, and a run end to end."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from model_core.io.bvh_export import write_bvh
from model_core.motion.synthetic import walking_skeleton

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "scripts"))

import check_extend  # noqa: E402


@pytest.fixture(scope="module")
def extension(tmp_path_factory) -> Path:
    pytest.importorskip("bpy")
    import build_extension

    return build_extension.main(["--out", str(tmp_path_factory.mktemp("dist"))])


def test_cuts_leave_the_frames_to_compare_with():
    assert check_extend.cut_frames(200, None, 15) == [50, 100, 150]  # a quarter, half and three quarters
    assert check_extend.cut_frames(200, [1, 20, 21, 185, 186, 100, 100], 15) == [21, 100, 185]
    assert check_extend.cut_frames(16, None, 15) == []
    assert check_extend.context_frames(30.0) == 21 and check_extend.context_frames(1 / 0.016667) == 40
    assert check_extend.cut_frames(152, None, 30, 1 / 0.016667) == [76, 114]  # a quarter is under the 40 it reads


def test_a_cut_is_measured_against_the_take_and_against_holding(tmp_path):
    walk = walking_skeleton(120)
    take = write_bvh(tmp_path / "take.bvh", walk)
    same = write_bvh(tmp_path / "same.bvh", walk)
    held = walk.copy()
    held[60:] = walk[59]  # the pose of scene frame 60 (index 59) held
    held = write_bvh(tmp_path / "held.bvh", held)
    exact = check_extend.measure_cut(take, same, 60, 15)
    assert exact["extend"] == pytest.approx(0, abs=1e-6) and exact["hold"] > 10 * 0.01  # cm-scale file units
    assert exact["before"] == pytest.approx(0, abs=1e-6)
    assert exact["canonical_cm"]["extend"] == pytest.approx(0, abs=1e-3) and exact["canonical_cm"]["hold"] > 10
    still = check_extend.measure_cut(take, held, 60, 15)  # holding the pose is level with holding it
    assert still["extend"] == pytest.approx(still["hold"], rel=1e-6) and still["before"] < 1e-6
    late = check_extend.measure_cut(take, held, 80, 15)  # cut after the hold began: the frames kept are not the take
    assert late["before"] > 1.0


def test_a_walk_that_walks_on_and_one_that_stops(tmp_path):
    walk = walking_skeleton(480)
    take = write_bvh(tmp_path / "take.bvh", walk[:150])
    on = write_bvh(tmp_path / "on.bvh", walk)
    stopped = walk.copy()
    stopped[300:] = walk[299]
    stopped = write_bvh(tmp_path / "stopped.bvh", stopped)
    good = check_extend.measure_walk(take, on, 5.0)
    assert good["frames"] == 330 and good["walks"]
    assert 0.9 < good["speed_ratio"] < 1.1 and 0.9 < good["feet_swing_ratio"] < 1.1 and good["touch_fraction"] == 1
    assert good["hips_m_per_s"] == pytest.approx(good["clip_hips_m_per_s"], rel=0.05)
    assert check_extend.verdict(good) == "walks"
    slow = check_extend.measure_walk(write_bvh(tmp_path / "said24.bvh", walk[:150], fps=24.0),
                                     write_bvh(tmp_path / "on24.bvh", walk, fps=24.0), 5.0)
    own = check_extend.measure_walk(tmp_path / "said24.bvh", tmp_path / "on24.bvh", 5.0, fps=30.0)
    assert slow["clip_hips_m_per_s"] == pytest.approx(0.8 * good["clip_hips_m_per_s"], rel=0.01)  # read at 24
    assert own["clip_hips_m_per_s"] == pytest.approx(good["clip_hips_m_per_s"], rel=0.01)  # --keys-per-second 30
    bad = check_extend.measure_walk(take, stopped, 5.0)
    assert bad["speed_ratio"] < 0.4 and not bad["walks"] and not bad["moves_on"]
    assert check_extend.verdict(bad) == "does not walk (slows down; no second moves)"
    standing = np.repeat(walk[:1], 150, axis=0)
    standing[:, 1:, 1] += 0.05 * np.sin(np.arange(150) / 4)[:, None]  # bobs in place, the hips still
    clip = write_bvh(tmp_path / "standing.bvh", standing)
    sways = write_bvh(tmp_path / "sways.bvh", np.concatenate([standing, standing, standing]))
    still = check_extend.measure_walk(clip, sways, 5.0)  # moves on at its pace, but never walked: not a walk
    assert still["moves_on"] and not still["walks"] and np.isnan(still["touch_fraction"])
    assert check_extend.verdict(still) == "does not walk (no second moves)"


def test_bad_arguments_are_refused_before_any_work(tmp_path, capsys):
    text = tmp_path / "notes.txt"
    text.write_text("not motion")
    for argv in (["cuts", str(text)], ["cuts", str(tmp_path / "missing.bvh")],
                 ["cuts", "--seconds", "0", str(text)], ["walk", "--frames", "0", str(text)],
                 ["walk", "--keys-per-second", "0", str(text)]):
        with pytest.raises(SystemExit) as e:
            check_extend.main(argv + ["--out", str(tmp_path / "out")])
        assert e.value.code == 2, argv
    assert not (tmp_path / "out").exists()
    walk = write_bvh(tmp_path / "walk.bvh", walking_skeleton(60))
    theirs = tmp_path / "mine" / "walk"  # a folder of the user's where this check would write: left alone
    theirs.mkdir(parents=True)
    (theirs / "keep.txt").write_text("mine")
    assert check_extend.main(["walk", str(walk), "--out", str(tmp_path / "mine")]) == 2
    assert (theirs / "keep.txt").read_text() == "mine" and "not made by check_extend.py" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        check_extend.main(["--help"])
    assert e.value.code == 0 and "holding the last pose" in capsys.readouterr().out


def test_end_to_end_in_blender(tmp_path, extension, capsys):
    """A 30 fps walk cut at scene frame 60 and extended 0.5 s by the real operator: the frames before the cut are
    the take's, and a steady walk's continuation is far nearer than holding the pose; the same walk extended by 90
    frames still walks."""
    walk = write_bvh(tmp_path / "walk.bvh", walking_skeleton(150))
    out = tmp_path / "check"
    before = walk.read_bytes()
    assert check_extend.main(["cuts", str(walk), "--at", "60", "--extension", str(extension), "--out", str(out),
                              "--json", str(tmp_path / "cuts.json")]) == 0
    cut = json.loads((tmp_path / "cuts.json").read_text())["rows"]
    assert [r["cut"] for r in cut] == [60] and cut[0]["horizon_frames"] == 15
    assert cut[0]["before"] < 0.01  # the operator left the frames up to the cut as they were (file units: cm)
    assert cut[0]["extend"] < 0.5 * cut[0]["hold"]
    assert "no further than holding in 1 of 1" in capsys.readouterr().out
    assert check_extend.main(["walk", str(walk), "--frames", "90", "--last", "2", "--extension", str(extension),
                              "--out", str(out), "--json", str(tmp_path / "walk.json")]) == 0
    row = json.loads((tmp_path / "walk.json").read_text())["rows"][0]
    assert row["frames"] == 90 and row["walks"] and np.isfinite(row["speed_ratio"])
    assert walk.read_bytes() == before  # the take itself is never touched


def test_a_walk_that_stumbles_at_the_cut_is_seen_there(tmp_path):
    """The walk check's step over the cut: a walk that goes on at its pace steps as the take did (about 1 x); one
    that stops for a frame where the take ends (a repeated last frame, extended from) is far under it; a clip at rest
    at its end has no pace to keep there (None), and the report says so in words."""
    walk = walking_skeleton(480)
    take = write_bvh(tmp_path / "take.bvh", walk[:150])
    on = check_extend.measure_walk(take, write_bvh(tmp_path / "on.bvh", walk), 5.0)
    assert on["seam_step_ratio"] == pytest.approx(1.0, abs=0.1)
    stumbles = np.concatenate([walk[:150], walk[149:150], walk[150:479]])  # frame 151 repeats frame 150
    late = check_extend.measure_walk(take, write_bvh(tmp_path / "stumbles.bvh", stumbles), 5.0)
    assert late["seam_step_ratio"] < 0.1 and late["walks"]  # the last 5 s walk: only the cut shows it
    assert check_extend.seam_words(late["seam_step_ratio"]).startswith("slowest step over the cut 0.0")
    standing = np.repeat(walk[:1], 150, axis=0)
    rest = check_extend.measure_walk(write_bvh(tmp_path / "standing.bvh", standing),
                                     write_bvh(tmp_path / "still.bvh", np.repeat(walk[:1], 300, axis=0)), 5.0)
    assert rest["seam_step_ratio"] is None and check_extend.seam_words(None) == "at rest at the cut"
