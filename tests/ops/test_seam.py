"""The seams (model_core/ops/seam.py): one set of lengths, the engine's and training's fade the
same twin, and a replaced range meets its neighbours without a jump."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.inference.engine import Engine
from model_core.ops.follow import ControlSettings
from model_core.ops.seam import (
    EDGE_FADE_S,
    PREDICT_SEAM_FRAMES,
    SEAM_ACCEL,
    SEAM_FRAMES,
    _cosine_fade,
    blend_seam,
    fade_edges,
    seam_fade,
    seam_target,
)


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


def test_the_seam_carries_a_clean_clips_acceleration_and_not_jitter():
    t = np.arange(20, dtype=np.float64)
    braking = np.zeros((20, 21, 3))
    braking[..., 0] = (2.0 * t - 0.04 * t ** 2)[:, None]  # slowing down, no jitter at all
    last, prev, prev2 = braking[-1], braking[-2], braking[-3]
    velocity_only = 2 * last - prev
    np.testing.assert_allclose(seam_target(braking), velocity_only + SEAM_ACCEL * (last - 2 * prev + prev2))
    np.testing.assert_allclose(seam_target(braking, accel=0.0), velocity_only)
    np.testing.assert_allclose(seam_target(braking[-7:]), 2 * last - prev)  # too short to tell jitter: velocity only
    # Jitter on a steady glide: its frame-to-frame "acceleration" is noise, and the seam does not follow it.
    rng = np.random.default_rng(0)
    kicks = []
    for _ in range(50):
        glide = np.zeros((20, 21, 3))
        glide[..., 0] = t[:, None]
        glide += rng.normal(0.0, 0.05, glide.shape)
        last, prev, prev2 = glide[-1], glide[-2], glide[-3]
        used = seam_target(glide) - (2 * last - prev)
        kicks.append(np.abs(used).mean() / np.abs(SEAM_ACCEL * (last - 2 * prev + prev2)).mean())
    assert np.mean(kicks) < 0.25
    # And a blend starts from that target.
    new = np.zeros((12, 21, 3))
    np.testing.assert_allclose(blend_seam(braking, new)[0], seam_target(braking))


def test_momentum_eases_from_the_clips_velocity_into_the_continuations():
    from model_core.ops.seam import MOMENTUM_FADE_FRAMES, MOMENTUM_RATIO, momentum_share

    ctx = np.zeros((20, 21, 3))
    ctx[..., 0] = (np.arange(20) * 0.05)[:, None]  # moving +x at 0.05 per frame
    new = np.zeros((40, 21, 3))
    new[..., 0] = 1.0 + (np.arange(40) * 0.01)[:, None]  # the model slows at once to 0.01 per frame
    plain, carried = blend_seam(ctx, new), blend_seam(ctx, new, momentum=1.0)
    np.testing.assert_allclose(carried[0], plain[0])  # the first frame is the seam's either way
    step = lambda out: np.diff(out[:6, 0, 0])  # noqa: E731
    assert np.all(step(carried) > step(plain) + 1e-6) and np.all(np.diff(step(carried)) < 0)  # slows gradually
    np.testing.assert_allclose(carried[MOMENTUM_FADE_FRAMES:], new[MOMENTUM_FADE_FRAMES:])  # and gives it back
    np.testing.assert_allclose(blend_seam(ctx, new, momentum=0.0), plain)
    lo, hi = MOMENTUM_RATIO
    assert momentum_share(None) == momentum_share(lo) == momentum_share(0.2) == 0.0
    assert momentum_share(hi) == momentum_share(3 * hi) == 1.0 and momentum_share((lo + hi) / 2) == 0.5


def test_new_frames_held_at_the_last_pose_coast_to_a_stop():
    """With ``coast``, new frames held at the clip's last pose keep that share of what the seam carries on (the
    clip's last velocity, its momentum's drift) through ``coast_frames`` frames and give it back over as many
    again: a body drifting 3 mm a frame as the clip ends coasts to a stop, where without it it carries the drift on
    and comes back to the pose within the seam's fade."""
    from model_core.ops.seam import MOMENTUM_FADE_FRAMES

    ctx = np.zeros((20, 21, 3))
    ctx[..., 0] = (np.arange(20) * 0.003)[:, None]
    held = np.repeat(ctx[-1:], 60, 0)
    drift = lambda out: out[:, 0, 0] - held[:, 0, 0]  # noqa: E731
    for momentum in (0.0, 1.0):
        back = drift(blend_seam(ctx, held, momentum=momentum))
        coasted = drift(blend_seam(ctx, held, momentum=momentum, coast=1.0, coast_frames=20))
        half = drift(blend_seam(ctx, held, momentum=momentum, coast=0.5, coast_frames=20))
        assert back[0] == pytest.approx(0.003) and np.all(back[MOMENTUM_FADE_FRAMES:] == 0.0)  # on, then back
        assert np.all(np.diff(coasted[:20]) >= -1e-12) and coasted[19] >= 0.003  # coasts and stays
        assert np.all(np.diff(coasted[20:]) <= 1e-12) and np.all(coasted[40:] == 0.0)  # given back after
        assert np.all(half[:20] >= back[:20] - 1e-12) and np.all(half[:20] <= coasted[:20] + 1e-12)
        np.testing.assert_allclose(blend_seam(ctx, held, momentum=momentum, coast=0.0, coast_frames=20),
                                   held + back[:, None, None] * np.array([1.0, 0.0, 0.0]))


def test_a_foot_coming_down_at_the_seam_lands_on_the_floor():
    """A heel and toe falling fast at the clip's end would be carried by the seam through the floor they
    stood on; they land on it instead, and every other joint is placed exactly as before."""
    from model_core.motion.conventions import CONTACT_JOINTS, UP_AXIS
    from model_core.motion.synthetic import walking_skeleton

    walk = walking_skeleton(60).astype(np.float64)
    ctx, new = walk[:30].copy(), walk[30:50].copy()
    feet = CONTACT_JOINTS
    floor = ctx[:, feet, UP_AXIS].min(0)
    drop = 0.01 + 0.03 * np.arange(5, -1, -1)[:, None]  # 16, 13 ... 1 cm above it, falling 3 cm a frame
    ctx[-6:, feet, UP_AXIS] = floor + drop
    new[:, feet, UP_AXIS] = floor[None] + 0.002  # the model's continuation has the feet down
    out = blend_seam(ctx, new)
    assert (out[:, feet, UP_AXIS] >= floor - 1e-9).all()
    assert out[0, feet, UP_AXIS].max() < floor.max() + 0.01  # it lands rather than hovering
    # without the floor the seam's momentum would have carried them below it
    target = seam_target(ctx)
    assert (target[feet, UP_AXIS] < floor - 0.015).all()
    others = np.setdiff1d(np.arange(walk.shape[1]), feet)
    unclamped = new + _cosine_fade(len(new), SEAM_FRAMES)[:, None, None] * (target - new[0])
    np.testing.assert_allclose(out[:, others], unclamped[:, others], atol=1e-12)
