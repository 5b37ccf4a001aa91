"""A root bone carried on with the body (model_core/ops/root_motion.py)."""

from __future__ import annotations

import numpy as np

from model_core.motion.features import facing
from model_core.motion.synthetic import walking_skeleton
from model_core.ops.root_motion import carried_root


def test_a_root_goes_on_with_the_body_round_a_turn_keeping_its_place_against_it():
    walk = walking_skeleton(240, radius=3.0).astype(np.float64)  # Y-up, turning left round a 3 m circle
    seam = 60
    root = np.eye(4)
    root[:3, 3] = walk[seam - 1, 0] * [1.0, 0.0, 1.0] + [0.05, 0.0, 0.0]  # on the floor, 5 cm off the hips
    out = carried_root(root, walk[:, 0], facing(walk), seam, 30.0, up=1)
    assert out.shape == (240 - seam, 4, 4)
    steps = np.linalg.norm(np.diff(np.concatenate([root[None, :3, 3], out[:, :3, 3]]), axis=0), axis=-1)
    assert steps.max() < 1.5 * 1.3 / 30.0  # no jump at the seam or after it: at the walk's pace
    np.testing.assert_allclose(out[:, 1, 3], 0.0)  # its height kept
    np.testing.assert_allclose(out[:, :3, :3] @ np.swapaxes(out[:, :3, :3], 1, 2), np.broadcast_to(np.eye(3),
                                                                                                  (180, 3, 3)),
                               atol=1e-9)  # still a rotation
    # it turns with the walk: 1.3 m/s round 3 m is 0.43 rad/s, 2.6 rad over the 6 s after the seam
    forward = out[:, :3, :3] @ np.array([0.0, 0.0, 1.0])
    turned = np.arctan2(forward[-1, 0], forward[-1, 2]) - np.arctan2(forward[0, 0], forward[0, 2])
    walked = np.arctan2(facing(walk)[-1, 0], facing(walk)[-1, 2]) - np.arctan2(facing(walk)[seam, 0],
                                                                                facing(walk)[seam, 2])
    assert abs(np.angle(np.exp(1j * (turned - walked)))) < 0.1
    # and stays about 5 cm off the hips' ground track to the last frame (their sway smoothed out; smoothed, a
    # 3 m circle comes some 7 cm in)
    ground = walk[seam:, 0] * [1.0, 0.0, 1.0]
    gap = np.linalg.norm(out[:, :3, 3] - ground, axis=-1)
    assert gap.max() < 0.15 and abs(gap[-1] - gap[len(gap) // 2]) < 0.03, gap


def test_smoothing_to_the_trend_keeps_a_steady_walk_going_to_the_ends():
    """``gaussian_smooth(..., ends="trend")`` leaves a straight track straight to its last frame, where padding with
    the last frame holds it back; on a track shorter than the filter it still gives one value a frame."""
    from model_core.motion.features import gaussian_smooth

    track = np.outer(np.arange(60.0), [0.05, 0.0, 0.02])
    np.testing.assert_allclose(gaussian_smooth(track, 15.0, ends="trend"), track, atol=1e-5)
    assert np.abs(gaussian_smooth(track, 15.0) - track)[-1].max() > 0.2  # held back by about a third of a metre
    assert gaussian_smooth(track[:5], 15.0, ends="trend").shape == (5, 3)


def test_a_root_carried_over_a_ground_rises_as_the_body_is_carried():
    walk = walking_skeleton(120, radius=1e6).astype(np.float64)
    seam, lift = 30, np.linspace(-0.2, 0.7, 120)  # the body carried up a slope, from 0.2 below where it was
    root = np.eye(4)
    root[:3, 3] = walk[seam - 1, 0] * [1.0, 0.0, 1.0]
    flat = carried_root(root, walk[:, 0], facing(walk), seam, 30.0, up=1)
    up = carried_root(root, walk[:, 0], facing(walk), seam, 30.0, up=1, lift=lift)
    np.testing.assert_allclose(up[:, 1, 3] - flat[:, 1, 3], lift[seam:] - lift[seam - 1])  # from where it stood
    np.testing.assert_allclose(up[:, [0, 2], 3], flat[:, [0, 2], 3])  # along the same track
