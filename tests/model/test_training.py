"""Training: the model learns, a resumed run equals an uninterrupted one, and
data-parallel training runs under torchrun with two CPU processes."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch
from safetensors.numpy import load_file

from model_core.model.dataset import Normaliser
from model_core.model.strnn import STRNN, STRNNConfig, smoothness_cost
from model_core.model.training import (
    Mirror,
    TrainConfig,
    rolled_context,
    rollout_batch,
    train,
    window_loss,
    world_error,
    world_positions,
)
from model_core.motion.conventions import LAYOUT
from model_core.motion.features import features_to_positions, mirror_features, positions_to_features
from model_core.motion.synthetic import walking_skeleton

REPO = Path(__file__).resolve().parents[2]


def tiny(**kw) -> STRNNConfig:
    return STRNNConfig(**({"width": 16, "residual_width": 16} | kw))


def test_overfits_one_batch():
    torch.manual_seed(0)
    model = STRNN(tiny(dropout=0.0))
    x = torch.randn(8, 40, model.cfg.frame_size) * 0.5
    opt = torch.optim.Adam(model.parameters(), 5e-3)
    losses = []
    for _ in range(80):
        out = model(x[:, :20])
        loss = (out - x).pow(2).mean() + 0.1 * smoothness_cost(out)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.5 * losses[0]


def _cfg(folder: Path, out: Path, **kw) -> TrainConfig:
    args = dict(model=tiny(), steps=8, batch=8, cache="", val_every=4, checkpoint_seconds=1e9) | kw
    return TrainConfig(data=str(folder), out=str(out), **args)


def test_resume_equals_uninterrupted_run(walk_folder, tmp_path):
    whole = train(_cfg(walk_folder, tmp_path / "whole"), progress=False)
    cut = _cfg(walk_folder, tmp_path / "cut", max_minutes=1e-9)  # stops, with a checkpoint, after one step
    train(cut, progress=False)
    assert not (tmp_path / "cut" / "release").exists()
    resumed = train(_cfg(walk_folder, tmp_path / "cut"), resume=True, progress=False)
    assert "resumed at step 1" in (tmp_path / "cut" / "train.log").read_text()
    a, b = load_file(str(whole / "model.safetensors")), load_file(str(resumed / "model.safetensors"))
    assert a.keys() == b.keys()
    for k in a:
        np.testing.assert_allclose(a[k], b[k], atol=1e-6, err_msg=k)


def test_release_has_config_seeds_and_licence(walk_folder, tmp_path):
    import json

    release = train(_cfg(walk_folder, tmp_path / "run"), progress=False)
    doc = json.loads((release / "model.json").read_text())
    assert doc["config"]["width"] == 16 and doc["fps"] == 30.0
    assert len(doc["normalisation"]["mean"]) == doc["layout"]["size"]
    assert "CC BY-NC" not in doc["licence"] and "other training data" in doc["licence"]  # not Bandai data
    seeds = np.load(release / "seeds.npz", allow_pickle=False)
    assert seeds["features"].shape[1:] == (20, doc["layout"]["size"])


def test_mirror_flips_only_the_chosen_rows_exactly():
    rng = np.random.default_rng(0)
    raw = rng.normal(size=(4, 6, 70)).astype(np.float32)
    norm = Normaliser(rng.normal(size=70).astype(np.float32), rng.uniform(0.5, 2, 70).astype(np.float32))
    x = torch.from_numpy(norm.encode(raw).astype(np.float32))
    rows = np.array([True, False, True, False])
    out = Mirror(norm)(x, rows).numpy()
    np.testing.assert_allclose(norm.decode(out[rows]), mirror_features(raw[rows]), atol=1e-5)
    np.testing.assert_array_equal(out[~rows], x.numpy()[~rows])


def test_the_licence_follows_the_libraries_trained_on():
    from model_core.model.dataset import Clip, MotionData
    from model_core.model.training import licence_of

    clip = lambda name: Clip(name, "train", np.zeros((1, 21, 3)), np.zeros((1, 70)))  # noqa: E731
    both = MotionData("mocap", [clip("bandai-namco/dataset-2/a.bvh"), clip("cmu/iclone/001_01.bvh")])
    assert "CC BY-NC 4.0" in licence_of(both) and "mocap.cs.cmu.edu" in licence_of(both)
    assert "CC BY-NC" not in licence_of(MotionData("mocap", [clip("cmu/iclone/001_01.bvh")]))
    assert licence_of(MotionData("studio", [clip("take.bvh")])) == "the terms of the other training data (studio)"


def test_offsets_model_learns_and_hold_out_trains(walk_folder, tmp_path):
    cfg = TrainConfig(data=str(walk_folder), out=str(tmp_path / "run"), model=tiny(offsets=True), steps=30,
                      batch=8, cache=str(tmp_path / "cache"), val_every=1000, mirror=0.5, hold_out=True)
    release = train(cfg, progress=False)
    assert json.loads((release / "model.json").read_text())["config"]["offsets"] is True


def test_world_positions_play_normalised_features_as_the_motion_is_played():
    # a walk along a circle, so the heading turns and the track bends
    feats, _ = positions_to_features(walking_skeleton(frames=60, radius=2.0))
    norm = Normaliser.fit(feats)
    x = torch.from_numpy((feats - norm.mean) / norm.std)[None].double()
    ours = world_positions(x, torch.from_numpy(norm.mean).double(), torch.from_numpy(norm.std).double())
    np.testing.assert_allclose(ours[0].numpy(), features_to_positions(feats), atol=1e-5)


def test_the_world_loss_charges_a_body_that_falls_behind_its_take():
    n, step = 20, 0.04  # metres a frame straight ahead, at the right pace and 10 % slower
    truth = torch.zeros(1, n + 1, LAYOUT.size, dtype=torch.float64)
    truth[..., LAYOUT.velocity.start + 1] = step
    slow = truth[:, 1:].clone()
    slow[..., LAYOUT.velocity.start + 1] = 0.9 * step
    mean, std = torch.zeros(LAYOUT.size, dtype=torch.float64), torch.ones(LAYOUT.size, dtype=torch.float64)
    assert world_error(truth[:, 1:], truth, mean, std).item() == 0.0
    # the first new frame is where the context's last velocity leads; every step after it falls 4 mm behind
    behind = 0.1 * step * torch.arange(n, dtype=torch.float64)
    torch.testing.assert_close(world_error(slow, truth, mean, std), behind.pow(2).mean())
    # a poses-only loss sees only the velocity channel's 4 mm, not the 7.6 cm the body is behind at the end
    assert (slow - truth[:, 1:]).abs().max().item() < 0.0041


def test_the_world_weight_adds_the_world_error_of_the_predicted_frames(walk_folder, tmp_path):
    torch.manual_seed(0)
    model = STRNN(tiny(residual=False))
    model.eval()
    feats, _ = positions_to_features(walking_skeleton(frames=40, radius=2.0))
    norm = Normaliser.fit(feats)
    mean, std = torch.from_numpy(norm.mean), torch.from_numpy(norm.std)
    x = torch.from_numpy((feats - norm.mean) / norm.std)[None].repeat(3, 1, 1)
    plain = _cfg(Path("."), Path("."))
    weighted = _cfg(Path("."), Path("."), world_weight=7.0)
    with torch.no_grad():
        out = model(x[:, :20])
        expected = window_loss(model, x, plain, "spatio_temporal", 0.0) + 7.0 * world_error(out[:, 20:], x[:, 19:],
                                                                                             mean, std)
        torch.testing.assert_close(window_loss(model, x, weighted, "spatio_temporal", 0.0, norm=(mean, std)),
                                   expected)
    cfg = TrainConfig(data=str(walk_folder), out=str(tmp_path / "run"), model=tiny(offsets=True), steps=12,
                      batch=8, cache=str(tmp_path / "cache"), val_every=1000, world_weight=20.0)
    release = train(cfg, progress=False)  # every phase, the filter's fine-tuning with the world loss too
    weights = load_file(release / "model.safetensors")
    assert weights and all(np.isfinite(w).all() for w in weights.values())


def test_rolled_context_is_the_models_own_open_loop_output():
    torch.manual_seed(0)
    model = STRNN(tiny())
    model.train()
    x = torch.randn(3, 80, model.cfg.frame_size)
    ctx = rolled_context(model, x, 2)
    assert ctx.shape == (3, 20, model.cfg.frame_size) and model.training and not ctx.requires_grad
    model.eval()
    with torch.no_grad():
        first = model(x[:, :20])[:, 20:]
        again = rolled_context(model, x, 1, seam_frames=1e-6)  # no seam correction: the plain prediction
    torch.testing.assert_close(again, first)
    assert not torch.allclose(ctx, x[:, 40:60])  # generated, not the true frames


def test_rollout_batch_targets_the_own_context_then_the_truth():
    torch.manual_seed(0)
    model = STRNN(tiny())
    full = torch.randn(2, 80, model.cfg.frame_size)
    window, context = rollout_batch(model, full, 2)
    assert window.shape == (2, 40, model.cfg.frame_size)
    torch.testing.assert_close(window[:, :20], context)  # the decoder reconstructs what it was given
    torch.testing.assert_close(window[:, 20:], full[:, 60:80])  # the predictor continues with the truth


def test_recon_weight_weights_the_decoded_frames():
    torch.manual_seed(0)
    model = STRNN(tiny(residual=False))
    model.eval()
    x = torch.randn(4, 40, model.cfg.frame_size)
    base = _cfg(Path("."), Path("."), smooth_weight=0.0)
    heavy = _cfg(Path("."), Path("."), smooth_weight=0.0, recon_weight=3.0)
    with torch.no_grad():
        out = model(x[:, :20])
        dec, pred = (out[:, :20] - x[:, :20]).pow(2).mean(), (out[:, 20:] - x[:, 20:]).pow(2).mean()
        torch.testing.assert_close(window_loss(model, x, base, "spatio_temporal", 0.0), (dec + pred) / 2)
        torch.testing.assert_close(window_loss(model, x, heavy, "spatio_temporal", 0.0), (3 * dec + pred) / 4)


def test_rollout_fine_tuning_from_init(walk_folder, tmp_path):
    first = train(_cfg(walk_folder, tmp_path / "base"), progress=False)
    tuned = train(_cfg(walk_folder, tmp_path / "tuned", init=str(first), rollout_windows=2, rollout_fraction=1.0),
                  progress=False)
    assert "initial weights from" in (tmp_path / "tuned" / "train.log").read_text()
    import json

    record = json.loads((tuned / "model.json").read_text())["training"]["init"]
    assert record["from"] == str(first) and record["training"]["steps"] == 8  # the whole recipe is named
    a, b = load_file(str(first / "model.safetensors")), load_file(str(tuned / "model.safetensors"))
    assert any(not np.allclose(a[k], b[k]) for k in a)  # trained on from there
    state = torch.load(tmp_path / "base" / "train_state.pt", weights_only=True)["model"]
    fresh = train(_cfg(walk_folder, tmp_path / "from_state", init=str(tmp_path / "base" / "train_state.pt"),
                       steps=0), progress=False)
    got = load_file(str(fresh / "model.safetensors"))
    for k in got:
        np.testing.assert_allclose(got[k], state[k].numpy(), err_msg=k)


def test_a_filter_that_reads_the_context_starts_from_a_filter_that_did_not(walk_folder, tmp_path):
    """``--init`` from a model whose filter read only the window: the new filter starts as that one (the
    true context's input weights at zero), so before training both give the same window."""
    first = train(_cfg(walk_folder, tmp_path / "base"), progress=False)
    reads = _cfg(walk_folder, tmp_path / "reads", model=tiny(filter_context=True), init=str(first), steps=0)
    second = train(reads, progress=False)
    a, b = load_file(str(first / "model.safetensors")), load_file(str(second / "model.safetensors"))
    w = b["filter.net.0.weight"]
    n = a["filter.net.0.weight"].shape[1]
    np.testing.assert_array_equal(w[:, :n], a["filter.net.0.weight"])
    assert w.shape[1] == n + 20 * reads.model.frame_size and not w[:, n:].any()
    x = torch.randn(3, 20, reads.model.frame_size)
    old, new = STRNN(tiny()), STRNN(tiny(filter_context=True))
    old.load_state_dict({k: torch.from_numpy(v) for k, v in a.items()}, strict=False)
    new.load_state_dict({k: torch.from_numpy(v) for k, v in b.items()}, strict=False)
    old.eval(), new.eval()
    with torch.no_grad():
        torch.testing.assert_close(new(x), old(x))


def test_a_longer_context_starts_with_the_filter_it_comes_from_on_the_frames_it_knew(walk_folder, tmp_path):
    """``--init`` into a model that reads more context frames (``--encode-len``): every weight but the residual
    filter's is taken as it is, and the filter is set into the place of the window's last frames, the earlier
    frames' weights at zero: on any window it corrects the last frames as the old filter did and leaves the
    earlier ones alone."""
    first = train(_cfg(walk_folder, tmp_path / "base"), progress=False)
    longer = _cfg(walk_folder, tmp_path / "longer", model=tiny(encode_len=30), init=str(first), steps=0)
    second = train(longer, progress=False)
    a, b = load_file(str(first / "model.safetensors")), load_file(str(second / "model.safetensors"))
    assert b["filter.net.0.weight"].shape[1] == a["filter.net.0.weight"].shape[1] + 10 * longer.model.frame_size
    for k in a:
        if not k.startswith("filter.net.0.") and not k.startswith("filter.net.6."):
            np.testing.assert_array_equal(b[k], a[k], err_msg=k)
    old, new = STRNN(tiny()), STRNN(tiny(encode_len=30))
    old.load_state_dict({k: torch.from_numpy(v) for k, v in a.items()}, strict=False)
    new.load_state_dict({k: torch.from_numpy(v) for k, v in b.items()}, strict=False)
    window = torch.randn(3, 50, longer.model.frame_size)
    with torch.no_grad():
        grown, known = new.filter(window), old.filter(window[:, 10:])
    torch.testing.assert_close(grown[:, 10:], known)
    torch.testing.assert_close(grown[:, :10], window[:, :10])
    assert (known - window[:, 10:]).abs().max() > 1e-4  # the old filter does correct those frames


def test_a_longer_prediction_starts_with_the_filter_it_comes_from_on_the_frames_it_knew(walk_folder, tmp_path):
    """``--init`` into a model that predicts more frames (``--predict-len``): the filter is set into the place of
    the window's first frames (the reconstructed ones and the prediction's first), the new last frames' weights at
    zero: it corrects the frames it knew as the old filter did and leaves the new ones alone."""
    first = train(_cfg(walk_folder, tmp_path / "base"), progress=False)
    longer = _cfg(walk_folder, tmp_path / "longer", model=tiny(predict_len=tiny().predict_len + 10), init=str(first),
                  steps=0)
    second = train(longer, progress=False)
    a, b = load_file(str(first / "model.safetensors")), load_file(str(second / "model.safetensors"))
    old, new = STRNN(tiny()), STRNN(longer.model)
    old.load_state_dict({k: torch.from_numpy(v) for k, v in a.items()}, strict=False)
    new.load_state_dict({k: torch.from_numpy(v) for k, v in b.items()}, strict=False)
    known_len = old.cfg.recon_len + old.cfg.predict_len
    window = torch.randn(3, known_len + 10, longer.model.frame_size)
    with torch.no_grad():
        grown, known = new.filter(window), old.filter(window[:, :known_len])
    torch.testing.assert_close(grown[:, :known_len], known)
    torch.testing.assert_close(grown[:, known_len:], window[:, known_len:])
    assert (known - window[:, :known_len]).abs().max() > 1e-4  # the old filter does correct those frames


def test_a_longer_context_that_decodes_the_last_frames_starts_as_the_model_it_comes_from(walk_folder, tmp_path):
    """``--encode-len 30 --decode-len 20`` from a 20-frame model: every weight is taken as it is (the window the
    decoder and filter cover is as long), training moves them, and the release records both lengths and runs
    in the engine."""
    from model_core.inference.engine import Engine

    first = train(_cfg(walk_folder, tmp_path / "base"), progress=False)
    start = train(_cfg(walk_folder, tmp_path / "start", model=tiny(encode_len=30, decode_len=20), init=str(first),
                       steps=0), progress=False)
    a, b = load_file(str(first / "model.safetensors")), load_file(str(start / "model.safetensors"))
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    tuned = train(_cfg(walk_folder, tmp_path / "tuned", model=tiny(encode_len=30, decode_len=20), init=str(first)),
                  progress=False)
    assert any(not np.array_equal(a[k], v) for k, v in load_file(str(tuned / "model.safetensors")).items())
    engine = Engine.load(tuned)
    assert (engine.m, engine.r) == (30, 20) and engine.ckpt.config["decode_len"] == 20
    assert engine.seeds.shape[1] == 30 and np.isfinite(engine.extrapolate(engine.seeds, 25)).all()
    assert "decode_len" not in STRNNConfig().to_dict()  # releases without it read as before


def test_a_predictor_that_reads_the_context_starts_as_the_model_it_comes_from_and_learns_to(walk_folder, tmp_path):
    """``--init`` from a model without ``predictor_context``: the new map starts at zero (the same model),
    and training moves it."""
    first = train(_cfg(walk_folder, tmp_path / "base"), progress=False)
    start = train(_cfg(walk_folder, tmp_path / "start", model=tiny(predictor_context=True), init=str(first),
                       steps=0), progress=False)
    assert not load_file(str(start / "model.safetensors"))["context_in.weight"].any()
    tuned = train(_cfg(walk_folder, tmp_path / "tuned", model=tiny(predictor_context=True), init=str(first)),
                  progress=False)
    assert load_file(str(tuned / "model.safetensors"))["context_in.weight"].any()
    skip = train(_cfg(walk_folder, tmp_path / "skip", model=tiny(temporal_skip=True), init=str(first)),
                 progress=False)
    assert load_file(str(skip / "model.safetensors"))["skip"].any()
    both_ends = train(_cfg(walk_folder, tmp_path / "both_ends", model=tiny(decoder_skip=True), init=str(first)),
                      progress=False)
    assert load_file(str(both_ends / "model.safetensors"))["dec_skip.weight"].any()


def test_torchrun_two_cpu_processes(walk_folder, tmp_path):
    torchrun = Path(sys.executable).parent / "torchrun"
    if not torchrun.exists():
        pytest.skip("torchrun is not installed beside this Python")
    out, ranks = tmp_path / "ddp", tmp_path / "ranks"
    # each rank's own output goes to its file, with Python's stacks on a fatal signal, so that a failure says
    # where each rank was (a rank aborted at teardown about once in 60 runs, without a stack, before train.leave)
    cmd = [str(torchrun), "--standalone", "--nproc_per_node", "2", "--log-dir", str(ranks), "--redirects", "3",
           str(REPO / "scripts" / "train.py"),
           "--data", str(walk_folder), "--out", str(out), "--steps", "10", "--batch", "8", "--width", "16",
           "--residual-width", "16", "--cache", "", "--quiet", "--threads", "1"]
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONFAULTHANDLER="1")
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=env)
    each = "".join(f"\n--- {f.relative_to(ranks)}:\n{f.read_text()[-3000:]}" for f in sorted(ranks.rglob("*.log")))
    assert done.returncode == 0, done.stderr[-1500:] + each
    assert (out / "release" / "model.safetensors").exists()
    log = (out / "train.log").read_text()
    assert "phase residual_finetune" in log


