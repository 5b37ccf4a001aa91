"""In-betweening: the continuation bent onto the target arrives there (pose, root, heading) and,
given two target frames, at the target's own velocity; the bundled model fills a gap of a user's
clip at any rate and unit; the interpolation baselines of the evaluation."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.eval.inbetween_evaluation import evaluate_inbetween, interpolate
from model_core.inference.engine import Engine
from model_core.motion.conventions import JOINT_INDEX, PARENTS
from model_core.motion.features import heading
from model_core.motion.synthetic import walking_skeleton
from model_core.ops.familiarity import momentum_shares
from model_core.ops.footlock import body_forward
from model_core.ops.inbetween import (
    INTERPOLATION_LEAN,
    LATE_LEAN,
    bend_onto,
    fill_from,
    gap_fill,
    gap_model_share,
    inbetween,
    inbetween_positions,
    interpolation,
    lean_on_interpolation,
    lean_weights,
)
from model_core.ops.seam import blend_seam
from model_core.ops.skeleton import knee_side, on_skeleton
from model_core.ops.transfer import bone_lengths as rest_lengths


def test_bend_onto_arrives_at_the_target_and_its_velocity():
    walk = walking_skeleton(120, radius=5.0).astype(np.float64)
    start, truth = walk[39], walk[40:71]
    pred = walking_skeleton(150, radius=3.0, speed=1.0)[40:71].astype(np.float64)  # a wrong continuation
    out = bend_onto(pred, start, walk[70:72])
    assert np.abs(out[-1] - walk[70]).max() < 1e-4  # the pose, root and heading of the target
    np.testing.assert_allclose(out[-1] - out[-2], walk[71] - walk[70], atol=1e-3)  # arrives moving on
    assert np.abs(out - truth).max() > 0.01  # it is the bent continuation, not the truth
    first = np.linalg.norm(out[0] - pred[0], axis=-1).max()
    assert first < 0.01, "no jump at the start of the gap"


def test_a_continuation_that_jumps_leaves_the_context_without_a_pop():
    """The model's first frame can sit a little off the context (its decoder's error): the jump is faded out
    as Extend fades it, so the gap's first frame goes on where the context's velocity leads."""
    walk = walking_skeleton(120).astype(np.float64)
    context, truth = walk[20:40], walk[40:71]
    pred = truth + np.array([0.0, 0.1, 0.12])  # the continuation, 16 cm off from its first frame on
    out = fill_from(context, pred, walk[70:72])
    usual = np.linalg.norm(np.diff(walk, axis=0), axis=-1).max()
    assert np.linalg.norm(bend_onto(pred, context[-1], walk[70:72])[0] - context[-1], axis=-1).max() > 1.8 * usual
    steps = np.linalg.norm(np.diff(np.concatenate([context[-2:], out]), axis=0), axis=-1).max(1)
    assert steps.max() < 1.5 * usual
    np.testing.assert_allclose(out[-1], walk[70], atol=1e-4)  # and still arrives


def test_the_model_fills_a_gap_at_any_rate_and_unit():
    engine = Engine.load()
    walk = walking_skeleton(8 * 60, fps=60.0) * 100.0  # centimetres at 60 fps
    before, after = walk[:100], walk[160:]
    gap = inbetween_positions(engine, before, after, 60.0, 59)
    assert gap.shape == (59, 21, 3) and np.isfinite(gap).all()
    seq = np.concatenate([before[-3:], gap, after[:3]])
    step = np.linalg.norm(np.diff(seq, axis=0), axis=-1).max(1)
    assert step.max() < 3 * np.linalg.norm(np.diff(walk, axis=0), axis=-1).max(1).max(), "no pop"
    assert np.linalg.norm(gap[-1] - after[0], axis=-1).mean() < 4.0  # 1/60 s before the target, in cm
    with pytest.raises(ValueError, match="longer than"):
        inbetween_positions(engine, before, after, 60.0, 300)
    with pytest.raises(ValueError, match="one after it"):  # nothing after the gap: said, not an IndexError
        inbetween_positions(engine, before, after[:0], 60.0, 59)


def test_every_window_of_a_gap_is_the_two_models_average():
    """A gap is bounded and bent onto its target, so the continuation through it is the release's and its
    companion's average window after window (Extend averages the first window only)."""
    engine = Engine.load()
    assert engine.companion is not None
    engine.gap = None  # the STRNN's continuation alone (the gap model's share: the next test)
    walk = walking_skeleton(120)
    context, target = walk[:20], walk[80:81]
    out = inbetween(engine, context, target, 59)
    paired = engine.extend(context, 60, paired_windows=None)
    first_only = engine.extend(context, 60)
    np.testing.assert_allclose(paired[:engine.n], first_only[:engine.n], atol=1e-5)
    assert np.abs(paired[engine.n:] - first_only[engine.n:]).max() > 1e-3
    momentum = momentum_shares(engine, context[None].astype(np.float32))[0]
    np.testing.assert_allclose(out, fill_from(context.astype(np.float64), paired.astype(np.float64),
                                              target.astype(np.float64), momentum)[:-1], atol=1e-4)


