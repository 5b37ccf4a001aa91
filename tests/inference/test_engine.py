"""The NumPy inference engine against its torch twin, on small random releases.

Each release is a random width-64 STRNN whose batch-norm statistics and residual filter
(zero-initialised by the model) are randomised, so that every folded term matters.
"""

from __future__ import annotations

import pickle
import subprocess
import sys

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from releases import random_release  # noqa: E402

from model_core.inference.engine import Engine, bone_lengths, offset_weights, project_to_skeleton  # noqa: E402
from model_core.inference.spatial_fold import rows_matmul, stack_matmul  # noqa: E402
from model_core.inference.steps import drive  # noqa: E402
from model_core.inference.torch_engine import TorchEngine  # noqa: E402
from model_core.io.checkpoint import DEFAULT_MODEL, REPO, CheckpointError, load_release  # noqa: E402
from model_core.model.strnn import STRNNConfig  # noqa: E402
from model_core.motion.conventions import LAYOUT  # noqa: E402
from model_core.motion.features import features_to_positions, lowest_foot, mirror_features  # noqa: E402
from model_core.motion.stance import SETTLE_FROM  # noqa: E402
from model_core.ops.seam import seam_fade  # noqa: E402

C = LAYOUT.size
VARIANTS = [(s, r) for s in (True, False) for r in (True, False)]  # (spatial, residual)


@pytest.fixture
def release(tmp_path):
    folder = tmp_path / "release"
    random_release(folder)
    return folder


def torch_forward(model, raw, mean, std):
    with torch.no_grad():
        out = model(torch.from_numpy(((raw - mean) / std).astype(np.float32)))
    return out.numpy() * std + mean


@pytest.mark.parametrize("spatial,residual", VARIANTS)
@pytest.mark.parametrize("m,n", [(10, 10), (6, 9), (9, 6)])
def test_numpy_forward_matches_torch(tmp_path, spatial, residual, m, n):
    model, mean, std = random_release(tmp_path, spatial, residual, m, n)
    engine = Engine.load(tmp_path)
    raw = engine.seeds
    want = torch_forward(model, raw, mean, std)
    got = engine.forward(raw)
    assert got.shape == (3, m + n, C)
    np.testing.assert_allclose(got, want, atol=1e-4, rtol=0)
    engine.seam_frames = 0  # the raw prediction, without the seam correction
    np.testing.assert_allclose(engine.predict_once(raw), want[:, m:], atol=1e-4, rtol=0)
    for b in (1, 2):  # one and two contexts: few rows, each product a matrix-vector one
        np.testing.assert_allclose(engine.forward(raw[:b]), want[:b], atol=1e-4, rtol=0)
    np.testing.assert_allclose(TorchEngine.load(tmp_path).forward(raw), want, atol=1e-5, rtol=0)


def test_a_model_without_spatial_norms_runs_the_same_in_numpy_and_torch(tmp_path):
    """``spatial_norm="none"``: no batch norm to fold; the NumPy engine still equals torch."""
    model, mean, std = random_release(tmp_path, offsets=True, spatial_norm="none")
    assert not any(isinstance(mod, torch.nn.BatchNorm1d) for mod in model.modules())
    engine = Engine.load(tmp_path)
    raw = engine.seeds
    np.testing.assert_allclose(engine.forward(raw), torch_forward(model, raw, mean, std), atol=1e-4, rtol=0)
    np.testing.assert_allclose(TorchEngine.load(tmp_path).forward(raw), torch_forward(model, raw, mean, std),
                               atol=1e-5, rtol=0)


def _engines_agree(tmp_path, spatial, residual, **kw):
    """A random offsets release with the options ``kw``: the NumPy and torch engines give the model's window.
    Returns (model, mean, std, raw seeds, the window)."""
    model, mean, std = random_release(tmp_path, spatial, residual, offsets=True, **kw)
    engine = Engine.load(tmp_path)
    raw = engine.seeds
    want = torch_forward(model, raw, mean, std)
    np.testing.assert_allclose(engine.forward(raw), want, atol=1e-4, rtol=0)
    np.testing.assert_allclose(TorchEngine.load(tmp_path).forward(raw), want, atol=1e-5, rtol=0)
    return model, mean, std, raw, want


@pytest.mark.parametrize("spatial", [True, False])
def test_a_filter_that_reads_the_context_runs_the_same_in_numpy_and_torch_and_uses_it(tmp_path, spatial):
    """``filter_context``: the residual filter's input is the window and the true context; NumPy equals
    torch, and the context changes the output through the filter alone."""
    model, mean, std, raw, want = _engines_agree(tmp_path, spatial, True, offset_keep=4, filter_context=True)
    x = torch.from_numpy((raw - mean) / std).float()
    with torch.no_grad():
        window = model(x, use_filter=False)
        assert not torch.allclose(model.filter(window, x), model.filter(window, torch.zeros_like(x)))
    with pytest.raises(ValueError, match="context"):
        model.filter(window)