def test_a_torchrun_worker_leaves_without_the_interpreters_teardown(tmp_path):
    """A worker's exit code and output come through ``leave`` (which skips the teardown that gloo can abort); a
    process outside torchrun returns its code as before."""
    probe = (f"import sys; sys.path.insert(0, {str(REPO / 'scripts')!r}); import train; print('written'); "
             "import atexit; atexit.register(print, 'teardown'); code = train.leave(3); print('returned', code)")
    env = dict(os.environ, WORLD_SIZE="2")
    worker = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, env=env,
                            cwd=REPO)
    assert worker.returncode == 3 and worker.stdout.split() == ["written"], worker.stdout + worker.stderr
    env.pop("WORLD_SIZE")
    alone = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, env=env,
                           cwd=REPO)
    assert alone.returncode == 0 and alone.stdout.split() == ["written", "returned", "3", "teardown"], alone.stderr


def test_seeds_come_from_another_split_when_the_folder_has_no_test_take(walk_folder):
    """A folder whose takes all fall in the training split still gets seeds (a release needs them)."""
    import dataclasses

    from model_core.model.dataset import MotionData, load_folder
    from model_core.model.training import pick_seeds

    data = load_folder(walk_folder, cache_dir=None, progress=False)
    only_train = MotionData(data.root, [dataclasses.replace(c, split="train") for c in data.clips])
    seeds, names = pick_seeds(only_train, 20)
    assert len(seeds) >= 1 and seeds.shape[1] == 20 and len(names) == len(seeds)
    short = MotionData(data.root, [dataclasses.replace(c, features=c.features[:5]) for c in data.clips])
    with pytest.raises(ValueError, match="no clip has 20 frames"):
        pick_seeds(short, 20)