def test_the_releases_gap_model_takes_its_share_more_in_long_gaps_and_less_in_unfamiliar_motion():
    """Fill Gap blends the STRNN's bent continuation with the release's gap model (a learnt in-betweener):
    more of the gap model the longer the gap, less where the context is unfamiliar; the blend keeps the body's
    bones and still arrives at the target."""
    engine = Engine.load()
    assert engine.gap is not None, "the default release ships its gap model (models/strnn_default/gap)"
    assert gap_model_share(15, 0.0) < gap_model_share(30, 0.0) < gap_model_share(60, 0.0) <= 1.0
    assert gap_model_share(30, 1.0) == pytest.approx(0.5 * gap_model_share(30, 0.0))
    walk = walking_skeleton(200, radius=4.0)
    context, target = walk[:20].astype(np.float64), walk[60:62].astype(np.float64)
    out = inbetween(engine, context, target, 39)
    pred = engine.extend(context.astype(np.float32), 40, paired_windows=None).astype(np.float64)
    momentum = momentum_shares(engine, context[None].astype(np.float32))[0]
    alone = fill_from(context, pred, target, momentum)
    other = gap_fill(engine.gap, context, target, 39)
    share = gap_model_share(39, momentum)
    assert 0.0 < share < 1.0
    mid = np.linalg.norm(out[20] - alone[20], axis=-1).mean()
    assert mid == pytest.approx(share * np.linalg.norm(other[20] - alone[20], axis=-1).mean(), rel=0.2)
    np.testing.assert_allclose(bones(out), np.broadcast_to(bones(context[-1:])[0], bones(out).shape), rtol=2e-3)
    last = np.concatenate([out[-1:], target[:1]])
    assert np.linalg.norm(np.diff(last, axis=0), axis=-1).max() < 0.1  # one frame before the target


def test_the_gap_model_is_nearer_a_real_take_than_interpolation(mocap_root):
    """The shipped gap model on a test-split take it never learnt from, at gaps of 30 frames (1 s)."""
    from model_core.rig.rigs import load_clip

    engine = Engine.load()
    walk = load_clip(mocap_root / "bandai-namco/dataset-2/dataset-2_walk-turn-left_active_032.bvh").astype(np.float64)
    ours, lerp = [], []
    for s in range(0, len(walk) - 51, 15):
        context, truth, target = walk[s:s + 20], walk[s + 20:s + 50], walk[s + 50:s + 52]
        ours.append(np.linalg.norm(gap_fill(engine.gap, context, target, 30)[:-1] - truth, axis=-1).mean())
        lerp.append(np.linalg.norm(interpolate(context[-1], target[0], 30) - truth, axis=-1).mean())
    assert len(ours) >= 3 and np.mean(ours) < 0.7 * np.mean(lerp)