@pytest.mark.parametrize("spatial,residual", VARIANTS)
@pytest.mark.parametrize("decoder_skip", [False, True])
def test_a_model_that_decodes_the_contexts_last_frames_runs_the_same_in_numpy_and_torch(tmp_path, spatial, residual,
                                                                                        decoder_skip):
    """``decode_len``: a model that reads 12 frames and reconstructs their last 5 gives a window of those 5 and the
    prediction, the same in NumPy and torch; its prediction depends on the frames it does not reconstruct; its
    seam correction is taken at the last decoded frame; the windowed reconstruction covers a take's every frame,
    its first ones too."""
    model, mean, std, raw, want = _engines_agree(tmp_path, spatial, residual, m=12, n=10, decode_len=5,
                                                 decoder_skip=decoder_skip)
    engine = Engine.load(tmp_path)
    assert want.shape == (3, 15, C) and (engine.m, engine.r, engine.n) == (12, 5, 10)
    early = raw.copy()
    early[:, :7] += 0.5
    assert np.abs(torch_forward(model, early, mean, std)[:, 5:] - want[:, 5:]).max() > 1e-3
    fade = seam_fade(engine.n, engine.seam_frames)
    seam = (raw[:, -1] - want[:, 4])[:, LAYOUT.positions]  # the last decoded frame's error
    np.testing.assert_allclose(engine.predict_once(raw)[..., LAYOUT.positions],
                               want[:, 5:, LAYOUT.positions] + fade[None, :, None] * seam[:, None], atol=1e-4, rtol=0)
    engine.seam_frames = 0
    np.testing.assert_allclose(engine.predict_once(raw), want[:, 5:], atol=1e-4, rtol=0)
    take = np.concatenate(list(raw))
    rebuilt = engine.reconstruct(take)
    assert rebuilt.shape == take.shape and np.isfinite(rebuilt).all()
    np.testing.assert_allclose(rebuilt, TorchEngine.load(tmp_path).reconstruct(take), atol=1e-4, rtol=0)


@pytest.mark.parametrize("spatial", [True, False])
def test_a_decoder_that_reads_the_encoders_states_runs_the_same_in_numpy_and_torch(tmp_path, spatial):
    """``decoder_skip``: the backward decoder reads the encoder's state at each frame it reconstructs;
    NumPy equals torch, the decoded frames depend on those states, and the last decoded frame (the
    decoder's first step) on the encoder's state at the last frame."""
    model, mean, std, raw, want = _engines_agree(tmp_path, spatial, False, decoder_skip=True)
    with torch.no_grad():
        model.dec_skip.weight.zero_()
    without = torch_forward(model, raw, mean, std)
    m = model.cfg.encode_len
    assert np.abs(without[:, :m] - want[:, :m]).min(axis=(0, 2)).min() > 0  # every decoded frame
    assert np.abs(without[:, m - 1] - want[:, m - 1]).max() > 1e-3


@pytest.mark.parametrize("spatial", [True, False])
def test_a_predictor_that_reads_the_context_runs_the_same_in_numpy_and_torch(tmp_path, spatial):
    """``predictor_context``: the context's frames less its last enter every predictor step; NumPy equals
    torch, the prediction depends on them and the decoded context does not."""
    model, mean, std, raw, want = _engines_agree(tmp_path, spatial, False, predictor_context=True)
    with torch.no_grad():
        model.context_in.weight.zero_()
    without = torch_forward(model, raw, mean, std)
    m = model.cfg.encode_len
    np.testing.assert_allclose(without[:, :m], want[:, :m], atol=1e-6)
    assert np.abs(without[:, m:] - want[:, m:]).max() > 1e-3


@pytest.mark.parametrize("spatial", [True, False])
def test_a_temporal_skip_runs_the_same_in_numpy_and_torch_and_extrapolates_linearly(tmp_path, spatial):
    """``temporal_skip``: each predicted frame adds a linear map of the context's motion; NumPy equals torch,
    and a map that repeats the last step (constant velocity) moves the prediction by exactly that."""
    model, mean, std, raw, want = _engines_agree(tmp_path, spatial, False, temporal_skip=True)
    x = torch.from_numpy((raw - mean) / std).float()
    m, n = model.cfg.encode_len, model.cfg.predict_len
    with torch.no_grad():
        model.skip.zero_()
        model.skip[:, m - 2] = -torch.arange(1, n + 1, dtype=torch.float32)  # frame i: (i + 1) x the last step
        step = x[:, -1] - x[:, -2]
        expected = step[:, None] * torch.arange(1, n + 1, dtype=torch.float32)[None, :, None]
        torch.testing.assert_close(model.skip_frames(x), expected)


@pytest.mark.parametrize("spatial,residual", VARIANTS)
@pytest.mark.parametrize("kw", [{}, {"decode_len": 5, "decoder_skip": True, "offset_keep": 4},
                                {"predictor_context": True, "temporal_skip": True, "filter_context": True}])
