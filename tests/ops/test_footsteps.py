"""Footsteps moved off edges (model_core/ops/footsteps.py): a walk made on a flat floor and carried up stairs."""

from __future__ import annotations

import numpy as np

from model_core.motion.conventions import JOINT_INDEX
from model_core.motion.features import gaussian_smooth
from model_core.motion.synthetic import walking_skeleton
from model_core.ops import footlock
from model_core.ops.footsteps import FOOTPRINT, clear_of_surface, even_steps, stances

FPS = 30.0
ANKLES, TOES = [JOINT_INDEX["l_foot"], JOINT_INDEX["r_foot"]], [JOINT_INDEX["l_toe"], JOINT_INDEX["r_toe"]]


def stairs(start: float = 1.0, tread: float = 0.28, rise: float = 0.17, steps: int = 10):
    """Heights ``[N]`` of a flight of stairs along +Z (Y-up) under points ``[N, 3]``."""
    def height(points):
        k = np.clip(np.floor((np.asarray(points)[..., 2] - start) / tread) + 1, 0, steps)
        return k * rise
    return height


def carried_walk(height, frames: int = 150):
    """A straight walk along +Z on a flat floor, carried up and down with the surface under its hips (smoothed
    over a quarter second, as the extension carries the model's walk), and its contacts on the flat."""
    pos = walking_skeleton(frames, radius=1e6).astype(np.float64)
    pos[..., 1] -= pos[:, [7, 8, 11, 12], 1].min()
    contacts = footlock.detect_foot_contacts(pos, FPS)
    out = pos.copy()
    out[..., 1] += gaussian_smooth(height(pos[:, 0]), 0.25 * FPS)[:, None]
    return out, contacts


def edges_under(pos, contacts, height) -> list[float]:
    """For each stance, how far the surface under its footprint (at its middle frame) strays from flat."""
    out = []
    for leg, a, b in stances(contacts, 2):
        mid = (a + b) // 2
        ankle, toe = pos[mid, ANKLES[leg]], pos[mid, TOES[leg]]
        points = ankle + FOOTPRINT[:, None] * ((toe - ankle) * [1.0, 0.0, 1.0])
        out.append(float(np.ptp(height(points))))
    return out


def test_steps_on_stair_edges_are_moved_onto_treads_and_the_legs_keep_their_bones():
    height = stairs()
    pos, contacts = carried_walk(height)
    before = edges_under(pos, contacts, height)
    assert sum(e > 0.05 for e in before) >= 2  # the flat walk's steps land on edges
    out, report = even_steps(pos, contacts, height)
    assert max(edges_under(out, contacts, height)) < 0.01
    assert report["moved"] == sum(e > 0.05 for e in before) and report["on_edges"] == 0
    assert 0.0 < report["largest"] < 0.35
    for hip, knee, ankle in ((5, 6, 7), (9, 10, 11)):
        for a, b in ((hip, knee), (knee, ankle)):
            np.testing.assert_allclose(np.linalg.norm(out[:, a] - out[:, b], axis=-1),
                                       np.linalg.norm(pos[:, a] - pos[:, b], axis=-1), atol=1e-9)
    legs = [5, 6, 7, 8, 9, 10, 11, 12]
    np.testing.assert_array_equal(np.delete(out, legs, axis=1), np.delete(pos, legs, axis=1))  # the body as it was
    # carried between stances in the air: no foot jumps from one frame to the next
    jump = np.abs(np.diff(out[:, ANKLES] - pos[:, ANKLES], axis=0)).max()
    assert jump < 0.02, jump


def test_a_slope_or_a_floor_moves_no_step():
    pos, contacts = carried_walk(lambda p: 0.15 * np.asarray(p)[..., 2])  # a ramp: the foot pitches with it
    out, report = even_steps(pos, contacts, lambda p: 0.15 * np.asarray(p)[..., 2])
    assert report["moved"] == 0 and report["on_edges"] == 0 and report["steps"] >= 8
    np.testing.assert_array_equal(out, pos)


