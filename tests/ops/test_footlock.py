"""Foot lock: contacts, span targets, two-bone IK, and the skate / knee-pop metrics."""

from __future__ import annotations

import numpy as np
import pytest

from model_core.eval.metrics import bone_lengths_of as bone_lengths
from model_core.motion.conventions import CONTACT_JOINTS, JOINT_INDEX, MODEL_FPS
from model_core.motion.features import positions_to_features
from model_core.motion.synthetic import up_a_slope, walking_skeleton
from model_core.ops import footlock as fl


def sliding(pos: np.ndarray, amplitude: float = 0.05) -> np.ndarray:
    """``pos`` ``[F, 21, 3]`` with the whole body drifting on the ground (feet slide while planted)."""
    t = np.arange(len(pos)) / MODEL_FPS
    drift = np.stack([np.sin(2 * np.pi * 1.1 * t), 0 * t, np.cos(2 * np.pi * 0.7 * t)], -1) * amplitude
    return (pos + drift[:, None]).astype(np.float32)


def check_lock(clean: np.ndarray, contacts: np.ndarray | None = None) -> np.ndarray:
    """Lock a sliding copy of ``clean``; assert the three promises; return the locked motion."""
    contacts = fl.detect_foot_contacts(clean) if contacts is None else contacts
    slid = sliding(clean)
    locked = fl.foot_lock(slid, MODEL_FPS, contacts)
    before, after = fl.foot_skate_cm(slid, contacts), fl.foot_skate_cm(locked, contacts)
    assert before > 0.8, "the test clip should slide"
    assert after <= 0.5, f"skate {before:.2f} -> {after:.2f} cm/frame"
    assert np.abs(bone_lengths(locked) - bone_lengths(slid)).max() < 1e-5
    assert fl.knee_pops(locked) <= fl.knee_pops(slid)
    return locked


def test_sliding_synthetic_walk_is_locked():
    clean = walking_skeleton(150)
    locked = check_lock(clean)
    moved = np.abs(locked - sliding(clean)).max(axis=(0, 2))
    legs = [j for leg in fl.LEGS for j in leg[1:]]
    assert np.all(np.delete(moved, legs) == 0), "only knees, ankles and toes move"


def test_real_walk_is_locked(mocap_root, smallest_bvh):
    from model_core.rig.rigs import load_clip

    clean = load_clip(smallest_bvh(mocap_root, "*walk*.bvh"))
    check_lock(clean)


def test_model_contact_channels_drive_the_lock():
    clean = walking_skeleton(120)
    feats, _ = positions_to_features(clean)
    contacts = fl.contacts_from_features(feats)
    assert contacts.shape == (120, 4) and set(np.unique(contacts)) <= {0.0, 1.0}
    check_lock(clean, contacts)


def test_any_unit_and_frame_rate():
    clean = walking_skeleton(90)
    cm = sliding(clean) * 100.0  # centimetres
    contacts = fl.detect_foot_contacts(cm)
    assert np.array_equal(contacts, fl.detect_foot_contacts(sliding(clean)))
    locked = fl.foot_lock(cm, MODEL_FPS, contacts)
    assert fl.foot_skate_cm(locked, contacts, scale=0.01) < 0.5 < fl.foot_skate_cm(cm, contacts, scale=0.01)


def test_no_contacts_changes_nothing():
    pos = walking_skeleton(40)
    out = fl.foot_lock(pos, contacts=np.zeros((40, 4)))
    bent = (fl.knee_angles(pos) > 1.0).all(1)  # a straight knee may be turned to bend forwards
    np.testing.assert_allclose(out[bent], pos[bent], atol=1e-6)
    np.testing.assert_allclose(out, pos, atol=3e-3)


def test_bad_shapes_raise():
    with pytest.raises(ValueError, match="positions"):
        fl.foot_lock(np.zeros((10, 20, 3)))
    with pytest.raises(ValueError, match="contacts"):
        fl.foot_lock(walking_skeleton(10), contacts=np.zeros((9, 4)))