def test_a_window_without_the_decoder_runs_the_same_in_numpy_and_torch(tmp_path, spatial, residual, kw):
    """``decode`` False (a rollout's later windows, :meth:`Engine.predict_next`): the context's last r frames stand
    in for their reconstruction, the prediction is the predictor's as in the full window but for what the
    residual filter makes of it, the same in NumPy and torch; without a filter, exactly the full window's."""
    if kw.get("filter_context") and not residual:
        kw = {k: v for k, v in kw.items() if k != "filter_context"}
    model, mean, std = random_release(tmp_path, spatial, residual, m=12, n=10, offsets=True, **kw)
    engine = Engine.load(tmp_path)
    raw = engine.seeds
    with torch.no_grad():
        x = torch.from_numpy(((raw - mean) / std).astype(np.float32))
        want = model(x, decode=False).numpy() * std + mean
    r = engine.r
    got = engine.forward(raw, decode=False)
    assert got.shape == (3, r + engine.n, C)
    np.testing.assert_allclose(got, want, atol=1e-4, rtol=0)
    np.testing.assert_allclose(TorchEngine.load(tmp_path).forward(raw, decode=False), want, atol=1e-5, rtol=0)
    for b in (1, 2):  # few rows: each product a matrix-vector one
        np.testing.assert_allclose(engine.forward(raw[:b], decode=False), want[:b], atol=1e-4, rtol=0)
    full = engine.forward(raw)
    if not residual:
        np.testing.assert_allclose(got[:, :r], raw[:, -r:], atol=1e-5, rtol=0)  # the context as it is
        np.testing.assert_allclose(got[:, r:], full[:, r:], atol=1e-4, rtol=0)  # the predictor's own
    else:
        assert np.abs(got[:, :r] - full[:, :r]).max() > 1e-3  # the filter reads the context, not its rebuild


def test_a_rollouts_later_windows_leave_out_the_decoder_unless_asked(release):
    """:meth:`Engine.extrapolate`: the first window is :meth:`predict_first` (decoded), each later one
    :meth:`predict_next`; with ``decode_later_windows`` every window is decoded, as :meth:`predict` does."""
    engine = Engine.load(release)
    seeds, n = engine.seeds, engine.n
    lengths = bone_lengths(seeds)
    out = engine.extrapolate(seeds, 2 * n)
    first = project_to_skeleton(engine.predict_first(seeds), lengths)
    np.testing.assert_allclose(out[:, :n], first, atol=1e-5, rtol=0)
    rolled = np.concatenate([seeds, first], 1)[:, -engine.m:]
    np.testing.assert_allclose(out[:, n:], project_to_skeleton(engine.predict_next(rolled), lengths), atol=1e-5,
                               rtol=0)
    engine.decode_later_windows = True
    np.testing.assert_allclose(engine.predict_next(rolled), engine.predict(rolled), atol=0, rtol=0)
    decoded = engine.extrapolate(seeds, 2 * n)
    np.testing.assert_allclose(decoded[:, n:], project_to_skeleton(engine.predict(rolled), lengths), atol=1e-5,
                               rtol=0)
    assert np.abs(decoded[:, n:] - out[:, n:]).max() > 1e-4  # a random model's decoder rebuilds loosely


def test_spatial_norm_is_checked():
    with pytest.raises(ValueError, match="spatial_norm"):
        STRNNConfig(spatial_norm="layer")


@pytest.mark.parametrize("spatial", [True, False])
def test_offset_decoder_matches_torch_and_starts_at_the_context(tmp_path, spatial):
    """With ``offsets`` the frame decoder adds the last context frame: NumPy equals torch, and a
    decoder that outputs nothing reproduces the last context frame everywhere."""
    model, mean, std = random_release(tmp_path, spatial, spatial, offsets=True)
    engine = Engine.load(tmp_path)
    raw = engine.seeds
    np.testing.assert_allclose(engine.forward(raw), torch_forward(model, raw, mean, std), atol=1e-4, rtol=0)
    out = "decode_frame.out" if spatial else "decode_frame"
    with torch.no_grad():
        for name, p in model.named_parameters():
            if name.startswith(out) or name.startswith("decode_frame.root") or name.startswith(
                    "decode_frame.contacts") or name.startswith("decode_frame.torso"):
                p.zero_()
        model.filter = None
        model.cfg.residual = False
    window = torch_forward(model, raw, mean, std)
    np.testing.assert_allclose(window, np.repeat(raw[:, -1:], window.shape[1], 1), atol=1e-5)


def test_offsets_let_go_after_offset_keep_in_numpy_as_in_torch(tmp_path):
    """``offset_keep``: the predicted frames from the K-th on add less and less of the last context frame,
    none at the window's end; NumPy equals torch, and a decoder that outputs nothing reproduces the last
    context frame only where the weight is 1."""
    model, mean, std = random_release(tmp_path, False, False, offsets=True, offset_keep=4)
    engine = Engine.load(tmp_path)
    raw = engine.seeds
    np.testing.assert_allclose(engine.forward(raw), torch_forward(model, raw, mean, std), atol=1e-4, rtol=0)
    np.testing.assert_allclose(offset_weights(10, 4), [1, 1, 1, 1, 5 / 6, 4 / 6, 3 / 6, 2 / 6, 1 / 6, 0])
    assert (offset_weights(10, None) == 1).all() and (offset_weights(10, 10) == 1).all()


