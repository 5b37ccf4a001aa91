"""Curve-driven synthesis: costs, the fine-tune / restore loop, determinism; and a trained
model walking the evaluation paths (skipped while no model is trained)."""

from __future__ import annotations

from pathlib import Path as FilePath

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from releases import random_release  # noqa: E402

from model_core.eval.metrics import bone_lengths_of as bone_lengths  # noqa: E402
from model_core.inference.steps import drive  # noqa: E402
from model_core.io.checkpoint import load_release  # noqa: E402
from model_core.motion.conventions import CONTACT_JOINTS, LAYOUT, PARENTS  # noqa: E402
from model_core.motion.features import features_to_positions, heading, positions_to_features  # noqa: E402
from model_core.motion.synthetic import walking_skeleton  # noqa: E402
from model_core.ops import footlock as fl  # noqa: E402
from model_core.ops.follow import (  # noqa: E402
    ControlSettings,
    PathFollower,
    align_to_path,
    follow_curve_positions,
    follow_curve_steps,
    follow_path,
    follow_path_steps,
    foot_speed_cm,
)
from model_core.ops.paths import Path, evaluation_paths, path_errors_cm  # noqa: E402

REPO = FilePath(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # small models: threads cost more than they give
    yield
    torch.set_num_threads(threads)


@pytest.fixture
def follower(tmp_path):
    random_release(tmp_path / "release")
    return lambda **kw: PathFollower(load_release(tmp_path / "release"), ControlSettings(**kw))


def straight(length=10.0):
    return Path(np.stack([np.zeros(101), np.linspace(0, length, 101)], -1))


def test_foot_speed_matches_the_positions():
    pos = walking_skeleton(30)
    feats, _ = positions_to_features(pos)
    speed = foot_speed_cm(torch.from_numpy(feats.astype(np.float64))).numpy()
    back = features_to_positions(feats)[:, CONTACT_JOINTS][..., [0, 2]]
    np.testing.assert_allclose(speed, 100 * np.linalg.norm(np.diff(back, axis=0), axis=-1), atol=1e-3)


def test_fine_tuning_pulls_the_window_to_the_control_and_restores_the_weights(follower):
    f0, f4 = follower(steps=0), follower(steps=8, lr=1e-2)
    ctx = f0.ckpt.seeds[0]
    control = np.tile([0.0, 0.05, 0.02], (f0.n, 1)).astype(np.float32)
    lengths = np.full(20, 0.2, np.float32)
    before = [p.detach().clone() for p in f4.model.parameters()]
    plain, tuned = f0.window(ctx, control, lengths), f4.window(ctx, control, lengths)
    std = f0.ckpt.std[LAYOUT.root]
    gap = lambda w: np.mean(((w[:, LAYOUT.root] - control) / std) ** 2)  # noqa: E731
    assert gap(tuned) < 0.9 * gap(plain)
    assert all(torch.equal(a, b) for a, b in zip(before, f4.model.parameters())), "weights restored"
    np.testing.assert_allclose(f4.window(ctx, control, lengths), tuned, atol=1e-6)  # every window starts afresh


def test_costs_are_zero_where_they_should_be(follower):
    f = follower()
    feats, _ = positions_to_features(walking_skeleton(f.n + 1))
    raw = torch.from_numpy(feats)
    out = (raw[1:] - f.mean) / f.std
    local = feats[:, LAYOUT.positions].reshape(len(feats), -1, 3)
    lengths = torch.from_numpy(np.linalg.norm(local[0, 1:] - local[0, PARENTS[1:]], axis=-1).astype(np.float32))
    cost = f.costs(raw[0], out, out[:, LAYOUT.root], lengths)
    assert cost["ctr"].item() < 1e-10 and cost["bone"].item() < 1e-8 and cost["fp"].item() >= 0


def test_follow_is_deterministic_and_has_the_asked_length(follower):
    seed = walking_skeleton(40)
    a, fa = follow_path(follower(steps=2), seed, straight(), frames=45)
    b, fb = follow_path(follower(steps=2), seed, straight(), frames=45)
    assert a.shape == (45, 21, 3) and fa.shape == (45, LAYOUT.size)
    np.testing.assert_array_equal(a, b)
    assert np.isfinite(a).all()


def test_steps_report_each_window_and_give_the_same_walk(follower):
    seed, f = walking_skeleton(40), follower(steps=2)
    fractions = []
    stepped = drive(follow_path_steps(f, seed, straight(), frames=45), fractions.append)
    windows = -(-45 // f.n)
    assert fractions == [min(k * f.n / 45, 1.0) for k in range(1, windows + 1)]  # after each n-frame window
    np.testing.assert_array_equal(stepped[0], follow_path(follower(steps=2), seed, straight(), frames=45)[0])


def test_closing_the_steps_part_way_leaves_the_follower_as_it_was(follower):
    f = follower(steps=3, lr=1e-2, threads=1)
    settings, weights = f.settings, [p.detach().clone() for p in f.model.parameters()]
    curve = np.stack([np.linspace(0, 6, 50), np.zeros(50), np.zeros(50)], -1)
    steps = follow_curve_steps(f, curve, False, 24.0, speed=1.5, rest=walking_skeleton(1)[0])
    assert next(steps) > 0 and f.settings is not settings  # running with the asked speed
    steps.close()
    assert f.settings is settings
    assert all(torch.equal(a, b) for a, b in zip(weights, f.model.parameters()))


def test_frames_default_to_the_end_of_the_path(follower):
    pos, _ = follow_path(follower(steps=0, speed=2.0), walking_skeleton(40), straight(5.0))
    assert len(pos) == 75  # 5 m at 2 m/s, 30 fps


def test_unknown_tune_option(follower):
    with pytest.raises(ValueError, match="tune"):
        follower(tune="encoder")


def trained_release() -> FilePath | None:
    for folder in [REPO / "models" / "strnn_default", *sorted(REPO.glob("runs/*/release"))]:
        if (folder / "model.json").exists():
            return folder
    return None


@pytest.mark.parametrize("name", ["line", "circle"])
def test_trained_model_walks_the_path(name):
    folder = trained_release()
    if folder is None:
        pytest.skip("no trained model (models/strnn_default or runs/*/release)")
    f = PathFollower.load(folder)
    walk = [i for i, n in enumerate(f.ckpt.seed_names) if "walk" in n] or [0]
    points, cyclic = evaluation_paths()[name]
    path = Path(points, cyclic)
    pos, feats = follow_path(f, features_to_positions(f.ckpt.seeds[walk[0]]), path, frames=150)
    mean, worst = path_errors_cm(pos[:, 0], path)
    print(f"{folder.parent.name} {name}: path error mean {mean:.1f} cm, max {worst:.1f} cm")
    assert np.isfinite(pos).all() and mean <= 20 and worst <= 60  # loose: any trained release may be here
    contacts = fl.contacts_from_features(feats)
    locked = fl.foot_lock(pos, contacts=contacts)
    assert fl.knee_pops(locked) <= fl.knee_pops(pos)


def test_curve_positions_continue_a_clip_in_scene_units(follower):
    f = follower(steps=1)
    clip = walking_skeleton(30, fps=24.0) * 100.0  # centimetres at 24 fps
    curve = np.stack([np.linspace(0, 300, 50), np.zeros(50), np.linspace(0, 500, 50)], -1)
    out = follow_curve_positions(f, curve, False, 24.0, frames=40, context=clip)
    assert out.shape == (40, 21, 3) and np.isfinite(out).all()
    legs = lambda p: np.linalg.norm(p[:, 9] - p[:, 10], axis=-1).mean()  # noqa: E731 (r_upleg - r_knee)
    assert legs(out) == pytest.approx(legs(clip), rel=0.2)


def test_curve_positions_start_from_a_shipped_seed_on_the_curve(follower):
    f = follower(steps=0, speed=1.0)
    rest = walking_skeleton(1)[0] * 2.0  # a character twice the standard size
    curve = np.stack([np.full(20, 5.0), np.zeros(20), np.linspace(0, 4, 20)], -1)
    out = follow_curve_positions(f, curve, False, 30.0, rest=rest, speed=2.0)
    assert len(out) == 60 and np.isfinite(out).all()  # 4 scene units at 2 per second, 30 fps


def test_align_to_path_puts_the_seed_on_the_start():
    path = Path(np.stack([np.linspace(3, 8, 20), np.full(20, -2.0)], -1))  # heading +X from (3, -2)
    seed = align_to_path(walking_skeleton(20), path)
    np.testing.assert_allclose(seed[-1, 0, [0, 2]], [3.0, -2.0], atol=1e-5)
    assert heading(seed)[-1] == pytest.approx(np.pi / 2, abs=1e-3)
    np.testing.assert_allclose(bone_lengths(seed), bone_lengths(walking_skeleton(20)), atol=1e-5)


@pytest.mark.parametrize("spatial,residual", [(True, True), (False, False)])
def test_predictor_pass_equals_the_full_model(tmp_path, spatial, residual):
    random_release(tmp_path / "r", spatial=spatial, residual=residual)
    f = PathFollower(load_release(tmp_path / "r"))
    x = torch.randn(1, f.m, LAYOUT.size)
    with torch.no_grad():
        torch.testing.assert_close(f._predictor_pass(x)(), f.model(x)[0, f.m:])


def test_path_evaluation_section(follower):
    from types import SimpleNamespace

    from model_core.eval.path_evaluation import evaluate_paths

    clips = [SimpleNamespace(name=f"walk_{i}", positions=walking_skeleton(60)) for i in range(2)]
    out = evaluate_paths(follower(steps=0, speed=3.0), clips, seeds=1, log=lambda m: None)
    assert out["names"] == ["line", "circle", "s_curve", "figure_eight"]
    for key in ("mean_cm", "max_cm", "bone_error"):
        assert len(out[key]) == 4 and all(np.isfinite(out[key]))
    assert len(out["foot_skate_cm"]["raw"]) == len(out["knee_pops"]["locked"]) == 4
    assert out["seed_clips"] == ["walk_0"] and out["frames_per_second"] > 0