def test_a_run_that_cannot_start_says_why_and_leaves_no_run_folder(walk_folder, tmp_path):
    """Checked before any work: an --out that cannot be written, an --init of another width, a data folder
    without takes. Each is one error, and no run folder is left behind."""
    blocked = tmp_path / "file"
    blocked.write_text("")
    with pytest.raises(ValueError, match="cannot write there"):
        train(_cfg(walk_folder, blocked / "run"), progress=False)
    wide = train(_cfg(walk_folder, tmp_path / "wide", model=tiny(width=64)), progress=False)
    with pytest.raises(ValueError, match="same width"):
        train(_cfg(walk_folder, tmp_path / "narrow", model=tiny(width=32), init=str(wide)), progress=False)
    assert not (tmp_path / "narrow").exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="no .bvh files"):
        train(_cfg(empty, tmp_path / "nothing"), progress=False)
    assert not (tmp_path / "nothing").exists()


def test_the_device_is_checked_before_any_work(walk_folder, tmp_path, capsys):
    """``--device``: a device this machine lacks, or a name torch does not know, is one clear error and leaves
    no run folder; the baselines train on the CPU only and say so."""
    sys.path.insert(0, str(REPO / "scripts"))
    from train import main

    missing = "cuda:7" if torch.cuda.is_available() else "cuda"
    for device, says in ((missing, "CUDA device"), ("warp9", "not a torch device")):
        out = tmp_path / device.replace(":", "_")
        assert main(["--data", str(walk_folder), "--out", str(out), "--steps", "1", "--device", device]) == 2
        assert says in capsys.readouterr().err and not out.exists(), device
    assert main(["--data", str(walk_folder), "--out", str(tmp_path / "g"), "--arch", "residual_gru",
                 "--steps", "1", "--device", "cuda"]) == 2
    assert "for STRNN runs" in capsys.readouterr().err and not (tmp_path / "g").exists()


