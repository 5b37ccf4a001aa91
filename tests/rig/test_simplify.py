"""refine: the frames to key so that a curve played through them stays within a tolerance."""

from __future__ import annotations

import numpy as np

from model_core.rig.simplify import refine


def linear_error(values: np.ndarray):
    frames = np.arange(len(values))
    return lambda kept: np.abs(np.interp(frames, kept, values[kept]) - values)


def test_a_smooth_curve_needs_few_keys_and_stays_within_the_tolerance():
    values = np.sin(np.arange(300) / 20.0)
    kept, err = refine(len(values), linear_error(values), 0.01)
    assert err.max() <= 0.01 and kept[0] == 0 and kept[-1] == 299
    assert len(kept) < 300 / 3
    np.testing.assert_allclose(err, linear_error(values)(kept))


def test_noise_keeps_every_frame_it_needs():
    values = np.random.default_rng(0).normal(0.0, 1.0, 50)
    kept, err = refine(len(values), linear_error(values), 1e-6)
    assert err.max() <= 1e-6 and len(kept) == 50


def test_a_straight_line_keeps_the_ends():
    values = np.linspace(0.0, 1.0, 40)
    kept, err = refine(len(values), linear_error(values), 1e-9, start_every=100)
    assert kept.tolist() == [0, 39] and err.max() < 1e-9
