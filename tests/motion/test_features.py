"""Features: layout, contacts, and the exact inverse (synthetic walker and real clips of each family)."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.eval.metrics import bone_lengths_of as bone_lengths
from model_core.io.bvh import read_bvh
from model_core.model.dataset import fps_override
from model_core.motion.conventions import JOINT_INDEX, JOINTS, LAYOUT, MODEL_FPS, STANDARD_LEG_LENGTH, UP_AXIS
from model_core.motion.features import (
    features_to_positions,
    mirror_features,
    mirror_positions,
    positions_to_features,
)
from model_core.motion.synthetic import walking_skeleton
from model_core.rig.rigs import detect_rig, leg_length, load_clip

# (folder under the mocap root, file pattern, expected rig family)
REAL_FAMILIES = [
    ("bandai-namco", "*.bvh", "bandai_namco"),
    ("cmu/iclone", "*.bvh", "iclone_cc_base"),
    ("cmu/acrnn-dance/salsa", "*.bvh", "acrnn"),
    ("cmu/acrnn-dance/martial", "*.bvh", "acrnn"),
    ("cmu/cgspeed", "tmoco_*.bvh", "cmu_cgspeed"),
    ("cmu/cgspeed", "bvh11_*.bvh", "cmu_bvh11"),
]


def test_synthetic_walker_keeps_bone_lengths():
    lengths = bone_lengths(walking_skeleton(200))
    assert np.ptp(lengths, axis=0).max() < 1e-5


def test_mirrored_features_are_the_features_of_the_mirrored_motion():
    pos = walking_skeleton(120, radius=4.0)  # a walk that turns, so the yaw rate is not zero
    other = {n: ("r_" + n[2:] if n.startswith("l_") else "l_" + n[2:] if n.startswith("r_") else n) for n in JOINTS}
    mirrored = pos[:, [JOINT_INDEX[other[n]] for n in JOINTS]] * np.array([-1.0, 1.0, 1.0])
    np.testing.assert_allclose(mirror_positions(pos), mirrored)
    np.testing.assert_allclose(mirror_positions(mirror_positions(pos)), pos)
    feats, _ = positions_to_features(pos)
    want, _ = positions_to_features(mirrored)
    np.testing.assert_allclose(mirror_features(feats), want, atol=1e-5)
    assert np.abs(feats[:, LAYOUT.yaw_rate]).max() > 1e-3
    np.testing.assert_allclose(mirror_features(mirror_features(feats)), feats)


def test_feature_layout_and_round_trip_on_synthetic_walk():
    pos = walking_skeleton(600)  # 20 s, a full turn of the arc and more
    feats, start = positions_to_features(pos)
    assert feats.shape == (600, LAYOUT.size) and feats.dtype == np.float32
    back = features_to_positions(feats, start)
    assert np.abs(back - pos).max() < 1e-3  # 1 mm


def test_clips_of_one_length_convert_together_frames_first_as_each_on_its_own():
    """``[F, B, 21, 3]`` -> ``[F, B, C]`` and back, as training converts a batch of windows: each clip's
    features, start and positions are exactly those of converting it alone."""
    clips = [walking_skeleton(40, radius=r)[k:k + 30] for r, k in ((4.0, 0), (2.5, 7), (9.0, 3))]
    clips[1] = clips[1] + np.array([1.0, 0.0, -2.0])
    batch = np.stack(clips, 1)  # (30, 3, 21, 3)
    feats, start = positions_to_features(batch)
    assert feats.shape == (30, 3, LAYOUT.size) and start.position.shape == (3, 3) and start.yaw.shape == (3,)
    for b, clip in enumerate(clips):
        one, one_start = positions_to_features(clip)
        np.testing.assert_array_equal(feats[:, b], one)
        np.testing.assert_allclose(start.position[b], one_start.position)
        assert start.yaw[b] == one_start.yaw
        np.testing.assert_array_equal(features_to_positions(feats)[:, b], features_to_positions(one))
    np.testing.assert_allclose(features_to_positions(feats, start), batch, atol=1e-3)


def test_features_are_root_relative_and_heading_aligned():
    pos = walking_skeleton(120)
    feats, _ = positions_to_features(pos)
    local = feats[:, LAYOUT.positions].reshape(len(pos), -1, 3)
    np.testing.assert_allclose(local[:, 0, [0, 2]], 0.0, atol=1e-6)  # hips above the local origin
    vel = feats[:-1, LAYOUT.velocity]
    assert np.all(vel[:, 1] > 0.03) and np.all(np.abs(vel[:, 0]) < 0.01)  # walking forward (+Z)
    speed = np.linalg.norm(vel, axis=-1).mean() * MODEL_FPS
    assert speed == pytest.approx(1.3, rel=0.02)  # the walker's speed, m/s
    assert feats[:-1, LAYOUT.yaw_rate].mean() > 0  # turning left


def test_contacts_alternate_while_walking():
    feats, _ = positions_to_features(walking_skeleton(300))
    contacts = feats[:, LAYOUT.contacts]
    assert set(np.unique(contacts)) <= {0.0, 1.0}
    left_heel, right_heel = contacts[:, 0], contacts[:, 2]
    assert 0.1 < left_heel.mean() < 0.9 and 0.1 < right_heel.mean() < 0.9
    assert np.mean(left_heel * right_heel) < np.mean(left_heel)  # not always both down


def test_round_trip_from_a_start_position_and_heading():
    pos = walking_skeleton(90)
    feats, start = positions_to_features(pos)
    start.position = start.position + np.array([3.0, 0.0, -2.0])
    moved = features_to_positions(feats, start)
    np.testing.assert_allclose(moved - pos, np.broadcast_to([3.0, 0.0, -2.0], pos.shape), atol=1e-4)


@pytest.mark.parametrize("folder, pattern, family", REAL_FAMILIES)
def test_real_clip_round_trip_within_1mm(mocap_root, smallest_bvh, folder, pattern, family):
    path = smallest_bvh(mocap_root / folder, pattern)
    rel = path.relative_to(mocap_root)
    assert detect_rig(read_bvh(path).names).family == family
    pos = load_clip(path, fps=fps_override(rel))
    assert pos.shape[1:] == (21, 3) and pos.dtype == np.float32 and len(pos) > 1
    assert leg_length(pos) == pytest.approx(STANDARD_LEG_LENGTH, rel=1e-4)
    feet = pos[:, [7, 8, 11, 12], UP_AXIS]
    assert abs(np.percentile(feet.min(axis=1), 5)) < 1e-4  # ground at y = 0
    feats, start = positions_to_features(pos)
    back = features_to_positions(feats, start)
    assert np.abs(back - pos).max() < 1e-3


def test_salsa_header_frame_rate_is_overridden(mocap_root, smallest_bvh):
    path = smallest_bvh(mocap_root / "cmu/acrnn-dance/salsa")
    header = read_bvh(path)
    assert header.fps == pytest.approx(120.0, rel=1e-3)  # what the file wrongly says
    assert fps_override(path.relative_to(mocap_root)) == 60
    pos = load_clip(path, fps=60)
    assert len(pos) == (header.frames - 1) // 2 + 1  # 60 -> 30 fps keeps every second frame


def test_continue_positions_goes_on_from_the_last_frame():
    from model_core.motion.features import continue_positions

    pos = walking_skeleton(120, radius=4.0)
    feats, start = positions_to_features(pos)  # the clip's features: the first 60 frames, then the rest
    np.testing.assert_allclose(continue_positions(feats[:60], start, feats[60:]), pos[60:], atol=1e-4)
