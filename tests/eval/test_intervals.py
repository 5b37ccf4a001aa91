"""The take-resampled paired bootstrap behind evaluate.py's ``as_extend_against``."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.eval.intervals import paired_gap


def _takes(count: int, windows: int) -> np.ndarray:
    return np.repeat(np.arange(count), windows)


def test_a_steady_lead_is_told_and_the_interval_holds_the_mean():
    rng = np.random.default_rng(1)
    theirs = rng.uniform(5, 15, (120, 3))
    ours = theirs - 1.0 + rng.normal(0, 0.2, theirs.shape)
    out = paired_gap(ours, theirs, _takes(12, 10))
    for gap, (lo, hi) in zip(out["gap_cm"], out["gap_interval_cm"]):
        assert lo < gap < hi < 0 and gap == pytest.approx(-1.0, abs=0.1)
    for ratio, (lo, hi) in zip(out["ratio"], out["ratio_interval"]):
        assert lo < ratio < hi < 1


def test_the_same_rows_are_level_exactly():
    theirs = np.random.default_rng(2).uniform(1, 2, (30, 6))
    out = paired_gap(theirs, theirs.copy(), _takes(5, 6))
    assert out["gap_cm"] == [0.0] * 6 and out["gap_interval_cm"] == [[0.0, 0.0]] * 6
    assert out["ratio"] == [1.0] * 6 and out["ratio_interval"] == [[1.0, 1.0]] * 6


def test_windows_of_one_take_are_not_counted_as_independent_trials():
    """Each take's windows share that take's gap (a take where ours is far better, one where it is far worse):
    resampling whole takes gives a wide interval that holds 0; the same windows read as one take each would give
    a narrow one that does not."""
    rng = np.random.default_rng(3)
    per_take = np.array([-3.0, 2.5, -2.0, 3.0, -2.5, 1.5])
    takes = _takes(6, 40)
    theirs = rng.uniform(10, 20, (240, 1))
    ours = theirs + per_take[takes][:, None] + rng.normal(0, 0.3, theirs.shape)
    by_take = paired_gap(ours, theirs, takes)["gap_interval_cm"][0]
    by_window = paired_gap(ours, theirs, np.arange(240))["gap_interval_cm"][0]
    assert by_take[0] < 0 < by_take[1]
    assert by_take[1] - by_take[0] > 3 * (by_window[1] - by_window[0])


def test_the_draws_are_seeded_and_take_labels_need_not_be_consecutive():
    rng = np.random.default_rng(4)
    theirs, ours = rng.uniform(1, 9, (50, 2)), rng.uniform(1, 9, (50, 2))
    takes = np.repeat([7, 3, 42, 11, 5], 10)
    assert paired_gap(ours, theirs, takes) == paired_gap(ours, theirs, takes)
    assert paired_gap(ours, theirs, takes) == paired_gap(ours, theirs, np.repeat(np.arange(5), 10))
    assert paired_gap(ours, theirs, takes, seed=1) != paired_gap(ours, theirs, takes)


def test_rows_that_do_not_pair_are_refused():
    with pytest.raises(ValueError, match="same windows"):
        paired_gap(np.ones((10, 6)), np.ones((9, 6)), _takes(2, 5))
    with pytest.raises(ValueError, match="same windows"):
        paired_gap(np.ones((10, 6)), np.ones((10, 6)), _takes(3, 3))
