"""Denoise that trusts the input as much as it deserves: noise level, pops, the banded solve, and
the bundled denoising model through the product path on a procedural walk at 30 and 60 fps."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.eval.metrics import add_noise, add_pops, best_butterworth, best_median, mpjpe_cm
from model_core.inference.engine import Engine
from model_core.io.checkpoint import DEFAULT_MODEL, default_denoiser
from model_core.motion.conventions import PARENTS
from model_core.motion.features import mirror_positions, yaw_matrix
from model_core.motion.synthetic import walking_skeleton
from model_core.ops import fusion
from model_core.ops.denoise import denoise_positions


@pytest.fixture(scope="module")
def denoiser():
    return Engine.load(default_denoiser(DEFAULT_MODEL))


def test_noise_level_reads_white_noise_not_motion():
    walk = walking_skeleton(1000)
    assert fusion.noise_level(walk).max() < 0.002  # a clean walk reads as (nearly) clean
    noisy = add_noise(walk, 3.0, np.random.default_rng(0))
    level = fusion.noise_level(noisy)
    assert level.shape == (21, 3) and np.all(np.abs(level - 0.03) < 0.006)


def test_noise_level_is_measured_per_axis():
    """Noise in one direction only (as rotation jitter moves a joint across its bone, not along it) reads
    on that axis, and the clean axes read clean."""
    walk = walking_skeleton(300)
    noisy = walk.copy()
    noisy[..., 0] += np.random.default_rng(1).normal(0, 0.02, walk.shape[:2])
    level = fusion.noise_level(noisy)
    assert np.all(np.abs(level[:, 0] - 0.02) < 0.005) and level[:, 1:].max() < 0.002


def test_pops_are_found_and_repaired_and_a_clean_walk_has_none():
    walk = walking_skeleton(200).astype(np.float64)
    assert not fusion.repair_pops(walk)[1].any()
    popped = walk.copy()
    hits = [(50, 3), (53, 3), (120, 15), (180, 7)]  # two close together on one joint
    for k, (f, j) in enumerate(hits):
        popped[f, j] += [0.1, 0.15, -0.2][k % 3]
    fixed, pops = fusion.repair_pops(popped)
    assert sorted(zip(*np.nonzero(pops))) == hits
    assert np.abs(fixed - walk).max() < 0.01


def test_solve_smooth_equals_a_dense_solve():
    rng = np.random.default_rng(1)
    f, k = 12, 3
    weights, rhs, lam = rng.uniform(0.5, 2, (f, k)), rng.normal(size=(f, k)), rng.uniform(0.1, 5, k)
    d = np.diff(np.eye(f), n=2, axis=0)
    for c in range(k):
        want = np.linalg.solve(np.diag(weights[:, c]) + lam[c] * d.T @ d, rhs[:, c])
        np.testing.assert_allclose(fusion.solve_smooth(weights, rhs, lam)[:, c], want, atol=1e-10)


def test_solve_smooth_with_a_prior_per_frame_equals_a_dense_solve():
    rng = np.random.default_rng(2)
    f, k = 12, 2
    weights, rhs, lam = rng.uniform(0.5, 2, (f, k)), rng.normal(size=(f, k)), rng.uniform(0.1, 5, (f - 2, k))
    d = np.diff(np.eye(f), n=2, axis=0)
    for c in range(k):
        want = np.linalg.solve(np.diag(weights[:, c]) + d.T @ np.diag(lam[:, c]) @ d, rhs[:, c])
        np.testing.assert_allclose(fusion.solve_smooth(weights, rhs, lam)[:, c], want, atol=1e-10)


def bone_lengths(pos):
    return np.stack([np.linalg.norm(pos[:, j] - pos[:, PARENTS[j]], axis=-1) for j in range(21) if PARENTS[j] >= 0], 1)


def test_keep_bone_lengths_removes_stretch_up_to_the_noise():
    walk = walking_skeleton(120)
    rng = np.random.default_rng(3)
    noisy = walk + rng.normal(0, 0.01, walk.shape)
    out = fusion.keep_bone_lengths(noisy, np.full(21, 0.01))
    assert bone_lengths(out).std(0).mean() < 0.5 * bone_lengths(noisy).std(0).mean()
    assert np.linalg.norm(out - walk, axis=-1).mean() < 0.9 * np.linalg.norm(noisy - walk, axis=-1).mean()
    assert np.linalg.norm(out - noisy, axis=-1).max() <= 0.01 + 1e-9  # never more than the noise


def test_keep_bone_lengths_holds_the_pelvis_and_chest_shapes(monkeypatch):
    """The joints that hang off one parent keep their distances too (the pelvis: hips, spine and both
    thighs; the chest: spine1, neck and both shoulders), so each of their joints sheds more noise."""
    pairs = fusion.rigid_pairs()
    bones = {(int(PARENTS[c]), c) for c in range(21) if PARENTS[c] >= 0}
    assert bones <= set(pairs)
    assert set(pairs) - bones == {(1, 5), (1, 9), (5, 9), (3, 13), (3, 17), (13, 17)}
    walk = walking_skeleton(240)
    rng = np.random.default_rng(4)
    noisy = walk + rng.normal(0, 0.02, walk.shape)
    out = fusion.keep_bone_lengths(noisy, np.full(21, 0.02))
    for a, b in set(pairs) - bones:
        assert np.linalg.norm(out[:, a] - out[:, b], axis=-1).std() < 0.5 * np.linalg.norm(
            noisy[:, a] - noisy[:, b], axis=-1).std()
    held = [0, 1, 5, 9, 2, 3, 13, 17]
    error = np.linalg.norm(out[:, held] - walk[:, held], axis=-1).mean()
    assert error < 0.8 * np.linalg.norm(noisy[:, held] - walk[:, held], axis=-1).mean()
    monkeypatch.setattr(fusion, "rigid_pairs", lambda: sorted(bones))  # the bones alone leave more
    bones_only = fusion.keep_bone_lengths(noisy, np.full(21, 0.02))
    assert error < 0.95 * np.linalg.norm(bones_only[:, held] - walk[:, held], axis=-1).mean()


def test_keep_bone_lengths_keeps_a_clean_stretching_rig():
    """A clean take whose bones change length on purpose (a stretchy rig) is kept: the input's noise is
    what the bones may be moved by, and a clean take has next to none."""
    walk = walking_skeleton(120)
    stretch = 1.0 + 0.2 * np.sin(np.linspace(0, 6, 120))[:, None, None]
    stretchy = walk[:, :1] + (walk - walk[:, :1]) * stretch
    noise = fusion.Assessment(fusion.noise_level(stretchy), None).joint_noise_m
    out = fusion.keep_bone_lengths(stretchy, noise)
    assert noise.max() < 0.002
    np.testing.assert_allclose(bone_lengths(out), bone_lengths(stretchy), atol=0.002)


def test_running_median_ignores_one_outlier():
    x = np.ones((30, 2))
    x[10] = 100.0
    out = fusion.running_median(x, 3)
    assert out.shape == x.shape and np.all(out == 1.0)


def test_where_the_two_readings_disagree_the_model_is_trusted_less():
    """The readings' disagreement marks where the model errs: there it is trusted less than the gap to the
    noisy input alone says, and where the readings agree, more, so the result keeps the model's detail
    there instead of the noise."""
    walk = walking_skeleton(150).astype(np.float64)
    noisy = add_noise(walk, 3.0, np.random.default_rng(4))
    model = walk.copy()
    model[60:90] += [0.02, 0.0, 0.0]  # the model is 2 cm off for a second
    found = fusion.Assessment(fusion.noise_level(noisy), np.zeros(walk.shape[:2], bool))
    spread2 = np.full(walk.shape[:2], 0.0005 ** 2)  # the readings agree to half a millimetre ...
    spread2[60:90] = 0.02 ** 2  # ... but where the model is off, they are 2 cm apart
    gap, sigma2 = noisy - model, found.noise_m ** 2
    alone, both = fusion.model_error2(gap, sigma2, 30.0), fusion.model_error2(gap, sigma2, 30.0, spread2)
    assert np.all(both[65:85] > alone[65:85]) and both[:50].mean() < 0.6 * alone[:50].mean()
    out_alone = fusion.fuse(noisy, model, found, 30.0)
    out_both = fusion.fuse(noisy, model, found, 30.0, spread2)
    err = lambda out, s: np.linalg.norm(out[s] - walk[s], axis=-1).mean()  # noqa: E731
    off, on = slice(65, 85), np.r_[:50, 100:150]
    assert err(out_both, on) < 0.9 * err(out_alone, on)
    assert err(out_both, off) < err(out_alone, off)
    assert err(out_both, slice(None)) < 0.97 * err(out_alone, slice(None))


def test_the_models_slow_offset_in_the_bodys_frame_is_taken_off_its_reading():
    """A reading off by a fixed offset in the body's frame (another body's proportions) while the body
    turns: the offset is measured on the noisy input and taken off; a reading that is right stays
    right, to a fraction of the noise."""
    walk = walking_skeleton(600).astype(np.float64)
    yaw = np.linspace(0.0, 10.0 * np.pi, len(walk))  # a full turn every 4 s, faster than the offset is smoothed over
    turn = yaw_matrix(yaw)  # body frame -> world
    walk = np.einsum("fij,fkj->fki", turn, walk)
    offset = np.random.default_rng(5).normal(0, 0.03, (21, 3))  # 3 cm per axis, in the body's frame
    reading = walk + np.einsum("fij,kj->fki", turn, offset)
    noisy = add_noise(walk, 3.0, np.random.default_rng(6))
    found = fusion.Assessment(fusion.noise_level(noisy), np.zeros(walk.shape[:2], bool))
    err = lambda x: np.linalg.norm(x - walk, axis=-1).mean()  # noqa: E731
    assert err(reading) > 0.04
    assert err(fusion.correct_bias(noisy, reading, found, 30.0)) < 0.2 * err(reading)
    assert err(fusion.correct_bias(noisy, walk, found, 30.0)) < 0.15 * err(noisy)
    clean = fusion.Assessment(fusion.noise_level(walk), np.zeros(walk.shape[:2], bool))
    assert err(fusion.correct_bias(walk, reading, clean, 30.0)) < 0.002  # a clean input: the offset, all of it


@pytest.mark.parametrize("fps", [30.0, 60.0])
def test_denoise_leaves_a_clean_take_and_beats_the_filters(denoiser, fps):
    """Through the product path (scene units, any rate), on a procedural walk far from the motion the
    model learnt (its reconstruction alone is 6 cm off): a clean walk comes back within a millimetre on
    average; 3 cm of jitter comes back at under half of it, within 35 % of what the best low-pass
    filter (its cutoff picked on the truth) leaves; 1 % of pops at under half of what the better of the
    best low-pass and median filters leaves. On real takes it beats the filter (see the model card)."""
    walk = walking_skeleton(int(6 * fps), fps=fps) * 100.0  # centimetres, as a user's scene may be
    assert mpjpe_cm(denoise_positions(denoiser, walk, fps) / 100.0, walk / 100.0).mean() < 0.1
    rng = np.random.default_rng(0)
    noisy = add_noise(walk / 100.0, 3.0, rng)
    out = denoise_positions(denoiser, noisy * 100.0, fps) / 100.0
    filtered, _ = best_butterworth([walk / 100.0], [noisy], fps=fps)
    error = mpjpe_cm(out, walk / 100.0).mean()
    assert error < 0.5 * mpjpe_cm(noisy, walk / 100.0).mean() and error < 1.35 * filtered
    popped = add_pops(walk / 100.0, 0.01, rng)
    out = denoise_positions(denoiser, popped * 100.0, fps) / 100.0
    best = min(best_butterworth([walk / 100.0], [popped], fps=fps)[0], best_median([walk / 100.0], [popped])[0])
    assert mpjpe_cm(out, walk / 100.0).mean() < 0.5 * best


@pytest.mark.parametrize("fps", [30.0, 60.0])
def test_denoise_of_a_mirrored_take_is_the_mirrored_denoise(denoiser, fps):
    """The model reads a take as it is and as its mirror image and averages the two: so what Denoise
    returns does not depend on which side of the body was captured as the left (a model trained on one
    reading alone only nearly has this)."""
    walk = walking_skeleton(int(4 * fps), fps=fps, radius=3.0)  # a turning walk
    noisy = add_noise(walk, 3.0, np.random.default_rng(3)) * 100.0  # 3 cm of noise, the take in cm
    out = denoise_positions(denoiser, noisy, fps)
    mirrored = denoise_positions(denoiser, mirror_positions(noisy), fps)
    # Up to the last bone-length pass, which goes bone by bone, left side first: within a millimetre
    # (read once, the two readings differ by 0.1 to 0.2 cm on average and up to 3 cm).
    diff = np.abs(mirror_positions(mirrored) - out)  # cm
    assert diff.mean() < 0.01 and diff.max() < 0.2
    denoiser.mirrored_reading = False  # the engine's switch: one reading, and the symmetry is gone
    try:
        once = denoise_positions(denoiser, noisy, fps)
        once_mirrored = denoise_positions(denoiser, mirror_positions(noisy), fps)
    finally:
        del denoiser.mirrored_reading
    assert np.abs(mirror_positions(once_mirrored) - once).mean() > 0.05
    assert np.abs(out - noisy).mean() > 0.5  # and it did denoise
