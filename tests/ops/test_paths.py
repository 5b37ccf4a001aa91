"""Paths: arc length, headings, projection, the control signal and the path-error metric."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.motion.features import yaw_matrix
from model_core.ops.paths import Path, PathError, control_signal, evaluation_paths, path_errors_cm, turning_path


def circle(radius=2.0, n=400):
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.stack([radius * (1 - np.cos(a)), radius * np.sin(a)], -1)


def test_arc_length_and_points():
    path = Path(np.array([[0.0, 0.0], [0.0, 3.0], [4.0, 3.0]]))
    assert path.length == pytest.approx(7.0)
    np.testing.assert_allclose(path.at([0.0, 1.5, 5.0, 99.0]), [[0, 0], [0, 1.5], [2, 3], [4, 3]])
    assert path.heading(1.0) == pytest.approx(0.0)  # +Z
    assert path.heading(6.0) == pytest.approx(np.pi / 2)  # +X
    t = path.tangent(1.0)
    ground = yaw_matrix(np.array(path.heading(1.0))) @ np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(ground[[0, 2]], t, atol=1e-12)  # headings follow features.yaw_matrix


def test_height_is_dropped_and_repeats_are_ignored():
    path = Path(np.array([[0.0, 5.0, 0.0], [0.0, 5.0, 0.0], [0.0, 7.0, 2.0]]))  # Y-up [P, 3]
    assert path.length == pytest.approx(2.0)


def test_cyclic_wraps():
    path = Path(circle(), cyclic=True)
    assert path.length == pytest.approx(4 * np.pi, rel=1e-3)
    np.testing.assert_allclose(path.at(path.length + 1.0), path.at(1.0), atol=1e-9)
    assert path.project(np.array([0.01, -0.01]), 0.5 * path.length, 1.5 * path.length) == \
        pytest.approx(path.length, abs=0.05)


@pytest.mark.parametrize("points", [np.zeros((1, 2)), np.zeros((5, 2)), np.full((3, 2), np.nan),
                                    np.array([[0.0, 1.0, 0.0], [0.0, 2.0, 0.0]])], ids=["one", "zero", "nan", "up"])
def test_bad_paths_raise(points):
    with pytest.raises(PathError):
        Path(points)


def test_project_respects_the_window():
    path = Path(np.stack([np.zeros(11), np.arange(11.0)], -1))
    assert path.project(np.array([0.3, 4.2])) == pytest.approx(4.2)
    assert path.project(np.array([0.3, 4.2]), 6.0, 8.0) == pytest.approx(6.0)


def test_control_on_the_path_walks_straight_at_speed():
    path = Path(np.stack([np.zeros(11), np.arange(11.0)], -1))
    channels, aim = control_signal(path, np.array([0.0, 1.0]), 0.0, 1.0, 1.5, 20, 30.0)
    np.testing.assert_allclose(channels, np.tile([0.0, 1.5 / 30, 0.0], (20, 1)), atol=1e-12)
    np.testing.assert_allclose(aim[-1], [0.0, 2.0])


def test_control_returns_to_the_path_and_turns_with_it():
    path = Path(circle(), cyclic=True)
    channels, aim = control_signal(path, np.array([0.3, 0.0]), 0.4, 0.0, 1.2, 60, 30.0)
    offsets = np.linalg.norm(aim - path.at(np.arange(61) * 1.2 / 30), axis=-1)
    assert offsets[0] == pytest.approx(0.3) and offsets[-1] < 0.01 and np.all(np.diff(offsets) <= 1e-12)
    total_turn = channels[:, 2].sum()  # from 0.4 rad to the tangent's heading after 2.4 m on r = 2 m
    assert total_turn == pytest.approx(2.4 / 2.0 - 0.4, abs=0.02)
    assert np.all(channels[:, 1] > 0)  # always forwards


def test_path_errors():
    path = Path(circle(), cyclic=True)
    exact = path.at(np.linspace(0, path.length, 200))
    assert path_errors_cm(exact, path) == pytest.approx((0.0, 0.0), abs=0.1)
    shifted = path.at(np.linspace(0, 3, 90)) * 1.05 - [0.1, 0.0]  # radius 2.1, same centre
    mean, worst = path_errors_cm(shifted, path)
    assert mean == pytest.approx(10.0, abs=0.5) and worst == pytest.approx(10.0, abs=0.5)


def test_figure_eight_errors_are_matched_along_the_branch():
    points, cyclic = evaluation_paths()["figure_eight"]
    path = Path(points, cyclic)
    walk = path.at(np.linspace(0, path.length, 600))
    assert path_errors_cm(walk, path)[1] < 0.5  # through the crossing without jumping branches


def test_evaluation_paths_start_at_the_origin():
    paths = evaluation_paths()
    assert list(paths) == ["line", "circle", "s_curve", "figure_eight"]
    for points, cyclic in paths.values():
        path = Path(points, cyclic)
        np.testing.assert_allclose(path.at(0.0), [0.0, 0.0], atol=1e-9)
        assert path.length > 8.0


@pytest.mark.parametrize("leave", [(0.0, 1.0), (1.0, 0.0), (0.0, -1.0), (-1.0, 0.0), (-0.7, 0.7)])
def test_turning_path_leaves_and_arrives_as_asked_and_never_turns_tighter_than_its_radius(leave):
    start, end, arrive, radius = np.zeros(2), np.array([2.0, 0.5]), np.array([1.0, 0.0]), 0.6
    pts = turning_path(start, np.array(leave), end, arrive, radius, step=0.02)
    np.testing.assert_allclose(pts[0], start)
    np.testing.assert_allclose(pts[-1], end)
    seg = np.diff(pts, axis=0)
    length = np.linalg.norm(seg, axis=-1)
    assert length.max() <= 0.02 + 1e-9
    direction = seg / length[:, None]
    np.testing.assert_allclose(direction[0], np.array(leave) / np.linalg.norm(leave), atol=0.03)
    np.testing.assert_allclose(direction[-1], arrive, atol=0.03)
    yaw = np.unwrap(np.arctan2(direction[:, 1], direction[:, 0]))
    curvature = np.abs(np.diff(yaw)) / (0.5 * (length[1:] + length[:-1]))
    assert curvature.max() < 1.02 / radius


def test_turning_path_goes_straight_when_it_can():
    pts = turning_path(np.zeros(2), np.array([1.0, 0.0]), np.array([3.0, 0.0]), np.array([1.0, 0.0]), 0.5)
    assert np.linalg.norm(np.diff(pts, axis=0), axis=-1).sum() == pytest.approx(3.0)
    np.testing.assert_allclose(pts[:, 1], 0.0, atol=1e-12)