def test_fine_tuning_a_release_with_partners_says_how_to_carry_them(walk_folder, tmp_path, capsys):
    sys.path.insert(0, str(REPO / "scripts"))
    import shutil

    from train import main

    tiny_run = ["--data", str(walk_folder), "--width", "16", "--residual-width", "16", "--steps", "2",
                "--batch", "4", "--quiet"]
    assert main([*tiny_run, "--out", str(tmp_path / "base")]) == 0
    base = tmp_path / "base" / "release"
    capsys.readouterr()
    assert main([*tiny_run, "--out", str(tmp_path / "plain"), "--init", str(base)]) == 0
    assert "companion" not in capsys.readouterr().err
    shutil.copytree(base, base / "companion", ignore=shutil.ignore_patterns("companion"))
    assert main([*tiny_run, "--out", str(tmp_path / "tuned"), "--init", str(base)]) == 0
    err = capsys.readouterr().err
    assert "companion" in err and str(tmp_path / "tuned" / "release" / "companion") in err
    assert not (tmp_path / "tuned" / "release" / "companion").exists()
    assert "siMLPe" not in err
    shutil.copytree(REPO / "models" / "baseline_simlpe", base / "simlpe")
    assert main([*tiny_run, "--out", str(tmp_path / "tuned2"), "--init", str(base)]) == 0
    err = capsys.readouterr().err
    assert "siMLPe (simlpe/)" in err and str(tmp_path / "tuned2" / "release" / "simlpe") in err
    assert "regularised" not in err
    shutil.copytree(base, base / "regularised", ignore=shutil.ignore_patterns("companion", "simlpe", "regularised"))
    assert main([*tiny_run, "--out", str(tmp_path / "tuned3"), "--init", str(base)]) == 0
    err = capsys.readouterr().err
    assert "regularised model (regularised/)" in err and "--dropout 0.2" in err
    assert str(tmp_path / "tuned3" / "release" / "regularised") in err


