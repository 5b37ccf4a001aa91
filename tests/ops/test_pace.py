"""A take's pace from its stride: right at the rate it was captured, flagged with the rate to set when
its keys are read at another (a 60 fps capture keyed frame by frame into a 24 fps scene)."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.motion.synthetic import walking_skeleton
from model_core.ops.pace import STRIDE_S, Pace, stride_period, take_pace
from model_core.rig.rigs import load_clip


def test_a_walk_read_at_its_own_rate_has_a_human_stride():
    walk = walking_skeleton(240, fps=60.0, cadence=0.9)  # one stride every 1.11 s
    pace = take_pace(walk, 60.0)
    assert pace.stride_s == pytest.approx(1 / 0.9, abs=0.03)
    assert pace.plausible and pace.note() == ""


@pytest.mark.parametrize("captured, read", [(60.0, 24.0), (120.0, 30.0), (30.0, 120.0)])
def test_a_walk_read_at_another_rate_is_flagged_with_the_rate_it_was_captured_at(captured, read):
    walk = walking_skeleton(int(8 * captured), fps=captured, cadence=0.9)
    pace = take_pace(walk, read)
    assert pace.stride_s == pytest.approx(captured / read / 0.9, rel=0.05)
    assert not pace.plausible
    assert pace.suggested_rate() == captured
    assert f"set Keys per Second to {captured:g}" in pace.note()


def test_standing_motion_and_too_short_takes_have_no_stride():
    walk = walking_skeleton(240, fps=30.0)
    still = np.repeat(walk[:1], 240, axis=0)
    still = still + 0.01 * np.sin(np.arange(240) / 5.0)[:, None, None]  # swaying, no steps
    assert stride_period(still, 30.0) is None
    assert stride_period(walk[:40], 30.0) is None  # 1.3 s: not two strides


def test_the_note_says_which_way_the_pace_is_off():
    assert "slower than people move" in Pace(2.8, 24.0).note()
    assert "faster than people move" in Pace(0.3, 60.0).note()
    assert Pace(sum(STRIDE_S) / 2, 30.0).note() == ""


def test_no_note_when_the_rate_read_at_is_already_the_nearest():
    """A 120 fps martial arts take shifting its stance every 3.7 s used to be told it "may have been
    captured at 120 fps", the rate it was read at: no rate explains such a pace, so nothing is said."""
    assert Pace(3.67, 120.0).suggested_rate() == 120.0 and Pace(3.67, 120.0).note() == ""
    assert Pace(3.67, 1 / 0.00833333).note() == ""  # the rate as a BVH's rounded Frame Time gives it (CMU's takes)
    assert "captured at 120 fps" in Pace(3.67, 30.0).note()  # the same strides read at 30: 4 x too slow


def test_real_walks_and_runs_read_at_their_rate_are_plausible_and_at_2_5x_are_not(mocap_root):
    """Bandai walks and runs (30 fps): every stride between 0.45 and 1.6 s; read as a 30 fps take keyed
    into a 12 fps scene would be (2.5 x slower, as 60 into 24), every one flagged."""
    files = sorted((mocap_root / "bandai-namco").rglob("*_walk_*.bvh"))[:6]
    files += sorted((mocap_root / "bandai-namco").rglob("*_run_*.bvh"))[:6]
    assert len(files) == 12
    for path in files:
        pos = load_clip(path)[:240]
        own, slow = take_pace(pos, 30.0), take_pace(pos, 12.0)
        assert own is not None and own.plausible, (path.name, own)
        assert slow is not None and not slow.plausible, (path.name, slow)
