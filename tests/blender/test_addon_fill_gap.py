"""Fill Gap (in-betweening): the frames between the keys before and after a gap, made by the model
into a new action; the gap from the playhead, a frame range or the first one; bad gaps refused."""

from __future__ import annotations

import shutil

import bpy
import numpy as np
import pytest
from scenes import (
    action_of,
    evaluated_joints,
    fcurves_of,
    find_mocap,
    import_bvh,
    key_snapshot,
    on_steps,
    same_keys,
    walk_bvh,
)


def cut(obj, start: int, end: int) -> None:
    """Delete every key of ``obj``'s action on frames ``start`` to ``end``."""
    for fc in fcurves_of(obj):
        for point in [p for p in fc.keyframe_points if start <= p.co.x <= end][::-1]:
            fc.keyframe_points.remove(point)
        fc.update()


@pytest.fixture
def gapped(addon, tmp_path):
    """A 120-frame walk (keys on every frame) with frames 41-70 cut out, and its true joints."""
    obj = import_bvh(walk_bvh(tmp_path, frames=120))
    truth = evaluated_joints(addon, obj, np.arange(1, 121))
    cut(obj, 41, 70)
    return obj, truth


def test_fill_the_gap_around_the_playhead(addon, real_model, gapped):
    obj, truth = gapped
    old, snapshot = action_of(obj), key_snapshot(obj)
    interpolated = evaluated_joints(addon, obj, np.arange(1, 121))
    bpy.context.scene.frame_set(55)
    assert bpy.ops.strnn.inbetween() == {"FINISHED"}
    new = action_of(obj)
    assert new is not old and new.name == f"{old.name}.filled" and old.use_fake_user
    assert same_keys(snapshot, key_snapshot(obj, old))  # the original is kept as it was
    assert new["strnn"]["operation"] == "Fill Gap" and new["strnn"]["settings"]["frame_start"] == 41
    out = evaluated_joints(addon, obj, np.arange(1, 121))
    np.testing.assert_allclose(out[:40], truth[:40], atol=1e-4)  # the frames around the gap stay
    np.testing.assert_allclose(out[70:], truth[70:], atol=1e-4)
    step = np.linalg.norm(np.diff(out[35:76], axis=0), axis=-1).max(1)
    usual = np.linalg.norm(np.diff(truth, axis=0), axis=-1).max(1).max()
    assert step.max() < 2.0 * usual, "no pop at either end of the gap"
    moved = np.abs(out[40:70] - interpolated[40:70]).max()
    assert moved > 0.01 * np.ptp(truth[..., 2]), "the gap holds the model's motion, not the F-curve interpolation"
    found = new["strnn"]["familiarity"]  # a procedural walk is far from any capture, and the record says so
    assert found["reconstruction_cm"] > found["usual_cm_p90"] and "unlike what the model learnt" in found["note"]


def test_fill_a_frame_range_and_the_first_gap(addon, real_model, gapped):
    obj, _ = gapped
    bpy.context.scene.frame_set(1)  # not in a gap: the first gap is filled
    assert bpy.ops.strnn.inbetween(foot_lock=False) == {"FINISHED"}
    assert action_of(obj)["strnn"]["settings"].to_dict() == {"frame_start": 41, "frame_end": 70,
                                                             "follow_take_frames": 90, "foot_lock": False}
    assert bpy.ops.strnn.inbetween(use_range=True, frame_start=90, frame_end=99) == {"FINISHED"}
    assert action_of(obj)["strnn"]["settings"]["frame_start"] == 90


def refuse(match: str, **kw) -> None:
    before = {a.name: key_snapshot(bpy.context.active_object, a) for a in bpy.data.actions}
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.strnn.inbetween(**kw)
    after = {a.name: key_snapshot(bpy.context.active_object, a) for a in bpy.data.actions}
    assert before.keys() == after.keys() and all(same_keys(before[k], after[k]) for k in before)


