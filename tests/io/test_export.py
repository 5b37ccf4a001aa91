"""BVH writer (write, read back, compare joint positions) and the contact-sheet PNG writer."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.eval.plots import contact_sheet, frame_indices
from model_core.io.bvh import forward_kinematics, read_bvh
from model_core.io.bvh_export import euler_zxy, swing, write_bvh
from model_core.motion.conventions import JOINTS
from model_core.motion.synthetic import walking_skeleton
from model_core.rig.rigs import canonical_positions, detect_rig, load_clip

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def test_euler_zxy_inverts_rz_rx_ry():
    rng = np.random.default_rng(1)
    angles = rng.uniform(-80, 80, size=(50, 3))  # (z, x, y) degrees, away from gimbal lock
    mats = np.stack([_rz(np.radians(z)) @ _rx(np.radians(x)) @ _ry(np.radians(y)) for z, x, y in angles])
    np.testing.assert_allclose(euler_zxy(mats), angles, atol=1e-9)
    lock = _rz(0.3) @ _rx(np.pi / 2) @ _ry(0.5)
    z, x, y = np.radians(euler_zxy(lock))
    np.testing.assert_allclose(_rz(z) @ _rx(x) @ _ry(y), lock, atol=1e-9)


def test_swing_takes_a_onto_b_including_opposite_vectors():
    a = np.array([0.0, 1.0, 0.0])
    b = np.array([[1.0, 0, 0], [0, 1, 0], [0, -1, 0], [0.6, 0.8, 0], [0, -0.6, 0.8]])
    r = swing(a, b)
    np.testing.assert_allclose(np.einsum("fij,j->fi", r, a), b, atol=1e-9)
    np.testing.assert_allclose(np.einsum("fij,fkj->fik", r, r), np.broadcast_to(np.eye(3), r.shape), atol=1e-9)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-9)


def test_written_bvh_reads_back_with_the_same_joint_positions(tmp_path):
    pos = walking_skeleton(150)
    path = write_bvh(tmp_path / "walk.bvh", pos)
    bvh = read_bvh(path)
    assert bvh.frames == 150 and bvh.fps == pytest.approx(30.0, rel=1e-6)
    assert detect_rig(bvh.names).family == "mixamo"
    back = canonical_positions(bvh)
    assert np.abs(back - pos).max() < 1e-4  # exact up to rounding: the walker's bone lengths are constant
    gpos, _ = forward_kinematics(bvh)
    assert np.all(np.isfinite(gpos))
    assert not list(tmp_path.glob(".*.tmp"))  # the temporary file was renamed into place


def test_rest_pose_is_a_t_pose(tmp_path):
    bvh = read_bvh(write_bvh(tmp_path / "walk.bvh", walking_skeleton(30)))
    off = {n: bvh.offsets[bvh.index(n)] for n in ("LeftLeg", "LeftFoot", "LeftForeArm", "RightForeArm", "Spine1")}
    assert off["LeftLeg"][1] < 0 and off["LeftFoot"][1] < 0  # legs down
    assert off["LeftForeArm"][0] > 0 > off["RightForeArm"][0]  # arms out to the sides
    assert off["Spine1"][1] > 0  # spine up


def test_write_bvh_refuses_bad_input_and_keeps_old_file(tmp_path):
    path = tmp_path / "keep.bvh"
    path.write_text("old")
    bad = walking_skeleton(10)
    bad[3, 4, 1] = np.nan
    with pytest.raises(ValueError, match="keep.bvh: positions contain NaN"):
        write_bvh(path, bad)
    with pytest.raises(ValueError, match=r"expected positions \[frames, 21, 3\]"):
        write_bvh(path, np.zeros((10, 20, 3)))
    assert path.read_text() == "old"


def test_real_clip_survives_bvh_export(tmp_path, mocap_root, smallest_bvh):
    pos = load_clip(smallest_bvh(mocap_root / "bandai-namco"))
    back = canonical_positions(read_bvh(write_bvh(tmp_path / "real.bvh", pos)))
    # real shoulders shrug, so the spine1-to-arm distance is not constant: allow 2 cm there
    err = np.linalg.norm(back - pos, axis=-1)
    assert err.max() < 0.02 and err.mean() < 0.005


def test_frame_indices_spread_evenly():
    assert frame_indices(100, 5).tolist() == [0, 25, 50, 74, 99]
    assert frame_indices(3, 10).tolist() == [0, 1, 2]
    assert frame_indices(1, 4).tolist() == [0]


def test_contact_sheet_writes_a_png(tmp_path):
    path = contact_sheet(tmp_path / "sheet.png", walking_skeleton(120), count=6, title="walk")
    data = path.read_bytes()
    assert data.startswith(PNG_SIGNATURE) and len(data) > 5000
    width, height = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    assert width > 2 * height  # a strip
    with pytest.raises(ValueError, match="expected positions"):
        contact_sheet(tmp_path / "bad.png", np.zeros((5, len(JOINTS))))