def test_noisy_contexts_with_rotation_jitter_keep_bone_lengths_and_position_noise_does_not(walk_folder):
    """``denoise_rotation_deg``: half of the noisy contexts turn the joints (bones keep their lengths), the
    others move them (bones stretch); all differ from the clean context."""
    from model_core.eval.metrics import bone_lengths_of
    from model_core.model.dataset import Normaliser, load_folder
    from model_core.model.training import Windows
    from model_core.motion.features import features_to_positions

    data = load_folder(walk_folder, cache_dir=None, progress=False)
    windows = Windows(data, "train", Normaliser.fit(np.concatenate([c.features for c in data.clips])), 40)
    idx = np.arange(40)
    noisy = windows.noisy_contexts(idx, 20, 3.0, np.random.default_rng(0), max_deg=3.0).numpy()
    clean = windows.batch(idx)[:, :20].numpy()
    kept = []
    for n, c in zip(noisy, clean):
        got, want = (bone_lengths_of(features_to_positions(windows.norm.decode(x))) for x in (n, c))
        kept.append(np.abs(got - want).max() < 1e-4)
        assert np.abs(n - c).max() > 1e-3
    assert 5 < sum(kept) < 35  # about half turned, half moved


def test_time_warped_windows_play_the_clip_faster_or_slower_and_stay_in_it(walk_folder):
    """``time_warp``: a window at speed 1 is the window itself; at speed 2 it holds every second frame of
    the clip with the root's per-frame motion doubled (so its ground path is the clip's, sampled); a window
    that speed would carry past its clip's end reads no frame of the next clip; contacts stay 0 or 1."""
    from model_core.model.dataset import Normaliser, load_folder
    from model_core.model.training import Windows
    from model_core.motion.conventions import LAYOUT
    from model_core.motion.features import features_to_positions

    data = load_folder(walk_folder, cache_dir=None, progress=False)
    windows = Windows(data, "train", Normaliser.fit(np.concatenate([c.features for c in data.clips])), 40)
    idx = np.arange(len(windows))
    same = windows.raw_frames(idx[:16], np.ones(16))
    np.testing.assert_allclose(same, windows.raw[windows.starts[:16, None] + windows.span], atol=1e-6)
    np.testing.assert_allclose(windows.batch(idx[:16], np.ones(16)).numpy(), windows.batch(idx[:16]).numpy(),
                               atol=1e-5)

    fits = idx[windows.starts + 2 * 39 < windows.ends - 1][:8]
    assert len(fits)
    fast = windows.raw_frames(fits, np.full(len(fits), 2.0))
    for w, s in zip(fast, windows.starts[fits]):
        clip = windows.raw[s:s + 79]
        np.testing.assert_allclose(w[:, LAYOUT.positions], clip[::2, LAYOUT.positions], atol=1e-6)
        np.testing.assert_allclose(w[:, LAYOUT.root], 2 * clip[::2, LAYOUT.root], atol=1e-6)
        ground = features_to_positions(w)[:, 0, [0, 2]]
        truth = features_to_positions(clip)[::2, 0, [0, 2]]
        assert np.abs(ground - truth).max() < 0.05  # the same path, from sampled per-frame motion

    last = idx[windows.ends - windows.starts == 40]  # windows that end at their clip's last frame
    assert len(last)
    squeezed = windows.raw_frames(last, np.full(len(last), 1.25))
    np.testing.assert_allclose(squeezed, windows.raw[windows.starts[last, None] + windows.span], atol=1e-6)
    slow = windows.raw_frames(idx, np.full(len(idx), 0.8))
    assert set(np.unique(slow[..., LAYOUT.contacts])) <= {0.0, 1.0}
    # noisy contexts (no noise here) are re-derived from the same warped frames: the body's own heading
    # against the sampled turn rate differs by at most about a centimetre
    noisy = windows.noisy_contexts(fits, 20, 0.0, np.random.default_rng(0), speeds=np.full(len(fits), 2.0))
    gap = np.abs(windows.norm.decode(noisy.numpy()) - fast[:, :20])[..., LAYOUT.positions]
    assert gap.mean() < 1e-3 and gap.max() < 0.02