def test_fill_gaps_and_span_targets():
    mask = np.array([1, 1, 0, 1, 0, 0, 0, 1], bool)[:, None]
    assert fl.fill_gaps(mask, 1)[:, 0].tolist() == [1, 1, 1, 1, 0, 0, 0, 1]
    x = np.arange(8, dtype=float)[:, None, None]
    span, targets = fl.span_targets(x, mask)
    assert span[:, 0].tolist() == [0, 0, -1, 1, -1, -1, -1, 2]
    assert targets[:, 0].tolist() == [0.5, 3.0, 7.0]


def test_lock_fades_in_and_out():
    x = np.zeros((21, 1, 3))
    x[:, 0, 0] = np.arange(21) * 0.1  # a joint moving at 0.1 per frame
    mask = np.zeros((21, 1), bool)
    mask[8:13] = True  # contact frames 8..12, target x = 1.0
    off, w = fl.lock_offsets(x, mask, blend=3)
    locked = x[:, 0, 0] + off[:, 0, 0]
    assert np.allclose(locked[8:13], 1.0)
    assert np.allclose(locked[:4], x[:4, 0, 0]) and np.allclose(locked[17:], x[17:, 0, 0])
    assert np.all(np.diff(locked) >= -1e-12), "the fade never moves the joint backwards"
    assert w[8:13].min() == 1.0 and w[0] == 0.0 and 0 < w[6] < 1


def leg(bend: float = 0.3):
    """A leg (hip, knee, ankle) ``[3]`` each: thigh 0.44, shin 0.43, knee bent forward (+Z)."""
    hip = np.array([0.1, 0.9, 0.0])
    knee = hip + 0.44 * np.array([0.0, -np.cos(bend), np.sin(bend)])
    ankle = knee + 0.43 * np.array([0.0, -np.cos(bend), -np.sin(bend)])
    return hip, knee, ankle


def test_ik_reaches_reachable_targets_in_the_knee_plane():
    hip, knee, ankle = leg()
    targets = ankle + np.array([[0.0, 0.0, 0.0], [0.0, 0.05, 0.1], [0.0, 0.2, -0.1], [0.0, 0.3, 0.0]])
    k, a = fl.two_bone_ik(hip, knee, ankle, targets)
    np.testing.assert_allclose(a, targets, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(k - hip, axis=-1), 0.44, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(a - k, axis=-1), 0.43, atol=1e-9)
    np.testing.assert_allclose(k[:, 0], hip[0], atol=1e-9)  # the knee stays in its (x = 0.1) plane
    assert np.all(k[:, 2] > a[:, 2] - 1e-9) and np.all(k[:, 2] > hip[2] - 1e-9), "the knee bends forwards"
    np.testing.assert_allclose(k[0], knee, atol=1e-9)  # the original target gives the original leg


def test_ik_eases_out_of_reach_without_jumps():
    hip, knee, ankle = leg(0.3)
    dist = np.linspace(0.7, 1.2, 501)
    targets = hip + dist[:, None] * np.array([0.0, -1.0, 0.0])
    k, a = fl.two_bone_ik(hip, knee, ankle, targets)
    reach = np.linalg.norm(a - hip, axis=-1)
    assert reach.max() <= 0.87 + 1e-9 and reach.max() > 0.86
    assert np.all(np.diff(reach) >= -1e-12) and np.abs(np.diff(reach)).max() < 2e-3
    assert np.abs(np.diff(k, axis=0)).max() < 0.02, "the knee never snaps"
    assert np.allclose(np.linalg.norm(k - hip, axis=-1), 0.44) and np.allclose(np.linalg.norm(a - k, axis=-1), 0.43)


def test_ik_is_vectorised_over_frames_and_legs():
    hip, knee, ankle = leg()
    shift = np.random.default_rng(0).normal(0, 0.05, (5, 2, 3))
    k, a = fl.two_bone_ik(*(np.broadcast_to(v, (5, 2, 3)) for v in (hip, knee, ankle)), ankle + shift)
    k1, a1 = fl.two_bone_ik(hip, knee, ankle, ankle + shift[3, 1])
    np.testing.assert_allclose(k[3, 1], k1) and np.testing.assert_allclose(a[3, 1], a1)