def test_extrapolate_shapes_and_batch_matches_single(release):
    engine = Engine.load(release)
    seeds, frames = engine.seeds, 3 * engine.n + 5  # not a whole number of windows
    batch = engine.extrapolate(seeds, frames)
    assert batch.shape == (3, frames, C)
    for i in range(3):
        single = engine.extrapolate(seeds[i], frames)
        assert single.shape == (frames, C)
        np.testing.assert_allclose(single, batch[i], atol=1e-5, rtol=0)
    longer = np.concatenate([seeds[0], seeds[1]])  # only the last m frames are context
    np.testing.assert_array_equal(engine.extrapolate(longer, 7), engine.extrapolate(seeds[1], 7))
    assert engine.extrapolate(seeds[0], 7, keep_bone_lengths=False).shape == (7, C)


def test_torch_engine_extrapolates_like_numpy(release):
    seeds = Engine.load(release).seeds
    want = Engine.load(release).extrapolate(seeds, 25)
    got = TorchEngine.load(release).extrapolate(seeds, 25)
    assert got.shape == want.shape == (3, 25, C)
    np.testing.assert_allclose(got, want, atol=1e-4, rtol=0)


def test_extrapolate_keeps_seed_bone_lengths(release):
    engine = Engine.load(release)
    seed = engine.seeds[0]
    out = engine.extrapolate(seed, 2 * engine.n)
    per_frame = bone_lengths(out[:, None])  # [F, J]: T = 1, so the median is the frame's own
    np.testing.assert_allclose(per_frame, np.broadcast_to(bone_lengths(seed[None]), per_frame.shape),
                               atol=1e-4, rtol=0)
    contacts = out[:, LAYOUT.contacts]
    assert set(np.unique(contacts)) <= {0.0, 1.0}


def test_denoise_shape(release):
    engine = Engine.load(release)
    rng = np.random.default_rng(1)
    feats = (engine.mean + engine.std * rng.normal(size=(engine.m * 3 + 1, C))).astype(np.float32)
    out = engine.reconstruct(feats)
    assert out.shape == feats.shape and np.isfinite(out).all()
    assert TorchEngine.load(release).reconstruct(feats).shape == feats.shape
    with pytest.raises(ValueError, match="at least"):
        engine.reconstruct(feats[: engine.m - 1])