def test_the_gap_follows_the_rest_of_the_take_unless_told_not_to(addon, real_model, gapped):
    """The walk steps on outside the gap: Fill Gap finds the steps that fit both ends of the gap there and
    follows them (nearer the cut frames than the models alone); with Follow the Take off it reads only the
    frames next to the gap, as the record says."""
    obj, truth = gapped
    original = action_of(obj)
    assert bpy.ops.strnn.inbetween(use_range=True, frame_start=41, frame_end=70) == {"FINISHED"}
    followed = evaluated_joints(addon, obj, np.arange(41, 71))
    assert action_of(obj)["strnn"]["settings"]["follow_take_frames"] == 90
    obj.animation_data.action = original
    assert bpy.ops.strnn.inbetween(use_range=True, frame_start=41, frame_end=70, follow_take=False) == {"FINISHED"}
    alone = evaluated_joints(addon, obj, np.arange(41, 71))
    assert action_of(obj)["strnn"]["settings"]["follow_take_frames"] == 0
    error = lambda joints: float(np.linalg.norm(joints - truth[40:70], axis=-1).mean())
    assert error(followed) < 0.6 * error(alone), (error(followed), error(alone))


def test_bad_gaps_are_refused_and_change_nothing(addon, real_model, gapped):
    obj, _ = gapped
    refuse("at least 2", use_range=True, frame_start=50, frame_end=50)
    refuse("swap them", use_range=True, frame_start=60, frame_end=50)
    refuse("longer than the 4 s", use_range=True, frame_start=2, frame_end=119)
    cut(obj, 71, 120)
    bpy.context.scene.frame_set(55)
    refuse("No key on the mapped bones .* after frame 40")


def test_a_damaged_gap_model_stops_fill_gap_alone(addon, real_model, gapped, tmp_path):
    """The release's gap model is read when Fill Gap first needs it: a damaged copy leaves Extend working and
    makes Fill Gap refuse, naming the file, with nothing changed."""
    if not (real_model / "gap" / "model.json").exists():
        pytest.skip("this release has no gap model")
    copy = tmp_path / "release"
    shutil.copytree(real_model, copy)
    (copy / "gap" / "model.safetensors").write_bytes(b"\x80\x04pickle")
    prefs = bpy.context.preferences.addons[addon.__name__].preferences
    prefs.model_folder = str(copy)
    bpy.context.scene.frame_set(55)
    refuse(r"Could not read the model: .*gap.*model\.safetensors")
    obj, _ = gapped
    cut(obj, 41, 120)  # a clip to extend: its last key is frame 40
    assert bpy.ops.strnn.extend_clip(frames=10) == {"FINISHED"}


def test_nothing_to_fill(addon, real_model, tmp_path):
    import_bvh(walk_bvh(tmp_path, frames=60))
    refuse("there is no gap to fill")


def test_poll_says_why_on_a_cube(addon):
    bpy.ops.mesh.primitive_cube_add()
    assert not bpy.ops.strnn.inbetween.poll()
    with pytest.raises(RuntimeError, match="not an armature"):
        bpy.ops.strnn.inbetween()


REAL_WALK = "bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh"


def peak_acceleration(joints: np.ndarray) -> float:
    """Largest change of any joint's per-frame velocity ``[F, J, 3]`` between frames (scene units)."""
    return float(np.linalg.norm(np.diff(joints, 2, axis=0), axis=-1).max())


@pytest.mark.parametrize("gap", [(40, 70), (60, 120)])
def test_a_gap_in_a_real_walk_keeps_the_rigs_bones_and_feet_without_a_pop(addon, real_model, gap):
    """A continuation out of step with the take's legs used to be bent onto the target with shins a quarter
    shorter mid-gap; the rig's solve kept its bones, missed the ankle by 10 cm and turned the foot round to
    reach the toe, for a 20 cm flick of the toes in one frame. The gap keeps the bones now: no joint moves
    more abruptly than anywhere in the take."""
    mocap = find_mocap()
    if mocap is None:
        pytest.skip("needs the real motion capture (../shared/mocap unpacked into data/mocap)")
    obj = import_bvh(mocap / REAL_WALK, global_scale=0.01, update_scene_fps=True, update_scene_duration=True)
    start, end = gap
    take = evaluated_joints(addon, obj, np.arange(1, 200))
    assert bpy.ops.strnn.inbetween(use_range=True, frame_start=start, frame_end=end) == {"FINISHED"}
    filled = evaluated_joints(addon, obj, np.arange(start - 5, end + 6))
    assert peak_acceleration(filled) < 1.25 * peak_acceleration(take)  # the bones bent: 5 x
    legs = np.linalg.norm(filled[:, [6, 7, 10, 11]] - filled[:, [5, 6, 9, 10]], axis=-1)  # thighs and shins
    np.testing.assert_allclose(legs, np.broadcast_to(legs[0], legs.shape), rtol=1e-3)