def test_foot_skate_metric():
    pos = np.zeros((5, 21, 3))
    pos[:, CONTACT_JOINTS[0], 0] = np.arange(5) * 0.01  # left heel slides 1 cm / frame
    pos[:, CONTACT_JOINTS[0], 1] = np.arange(5) * 1.0  # vertical motion is not skate
    contacts = np.zeros((5, 4))
    contacts[1:4, 0] = 1  # on at frames 1..3: steps 1->2 and 2->3
    assert fl.foot_skate_cm(pos, contacts) == pytest.approx(1.0)
    assert fl.foot_skate_cm(pos, np.zeros((5, 4))) == 0.0


def test_knee_angles_and_pops():
    pos = np.repeat(walking_skeleton(1), 4, 0).astype(np.float64)
    hip, knee, ankle = leg(0.0)
    for f, bend in enumerate((0.0, 0.2, 1.0, 1.1)):  # 0, 23, 115 -> pop of 92 degrees, 126
        pos[f, fl._HIP[0]], pos[f, fl._KNEE[0]], pos[f, fl._ANKLE[0]] = leg(bend)
    angles = fl.knee_angles(pos)[:, 0]
    np.testing.assert_allclose(angles, np.degrees([0.0, 0.4, 2.0, 2.2]), atol=1e-6)
    assert fl.knee_pops(pos) == 1


def test_fixed_frames_stay_and_locks_continue_from_them():
    clean = walking_skeleton(150)
    contacts = fl.detect_foot_contacts(clean)
    slid = sliding(clean)
    keep = 47  # the seam cuts through contact spans and fades
    fixed = np.arange(150) < keep
    locked = fl.foot_lock(slid, MODEL_FPS, contacts, fixed=fixed)
    assert np.array_equal(locked[:keep], slid[:keep])
    tail = contacts[keep - 1:]
    assert fl.foot_skate_cm(locked[keep - 1:], tail) <= 0.5 < fl.foot_skate_cm(slid[keep - 1:], tail)
    jump = np.linalg.norm(np.diff(locked[keep - 3:keep + 3], axis=0), axis=-1).max()
    usual = np.linalg.norm(np.diff(slid, axis=0), axis=-1).max()
    assert jump <= usual, "no jump at the seam"


def test_ik_keeps_a_bent_knee_off_full_extension():
    """A target far out of reach leaves the knee bent by the soft limit, never snapped straight;
    a leg that was straight already may stay straight."""
    hip, knee, ankle = leg(0.3)
    far = hip + np.array([0.0, -1.5, 0.0])
    k, a = fl.two_bone_ik(hip, knee, ankle, far)
    pos = np.repeat(walking_skeleton(1), 1, 0).astype(np.float64)
    pos[0, fl._HIP[0]], pos[0, fl._KNEE[0]], pos[0, fl._ANKLE[0]] = hip, k, a
    assert fl.knee_angles(pos)[0, 0] >= fl.MIN_KNEE_DEG - 1e-6
    hip, knee, ankle = leg(0.0)
    k, a = fl.two_bone_ik(hip, knee, ankle, far)
    assert np.linalg.norm(a - hip) == pytest.approx(0.87, abs=1e-6)


@pytest.mark.parametrize("shift", [-0.07, 0.10])
def test_generated_feet_are_put_back_on_the_floor(shift):
    """Frames after a fixed stretch that sink 7 cm into the floor (or hover 10 cm above it): after the
    lock, contact heels and toes are back at the heights the clean walk has them (within the lock's 1 cm
    tolerance on average, 3 cm at worst), and no
    heel or toe is more than 2 cm below its height in contact in the fixed frames."""
    clean = walking_skeleton(150).astype(np.float64)
    keep = 40
    moved = clean.copy()
    moved[keep:, :, 1] += shift * np.clip((np.arange(150 - keep) / 15.0), 0, 1)[:, None]  # eases in over 0.5 s
    contacts = fl.detect_foot_contacts(clean)
    locked = fl.foot_lock(moved, MODEL_FPS, contacts, fixed=np.arange(150) < keep)
    rest = fl.rest_heights(clean, contacts > 0.5, np.arange(150) < keep)
    on = contacts[keep + 20:] > 0.5
    heights = locked[keep + 20:][:, CONTACT_JOINTS, 1]
    before = moved[keep + 20:][:, CONTACT_JOINTS, 1]
    truth = clean[keep + 20:][:, CONTACT_JOINTS, 1]  # the heights the feet had on the floor
    assert np.abs(heights - truth)[on].mean() < 0.015 < 0.05 < np.abs(before - truth)[on].mean()
    assert np.abs(heights - truth)[on].max() < 0.03
    assert (rest - locked[keep:][:, CONTACT_JOINTS, 1]).max() < 0.02
    assert np.abs(bone_lengths(locked) - bone_lengths(moved)).max() < 1e-5


