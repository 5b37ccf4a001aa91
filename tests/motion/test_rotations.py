"""Rotation conversions: round trips in every Blender rotation mode, continuity."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.motion import rotations as R


@pytest.fixture
def matrices():
    rng = np.random.default_rng(0)
    q = rng.normal(size=(200, 4))
    return R.quat_to_matrix(q)


@pytest.mark.parametrize("order", R.EULER_ORDERS)
def test_euler_round_trip(matrices, order):
    e = R.matrix_to_euler(matrices, order)
    assert np.allclose(R.euler_to_matrix(e, order), matrices, atol=1e-9)


@pytest.mark.parametrize("order", R.EULER_ORDERS)
def test_euler_gimbal_lock(order):
    e = np.array([[0.3, 0.4, 0.5]])
    i, j, k = ("XYZ".index(a) for a in order)
    e[0, j] = np.pi / 2
    m = R.euler_to_matrix(e, order)
    assert np.allclose(R.euler_to_matrix(R.matrix_to_euler(m, order), order), m, atol=1e-9)


def test_euler_order_convention():
    """Blender's 'XYZ' applies X first: M = Rz @ Ry @ Rx."""
    e = np.array([0.1, 0.2, 0.3])
    want = R.axis_matrix(2, 0.3) @ R.axis_matrix(1, 0.2) @ R.axis_matrix(0, 0.1)
    assert np.allclose(R.euler_to_matrix(e, "XYZ"), want)


def test_quaternion_and_axis_angle_round_trip(matrices):
    q = R.matrix_to_quat(matrices)
    assert np.allclose(np.linalg.norm(q, axis=-1), 1) and (q[:, 0] >= 0).all()
    assert np.allclose(R.quat_to_matrix(q), matrices, atol=1e-9)
    assert np.allclose(R.axis_angle_to_matrix(R.quat_to_axis_angle(q)), matrices, atol=1e-9)


def test_batch_matches_single(matrices):
    batch = R.matrix_to_quat(matrices.reshape(20, 10, 3, 3)).reshape(200, 4)
    single = np.stack([R.matrix_to_quat(m) for m in matrices])
    assert np.allclose(batch, single)


def test_quaternion_continuity_flips_signs():
    angles = np.linspace(0, 4 * np.pi, 50)
    q = R.matrix_to_quat(R.axis_matrix(2, angles))  # w >= 0 makes it jump
    c = R.quat_continuous(q)
    assert (np.sum(c[1:] * c[:-1], -1) > 0).all()
    assert np.allclose(R.quat_to_matrix(c), R.quat_to_matrix(q))
    seam = R.quat_continuous(q[:1], previous=-q[0])
    assert np.allclose(seam, -q[:1])


@pytest.mark.parametrize("order", ["XYZ", "YZX"])  # X (the big turn) is not the middle axis
def test_euler_continuity_unwraps(order):
    angles = np.linspace(0, 6 * np.pi, 80)
    m = R.axis_matrix(0, angles) @ R.axis_matrix(1, 0.3 * np.sin(angles))
    e = R.euler_continuous(R.matrix_to_euler(m, order), order)
    assert np.abs(np.diff(e, axis=0)).max() < 0.5
    assert np.allclose(R.euler_to_matrix(e, order), m, atol=1e-9)


def test_closing_turns_bring_the_last_rotation_onto_the_first_by_the_shares_given():
    """A cycle's rotations (two bones) that end turned away from their start: turned by their shares of the miss,
    the untouched frames stay, the last lands on the first, and half a share turns half the angle."""
    rng = np.random.default_rng(5)
    rot = R.euler_to_matrix(rng.normal(0.0, 0.8, (9, 2, 3)), "XYZ")
    weights = np.array([0, 0, 0, 0, 0, 0, 0.5, 0.9, 1.0])
    out = R.closing_turns(rot, weights)
    assert np.allclose(out[:6], rot[:6]) and np.allclose(out[-1], rot[0], atol=1e-9)
    full = np.linalg.norm(R.matrix_to_rotvec(rot[0] @ np.swapaxes(rot[-1], -1, -2)), axis=-1)
    half = np.linalg.norm(R.matrix_to_rotvec(out[6] @ np.swapaxes(rot[6], -1, -2)), axis=-1)
    assert np.allclose(half, 0.5 * full) and (full > 0.1).all()
