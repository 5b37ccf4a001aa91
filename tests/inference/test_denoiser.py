"""The bundled denoising model (``models/strnn_denoise``): the NumPy engine matches torch, it
refuses to predict, and on real test-split takes it removes more noise than the best
low-pass filter (at most 0.7 x its error at 3 cm noise)."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.eval.metrics import add_noise, best_butterworth, mpjpe_cm
from model_core.inference.engine import Engine
from model_core.io.checkpoint import DENOISE_MODEL, CheckpointError
from model_core.model.dataset import split_of
from model_core.motion.conventions import LAYOUT
from model_core.rig.rigs import load_clip

pytestmark = pytest.mark.skipif(not (DENOISE_MODEL / "model.safetensors").exists(), reason="no denoising model")


@pytest.fixture(scope="module")
def denoiser() -> Engine:
    return Engine.load(DENOISE_MODEL)


def test_numpy_matches_torch_and_prediction_is_refused(denoiser):
    torch_engine = pytest.importorskip("model_core.inference.torch_engine")
    seeds = denoiser.seeds
    assert len(seeds) > 0 and seeds.shape[1:] == (denoiser.m, LAYOUT.size)
    np.testing.assert_allclose(denoiser.forward(seeds), torch_engine.TorchEngine.load(DENOISE_MODEL).forward(seeds),
                               atol=1e-4, rtol=0)
    with pytest.raises(CheckpointError, match="trained for Denoise alone"):
        denoiser.extrapolate(seeds[0], 20)


def test_beats_the_best_low_pass_filter_on_test_takes(denoiser, mocap_root):
    files = sorted((mocap_root / "bandai-namco").rglob("*.bvh"))
    takes = [p for p in files if split_of(p.relative_to(mocap_root)) == "test"][:6]
    if not takes:
        pytest.skip("no Bandai-Namco test-split takes")
    clean = [load_clip(p)[:300] for p in takes]
    rng = np.random.default_rng(0)
    noisy = [add_noise(c, 3.0, rng) for c in clean]
    ours = np.concatenate([mpjpe_cm(denoiser.reconstruct_positions(n), c) for n, c in zip(noisy, clean)]).mean()
    filtered, cutoff = best_butterworth(clean, noisy)
    raw = np.concatenate([mpjpe_cm(n, c) for n, c in zip(noisy, clean)]).mean()
    print(f"3 cm noise on {len(takes)} takes: noisy {raw:.2f} cm, Butterworth {filtered:.2f} ({cutoff} Hz), "
          f"denoiser {ours:.2f}")
    assert filtered < raw and ours < 0.7 * filtered  # the model card's criterion, on a few takes