def test_a_step_into_fixed_frames_stays_and_steps_after_them_ease_in():
    height = stairs()
    pos, contacts = carried_walk(height)
    moved = even_steps(pos, contacts, height)[0]
    first = next(a for leg, a, b in sorted(stances(contacts, 2), key=lambda s: s[1])
                 if not np.allclose(moved[a:b + 1, ANKLES[leg]], pos[a:b + 1, ANKLES[leg]]))
    fixed = np.arange(len(pos)) < first + 2  # the first moved stance reaches into the fixed frames
    out, report = even_steps(pos, contacts, height, fixed=fixed)
    np.testing.assert_array_equal(out[fixed], pos[fixed])
    assert report["moved"] < even_steps(pos, contacts, height)[1]["moved"]
    assert np.abs(np.diff(out[:, ANKLES] - pos[:, ANKLES], axis=0)).max() < 0.02  # no jump after the fixed frames


def test_a_step_with_no_even_ground_near_is_left_and_counted():
    height = stairs(tread=0.1, rise=0.12, steps=60)  # treads shorter than a foot: an edge under every footprint
    pos, contacts = carried_walk(height)
    out, report = even_steps(pos, contacts, height)
    on_flight = [1 for leg, a, b in stances(contacts, 2) if pos[(a + b) // 2, ANKLES[leg], 2] > 1.1]
    assert report["on_edges"] >= len(on_flight) > 0
    assert report["moved"] == 0 and np.array_equal(out, pos)


def _under(pos, height, standing) -> np.ndarray:
    """How far ``[F, 4]`` each heel and toe is under the surface plus where it stands when down (>0: under)."""
    joints = pos[:, [7, 8, 11, 12]]
    return height(joints) + standing - joints[..., 1]


def test_feet_carried_down_stairs_are_raised_clear_of_the_treads_they_would_pass_through():
    height = stairs()
    flight = lambda p: height(np.asarray(p) * [1, 1, -1] + [0, 0, 4.0])  # walked down: the treads fall along +Z
    pos, contacts = carried_walk(flight)
    flat = walking_skeleton(150, radius=1e6).astype(np.float64)
    standing = footlock.rest_heights(flat - [0, flat[:, [7, 8, 11, 12], 1].min(), 0], contacts)
    before = _under(pos, flight, standing)
    assert before.max() > 0.05  # the feet drop with the hips into the treads they leave or reach over
    out, raised = clear_of_surface(pos, flight(pos[:, [7, 8, 11, 12]]), standing, FPS)
    assert _under(out, flight, standing).max() < 0.0101 and raised > 0  # within Foot Lock's tolerance (1 cm)
    assert (out[:, [7, 8, 11, 12], 1] >= pos[:, [7, 8, 11, 12], 1] - 1e-9).all()  # only ever raised
    for hip, knee, ankle in ((5, 6, 7), (9, 10, 11)):  # the legs keep their bones, the feet their shape
        for a, b in ((hip, knee), (knee, ankle)):
            np.testing.assert_allclose(np.linalg.norm(out[:, a] - out[:, b], axis=-1),
                                       np.linalg.norm(pos[:, a] - pos[:, b], axis=-1), atol=1e-9)
    np.testing.assert_allclose(out[:, TOES] - out[:, ANKLES], pos[:, TOES] - pos[:, ANKLES], atol=1e-12)
    legs = [6, 7, 8, 10, 11, 12]
    np.testing.assert_array_equal(np.delete(out, legs, axis=1), np.delete(pos, legs, axis=1))  # the body as it was
    assert np.abs(np.diff(out[:, ANKLES, 1] - pos[:, ANKLES, 1], axis=0)).max() < 0.05  # eased in and out
    fixed = np.arange(len(pos)) < 40
    kept, _ = clear_of_surface(pos, flight(pos[:, [7, 8, 11, 12]]), standing, FPS, fixed)
    np.testing.assert_array_equal(kept[fixed], pos[fixed])


def test_feet_over_a_floor_are_left_as_they_are():
    pos, contacts = carried_walk(lambda p: np.zeros(np.shape(p)[:-1]))
    standing = footlock.rest_heights(pos, contacts)
    out, raised = clear_of_surface(pos, np.zeros((len(pos), 4)), standing, FPS)
    assert raised == 0 and np.array_equal(out, pos)
