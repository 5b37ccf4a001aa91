"""The shared geometry (model_core/motion/geometry.py): each formula once, checked against the
forms it replaced and, for the ground turn, its NumPy and torch runs against each other."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.motion.features import facing, heading, yaw_matrix
from model_core.motion.geometry import (
    cubic_frames,
    interpolate_frames,
    nearest_rotation,
    rotate_ground,
    rotvec_to_matrix,
    shortest_arc,
)
from model_core.motion.synthetic import walking_skeleton


def test_shortest_arc_takes_a_onto_b_over_leading_dimensions_including_opposite():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(5, 2, 3))
    b = rng.normal(size=(5, 2, 3))
    b[0, 0] = -3.0 * a[0, 0]  # opposite
    b[1, 1] = 2.0 * a[1, 1]  # the same direction
    r = shortest_arc(a, b)
    unit = lambda v: v / np.linalg.norm(v, axis=-1, keepdims=True)
    np.testing.assert_allclose(np.einsum("...ij,...j->...i", r, unit(a)), unit(b), atol=1e-9)
    np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), np.broadcast_to(np.eye(3), r.shape), atol=1e-9)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-9)
    np.testing.assert_allclose(r[1, 1], np.eye(3), atol=1e-9)


def test_shortest_arc_matches_the_closed_form_on_vectors():
    """v c + (a x b) x v + (a x b)((a x b) . v) / (1 + c): the form the foot lock used."""
    rng = np.random.default_rng(1)
    a, b = (v / np.linalg.norm(v, axis=-1, keepdims=True) for v in rng.normal(size=(2, 50, 3)))
    v = rng.normal(size=(50, 3))
    axis, c = np.cross(a, b), np.sum(a * b, -1, keepdims=True)
    closed = v * c + np.cross(axis, v) + axis * np.sum(axis * v, -1, keepdims=True) / (1.0 + c)
    np.testing.assert_allclose(np.einsum("fij,fj->fi", shortest_arc(a, b), v), closed, atol=1e-9)


def test_nearest_rotation_keeps_rotations_and_mends_a_nearly_rotation_over_leading_dimensions():
    rng = np.random.default_rng(0)
    r = rotvec_to_matrix(rng.normal(size=(4, 5, 3)))
    assert np.allclose(nearest_rotation(r), r, atol=1e-12)
    near = nearest_rotation(r @ (np.eye(3) + 1e-3 * rng.normal(size=(4, 5, 3, 3))))
    assert np.abs(np.swapaxes(near, -1, -2) @ near - np.eye(3)).max() < 1e-12
    assert np.allclose(np.linalg.det(near), 1.0) and np.abs(near - r).max() < 1e-2
    assert np.allclose(np.linalg.det(nearest_rotation(-r)), 1.0)  # a reflection gives a rotation, never a mirror


def test_rotate_ground_numpy_and_torch_twins_agree_with_yaw_matrix():
    torch = pytest.importorskip("torch")
    rng = np.random.default_rng(2)
    yaw, xz = rng.uniform(-4, 4, size=7), rng.normal(size=(7, 2))
    turned = rotate_ground(yaw, xz)
    full = np.einsum("fij,fj->fi", yaw_matrix(yaw), np.stack([xz[:, 0], np.zeros(7), xz[:, 1]], -1))
    np.testing.assert_allclose(turned, full[:, [0, 2]], atol=1e-12)
    np.testing.assert_allclose(rotate_ground(torch.from_numpy(yaw), torch.from_numpy(xz), torch).numpy(), turned,
                               atol=1e-12)


def test_interpolate_frames_picks_whole_frames_exactly_and_clamps():
    x = np.arange(12, dtype=np.float64).reshape(4, 3) ** 2
    np.testing.assert_array_equal(interpolate_frames(x, np.array([0.0, 2.0, 3.0])), x[[0, 2, 3]])
    halves = [(x[0] + x[1]) / 2, 0.75 * x[2] + 0.25 * x[3]]
    np.testing.assert_allclose(interpolate_frames(x, np.array([0.5, 2.25])), halves)
    np.testing.assert_array_equal(interpolate_frames(x, np.array([-1.0, 9.0])), x[[0, 3]])
    t = np.linspace(0, 3, 17)
    np.testing.assert_allclose(interpolate_frames(x, t)[:, 1], np.interp(t, np.arange(4), x[:, 1]), atol=1e-12)


def test_heading_is_the_angle_of_facing():
    pos = walking_skeleton(40)
    fwd = facing(pos)
    np.testing.assert_allclose(heading(pos, sigma=0), np.unwrap(np.arctan2(fwd[:, 0], fwd[:, 2])), atol=1e-12)


def test_cubic_frames_passes_every_frame_and_follows_an_arc():
    t = np.arange(12.0)
    x = np.stack([np.cos(0.4 * t), np.sin(0.4 * t), 0.3 * t ** 2], -1)  # an arc, rising faster and faster
    np.testing.assert_allclose(cubic_frames(x, t), x, atol=1e-12)
    np.testing.assert_allclose(cubic_frames(x, np.array([-1.0, 20.0])), x[[0, -1]])  # clamped
    mid = np.arange(1, 10) + 0.5  # between frames that have a neighbour on each side
    true = np.stack([np.cos(0.4 * mid), np.sin(0.4 * mid), 0.3 * mid ** 2], -1)
    np.testing.assert_allclose(cubic_frames(x, mid)[:, 2], true[:, 2], atol=1e-12)  # exact on a quadratic
    cubic_err = np.linalg.norm(cubic_frames(x, mid)[:, :2] - true[:, :2], axis=-1).max()
    line_err = np.linalg.norm(interpolate_frames(x, mid)[:, :2] - true[:, :2], axis=-1).max()
    assert cubic_err < 0.1 * line_err  # a straight line cuts the arc's corner
