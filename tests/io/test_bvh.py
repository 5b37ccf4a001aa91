"""BVH parsing, forward kinematics against hand-computed positions, and resampling."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.io.bvh import forward_kinematics, read_bvh, resample

TWO_BONES = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Chest
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
  JOINT Leg
  {
    OFFSET 2 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 -4 0
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.0083333333
1 2 3 0 0 0 0 0 0 0 0 0
0 0 0 90 0 0 0 0 0 0 0 0
0 0 0 0 0 0 0 90 0 0 0 0
"""


def test_hierarchy_names_parents_and_end_sites(write_text):
    bvh = read_bvh(write_text("two.bvh", TWO_BONES))
    assert bvh.names == ["Hips", "Chest", "Chest_end", "Leg", "Leg_end"]
    assert bvh.parents.tolist() == [-1, 0, 1, 0, 3]
    assert bvh.is_end.tolist() == [False, False, True, False, True]
    assert bvh.frames == 3
    assert bvh.fps == pytest.approx(120.0, rel=1e-6)
    assert bvh.channel_start == [0, 6, 9, 9, 12]


def test_forward_kinematics_matches_hand_computed_positions(write_text):
    gpos, _ = forward_kinematics(read_bvh(write_text("two.bvh", TWO_BONES)))
    expected = np.array([
        # frame 0: root translated to (1, 2, 3), no rotation
        [[1, 2, 3], [1, 12, 3], [1, 17, 3], [3, 2, 3], [3, -2, 3]],
        # frame 1: root turned 90 degrees about Z, which maps (x, y, z) to (-y, x, z)
        [[0, 0, 0], [-10, 0, 0], [-15, 0, 0], [0, 2, 0], [4, 2, 0]],
        # frame 2: Chest turned 90 degrees about X, which maps +Y to +Z
        [[0, 0, 0], [0, 10, 0], [0, 10, 5], [2, 0, 0], [2, -4, 0]],
    ], dtype=float)
    np.testing.assert_allclose(gpos, expected, atol=1e-9)


def _one_joint(root_channels: str, joint_channels: str, values: str) -> str:
    n_root, n_joint = len(root_channels.split()), len(joint_channels.split())
    return f"""HIERARCHY
ROOT Root
{{
  OFFSET 0 0 0
  CHANNELS {n_root} {root_channels}
  JOINT Arm
  {{
    OFFSET 0 1 0
    CHANNELS {n_joint} {joint_channels}
    End Site
    {{
      OFFSET 5 0 0
    }}
  }}
}}
MOTION
Frames: 1
Frame Time: 0.033333
{values}
"""


@pytest.mark.parametrize("channels, values, tip", [
    # R = Rx(90) Ry(90): Ry takes (5,0,0) to (0,0,-5), then Rx takes that to (0,5,0)
    ("Xrotation Yrotation Zrotation", "90 90 0", (0, 6, 0)),
    # R = Ry(90) Rx(90): Rx leaves (5,0,0), Ry takes it to (0,0,-5)
    ("Yrotation Xrotation Zrotation", "90 90 0", (0, 1, -5)),
    # R = Rz(90): (5,0,0) -> (0,5,0)
    ("Zrotation Xrotation Yrotation", "90 0 0", (0, 6, 0)),
])
def test_rotation_channels_compose_in_listed_order(write_text, channels, values, tip):
    text = _one_joint("Xposition Yposition Zposition", channels, f"0 0 0 {values}")
    gpos, _ = forward_kinematics(read_bvh(write_text("one.bvh", text)))
    np.testing.assert_allclose(gpos[0, 2], tip, atol=1e-9)


def test_position_channels_in_any_order_and_on_a_child(write_text):
    text = _one_joint("Zposition Yposition Xposition", "Xposition Yposition Zposition Zrotation Xrotation Yrotation",
                      "3 2 1 0 7 0 0 0 0")
    bvh = read_bvh(write_text("six.bvh", text))
    gpos, _ = forward_kinematics(bvh)
    np.testing.assert_allclose(gpos[0, 0], (1, 2, 3))  # root read as Z, Y, X
    np.testing.assert_allclose(gpos[0, 1], (1, 9, 3))  # child's position channels replace its OFFSET
    np.testing.assert_allclose(gpos[0, 2], (6, 9, 3))


def test_fps_argument_overrides_frame_time(write_text):
    bvh = read_bvh(write_text("two.bvh", TWO_BONES), fps=60)
    assert bvh.fps == pytest.approx(60.0)


def test_resample_120_to_30_picks_every_fourth_frame():
    x = np.arange(121, dtype=np.float64)[:, None] * np.ones((1, 3))
    y = resample(x, 120.0, 30.0)
    np.testing.assert_array_equal(y[:, 0], np.arange(0, 121, 4))


def test_resample_24_to_30_is_exact_on_linear_motion():
    t = np.arange(25) / 24.0  # one second at 24 fps
    x = np.stack([t, 2 * t, -t], axis=-1)[:, None, :]  # (F, 1, 3)
    y = resample(x, 24.0, 30.0)
    assert y.shape == (31, 1, 3)
    t30 = np.arange(31) / 30.0
    np.testing.assert_allclose(y[:, 0], np.stack([t30, 2 * t30, -t30], axis=-1), atol=1e-12)


def test_resample_same_rate_is_identity():
    x = np.random.default_rng(0).normal(size=(10, 21, 3))
    assert resample(x, 30.0, 30.0) is x


def test_joint_names_with_spaces_are_joined_with_underscores(write_text):
    """3ds Max's Biped writes names such as ``Bip01 L Thigh``; they read as Blender's importer names the bones."""
    text = _one_joint("Xposition Yposition Zposition", "Zrotation Xrotation Yrotation", "0 0 0 0 0 0")
    text = text.replace("ROOT Root", "ROOT Bip01 Pelvis").replace("JOINT Arm\n  {", "JOINT Bip01 L Thigh {")
    path = write_text("spaces.bvh", text)  # the second name with its brace on the same line
    assert read_bvh(path).names[:2] == ["Bip01_Pelvis", "Bip01_L_Thigh"]


def test_a_byte_order_mark_before_hierarchy_is_read_past(write_text):
    """Some Windows tools start a text file with a UTF-8 byte-order mark; Blender's importer reads such a file."""
    text = _one_joint("Xposition Yposition Zposition", "Zrotation Xrotation Yrotation", "0 0 0 0 0 0")
    path = write_text("bom.bvh", "\ufeff" + text)
    assert read_bvh(path).names[:2] == ["Root", "Arm"]
