"""The seams (model_core/ops/seam.py): one set of lengths, the engine's and training's fade the
same twin, and a replaced range meets its neighbours without a jump."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.inference.engine import Engine
from model_core.ops.follow import ControlSettings
from model_core.ops.seam import EDGE_FADE_S, PREDICT_SEAM_FRAMES, SEAM_FRAMES, fade_edges, seam_fade


def test_the_seam_lengths_are_the_ones_each_user_takes():
    assert Engine.seam_frames == PREDICT_SEAM_FRAMES == 10.0
    assert ControlSettings().seam_frames == SEAM_FRAMES == 10
    assert EDGE_FADE_S == 0.2


def test_seam_fade_numpy_and_torch_twins_agree():
    torch = pytest.importorskip("torch")
    fade = seam_fade(10, 4.0)
    assert fade.dtype == np.float32
    np.testing.assert_allclose(fade, np.exp(-np.arange(1, 11) / 4.0), rtol=1e-6)
    np.testing.assert_allclose(seam_fade(10, 4.0, torch, torch.float32).numpy(), fade, rtol=1e-6)  # exp to 1 ulp


def test_fade_edges_blends_only_the_faded_edges():
    before, after = np.zeros((40, 21, 3)), np.ones((40, 21, 3))
    fps = 30.0
    k = int(round(EDGE_FADE_S * fps))
    both = fade_edges(before, after, fps, True, True)
    w = both[:, 0, 0]
    assert np.all(np.diff(w[:k + 1]) > 0) and np.all(w[k:-k] == 1.0) and np.all(np.diff(w[-k - 1:]) < 0)
    assert w[0] == pytest.approx(1 / (k + 1)) and w[-1] == pytest.approx(1 / (k + 1))
    np.testing.assert_array_equal(fade_edges(before, after, fps, False, False), after)
    start_only = fade_edges(before, after, fps, True, False)[:, 0, 0]
    assert start_only[0] < 1.0 and np.all(start_only[k:] == 1.0)