def test_denoise_steps_report_batches_and_give_the_same_result(release):
    engine = Engine.load(release)
    rng = np.random.default_rng(2)
    feats = (engine.mean + engine.std * rng.normal(size=(engine.m * 6, C))).astype(np.float32)
    fractions = []
    out = drive(engine.reconstruct_steps(feats, batch=4), fractions.append)
    windows = len(range(0, len(feats) - engine.m + 1, max(1, engine.m // 4)))
    assert fractions == [min(4 * (k + 1), windows) / windows for k in range(-(-windows // 4))]
    np.testing.assert_allclose(out, engine.reconstruct(feats), atol=1e-5)


def test_a_denoise_only_model_denoises_and_refuses_to_predict(tmp_path):
    random_release(tmp_path, purpose="denoise")
    for engine in (Engine.load(tmp_path), TorchEngine.load(tmp_path)):
        assert engine.ckpt.purpose == "denoise"
        assert engine.reconstruct(np.repeat(engine.seeds[0], 3, 0)).shape == (3 * engine.m, C)
        with pytest.raises(CheckpointError, match="trained for Denoise alone.*strnn_default"):
            engine.extrapolate(engine.seeds[0], 5)
    from model_core.ops.follow import PathFollower

    with pytest.raises(CheckpointError, match="cannot follow a path"):
        PathFollower.load(tmp_path)


def test_an_unknown_purpose_is_a_clear_error(tmp_path):
    random_release(tmp_path, purpose="dance")
    with pytest.raises(CheckpointError, match="unknown purpose 'dance'"):
        Engine.load(tmp_path)


def test_loading_never_unpickles(release, monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("a release must load without pickle")

    monkeypatch.setattr(pickle, "load", refuse)
    monkeypatch.setattr(pickle, "loads", refuse)
    monkeypatch.setattr(torch, "load", refuse)
    Engine.load(release)
    TorchEngine.load(release)
    assert sorted(p.name for p in release.iterdir()) == ["model.json", "model.safetensors", "seeds.npz"]


def test_pickled_seeds_are_refused(release):
    with open(release / "seeds.npz", "wb") as f:
        np.savez(f, features=np.zeros((1, 10, C), np.float32), names=np.array([object()], dtype=object))
    with pytest.raises(ValueError, match="allow_pickle"):
        load_release(release)


def test_missing_config_is_a_clear_error(release):
    (release / "model.json").unlink()
    with pytest.raises(CheckpointError, match="missing model.json"):
        Engine.load(release)
    with pytest.raises(CheckpointError, match="missing model.json"):
        TorchEngine.load(release)


def test_config_mismatch_is_a_clear_error(release):
    """model.json of one model beside the weights of another: one message, from either engine."""
    doc = (release / "model.json").read_text().replace('"width": 64', '"width": 32')
    (release / "model.json").write_text(doc)
    for engine in (TorchEngine, Engine):
        with pytest.raises(CheckpointError, match="describes a width of 32 but model.safetensors holds one of 64"):
            engine.load(release)


def test_the_torch_twin_has_every_method_of_the_numpy_engine():
    """The add-on may be handed either engine: a method written on one only fails where the other is used."""
    public = {name for name, value in vars(Engine).items() if callable(value) and not name.startswith("_")}
    missing = sorted(name for name in public if not hasattr(TorchEngine, name))
    assert not missing, f"TorchEngine lacks {missing}"


@pytest.mark.skipif(not (DEFAULT_MODEL / "model.safetensors").exists(), reason="no bundled model yet")
def test_both_engines_extend_a_clip_onto_the_same_floor():
    engine, twin = Engine.load(), TorchEngine.load()
    take = engine.seeds[:1]
    pos = features_to_positions(take)[0]
    floor = float(pos[..., 1].min()) + 0.05  # above the clip's feet: the lift must act
    eased_in = (SETTLE_FROM + 1) * engine.n  # the lift is whole once it has eased in over the third window
    got = [e.extend(pos, eased_in + 5, floor=floor) for e in (engine, twin)]
    np.testing.assert_allclose(got[0], got[1], atol=2e-3, rtol=0)
    assert lowest_foot(got[0][eased_in:]).min() >= floor - 1e-6


def test_numpy_engine_does_not_import_torch():
    code = "import sys, model_core.inference.engine, model_core.eval.benchmark; sys.exit('torch' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], cwd=REPO).returncode == 0


@pytest.mark.skipif(not (DEFAULT_MODEL / "model.safetensors").exists(), reason="no bundled model yet")
def test_bundled_model():
    engine, twin = Engine.load(), TorchEngine.load()
    seeds = engine.seeds
    assert len(seeds) > 0 and seeds.shape[1:] == (engine.m, C)
    np.testing.assert_allclose(engine.forward(seeds), twin.forward(seeds), atol=1e-4, rtol=0)
    out = engine.extrapolate(seeds[:4], 4 * engine.n)
    assert out.shape == (4, 4 * engine.n, C) and np.isfinite(out).all()


def test_numpy_safetensors_reader_matches_the_library(tmp_path):
    """Blender's Python has no safetensors package: the NumPy reader must give the same arrays."""
    from safetensors.numpy import load_file, save_file

    from model_core.io.checkpoint import read_safetensors

    arrays = {"a": np.arange(12, dtype=np.float32).reshape(3, 4), "b": np.array([1, -2], dtype=np.int64),
              "c": np.zeros((0, 5), np.float32)}
    save_file(arrays, str(tmp_path / "x.safetensors"))
    ours, lib = read_safetensors(tmp_path / "x.safetensors"), load_file(str(tmp_path / "x.safetensors"))
    assert ours.keys() == lib.keys()
    for k in lib:
        assert ours[k].dtype == lib[k].dtype
        np.testing.assert_array_equal(ours[k], lib[k])


def test_seam_correction_carries_the_context_offset_into_the_prediction(tmp_path):
    random_release(tmp_path, True, True, 10, 10)
    engine = Engine.load(tmp_path)
    raw = engine.seeds
    window = engine.forward(raw)
    offset = raw[:, -1, LAYOUT.positions] - window[:, 9, LAYOUT.positions]
    engine.seam_frames = 4.0
    pred = engine.predict_once(raw)
    np.testing.assert_allclose(pred[:, :, LAYOUT.positions] - window[:, 10:, LAYOUT.positions],
                               np.exp(-np.arange(1, 11) / 4.0)[None, :, None] * offset[:, None], atol=1e-4)
    np.testing.assert_allclose(pred[:, :, LAYOUT.velocity], window[:, 10:, LAYOUT.velocity], atol=1e-6)


def test_prediction_reads_the_context_and_its_mirror_image(tmp_path):
    """``predict`` averages the model's reading of each context and of its mirror image (mirrored back),
    so predicting a mirrored context gives the mirrored prediction; a random model alone does not."""
    random_release(tmp_path, True, True, 10, 10, offsets=True)
    engine = Engine.load(tmp_path)
    raw = engine.seeds
    once, mirrored_once = engine.predict_once(raw), engine.predict_once(mirror_features(raw))
    assert np.abs(mirror_features(mirrored_once) - once).max() > 1e-2  # one reading is not mirror-symmetric
    for b in (1, len(raw)):  # one context (two matrix-vector passes) and a batch
        pred = engine.predict(raw[:b])
        np.testing.assert_allclose(pred, 0.5 * (once[:b] + mirror_features(mirrored_once[:b])), atol=1e-5)
        np.testing.assert_allclose(engine.predict(mirror_features(raw[:b])), mirror_features(pred), atol=1e-5)
    engine.mirrored_reading = False
    np.testing.assert_allclose(engine.predict(raw), once, atol=1e-6)


def test_rows_matmul_is_the_matrix_product():
    rng = np.random.default_rng(0)
    w = rng.normal(size=(37, 23)).astype(np.float32)
    for rows in range(1, 7):
        a = rng.normal(size=(rows, 37)).astype(np.float32)
        np.testing.assert_allclose(rows_matmul(a, w), a @ w, rtol=1e-5, atol=1e-5)
    stack = rng.normal(size=(2, 3, 37)).astype(np.float32)
    np.testing.assert_allclose(stack_matmul(stack, np.stack([w, 2 * w])), np.matmul(stack, np.stack([w, 2 * w])),
                               rtol=1e-5, atol=1e-5)


def test_blend_track_keeps_consistent_data_and_takes_the_rates_when_weighted():
    from model_core.inference.engine import blend_track

    rng = np.random.default_rng(0)
    track = np.cumsum(rng.normal(size=(50, 2)), 0)
    steps = np.diff(track, axis=0)
    for weight in (0.0, 1.0, 1e4):  # data that agree with the rates are kept as they are
        np.testing.assert_allclose(blend_track(track, steps, weight), track, atol=1e-8)
    noisy = track + rng.normal(0, 0.5, track.shape)
    np.testing.assert_allclose(blend_track(noisy, steps, 0.0), noisy)  # weight 0: the noisy track
    stiff = blend_track(noisy, steps, 1e8)  # a large weight: the rates, placed at the noisy track's mean
    np.testing.assert_allclose(stiff - stiff.mean(0), track - track.mean(0), atol=1e-4)
    np.testing.assert_allclose(stiff.mean(0), noisy.mean(0), atol=1e-4)


def test_fit_yaw_shift_recovers_a_known_placement():
    from model_core.inference.engine import fit_yaw_shift
    from model_core.motion.features import yaw_matrix

    rng = np.random.default_rng(0)
    body = rng.normal(0, 0.4, (30, 21, 3))
    yaw = np.linspace(-3.0, 9.0, 30)  # more than a full turn: the fit comes back unwrapped
    shift = rng.normal(0, 2.0, (30, 3))
    target = np.einsum("fij,fkj->fki", yaw_matrix(yaw), body) + shift[:, None]
    got_yaw, got_shift = fit_yaw_shift(body, target)
    np.testing.assert_allclose(got_yaw - got_yaw[0] + yaw[0], yaw, atol=1e-9)
    np.testing.assert_allclose(got_shift, shift, atol=1e-9)


def test_a_companion_model_shares_the_first_window_only(tmp_path):
    """A release with a second STRNN (checkpoint.COMPANION): the first window of a rollout is the average of
    the two models' predictions, every later window the release's own, in both engines."""
    from model_core.io.checkpoint import COMPANION

    random_release(tmp_path / "alone", seed=0)
    random_release(tmp_path / "pair", seed=0)
    random_release(tmp_path / "pair" / COMPANION, seed=5)
    own, pair = Engine.load(tmp_path / "alone"), Engine.load(tmp_path / "pair")
    other = Engine.load(tmp_path / "pair" / COMPANION)
    assert own.companion is None and pair.companion is not None and other.companion is None
    seeds = pair.seeds
    lengths = bone_lengths(seeds)
    first = project_to_skeleton(0.5 * (own.predict(seeds) + other.predict(seeds)), lengths)
    out = pair.extrapolate(seeds, 2 * pair.n)
    np.testing.assert_allclose(out[:, :pair.n], first, atol=1e-5, rtol=0)
    rolled = np.concatenate([seeds, first], 1)[:, -pair.m:]
    np.testing.assert_allclose(out[:, pair.n:], project_to_skeleton(own.predict_next(rolled), lengths), atol=1e-5,
                               rtol=0)
    assert np.abs(out[:, :pair.n] - own.extrapolate(seeds, pair.n)).max() > 1e-3  # the companion counts
    in_torch = TorchEngine.load(tmp_path / "pair").extrapolate(seeds, 2 * pair.n)
    np.testing.assert_allclose(in_torch, out, atol=1e-4, rtol=0)
    # paired_windows=None (Fill Gap's bounded gaps): every window is the two models' average
    both = pair.extrapolate(seeds, 2 * pair.n, paired_windows=None)
    np.testing.assert_allclose(both[:, :pair.n], first, atol=1e-5, rtol=0)
    second = 0.5 * (own.predict(rolled) + other.predict(rolled))
    np.testing.assert_allclose(both[:, pair.n:], project_to_skeleton(second, lengths), atol=1e-5, rtol=0)
    alone = own.extrapolate(seeds, 2 * own.n, paired_windows=None)  # without a companion: nothing to pair
    own.decode_later_windows = True  # (every window of a bounded gap is decoded)
    np.testing.assert_allclose(alone, own.extrapolate(seeds, 2 * own.n))


def test_a_companion_of_a_shorter_window_continues_itself_as_far_and_one_of_a_longer_is_refused(tmp_path):
    """A release that predicts more frames than its companion (a release trained with ``--predict-len 30`` beside a
    20-frame companion): the companion's share of the first window is its own open loop continued as far (its
    second window reads its own first); a companion that predicts more than the release is refused."""
    from model_core.inference.engine import partner_ahead
    from model_core.io.checkpoint import COMPANION

    random_release(tmp_path / "pair", n=10)
    random_release(tmp_path / "pair" / COMPANION, n=4, seed=5)
    pair, other = Engine.load(tmp_path / "pair"), Engine.load(tmp_path / "pair" / COMPANION)
    alone = Engine.load(tmp_path / "pair")
    alone.companion = None
    seeds = pair.seeds
    first = other.predict(seeds)
    second = other.predict_next(np.concatenate([seeds, first], 1)[:, -other.m:])
    ahead = partner_ahead(other, seeds, 10)
    assert ahead.shape == (len(seeds), 10, seeds.shape[2])
    np.testing.assert_allclose(ahead[:, :4], first, atol=1e-6, rtol=0)
    np.testing.assert_allclose(ahead[:, 4:8], second, atol=1e-6, rtol=0)
    np.testing.assert_allclose(pair.predict_first(seeds), 0.5 * (alone.predict(seeds) + ahead), atol=1e-6, rtol=0)
    np.testing.assert_allclose(TorchEngine.load(tmp_path / "pair").predict_first(seeds), pair.predict_first(seeds),
                               atol=1e-4, rtol=0)
    random_release(tmp_path / "short", n=5)
    random_release(tmp_path / "short" / COMPANION, n=10)
    with pytest.raises(CheckpointError, match="companion"):
        Engine.load(tmp_path / "short")


def test_a_companion_that_reads_fewer_frames_reads_the_last_of_the_context_and_one_that_reads_more_is_refused(
        tmp_path):
    """A release that reads a longer context than its companion (a release trained with ``--encode-len 50`` beside
    a 20-frame companion): the companion reads the context's last frames; a companion that would need more
    frames than the release reads is refused, naming what to do."""
    from model_core.io.checkpoint import COMPANION

    random_release(tmp_path / "pair", m=12, n=10, seed=0)
    random_release(tmp_path / "pair" / COMPANION, m=6, n=10, seed=5)
    pair, other = Engine.load(tmp_path / "pair"), Engine.load(tmp_path / "pair" / COMPANION)
    alone = Engine.load(tmp_path / "pair")
    alone.companion = None
    seeds = pair.seeds
    assert seeds.shape[1] == 12 and pair.companion.m == 6
    np.testing.assert_allclose(pair.predict_first(seeds), 0.5 * (alone.predict(seeds) + other.predict(seeds[:, -6:])),
                               atol=1e-6, rtol=0)
    random_release(tmp_path / "wide", m=6, n=10, seed=0)
    random_release(tmp_path / "wide" / COMPANION, m=12, n=10, seed=5)
    with pytest.raises(CheckpointError, match="reads no more"):
        Engine.load(tmp_path / "wide")


def test_a_context_shorter_than_the_model_reads_is_led_in_by_its_first_frame(tmp_path):
    """A rollout from fewer frames than the model reads (a clip shorter than a long-context model's window): the
    missing frames before it are its first frame's features, so it continues as from that padded context, in
    both engines; a context of no frame is refused."""
    random_release(tmp_path / "r", m=12, n=10, seed=3)
    engine, in_torch = Engine.load(tmp_path / "r"), TorchEngine.load(tmp_path / "r")
    short = engine.seeds[:, -5:]
    padded = np.concatenate([np.repeat(short[:, :1], 7, 1), short], 1)
    np.testing.assert_allclose(engine.extrapolate(short, 25), engine.extrapolate(padded, 25), atol=1e-6, rtol=0)
    np.testing.assert_allclose(in_torch.extrapolate(short, 25), engine.extrapolate(padded, 25), atol=1e-4, rtol=0)
    np.testing.assert_array_equal(engine.full_context(engine.seeds), engine.seeds)
    with pytest.raises(ValueError, match="at least one context frame"):
        engine.extrapolate(short[:, :0], 5)


def test_the_shipped_model_carries_its_companion():
    engine = Engine.load()
    assert engine.companion is not None and engine.companion.m <= engine.m and engine.companion.n == engine.n
    assert engine.companion.ckpt.meta["training"]  # how it was made is in its model.json


def test_the_shipped_model_carries_its_regularised_model_fine_tuned_from_it_with_dropout():
    engine = Engine.load()
    reg = engine.regularised
    assert reg is not None and (reg.m, reg.n) == (engine.m, engine.n)
    training = reg.ckpt.meta["training"]  # how it was made is in its model.json: the release's command, with dropout
    assert "--dropout 0.2" in training["command"] and "--init models/strnn_default" in training["command"]
    assert training["init"]["training"]["command"] == engine.ckpt.meta["training"]["command"]


def test_a_regularised_model_shares_the_first_two_windows_as_far_as_the_motion_is_unfamiliar(tmp_path):
    """A release with a regularised STRNN (checkpoint.REGULARISED): with ``unfamiliar`` 0 a rollout is the release's
    own, exactly; with a share per seed, the first window's STRNNs (the release's reading averaged with its companion's)
    and its second window go that share of the way to the regularised model's, and the third window is the release's
    own again, in both engines. A regularised model that reads or predicts other frames than the release is
    refused."""
    from model_core.inference.engine import REGULARISED_WINDOWS
    from model_core.io.checkpoint import COMPANION, REGULARISED

    assert REGULARISED_WINDOWS == 2
    random_release(tmp_path / "alone", seed=0)
    random_release(tmp_path / "alone" / COMPANION, seed=5)
    random_release(tmp_path / "both", seed=0)
    random_release(tmp_path / "both" / COMPANION, seed=5)
    random_release(tmp_path / "both" / REGULARISED, seed=7)
    own, both = Engine.load(tmp_path / "alone"), Engine.load(tmp_path / "both")
    reg, comp = Engine.load(tmp_path / "both" / REGULARISED), Engine.load(tmp_path / "alone" / COMPANION)
    assert own.regularised is None and both.regularised is not None and reg.regularised is None
    seeds = both.seeds
    frames = 3 * both.n
    np.testing.assert_array_equal(both.extrapolate(seeds, frames), own.extrapolate(seeds, frames))
    share = np.linspace(0.0, 1.0, len(seeds)).astype(np.float32)
    out = both.extrapolate(seeds, frames, unfamiliar=share)
    lengths, s = bone_lengths(seeds), share[:, None, None]
    first = project_to_skeleton((1 - s) * 0.5 * (own.predict(seeds) + comp.predict(seeds)) + s * reg.predict(seeds),
                                lengths)
    np.testing.assert_allclose(out[:, :both.n], first, atol=1e-5, rtol=0)
    ctx = np.concatenate([seeds, first], 1)[:, -both.m:]
    second = project_to_skeleton((1 - s) * own.predict_next(ctx) + s * reg.predict_next(ctx), lengths)
    np.testing.assert_allclose(out[:, both.n:2 * both.n], second, atol=1e-5, rtol=0)
    ctx = np.concatenate([ctx, second], 1)[:, -both.m:]
    np.testing.assert_allclose(out[:, 2 * both.n:], project_to_skeleton(own.predict_next(ctx), lengths), atol=1e-5,
                               rtol=0)
    assert np.abs(out[-1, :2 * both.n] - own.extrapolate(seeds, frames)[-1, :2 * both.n]).max() > 1e-3  # it counts
    np.testing.assert_allclose(out[0], own.extrapolate(seeds, frames)[0], atol=1e-6, rtol=0)  # a share of 0: none
    in_torch = TorchEngine.load(tmp_path / "both").extrapolate(seeds, frames, unfamiliar=share)
    np.testing.assert_allclose(in_torch, out, atol=1e-4, rtol=0)
    random_release(tmp_path / "odd", m=10, n=10)
    random_release(tmp_path / "odd" / REGULARISED, m=10, n=5, seed=7)
    with pytest.raises(CheckpointError, match="regularised"):
        Engine.load(tmp_path / "odd")


def test_extend_leans_on_a_regularised_model_only_where_the_model_does_not_know_the_motion(tmp_path):
    """Extend (:func:`extend.extend_positions`) passes the clip's momentum share (how far the model does not know its
    motion; :func:`familiarity.momentum_shares`) as ``unfamiliar``: beside the shipped release, with a regularised
    model added (its companion standing in), a clip the model knows is extended exactly as before, one it does not
    know otherwise."""
    from model_core.io.checkpoint import COMPANION, REGULARISED
    from model_core.ops.extend import extend_positions
    from model_core.ops.familiarity import momentum_shares
    from model_core.ops.normalise import fit_normalisation

    release = tmp_path / "release"
    release.mkdir()
    for item in DEFAULT_MODEL.iterdir():
        if item.name != REGULARISED:
            (release / item.name).symlink_to(item)
    (release / REGULARISED).symlink_to(DEFAULT_MODEL / COMPANION)
    shipped, added = Engine.load(), Engine.load(release)
    shipped.regularised = None
    assert added.regularised is not None
    clips = [features_to_positions(seed) for seed in shipped.seeds]
    shares = [momentum_shares(shipped, fit_normalisation(c).to_model(c)[None])[0] for c in clips]
    known, unknown = shares.index(0.0), shares.index(1.0)
    for k, differs in ((known, False), (unknown, True)):
        before = extend_positions(shipped, clips[k], 30.0, 45)
        after = extend_positions(added, clips[k], 30.0, 45)
        assert (np.abs(after - before).max() > 1e-3) == differs, k
