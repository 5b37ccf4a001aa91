"""Make Loop on positions: the seam found where the pose comes round again, and a cycle that repeats without a pop,
on the real model (and on a real walk where the data is here)."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.inference.engine import Engine
from model_core.io.bvh import read_bvh
from model_core.motion.conventions import GROUND_AXES, ROOT
from model_core.motion.features import heading, root_and_local
from model_core.motion.synthetic import walking_skeleton
from model_core.ops.loop import MIN_CYCLE_S, find_seam, loop_positions, pose_distance, unwound
from model_core.rig.rigs import canonical_clip

GROUND = list(GROUND_AXES)


@pytest.fixture(scope="module")
def engine():
    return Engine.load()


def real_walk(mocap_root, fps: float = 30.0) -> np.ndarray:
    path = mocap_root / "bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh"
    if not path.exists():
        pytest.skip(f"{path} is not here")
    return canonical_clip(read_bvh(path), fps)


def steps(pos: np.ndarray) -> np.ndarray:
    """Each joint's move from frame to frame ``[F - 1, 21]``."""
    return np.linalg.norm(np.diff(pos, axis=0), axis=-1)


def repeated(loop, times: int = 3) -> np.ndarray:
    """The cycle played ``times`` times as a Cycles modifier plays it (the travel added each time)."""
    cycle = loop.positions[:-1]
    return np.concatenate([cycle + k * loop.travel for k in range(times)] + [loop.positions[-1:] +
                                                                           (times - 1) * loop.travel])


def test_the_seam_is_where_the_pose_comes_round_again():
    """The procedural walk (0.9 strides a second) comes round every 33.3 frames: the seam of 1.5 s of it is one
    stride on, the pose there within a few mm of the first."""
    walk = walking_skeleton(46)
    seam = find_seam(walk, 30.0)
    assert seam in (33, 34), seam
    assert pose_distance(walk, 30.0, np.array([seam]))[0] < 1.5
    assert find_seam(walk, 30.0, match=False) == 45  # the range's last frame, as given


def test_a_stretch_shorter_than_a_cycle_is_refused():
    with pytest.raises(ValueError, match=f"a loop needs at least 16 .*{MIN_CYCLE_S:g} s.*widen the frame range"):
        find_seam(walking_skeleton(12), 30.0)


def test_a_real_walk_loops_where_it_comes_round_and_repeats_without_a_pop(mocap_root, engine):
    walk = real_walk(mocap_root)
    stretch = walk[60:121]
    loop = loop_positions(engine, stretch, 30.0, blend=12)
    assert 0.9 * 30 <= loop.seam <= 1.3 * 30, loop.seam  # one stride of a walk (two steps)
    assert loop.match_cm < 6.0
    assert loop.positions.shape == (loop.seam + 1, 21, 3)
    kept = loop.seam - 12  # before the blend: the take's own frames (unwound by its small turn)
    assert np.allclose(loop.positions[:kept], unwound(stretch, loop.seam)[0][:kept])
    assert np.abs(root_and_local(loop.positions[:kept])[2] - root_and_local(stretch[:kept])[2]).max() < 1e-5
    assert np.allclose(loop.positions[-1], stretch[0] + loop.travel)  # the next cycle starts as the first frame
    assert loop.travel[1] == 0 and 1.0 < np.linalg.norm(loop.travel) < 1.6  # a stride's travel (m), over the ground
    played = steps(repeated(loop))
    assert played.max() <= 1.05 * steps(stretch).max()  # no joint jumps at the seams


def test_a_stretch_that_does_not_come_round_is_carried_into_its_start(mocap_root, engine):
    """Frames 60 to 110 as given (match off): the last pose is 21 cm a joint from the first, and looped as it is the
    cycle would jump there; the blend carries it into the start at the take's own pace."""
    walk = real_walk(mocap_root)
    stretch = walk[60:111]
    loop = loop_positions(engine, stretch, 30.0, blend=15, match=False)
    assert loop.seam == 50 and loop.match_cm > 15.0
    naive = np.concatenate([stretch[:-1], stretch[:1] + loop.travel])
    assert steps(naive)[-1].mean() > 3 * steps(stretch).mean()  # the pop the blend takes away
    wrap = steps(repeated(loop))[loop.seam - 16:loop.seam + 2]
    assert wrap.mean(1).max() < 1.3 * steps(stretch).mean(1).max(), wrap.mean(1)
    accel = np.linalg.norm(np.diff(repeated(loop), 2, axis=0), axis=-1).mean(1)
    assert accel[loop.seam - 17:loop.seam + 1].max() < 3 * accel.mean()


def test_in_place_the_cycle_repeats_on_the_spot_with_its_sway(engine):
    walk = walking_skeleton(46)
    loop = loop_positions(engine, walk, 30.0, blend=10, in_place=True)
    assert not loop.travel.any()
    assert np.allclose(loop.positions[-1], loop.positions[0])
    hips = loop.positions[:, ROOT][:, GROUND]
    assert np.linalg.norm(hips - hips[0], axis=-1).max() < 0.1  # the walk travelled 1.4 m in the cycle
    feet = loop.positions[:, [7, 11]][..., GROUND] - hips[:, None]
    assert np.linalg.norm(np.diff(feet, axis=0), axis=-1).mean() * 30 > 0.5  # the feet still step (m/s about the hips)
    sway = loop.positions[:, ROOT, 1]
    assert np.ptp(sway) > 0.02  # the hips' bob kept


def test_a_stretch_that_turns_is_unwound_so_the_cycle_repeats_straight(engine):
    """The procedural walk goes round a 6 m circle (14 degrees a stride, to the left): the cycle is unwound, its
    seam facing as its first frame does, so that it repeats in a straight line without the blend turning the body
    back; every frame keeps its pose in the body's own frame; a foot lock then covers the whole cycle."""
    walk = walking_skeleton(46).astype(np.float64)
    loop = loop_positions(engine, walk, 30.0, blend=10)
    assert 12 < np.degrees(loop.turn) < 16, np.degrees(loop.turn)
    yaw = heading(loop.positions)
    assert abs(np.degrees(yaw[-1] - yaw[0])) < 1.0
    _, _, before = root_and_local(walk[:loop.seam - 10])
    _, _, after = root_and_local(loop.positions[:loop.seam - 10])
    assert np.abs(after - before).max() < 1e-6  # the same steps, in the body's own frame
    rate = np.abs(np.diff(heading(np.concatenate([loop.positions[:-1], loop.positions + loop.travel]))))
    assert rate.max() < 1.5 * np.abs(np.diff(heading(walk))).max() + 1e-3
    assert not loop.fixed()[1:-1].any() and loop.fixed()[[0, -1]].all()


def test_a_real_walk_turn_loops_without_turning_back_at_the_seam(mocap_root, engine):
    """A walk-turn-left of the held-out style (45 degrees over the cycle): the body turns no faster around the seams
    than the take does (left as it was, the blend turned it back at over twice the take's fastest)."""
    path = mocap_root / "bandai-namco/dataset-2/dataset-2_walk-turn-left_exhausted_001.bvh"
    pos = canonical_clip(read_bvh(path), 30.0)
    a = (len(pos) - 60) // 2
    loop = loop_positions(engine, pos[a:a + 61], 30.0, blend=12, lead=pos[a - 20:a])
    assert 35 < np.degrees(loop.turn) < 55
    played = repeated(loop)
    rate = np.abs(np.diff(heading(played)))[loop.seam - 14:loop.seam + 3]
    assert rate.max() <= np.percentile(np.abs(np.diff(heading(pos[a:a + 61]))), 99) + 1e-3