def test_feet_evaluation_of_extended_walks():
    """The bundled model extends procedural walks; after Foot Lock the feet skate less, sink no
    more than 2 cm below the context's floor, and no knee is left fully straight."""
    from model_core.eval.feet_evaluation import evaluate_feet
    from model_core.inference.engine import Engine
    from model_core.model.dataset import Clip

    clips = [Clip(f"walk_{i}", "test", walking_skeleton(60, speed=1.0 + 0.2 * i), np.zeros((60, 70)))
             for i in range(3)]
    out = evaluate_feet(Engine.load(), clips, frames=90)
    assert out["clips"] == 3 and out["frames"] == 90
    assert out["skate_locked_cm"] < out["skate_raw_cm"]
    assert out["sink_locked_cm"] <= 2.0 and out["straight_knees_locked"] == 0.0


def test_feet_brought_to_the_floor_after_fixed_frames_ease_down_without_a_jump():
    """A contact span that runs on from the fixed frames, in a take that rises slowly off the floor
    (a smooth input): the free frames are brought down to the floor the fixed frames stand on, but
    gradually from the seam on, never by a step at the first free frame (Fill Gap on a 120 fps martial
    arts take dropped the whole body 1.4 cm there)."""
    clean = walking_skeleton(150).astype(np.float64)
    contacts = fl.detect_foot_contacts(clean)
    rising = clean.copy()
    rising[..., 1] += 0.002 * np.arange(150)[:, None]  # 2 mm a frame, whole body: no jump anywhere
    keep = 47  # the seam cuts through contact spans
    locked = fl.foot_lock(rising, MODEL_FPS, contacts, fixed=np.arange(150) < keep)
    assert np.array_equal(locked[:keep], rising[:keep].astype(np.float32))
    step = np.abs(np.diff(locked[:, :, 1], axis=0))  # [F - 1, J] vertical moves
    usual = np.abs(np.diff(rising[:, :, 1], axis=0)).max(0)  # each joint's largest in the input
    assert (step[keep - 1] <= usual + 0.002).all(), "no step at the seam"
    later = contacts[keep + 30:] > 0.5
    low = locked[keep + 30:][:, CONTACT_JOINTS, 1] - rising[keep + 30:][:, CONTACT_JOINTS, 1]
    assert low[later].mean() < -0.05  # further on, the feet are brought down (the hovering is corrected)


def test_a_lock_reaches_the_next_spans_target_without_a_step_when_the_last_one_ended_close_by():
    """Two contact spans five frames apart on a joint sliding 1 cm a frame: the pinned joint passes from
    the first span's spot to the second's over the frames between, and arrives there at the span's first
    frame. (A weighted mean of the two spans' corrections stopped short and jumped there: a toe on a 120 fps
    martial arts take snapped 6 cm in one frame as a toe span began just after the last one.)"""
    x = np.zeros((60, 1, 3))
    x[:, 0, 0] = 0.01 * np.arange(60)
    mask = np.zeros((60, 1), bool)
    mask[10:21], mask[26:41] = True, True
    pull, weight = fl.lock_offsets(x, mask, blend=9.0)
    out = (x + pull)[:, 0, 0]
    np.testing.assert_allclose(out[10:21], 0.15, atol=1e-9)  # each span on its spot
    np.testing.assert_allclose(out[26:41], 0.33, atol=1e-9)
    steps = np.diff(out[20:27])  # 18 cm over the 6 steps between them: eased out of one spot and into the next
    assert (steps > 0).all() and steps[0] < 0.015 and steps[-1] < 0.015 and steps.max() < 0.05, steps
    assert (weight >= 0).all() and (weight <= 1).all()


