"""Transfer Motion's retarget on real and synthetic takes: proportions, root path, feet on the floor."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.motion.conventions import JOINT_INDEX, PARENTS, UP_AXIS
from model_core.motion.features import floor_height, lowest_foot
from model_core.motion.synthetic import walking_skeleton
from model_core.ops.transfer import bone_lengths, retarget


def stretched(pos: np.ndarray, factors: dict[str, float]) -> np.ndarray:
    """``pos`` with the bones ending at the named joints scaled (their subtrees carried along)."""
    out = np.array(pos, dtype=np.float64)
    for j in range(1, out.shape[1]):
        p = PARENTS[j]
        name = [k for k, v in JOINT_INDEX.items() if v == j][0]
        out[:, j] = out[:, p] + (pos[:, j] - pos[:, p]) * factors.get(name, 1.0)
    return out


def test_same_body_gives_the_same_motion():
    walk = walking_skeleton(90).astype(np.float64)
    out = retarget(walk, walk[:1])
    out[..., UP_AXIS] -= lowest_foot(walk[:1])[0] - floor_height(walk)  # the target's floor: its first frame's foot
    assert np.abs(out - walk).max() < 1e-6


def test_a_taller_body_walks_the_same_steps_longer():
    walk = walking_skeleton(90).astype(np.float64)
    tall = stretched(walk[:1], {n: 1.2 for n in ("l_knee", "l_foot", "r_knee", "r_foot")})
    tall[..., 0] += 3.0  # the target stands elsewhere
    out = retarget(walk, tall)
    np.testing.assert_allclose(bone_lengths(out), bone_lengths(tall), atol=1e-6)
    travel = lambda p: np.linalg.norm(p[-1, 0, [0, 2]] - p[0, 0, [0, 2]])  # noqa: E731
    ratio = travel(out) / travel(walk)
    assert ratio == pytest.approx(1.2, rel=0.02)
    assert out[0, 0, 0] == pytest.approx(tall[0, 0, 0])
    # feet: as high above the target's floor as the source's above its own, scaled
    want = 1.2 * (lowest_foot(walk) - floor_height(walk)) + lowest_foot(tall).min()
    np.testing.assert_allclose(lowest_foot(out), want, atol=1e-6)
    # bone directions are the source's
    child = PARENTS >= 0
    d_src = walk[:, child] - walk[:, PARENTS[child]]
    d_out = out[:, child] - out[:, PARENTS[child]]
    cos = np.sum(d_src * d_out, -1) / np.linalg.norm(d_src, axis=-1) / np.linalg.norm(d_out, axis=-1)
    assert cos.min() > 1 - 1e-9


def test_no_frames_is_an_error():
    walk = walking_skeleton(10)
    with pytest.raises(ValueError, match="no frames"):
        retarget(walk[:0], walk[:1])


def test_real_take_onto_a_smaller_body(walk_folder):
    from model_core.rig.rigs import load_clip

    source = load_clip(sorted(walk_folder.rglob("*.bvh"))[0]).astype(np.float64)
    target = walking_skeleton(1).astype(np.float64) * 0.8
    out = retarget(source, target)
    assert np.isfinite(out).all()
    np.testing.assert_allclose(bone_lengths(out), bone_lengths(target), atol=1e-6)
    floor = lowest_foot(target).min()
    assert np.percentile(lowest_foot(out), 5) == pytest.approx(floor, abs=0.01)