def test_the_gaps_feet_settle_on_the_floor(addon, real_model, gapped):
    """With Foot Lock (the default) the filled gap's feet rest where they touch the floor: on the contact
    frames detected on the result itself, the heels and toes creep a fraction of what the models' gap does
    unlocked, and under a millimetre per frame."""
    from model_core.motion.conventions import zup_to_yup
    from model_core.ops import footlock as fl

    obj, _ = gapped
    original = action_of(obj)
    creep = {}
    for lock in (False, True):
        obj.animation_data.action = original
        assert bpy.ops.strnn.inbetween(use_range=True, frame_start=41, frame_end=70, foot_lock=lock) == {"FINISHED"}
        pos = zup_to_yup(evaluated_joints(addon, obj, np.arange(1, 121)))
        contacts = fl.detect_foot_contacts(pos, 30.0)
        creep[lock] = fl.foot_skate_cm(pos[39:71], contacts[39:71])
    print("gap creep unlocked / locked (cm per frame):", creep)
    assert creep[True] < 0.2 * creep[False] and creep[True] < 0.1


def test_a_gap_in_an_action_on_twos_is_found_past_its_holds_and_filled_on_twos(addon, real_model, tmp_path):
    """Animation on twos (Constant keys every second frame): the frame between two keys is no gap, so the hole cut
    in it is the one filled, at its keys' rate and on twos, Constant, the pose held in between, without a pop."""
    obj = import_bvh(walk_bvh(tmp_path, frames=121))
    on_steps(obj, 2)  # keys on frames 1, 3, ..., 121
    cut(obj, 42, 70)  # keys on 41 and 71 around the hole
    before = evaluated_joints(addon, obj, np.arange(1, 122))
    bpy.context.scene.frame_set(1)
    assert bpy.ops.strnn.inbetween() == {"FINISHED"}
    new = action_of(obj)
    assert new["strnn"]["settings"]["frame_start"] == 42 and new["strnn"]["settings"]["frame_end"] == 70
    assert new["strnn"]["key_step"] == 2
    hips = obj.strnn_map.hips
    fc = next(fc for fc in fcurves_of(obj) if fc.data_path.startswith(f'pose.bones["{hips}"]'))
    inside = [p for p in fc.keyframe_points if 41.5 < p.co[0] < 70.5]
    assert [p.co[0] for p in inside] == list(range(43, 70, 2)) and {p.interpolation for p in inside} == {"CONSTANT"}
    out = evaluated_joints(addon, obj, np.arange(1, 122))
    np.testing.assert_allclose(out[:41], before[:41], atol=1e-4)
    np.testing.assert_allclose(out[70:], before[70:], atol=1e-4)
    moved = np.linalg.norm(np.diff(out, axis=0), axis=-1).mean(-1)  # moved[k]: frame k + 1 -> k + 2
    assert moved[0::2].max() < 1e-6  # onto each even frame: the pose held
    usual, filled = moved[1:40:2].max(), moved[41:70:2]  # onto each key before the hole, and in it (to 71)
    print(f"per key in the hole: {filled.min():.4f} to {filled.max():.4f} against {usual:.4f} before it")
    assert filled.max() < 2.0 * usual and filled.min() > 0.2 * usual


@pytest.mark.parametrize("fps", [24, 30, 60])
def test_the_gap_plays_where_the_model_put_it_at_any_scene_rate(model_calls, addon, fps):
    """Frames 41-60 of a walk filled (Foot Lock off) at 24, 30 and 60 fps: Blender plays every joint of the gap within
    0.5 cm of where the model put it, the frames between the model's own included (most of them at 24 and 60 fps)."""
    from scenes import mixamo_walk

    obj = mixamo_walk(90)
    bpy.context.scene.render.fps = fps
    assert bpy.ops.strnn.inbetween(use_range=True, frame_start=41, frame_end=60, foot_lock=False) == {"FINISHED"}
    made = model_calls.blender(model_calls.inbetween[-1]["out"])
    err = np.linalg.norm(evaluated_joints(addon, obj, np.arange(41, 61)) - made, axis=-1)
    assert err.max() < 0.005, err.max()