@pytest.mark.parametrize("speed", [0.5, 1.4])
def test_a_settled_lock_leaves_the_feet_of_its_own_result_at_rest(speed):
    """One pass pins the contacts the input has; the result's own resting feet (detected on it, as Fill Gap
    is measured) still creep. Settled, they creep at most half as much, the feet stay at the heights the
    first pass gave them (settling moves them along the ground) and go no deeper below the floor, and the
    settled lock keeps every bone's length, the fixed frames, and the seam free of jumps."""
    slid = sliding(walking_skeleton(150, speed=speed), 0.05).astype(np.float64)
    keep = 47
    fixed = np.arange(150) < keep
    creep, feet = [], []
    for passes in (1, fl.SETTLE_PASSES):
        out = fl.foot_lock(slid, MODEL_FPS, fixed=fixed, settings=fl.FootLockSettings(passes=passes))
        creep.append(fl.foot_skate_cm(out[keep - 1:], fl.detect_foot_contacts(out)[keep - 1:]))
        feet.append(out[:, CONTACT_JOINTS, 1])
    assert creep[1] < creep[0] / 2.0, creep
    assert np.abs(feet[1] - feet[0]).mean() < 0.002 and np.abs(feet[1] - feet[0]).max() < 0.02
    rest = fl.rest_heights(slid, fl.detect_foot_contacts(slid) > 0.5, fixed)[None]
    assert (rest - feet[1]).max() <= max((rest - feet[0]).max(), 0.01) + 1e-6, "no deeper below the floor"
    assert np.array_equal(out[:keep], slid[:keep].astype(np.float32))
    assert np.abs(bone_lengths(out) - bone_lengths(slid)).max() < 1e-5
    jump = np.linalg.norm(np.diff(out[keep - 3:keep + 3], axis=0), axis=-1).max()
    assert jump <= np.linalg.norm(np.diff(slid, axis=0), axis=-1).max()


def test_settling_keeps_the_contacts_it_was_given():
    """Given contacts (the model's channels, say) stay pinned in every pass of a settled lock."""
    clean = walking_skeleton(150)
    contacts = fl.detect_foot_contacts(clean)
    slid = sliding(clean)
    one = fl.foot_skate_cm(fl.foot_lock(slid, MODEL_FPS, contacts), contacts)
    settled = fl.foot_lock(slid, MODEL_FPS, contacts, settings=fl.FootLockSettings(passes=fl.SETTLE_PASSES))
    assert fl.foot_skate_cm(settled, contacts) <= min(one + 0.01, 0.5)


def test_feet_are_found_and_pinned_on_the_ground_under_them():
    """A walk up a slope (0.9 m over its 6 m): measured from one flat floor, only its first steps touch it.
    Measured from the ground under each heel and toe, it has the contacts of the same walk on the flat, and the
    sliding copy is locked with each contact on the slope where the walk put it (on one floor, the middle step's
    height, the first steps were lifted over 30 cm off it)."""
    clean = walking_skeleton(150)
    climbed, ground = up_a_slope(clean)
    truth = fl.detect_foot_contacts(clean)
    flat = fl.detect_foot_contacts(climbed)
    on_ground = fl.detect_foot_contacts(climbed, ground=ground)
    assert flat[75:].sum() < 0.1 * truth[75:].sum()  # the second half's steps are too high to count
    assert (on_ground == truth).mean() > 0.97
    slid = sliding(climbed)
    locked = fl.foot_lock(slid, MODEL_FPS, truth, ground=ground)
    assert fl.foot_skate_cm(slid, truth) > 0.8 and fl.foot_skate_cm(locked, truth) <= 0.5
    assert np.abs(bone_lengths(locked) - bone_lengths(slid)).max() < 1e-5
    on = truth > 0.5
    want = clean[:, CONTACT_JOINTS, 1]  # each contact's height over the slope, as the walk had it
    assert np.abs((locked[:, CONTACT_JOINTS, 1] - ground) - want)[on].max() < 0.02
    flat = fl.foot_lock(slid, MODEL_FPS, truth)  # one flat floor, the steps' median: the first lifted off the slope
    assert np.abs((flat[:, CONTACT_JOINTS, 1] - ground) - want)[on].max() > 0.3