def test_the_gap_leans_on_the_interpolation_late_and_unfamiliar_motion_mid_gap_keeping_both_ends():
    """Every gap leans a tenth of the way towards the interpolation two thirds through it; where the model
    does not know the motion (momentum share 1) half-way at its middle. Either way it leaves the context
    without a pop and arrives at the target and about at its velocity, the body's build kept."""
    walk = walking_skeleton(120, radius=5.0).astype(np.float64)
    context = walk[20:40]
    pred = walking_skeleton(150, radius=3.0, speed=1.0)[40:71].astype(np.float64)  # a wrong continuation
    target = walk[70:72]
    bent = bend_onto(blend_seam(context, pred), context[-1], target)
    np.testing.assert_array_equal(lean_on_interpolation(bent, context[-1], target[0], np.zeros(len(bent))), bent)
    w0, w1 = lean_weights(len(bent), 0.0), lean_weights(len(bent), 1.0)
    assert w0[-1] == w1[-1] == 0.0 and w0.max() == pytest.approx(LATE_LEAN, rel=0.01)
    assert w1.max() == pytest.approx(INTERPOLATION_LEAN, rel=0.01)
    between = np.concatenate([interpolation(context[-1], target[0], len(bent) - 1), target[:1]])

    def far(x, f):
        return np.linalg.norm(x[f] - between[f], axis=-1).mean()

    usual = np.linalg.norm(np.diff(walk, axis=0), axis=-1).max()
    for share, frame, weight in ((0.0, 20, LATE_LEAN), (1.0, 15, INTERPOLATION_LEAN)):  # s = 21/31, 16/31
        leant = fill_from(context, pred, target, share)
        assert far(bent, frame) > 0.05, "the wrong continuation is far from the interpolation there"
        assert far(leant, frame) == pytest.approx((1 - weight) * far(bent, frame), rel=0.1)
        np.testing.assert_allclose(leant[-1], target[0], atol=1e-4)  # arrives
        np.testing.assert_allclose(leant[-1] - leant[-2], target[1] - target[0], atol=0.01)  # about moving on
        steps = np.linalg.norm(np.diff(np.concatenate([context[-2:], leant]), axis=0), axis=-1).max(1)
        assert steps.max() < 1.5 * usual, "no pop where it leaves the context"
        lengths = [np.linalg.norm(x[frame, 4] - x[frame, 0]) for x in (bent, leant)]  # no limb shrinks
        assert lengths[1] == pytest.approx(lengths[0], rel=0.05)


def bones(pos: np.ndarray) -> np.ndarray:
    """Bone lengths ``[F, J - 1]`` of joints ``[F, J, 3]``."""
    return np.linalg.norm(pos[:, 1:] - pos[:, PARENTS[1:]], axis=-1)


def test_the_gap_keeps_the_bodys_bones_where_its_legs_swing_against_the_target():
    """A continuation out of step with the target: bending each joint by its own offset (and leaning on
    the interpolation) shortens the swinging legs mid-gap, which a rig cannot follow (its solve misses
    the ankle and turns the foot round). The gap keeps the body's bones from the context's lengths to the
    target's, each leg's ankle kept by IK, and still arrives at the target."""
    walk = walking_skeleton(200, radius=5.0).astype(np.float64)
    context, target = walk[20:40], walk[70:72]
    pred = walk[70:101]  # the same walk a second ahead: its legs in another phase than the target's
    shins = [JOINT_INDEX[f"{s}_foot"] - 1 for s in "lr"]  # bone index of each shin (joint - 1)
    bent = lean_on_interpolation(bend_onto(blend_seam(context, pred), context[-1], target), context[-1], target[0],
                                 lean_weights(len(pred), 0.0))
    rest = bones(context[-1:])[0]
    assert (bones(bent)[:, shins] / rest[shins]).min() < 0.9, "bending alone shortens the legs mid-gap"
    out = fill_from(context, pred, target)
    np.testing.assert_allclose(bones(out), np.broadcast_to(rest, bones(out).shape), rtol=1e-3)
    np.testing.assert_allclose(out[-1], target[0], atol=1e-4)  # still arrives
    ankles = [JOINT_INDEX[f"{s}_foot"] for s in "lr"]
    assert np.linalg.norm(out[:, ankles] - bent[:, ankles], axis=-1).max() < 0.03  # the feet go about where they went
    # each knee bends the way the context's do, never through the leg (this procedural walk's bend backwards)
    hip, knee, ankle = (out[:, [JOINT_INDEX[f"{s}_{j}"] for s in "lr"]] for j in ("upleg", "knee", "foot"))
    axis = (ankle - hip) / np.linalg.norm(ankle - hip, axis=-1, keepdims=True)
    off = (knee - hip) - axis * np.sum((knee - hip) * axis, -1, keepdims=True)
    assert knee_side(context) == -1.0
    assert (np.sum(off * body_forward(out)[:, None], -1) < 1e-6).all()
    # with other lengths at the target, they change smoothly over the gap
    longer = on_skeleton(bent, rest_lengths(context), 1.1 * rest_lengths(target[:1]))
    ratio = bones(longer)[:, shins[0]] / rest[shins[0]]
    assert ratio[0] == pytest.approx(1.0 + 0.1 / len(bent), abs=2e-3) and ratio[-1] == pytest.approx(1.1, abs=1e-3)


