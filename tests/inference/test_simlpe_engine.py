"""The NumPy siMLPe (model_core/inference/simlpe_engine.py) and the release's first window shared with it."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from releases import random_release  # noqa: E402

from model_core.inference import engine as engine_module  # noqa: E402
from model_core.inference.engine import Engine, bone_lengths, project_to_skeleton  # noqa: E402
from model_core.inference.simlpe_engine import SiMLPeEngine  # noqa: E402
from model_core.inference.torch_engine import TorchEngine  # noqa: E402
from model_core.io.checkpoint import REPO, SIMLPE, CheckpointError, load_release, read_safetensors  # noqa: E402
from model_core.model.baselines import BaselineEngine  # noqa: E402


def test_the_numpy_simlpe_predicts_as_the_torch_model(baseline_release):
    folder = baseline_release("simlpe", blocks=3, encode_len=10, predict_len=8)
    ours, theirs = SiMLPeEngine(load_release(folder)), BaselineEngine.load(folder)
    ctx = np.random.default_rng(1).normal(size=(4, 10, ours.mean.size)).astype(np.float32) * ours.std + ours.mean
    got, want = ours.predict_once(ctx), theirs.predict_once(ctx)
    assert got.shape == (4, 8, ours.mean.size)
    assert np.abs(want - ctx[:, -1:]).max() > 0.05  # the model moves, so the comparison means something
    np.testing.assert_allclose(got, want, atol=1e-4, rtol=0)
    np.testing.assert_allclose(ours.predict(ctx), theirs.predict(ctx), atol=1e-4, rtol=0)  # the mirrored reading


def test_a_simlpe_shares_the_first_window_only(tmp_path, baseline_release):
    """A release with a siMLPe (checkpoint.SIMLPE): the first window of a rollout is the STRNN's prediction
    weighted with the siMLPe's by SIMLPE_SHARE, every later window the STRNN's own (predict_next), in both
    engines; Fill Gap's bounded gaps (paired_windows=None) share every window."""
    random_release(tmp_path / "alone", seed=0)
    random_release(tmp_path / "pair", seed=0)
    shutil.copytree(baseline_release("simlpe", blocks=2, encode_len=10, predict_len=10), tmp_path / "pair" / SIMLPE)
    own, pair = Engine.load(tmp_path / "alone"), Engine.load(tmp_path / "pair")
    assert own.simlpe is None and pair.simlpe is not None and pair.companion is None
    share = engine_module.SIMLPE_SHARE
    assert 0 < share < 1
    seeds = pair.seeds
    lengths = bone_lengths(seeds)
    first = project_to_skeleton((1 - share) * own.predict(seeds) + share * pair.simlpe.predict(seeds), lengths)
    out = pair.extrapolate(seeds, 2 * pair.n)
    np.testing.assert_allclose(out[:, :pair.n], first, atol=1e-5, rtol=0)
    rolled = np.concatenate([seeds, first], 1)[:, -pair.m:]
    np.testing.assert_allclose(out[:, pair.n:], project_to_skeleton(own.predict_next(rolled), lengths), atol=1e-5,
                               rtol=0)
    assert np.abs(out[:, :pair.n] - own.extrapolate(seeds, pair.n)).max() > 1e-3  # the siMLPe counts
    np.testing.assert_allclose(TorchEngine.load(tmp_path / "pair").extrapolate(seeds, 2 * pair.n), out, atol=1e-4,
                               rtol=0)
    both = pair.extrapolate(seeds, 2 * pair.n, paired_windows=None)
    second = (1 - share) * own.predict(rolled) + share * pair.simlpe.predict(rolled)
    np.testing.assert_allclose(both[:, pair.n:], project_to_skeleton(second, lengths), atol=1e-5, rtol=0)


def test_a_simlpe_of_a_shorter_window_continues_itself_as_far(tmp_path, baseline_release):
    """A release that predicts more frames than its siMLPe: the siMLPe's share of the first window is its own
    open loop continued as far (:func:`engine.partner_ahead`)."""
    random_release(tmp_path / "alone", n=10, seed=0)
    random_release(tmp_path / "pair", n=10, seed=0)
    shutil.copytree(baseline_release("simlpe", blocks=2, encode_len=10, predict_len=4), tmp_path / "pair" / SIMLPE)
    own, pair = Engine.load(tmp_path / "alone"), Engine.load(tmp_path / "pair")
    seeds, share = pair.seeds, engine_module.SIMLPE_SHARE
    first = pair.simlpe.predict(seeds)
    second = pair.simlpe.predict(np.concatenate([seeds, first], 1)[:, -pair.simlpe.m:])
    ahead = engine_module.partner_ahead(pair.simlpe, seeds, pair.n)
    np.testing.assert_allclose(ahead[:, :8], np.concatenate([first, second], 1), atol=1e-6, rtol=0)
    np.testing.assert_allclose(pair.predict_first(seeds), (1 - share) * own.predict(seeds) + share * ahead,
                               atol=1e-6, rtol=0)


@pytest.mark.parametrize("wrong", ["a longer window", "an STRNN"])
def test_a_simlpe_folder_that_does_not_fit_the_release_is_refused(tmp_path, baseline_release, wrong):
    random_release(tmp_path / "pair", n=10 if wrong == "an STRNN" else 5)
    if wrong == "a longer window":
        shutil.copytree(baseline_release("simlpe", blocks=2, encode_len=10, predict_len=10), tmp_path / "pair" / SIMLPE)
    else:
        random_release(tmp_path / "pair" / SIMLPE, n=10)
    with pytest.raises(CheckpointError, match=f"{SIMLPE}: a {SIMLPE} must be a generating simlpe model"):
        Engine.load(tmp_path / "pair")


def test_the_shipped_model_carries_the_projects_simlpe():
    """The siMLPe in the release is the project's siMLPe baseline itself, so evaluate.py's siMLPe row is the
    model that shares Extend's first window."""
    engine = Engine.load()
    assert engine.simlpe is not None and engine.simlpe.n == engine.n and engine.simlpe.m <= engine.m
    assert engine.simlpe.ckpt.meta["training"]["hold_out"]  # trained without the held-out groups, as the release
    shipped = read_safetensors(REPO / "models" / "strnn_default" / SIMLPE / "model.safetensors")
    baseline = read_safetensors(REPO / "models" / "baseline_simlpe" / "model.safetensors")
    assert shipped.keys() == baseline.keys() and all(np.array_equal(shipped[k], baseline[k]) for k in shipped)