def test_ground_of_the_wrong_shape_or_with_holes_is_refused():
    pos = walking_skeleton(20)
    with pytest.raises(ValueError, match="ground"):
        fl.foot_lock(pos, ground=np.zeros((20, 2)))
    with pytest.raises(ValueError, match="ground"):
        fl.foot_lock(pos, ground=np.full((20, 4), np.nan))


def test_a_foot_planted_on_a_slope_pitches_with_it():
    """A left foot planted flat for a second, on a ground rising 20 % along it: told how high heel and toe stand
    over a floor (``standing``: the pose's own on the flat), the lock keeps the heel there and turns the foot about
    it until the toe stands as high over the slope too (the flat foot's toe was 2.7 cm in it); the foot keeps its
    length. Measured on the pose over the slope instead, the toe's sunk height is taken for its own."""
    still = np.repeat(walking_skeleton(30)[:1], 30, 0)
    heel, toe = JOINT_INDEX["l_foot"], JOINT_INDEX["l_toe"]
    contacts = np.zeros((30, 4), np.float32)
    contacts[:, :2] = 1.0  # the left heel and toe down
    along = (still[0, toe] - still[0, heel]) * np.array([1.0, 0.0, 1.0])
    along /= np.linalg.norm(along)

    def slope(p):
        return 0.2 * ((p - still[0, heel]) @ along)

    ground = slope(still[:, CONTACT_JOINTS])
    standing = still[0, CONTACT_JOINTS, 1]
    length = np.linalg.norm(still[0, toe] - still[0, heel])
    for given, toe_off in ((standing, 0.005), (None, -0.02)):
        out = fl.foot_lock(still, contacts=contacts, ground=ground, standing=given)
        over = out[15, [heel, toe], 1] - slope(out[15, [heel, toe]]) - standing[:2]
        assert abs(over[0]) < 1e-6 and np.linalg.norm(out[15, toe] - out[15, heel]) == pytest.approx(length, abs=1e-5)
        assert (abs(over[1]) < toe_off) if given is not None else (over[1] < toe_off)


def test_a_foot_under_the_floor_is_raised_by_its_own_leg_and_the_hips_stay():
    """A walk sunk 4 cm into its floor: legs_out_of_floor raises each foot that goes under by its own leg, the knee
    bending to reach (every bone keeps its length), so no heel or toe is more than a millimetre under the floor;
    the hips and the upper body do not move, and neither does a leg whose foot is over the floor. A NaN
    floor leaves the clip as it is."""
    walk = walking_skeleton(90).astype(np.float64)
    floor = float(walk[:, CONTACT_JOINTS, 1].min())
    sunk = walk.copy()
    sunk[..., 1] -= 0.04
    out = fl.legs_out_of_floor(sunk, floor)
    assert (floor - sunk[:, CONTACT_JOINTS, 1]).max() > 0.035
    assert (floor - out[:, CONTACT_JOINTS, 1]).max() < 1e-3
    legs = [j for leg in fl.LEGS for j in leg[1:]]
    others = [j for j in range(out.shape[1]) if j not in legs]
    np.testing.assert_array_equal(out[:, others], sunk[:, others])
    assert np.abs(bone_lengths(out) - bone_lengths(sunk)).max() < 1e-6
    for _hip, knee, ankle, toe in fl.LEGS:  # a foot clear of the floor, and for the lift's ease either side, stays
        over = (sunk[:, [ankle, toe], 1] > floor).all(-1)
        clear = np.convolve(over, np.ones(9), "same") == 9
        assert clear.any()
        np.testing.assert_allclose(out[clear][:, [knee, ankle, toe]], sunk[clear][:, [knee, ankle, toe]], atol=1e-9)
    np.testing.assert_array_equal(fl.legs_out_of_floor(sunk[None], np.array([np.nan]))[0], sunk)