def test_captured_knees_bend_forwards(mocap_root):
    from model_core.rig.rigs import load_clip

    walk = load_clip(mocap_root / "bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh")
    assert knee_side(walk) == 1.0 and knee_side(walk[:1] * 0 + walk[:1, :1]) == 1.0  # and a body that never bends


def test_a_single_context_pose_is_enough():
    engine = Engine.load()
    walk = walking_skeleton(60)
    out = inbetween(engine, walk[:1], walk[40:41], 39)
    assert out.shape == (39, 21, 3) and np.isfinite(out).all()


def test_interpolation_baselines_and_the_evaluation_keys():
    walk = walking_skeleton(200, radius=4.0)
    lerp = interpolate(walk[0], walk[30], 29)
    np.testing.assert_allclose(lerp[14], 0.5 * (walk[0] + walk[30]), atol=0.02)  # halfway, up to the root split
    turn = interpolate(walk[0], walk[30], 29, heading=True)
    yaw = heading(turn, sigma=0.0)
    assert np.all(np.diff(np.unwrap(yaw)) * np.sign(np.unwrap(yaw)[-1] - yaw[0]) >= -1e-6)  # turns one way

    class Clip:
        positions = walk

    out = evaluate_inbetween(Engine.load(), [Clip()], gaps=(15, 30))
    assert out["gap_frames"] == [15, 30] and out["windows"][0] > 0
    assert set(out["l2p_cm"]) == {"strnn", "interpolation", "interpolation_heading", "strnn_without_take"}
    # a periodic walk: Fill Gap follows the take's other laps and is nearer the truth than the models alone
    assert all(a < 0.5 * b for a, b in zip(out["l2p_cm"]["strnn"], out["l2p_cm"]["strnn_without_take"]))
    assert max(out["target_error_cm"]["strnn"]) < 1.0
    assert set(out["foot_skate_cm"]) == set(out["foot_contact_share"]) == {"strnn", "strnn_locked", "interpolation",
                                                                         "real"}
    assert 0.1 < out["foot_contact_share"]["real"][0] < 0.9  # a walk has its feet down part of the time


def test_gap_skate_is_pooled_over_contact_steps_and_floating_feet_show_in_the_share():
    """A window whose feet never touch the floor has no contact step: it adds nothing to the skate (it
    used to count as a window of perfect feet) and lowers the share of contact steps instead."""
    from model_core.eval.inbetween_evaluation import _skate

    walk = walking_skeleton(200, radius=4.0)
    ctx, gap, tgt = walk[None, :20], walk[None, 20:50], walk[None, 50]
    skate, share = _skate(ctx, gap, tgt)
    assert skate > 0 and share > 0.1
    floating = gap + np.array([0.0, 0.3, 0.0])  # the same motion 30 cm up: no foot near the floor
    both = _skate(np.concatenate([ctx, ctx]), np.concatenate([gap, floating]), np.concatenate([tgt, tgt]))
    assert both[0] == pytest.approx(skate)  # not halved by the floating window
    assert both[1] == pytest.approx(share / 2, rel=0.1)


@pytest.mark.parametrize("turn", [np.pi - 0.1, -np.pi + 0.05, 2.0])
def test_bend_onto_turns_with_the_scene_across_the_back_heading(turn):
    """The bend does not care which way the scene faces: turned about the vertical (headings crossing
    +-180 degrees included), the result is the same motion turned, with no spin."""
    walk = walking_skeleton(120, radius=5.0).astype(np.float64)
    pred = walking_skeleton(150, radius=3.0, speed=1.0)[40:71].astype(np.float64)
    c, s = np.cos(turn), np.sin(turn)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])  # about +Y
    turned = bend_onto(pred @ rot.T, walk[39] @ rot.T, walk[70:72] @ rot.T)
    np.testing.assert_allclose(turned, bend_onto(pred, walk[39], walk[70:72]) @ rot.T, atol=1e-4)