def test_a_time_warped_run_trains_and_records_its_speed_range(walk_folder, tmp_path):
    release = train(_cfg(walk_folder, tmp_path / "warp", time_warp=0.25, denoise_fraction=0.5), progress=False)
    assert (release / "model.safetensors").exists()
    assert '"time_warp": 0.25' in (tmp_path / "warp" / "train.log").read_text()  # the run's config, as logged
    r = subprocess.run([sys.executable, str(REPO / "scripts" / "train.py"), "--data", str(walk_folder), "--out",
                        str(tmp_path / "bad"), "--time-warp", "-1"], capture_output=True, text=True)
    assert r.returncode == 2 and "--time-warp" in r.stderr and not (tmp_path / "bad").exists()


def test_body_proportions_scale_the_torso_and_arms_and_keep_the_legs_and_the_root(walk_folder):
    """``proportions``: a window's torso and arm bones grow or shrink by their factors, each keeping its
    direction; the hips, legs and feet, the root's motion and the contacts stay as they were."""
    from model_core.eval.metrics import bone_lengths_of
    from model_core.model.dataset import Normaliser, load_folder
    from model_core.model.training import Windows
    from model_core.motion.conventions import JOINT_INDEX, LAYOUT, PARENTS
    from model_core.motion.features import PROPORTION_BONES, features_to_positions, scale_proportions

    data = load_folder(walk_folder, cache_dir=None, progress=False)
    windows = Windows(data, "train", Normaliser.fit(np.concatenate([c.features for c in data.clips])), 40)
    idx = np.arange(6)
    raw = windows.raw_frames(idx, None)
    np.testing.assert_allclose(scale_proportions(raw, np.ones(6), np.ones(6)), raw, atol=1e-6)
    torso, arms = np.array([0.9, 1.1, 1.2, 0.8, 1.0, 1.05]), np.array([1.1, 0.9, 1.0, 1.2, 0.85, 1.0])
    out = windows.raw_frames(idx, None, bodies=np.stack([torso, arms], 1))
    legs = [JOINT_INDEX[f"{s}_{j}"] for s in "lr" for j in ("upleg", "knee", "foot", "toe")] + [JOINT_INDEX["hips"]]
    for w in range(6):
        before, after = features_to_positions(raw[w]), features_to_positions(out[w])
        np.testing.assert_allclose(after[:, legs], before[:, legs], atol=1e-5)
        ratio = bone_lengths_of(after) / bone_lengths_of(before)
        want = np.ones(len(PARENTS))
        want[PROPORTION_BONES["torso"]], want[PROPORTION_BONES["arms"]] = torso[w], arms[w]
        np.testing.assert_allclose(ratio, np.broadcast_to(want[1:], ratio.shape), rtol=1e-3)  # [frames, bones]
        bone = lambda p: (p - p[:, PARENTS.clip(0)])[:, 1:]  # noqa: E731
        cos = (bone(after) * bone(before)).sum(-1) / (np.linalg.norm(bone(after), axis=-1)
                                                       * np.linalg.norm(bone(before), axis=-1))
        assert cos.min() > 1 - 1e-5  # every bone keeps its direction
    np.testing.assert_array_equal(out[..., LAYOUT.root], raw[..., LAYOUT.root])
    np.testing.assert_array_equal(out[..., LAYOUT.contacts], raw[..., LAYOUT.contacts])


def test_a_run_with_body_proportions_trains_and_a_bad_range_is_refused(walk_folder, tmp_path):
    release = train(_cfg(walk_folder, tmp_path / "bodies", proportions=0.1, time_warp=0.2, denoise_fraction=0.5),
                    progress=False)
    assert (release / "model.safetensors").exists()
    assert '"proportions": 0.1' in (tmp_path / "bodies" / "train.log").read_text()
    r = subprocess.run([sys.executable, str(REPO / "scripts" / "train.py"), "--data", str(walk_folder), "--out",
                        str(tmp_path / "bad"), "--proportions", "1.5"], capture_output=True, text=True)
    assert r.returncode == 2 and "--proportions" in r.stderr and not (tmp_path / "bad").exists()
