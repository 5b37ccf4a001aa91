"""Extend Clip on BVH imports and on armatures built in code, with the real model.

The new frames must put the rig's joints where the model put them (its calls recorded, ``model_calls``); on
real takes the result must continue the clip without a jump, neither freeze nor explode, and keep bone lengths.
"""

from __future__ import annotations

import importlib

import bpy
import numpy as np
import pytest
from scenes import (
    action_of,
    addon_module,
    evaluated_joints,
    fcurves_of,
    find_mocap,
    first_fractions,
    frames_set_until,
    import_bvh,
    key_snapshot,
    makehuman_walk,
    mixamo_walk,
    object_walk,
    on_moving_parent,
    on_steps,
    ramp,
    rigify_walk,
    same_keys,
    smpl_walk,
    walk_bvh,
)

# How near Blender plays the joints to where the model put them: the solve keeps the rig's bone lengths, which the
# model's joints keep only nearly.
FOLLOW_CM = 1.0

CLIPS = {
    "bandai_namco": "bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh",
    "iclone_cc_base": "cmu/iclone/002_01.bvh",
    "acrnn": "cmu/acrnn-dance/salsa/01.bvh",
    "cmu_cgspeed": "cmu/cgspeed/tmoco_02_01.bvh",
}


def extend(frames: int) -> tuple:
    """Run the operator on the active object; (old action, new action, old keys)."""
    obj = bpy.context.active_object
    old = action_of(obj)
    before = key_snapshot(obj)
    assert bpy.ops.strnn.extend_clip(frames=frames) == {"FINISHED"}
    return old, action_of(obj), before


def check_new_action(obj, old, new, before, frames: int) -> None:
    assert new is not old and new.name.startswith(old.name)
    assert old.use_fake_user and same_keys(before, key_snapshot(obj, old))
    assert new.frame_range[1] == old.frame_range[1] + frames


def follows(got: np.ndarray, made: np.ndarray, cm: float = FOLLOW_CM) -> None:
    """Blender plays the joints ``got`` ``[F, 21, 3]`` where the model put them (``made``), within ``cm``."""
    err = np.linalg.norm(got - made, axis=-1)
    assert err.max() < cm / 100, (err.max(), np.unravel_index(err.argmax(), err.shape), err.max(0).round(4))


@pytest.mark.parametrize("fps", [30, 24, 60])
def test_extend_bvh_fixture_follows_the_model(tmp_path, model_calls, addon, fps):
    obj = import_bvh(walk_bvh(tmp_path, frames=90))
    bpy.context.scene.render.fps = fps
    last = int(action_of(obj).frame_range[1])
    old, new, before = extend(40)
    check_new_action(obj, old, new, before, 40)
    assert bpy.context.scene.frame_end >= last + 40
    follows(evaluated_joints(addon, obj, np.arange(last + 1, last + 41)), model_calls.extended())


@pytest.mark.parametrize("make", [mixamo_walk, rigify_walk], ids=["mixamo", "rigify"])
def test_extend_built_armatures_follows_the_model(model_calls, addon, make):
    obj = make(60)
    original = evaluated_joints(addon, obj, np.arange(1, 61))
    old, new, before = extend(30)
    check_new_action(obj, old, new, before, 30)
    assert np.abs(evaluated_joints(addon, obj, np.arange(1, 61)) - original).max() < 1e-5  # old frames unchanged
    follows(evaluated_joints(addon, obj, np.arange(61, 91)), model_calls.extended())
    hips = obj.strnn_map.hips
    loc_keys = [fc for fc in fcurves_of(obj) if fc.data_path == f'pose.bones["{hips}"].location']
    assert loc_keys and all(fc.keyframe_points[-1].co[0] == 90 for fc in loc_keys)  # root motion continues
    for fc in fcurves_of(obj):  # bones outside the map keep their keys
        if "Middle1" in fc.data_path or "f_middle.01" in fc.data_path:
            assert fc.keyframe_points[-1].co[0] <= 60


def test_bone_names_with_quotes_and_backslashes(model_calls, addon):
    """Blender escapes " and \\ in F-curve paths; such bones must be read and written like any other."""
    obj = mixamo_walk(60)
    assert bpy.ops.strnn.auto_map() == {"FINISHED"}
    bone = obj.data.bones[obj.strnn_map.l_knee]  # a keyed bone
    bone.name = 'Sh"in\\L'  # Blender renames the action's F-curve paths with it
    obj.strnn_map.l_knee = bone.name
    assert any('Sh\\"in\\\\L' in fc.data_path for fc in fcurves_of(obj))
    bpy.context.scene.frame_set(1)  # a bone whose keys were missed would be read in its frame-1 pose
    old, new, before = extend(30)
    check_new_action(obj, old, new, before, 30)
    follows(evaluated_joints(addon, obj, np.arange(61, 91)), model_calls.extended())


def seam_and_speed(pos: np.ndarray, n_ctx: int) -> tuple[float, float]:
    """(seam step / largest context step, new mean speed / context mean speed) of joints ``[F, 21, 3]``."""
    step = np.linalg.norm(np.diff(pos, axis=0), axis=-1).mean(-1)  # mean joint displacement per frame
    ctx, seam, new = step[: n_ctx - 1], step[n_ctx - 1], step[n_ctx:]
    return seam / ctx.max(), new.mean() / ctx.mean()


def bone_length_change(addon, obj, frames: np.ndarray) -> float:
    """Largest relative change of any bone's length (parent head to head) against the first frame;
    the hips bone moves freely (root motion), so its link to its parent is left out."""
    rig_io = addon_module(addon, "strnn_addon.scene.rig_io")
    pipeline = addon_module(addon, "strnn_addon.scene.pipeline")
    clip = pipeline.prepare(bpy.context, obj)
    rig, hips = clip.rig, clip.anchors.bone[0]
    pose, _ = rig_io.pose_matrices_evaluated(bpy.context, obj, rig, frames.astype(np.float64))
    child = np.flatnonzero((rig.parents >= 0) & (np.arange(len(rig.names)) != hips))
    heads = pose[..., :3, 3]  # (F, B, 3)
    length = np.linalg.norm(heads[:, child] - heads[:, rig.parents[child]], axis=-1)
    keep = length[0] > 1e-3 * length[0].max()  # coincident heads have no length to keep
    return float(np.abs(length[:, keep] / length[:1, keep] - 1).max(initial=0.0))


def check_real_extension(addon, obj, frames: int) -> None:
    last = int(action_of(obj).frame_range[1])
    old, new, before = extend(frames)
    check_new_action(obj, old, new, before, frames)
    span = np.arange(last - 29, last + frames + 1)
    pos = evaluated_joints(addon, obj, span)
    assert np.isfinite(pos).all()
    seam, speed = seam_and_speed(pos, 30)
    lengths = bone_length_change(addon, obj, span)
    print(f"seam {seam:.2f}, speed ratio {speed:.2f}, bone length change {lengths:.5f}")
    assert seam < 3.0, "jump at the seam"
    assert 0.05 < speed < 5.0, "frozen or exploding"
    assert lengths < 1e-3


@pytest.mark.parametrize("family", sorted(CLIPS))
def test_extend_real_clip_with_model(real_model, addon, family):
    root = find_mocap()
    if root is None or not (root / CLIPS[family]).exists():
        pytest.skip("motion capture not unpacked (data/mocap or ../shared/mocap)")
    obj = import_bvh(root / CLIPS[family], update_scene_fps=True)
    check_real_extension(addon, obj, 60)


@pytest.mark.parametrize("make", [mixamo_walk, rigify_walk, makehuman_walk, smpl_walk],
                         ids=["mixamo", "rigify", "makehuman", "smpl"])
def test_extend_built_armature_with_model(real_model, addon, make):
    check_real_extension(addon, make(60), 60)


def test_from_current_frame_replaces_the_tail(model_calls, addon):
    """Continue after the playhead: frames up to it stay, the mapped bones' later keys are replaced
    by the continuation, unmapped bones keep theirs, the original action is kept."""
    obj = mixamo_walk(90)
    finger = obj.pose.bones["mixamorig:LeftHandMiddle2"]  # not written by the solve
    for frame in (1, 90):
        finger.keyframe_insert("rotation_quaternion", frame=frame)
    frames = np.arange(1, 91)
    before = evaluated_joints(addon, obj, frames)
    bpy.context.scene.frame_set(60)
    old = action_of(obj)
    snapshot = key_snapshot(obj)
    assert bpy.ops.strnn.extend_clip(frames=20, from_current=True) == {"FINISHED"}
    new = action_of(obj)
    assert new is not old and old.use_fake_user and same_keys(snapshot, key_snapshot(obj, old))
    assert np.abs(evaluated_joints(addon, obj, np.arange(1, 61)) - before[:60]).max() < 1e-5
    follows(evaluated_joints(addon, obj, np.arange(61, 81)), model_calls.extended())
    hips = obj.strnn_map.hips
    assert any(finger.name in fc.data_path for fc in fcurves_of(obj))
    for fc in fcurves_of(obj):
        last = fc.keyframe_points[-1].co[0]
        if fc.data_path.startswith(f'pose.bones["{hips}"]'):
            assert last == 80  # the old tail (61-90) is gone
        elif finger.name in fc.data_path:
            assert last == 90  # a bone the solve does not write keeps its keys
    assert new["strnn"]["settings"]["from_frame"] == 60


@pytest.mark.parametrize("frame, match", [
    (200, r"Frame 200 lies outside the action 'MixamoAction' \(frames 1-90\): move the current frame into it"),
    (10, r"has 10 up to frame 10; extending needs at least 20"),
], ids=["outside", "too_early"])
def test_from_current_frame_refused(model_calls, addon, frame, match):
    obj = mixamo_walk(90)
    bpy.context.scene.frame_set(frame)
    old, snapshot = action_of(obj), key_snapshot(obj)
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.strnn.extend_clip(frames=20, from_current=True)
    assert action_of(obj) is old and same_keys(snapshot, key_snapshot(obj))


def test_extend_says_when_the_motion_is_unfamiliar(real_model, addon):
    """A procedural walk is far from any capture: the new action records how far, and the report
    (built from that record) tells the animator to check the result."""
    obj = mixamo_walk(60)
    assert bpy.ops.strnn.extend_clip(frames=10) == {"FINISHED"}
    found = action_of(obj)["strnn"]["familiarity"]
    assert found["reconstruction_cm"] > found["usual_cm_p90"]
    assert "unlike what the model learnt" in found["note"]
    common = importlib.import_module(addon.__name__ + ".strnn_addon.stages.common")
    assert common.report_note(action_of(obj)).startswith(". This motion is unlike")


@pytest.mark.parametrize("playhead", [1, 30, 60])
def test_an_action_that_moves_the_object_itself_is_extended_from_where_it_ends(real_model, addon, playhead):
    """The walk's travel is keyed on the armature object: wherever the playhead stands when Extend runs, the new
    frames go on from where the action ends (they used to be put through the object's matrix at the playhead,
    and with it at frame 1 the character jumped back 1.2 m at the seam)."""
    obj = object_walk(60)
    bpy.context.scene.frame_set(playhead)
    old, new, before = extend(30)
    check_new_action(obj, old, new, before, 30)
    pos = evaluated_joints(addon, obj, np.arange(55, 91))
    step = np.linalg.norm(np.diff(pos[:, 0], axis=0), axis=-1)  # the hips' world step, a frame
    assert step.max() < 0.05, step  # 2 cm a frame before the seam; no jump
    assert pos[0, 0, 1] - pos[-1, 0, 1] > 0.3  # and it walks on along -Y, as the take


def test_where_an_action_moves_the_object_itself_its_new_frames_place_is_had_without_setting_the_scenes_frame(
        real_model, addon):
    """The object's own channels carry the walk and nothing else of the scene moves it: where it stands at each new
    frame is evaluated with the rig alone (as its read is), not by setting the whole scene to each new frame."""
    obj = object_walk(60)
    bpy.context.scene.frame_set(30)
    steps = addon_module(addon, "strnn_addon.stages.extend").extend_steps(bpy.context, obj, frames=30)
    assert set(frames_set_until(steps)) <= {30}  # (the scene's own frame, put back after a read)
    steps.close()


def test_a_rig_on_a_moving_parent_is_extended_in_steps_where_the_parent_takes_it(tmp_path, addon, model_calls,
                                                                                 monkeypatch):
    """A rig parented to a keyed empty (a rider on a moving vehicle): where the parent takes it at each new frame is
    had from Blender frame by frame, in steps the operator shows and Esc stops at (closed there, the rig, its take
    and the scene's frame as they were, no action left behind); run to the end, the new frames ride with the
    parent, as the model made them."""
    rig_io = addon_module(addon, "strnn_addon.scene.rig_io")
    stages = addon_module(addon, "strnn_addon.stages.extend")
    drive = addon_module(addon, "model_core.inference.steps").drive
    monkeypatch.setattr(rig_io, "STEP_SECONDS", 0.0)  # hand back after every frame
    obj = import_bvh(walk_bvh(tmp_path, frames=60))
    on_moving_parent(obj, 6.0, 120, linear=True)
    bpy.context.view_layer.objects.active = obj
    scene = bpy.context.scene
    scene.frame_set(20)
    old, keys, actions = action_of(obj), key_snapshot(obj), set(bpy.data.actions)
    steps = stages.extend_steps(bpy.context, obj, frames=60)
    first_fractions(steps, "solve")
    steps.close()
    assert action_of(obj) is old and set(bpy.data.actions) == actions and same_keys(keys, key_snapshot(obj))
    assert scene.frame_current == 20
    new = drive(stages.extend_steps(bpy.context, obj, frames=60))
    assert action_of(obj) is new and new is not old
    played = evaluated_joints(addon, obj, np.arange(61, 121))
    assert np.linalg.norm(played - model_calls.extended(), axis=-1).max() < FOLLOW_CM / 100
    assert np.ptp(played[:, 0, 0]) > 2.5  # the parent carried it 3 m along X


def test_an_action_shared_by_two_armatures_each_on_its_own_slot_is_extended_on_the_right_slot(real_model, addon):
    """Blender 4.4 and later let one action animate several objects, each through a slot of its own. Extending the
    second armature writes its new keys into its own slot of the new action (they went into the first slot, and
    the second armature stood still in every new frame); the first armature's motion is untouched."""
    a, b = mixamo_walk(60), mixamo_walk(60)
    shared, own = action_of(a), action_of(b)
    if not hasattr(shared, "slots"):
        pytest.skip("actions have no slots before Blender 4.4")
    anim = addon_module(addon, "strnn_addon.scene.anim")
    slot = shared.slots.new(id_type="OBJECT", name="Second")
    bag = anim.ensure_channelbag(shared, slot)
    for fc in anim.Channels(own, b.animation_data).fcurves:
        new = bag.fcurves.new(fc.data_path, index=fc.array_index)
        new.keyframe_points.add(len(fc.keyframe_points))
        for key, src in zip(new.keyframe_points, fc.keyframe_points):
            key.co, key.handle_left, key.handle_right = src.co, src.handle_left, src.handle_right
    b.animation_data.action = shared
    b.animation_data.action_slot = slot
    frames = np.arange(1, 61)
    a_before = evaluated_joints(addon, a, frames)
    bpy.context.view_layer.objects.active = b
    a.select_set(False)  # the second armature alone (with both selected, each is extended)
    old, new, before = extend(30)
    check_new_action(b, old, new, before, 30)
    assert b.animation_data.action_slot.identifier == slot.identifier
    pos = evaluated_joints(addon, b, np.arange(55, 91))
    step = np.linalg.norm(np.diff(pos[:, 0], axis=0), axis=-1)
    assert step[6:].min() > 0.003, step  # the second armature walks on in the new frames
    assert action_of(a) is shared and np.abs(evaluated_joints(addon, a, frames) - a_before).max() < 1e-6


def test_a_hand_keyed_pass_keeps_its_frames_when_extended(real_model, addon):
    """Keys every 10th frame with Bezier curves between (a blocking pass): keys following the last one made Blender
    recompute its automatic handles, and the last stretch of the original motion moved (up to 4.7 cm at frame
    58). The keys that were there keep their handles, so every original frame stays as it was."""
    obj = mixamo_walk(61)
    for fc in fcurves_of(obj):
        for key in [k for k in fc.keyframe_points if (round(k.co[0]) - 1) % 10][::-1]:
            fc.keyframe_points.remove(key)
        fc.update()
    frames = np.arange(1, 62)
    before = evaluated_joints(addon, obj, frames)
    assert bpy.ops.strnn.extend_clip(frames=20) == {"FINISHED"}
    assert np.abs(evaluated_joints(addon, obj, frames) - before).max() < 1e-5


def test_an_action_with_a_manual_frame_range_is_extended_from_the_ranges_end(real_model, addon):
    """A manual frame range (Action > Manual Frame Range, 1-30 on 60 frames of keys) is the clip the animator
    declared: Extend goes on from frame 30, the written bones' keys after it give way to the new frames (they
    were left in, and the motion jumped back to them after the new frames), and the new action's range widens to
    hold them (it stayed 1-30, leaving them outside)."""
    obj = mixamo_walk(60)
    old = action_of(obj)
    old.use_frame_range = True
    old.frame_start, old.frame_end = 1, 30
    before = key_snapshot(obj)
    assert bpy.ops.strnn.extend_clip(frames=20) == {"FINISHED"}
    new = action_of(obj)
    assert new is not old and same_keys(before, key_snapshot(obj, old)) and tuple(old.frame_range) == (1, 30)
    assert new.use_frame_range and tuple(new.frame_range) == (1, 50)
    assert max(k.co[0] for fc in fcurves_of(obj) for k in fc.keyframe_points) == 50
    pos = evaluated_joints(addon, obj, np.arange(25, 51))
    assert np.linalg.norm(np.diff(pos[:, 0], axis=0), axis=-1).max() < 0.05  # the hips go on from frame 30


def test_extend_says_when_the_character_lies_as_a_z_up_file_imported_y_up_does(real_model, addon, tmp_path):
    """A Z-up BVH imported with the importer's default Up (Y) lies on its back in the scene: Extend still runs, and
    its record and report say the character stands along the scene's -Y and how to import it standing. Imported
    with Up Z, it stands and nothing is said."""
    from model_core.io.bvh_export import write_bvh
    from model_core.motion.synthetic import walking_skeleton

    take = write_bvh(tmp_path / "z_up.bvh", walking_skeleton(60) @ np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]).T)
    notes = {}
    for up, forward in (("Y", "-Z"), ("Z", "Y")):
        bpy.ops.wm.read_homefile(use_empty=True)
        obj = import_bvh(take, axis_up=up, axis_forward=forward)
        assert bpy.ops.strnn.extend_clip(frames=10) == {"FINISHED"}
        notes[up] = action_of(obj)["strnn"].get("stance", {}).get("note", "")
    assert "stands along the scene's -Y axis" in notes["Y"] and "Transform > Up" in notes["Y"], notes
    common = importlib.import_module(addon.__name__ + ".strnn_addon.stages.common")
    assert notes["Z"] == "" and "stands along" not in common.report_note(action_of(bpy.context.active_object))


def test_extend_says_when_the_action_is_too_short_for_follow_the_clip(real_model, addon):
    """A 1.5 s action extended by 4 s with Follow the Clip on: the new action's record says how much the clip gave and
    how much it needs, and how the clip was played on (back and forth or round), and the report tells the animator
    what that means and what to do; a 4 s action gets the entry without a note, and with Follow the Clip off there
    is nothing to say."""
    common = importlib.import_module(addon.__name__ + ".strnn_addon.stages.common")
    fps = bpy.context.scene.render.fps
    obj = mixamo_walk(int(1.5 * fps))
    assert bpy.ops.strnn.extend_clip(frames=4 * fps) == {"FINISHED"}
    entry = action_of(obj)["strnn"]["follow_clip"].to_dict()
    assert entry["seconds"] < entry["needed_s"] and "Follow the Clip off" in entry["note"]
    assert f"play it {entry['plays']}, over and over (every {entry['cycle_s']:.1f} s)" in entry["note"]
    assert "The action gives Follow the Clip" in common.report_note(action_of(obj))
    for seconds, follow in ((4, True), (1.5, False)):
        bpy.ops.wm.read_homefile(use_empty=True)
        obj = mixamo_walk(int(seconds * fps))
        assert bpy.ops.strnn.extend_clip(frames=4 * fps, follow_clip=follow) == {"FINISHED"}
        record = action_of(obj)["strnn"].to_dict()
        assert ("note" not in record["follow_clip"]) if follow else ("follow_clip" not in record)


def test_a_fighter_paused_at_the_cut_is_continued_near_the_pause(real_model, addon, monkeypatch):
    """Martial arts, an action family the model never learnt (take 08, 120 fps), cut at frame 600 where the
    fighter stands between moves and extended by half a second from there (From Current Frame): the first frames
    stay near the pause, nearer the take than the move the model alone invents (``ops.extend.STILL_SPEED`` turned
    off in the installed extension, for the comparison), and the new action's record says so."""
    mocap = find_mocap()
    if mocap is None:
        pytest.skip("needs the motion-capture data (data/mocap)")
    bridge = addon_module(addon, "strnn_addon.engine_bridge")
    error = {}
    for still in (True, False):
        if not still:
            monkeypatch.setattr(addon_module(addon, "model_core.ops.extend"), "STILL_SPEED", 0.0)
            bridge._RESULTS.clear()  # the same clip: not the result kept from the first run
        bpy.ops.wm.read_homefile(use_empty=True)
        obj = import_bvh(mocap / "cmu/acrnn-dance/martial/08.bvh", global_scale=0.01, update_scene_fps=True)
        frames = np.arange(600, 661)
        take = evaluated_joints(addon, obj, frames)
        bpy.context.scene.frame_set(600)
        assert bpy.ops.strnn.extend_clip(frames=60, from_current=True) == {"FINISHED"}
        record = action_of(obj)["strnn"].to_dict()
        if still:  # the record, and so the report, says the first window was held near the pause
            assert record["first_window"]["motion_kept"] < 0.75 and "come to rest" in record["first_window"]["note"]
        else:
            assert "first_window" not in record
        new = evaluated_joints(addon, obj, frames)
        assert np.abs(new[0] - take[0]).max() < 1e-4  # the frames up to the cut stay
        error[still] = np.linalg.norm(new[1:] - take[1:], axis=-1).mean(-1)  # metres, frame by frame
    held = np.linalg.norm(take[1:] - take[0], axis=-1).mean(-1)  # holding the last pose
    assert error[True].mean() < 0.7 * error[False].mean(), error
    assert error[True][-1] < error[False][-1] and error[True][-1] < 2 * held[-1]


def test_an_unseen_walk_extended_by_20_s_still_walks_when_it_follows_the_clip(real_model, addon):
    """A 60 fps walk of an actor the model never saw (the held-out CMU subject's 006_01, 4 s), extended by
    1,200 frames: with Follow the Clip (the default) the last 5 s still step (the feet swing past each other
    and stay on the floor, as in the take); the model alone turns it into a two-footed hop, its feet out of the floor.
    The record says how much of the clip was followed."""
    mocap = find_mocap()
    if mocap is None:
        pytest.skip("needs the motion-capture data (data/mocap)")
    results = {}
    for follow in (True, False):
        bpy.ops.wm.read_homefile(use_empty=True)
        obj = import_bvh(mocap / "cmu/iclone/006_01.bvh", global_scale=0.01, update_scene_fps=True)
        last = int(action_of(obj).frame_range[1])
        assert bpy.ops.strnn.extend_clip(frames=1200, follow_clip=follow) == {"FINISHED"}
        record = action_of(obj)["strnn"].to_dict()
        assert (record["settings"]["follow_clip_frames"] == last) if follow else \
            (record["settings"]["follow_clip_frames"] == 0)
        take = evaluated_joints(addon, obj, np.arange(1, last + 1))
        new = evaluated_joints(addon, obj, np.arange(last + 1, last + 1201))
        results[follow] = take, new
    (take, new), (_, alone) = results[True], results[False]
    # the first window leans on the clip too (the walk's next step), and both leave the clip without a pop
    assert np.abs(new[:30] - alone[:30]).max() > 0.01
    usual = np.linalg.norm(np.diff(take, axis=0), axis=-1).max()
    for joints in (new, alone):
        assert np.linalg.norm(np.diff(np.concatenate([take[-1:], joints[:30]]), axis=0), axis=-1).max() < 1.5 * usual
    up = 2  # Blender's Z
    floor = np.percentile(take[:, [7, 8, 11, 12], up].min(1), 5)

    def stepping(pos):
        way = pos[-1, 0, :2] - pos[0, 0, :2]
        lead = (pos[:, 7, :2] - pos[:, 11, :2]) @ (way / np.linalg.norm(way))
        airborne = np.mean(pos[:, [7, 8, 11, 12], up].min(1) - floor > 0.05)
        return lead.std(), airborne

    take_lead, _ = stepping(take)
    lead, airborne = stepping(new[-300:])
    assert lead > 0.5 * take_lead and airborne < 0.03
    alone_lead, alone_airborne = stepping(alone[-300:])
    # the model alone places the hips for the bodies it learnt: on this actor's longer legs its feet sank 5 cm into
    # the floor (1st percentile of the lowest heel or toe) until the new frames were kept out of it (stance.ground)
    sink = floor - np.percentile(alone[-300:, [7, 8, 11, 12], up].min(1), 1)
    print(f"last 5 s: feet lead sd {lead:.2f} m, airborne {airborne:.2f} (take {take_lead:.2f}); model alone "
          f"{alone_lead:.2f}, {alone_airborne:.2f}, {100 * sink:.1f} cm into the floor")
    assert sink < 0.02


def test_foot_lock_leaves_the_extensions_feet_at_rest(real_model, addon, tmp_path):
    """With Foot Lock the extended frames' feet rest where they touch the floor (the lock settles): on the
    contact frames detected on the result itself, the heels and toes creep a fraction of what the
    extension does unlocked, under a millimetre per frame."""
    from model_core.motion.conventions import zup_to_yup
    from model_core.ops import footlock as fl

    obj = import_bvh(walk_bvh(tmp_path, frames=60))
    original = action_of(obj)
    creep = {}
    for lock in (False, True):
        obj.animation_data.action = original
        assert bpy.ops.strnn.extend_clip(frames=60, foot_lock=lock) == {"FINISHED"}
        pos = zup_to_yup(evaluated_joints(addon, obj, np.arange(1, 121)))
        contacts = fl.detect_foot_contacts(pos, 30.0)
        creep[lock] = fl.foot_skate_cm(pos[59:], contacts[59:])
    print("extension creep unlocked / locked (cm per frame):", creep)
    assert creep[True] < 0.2 * creep[False] and creep[True] < 0.1


def test_an_armature_scaled_and_turned_as_an_fbx_import_makes_it_is_extended_as_any_other(addon, real_model,
                                                                                         tmp_path):
    """An FBX import (a Mixamo character) keeps its bones Y-up in centimetres and makes the armature object Z-up at
    metres with a 90 degree turn about X and a scale of 0.01. The same walk so built and imported plainly (metres,
    Z-up) are extended alike: the new frames' joints, as Blender evaluates them in the world, within 0.1 mm."""
    import math

    path = walk_bvh(tmp_path, frames=90)
    extended = []
    for fbx_like in (False, True):
        bpy.ops.wm.read_homefile(use_empty=True)
        if fbx_like:  # the file read as it is (its Y up), then the object turned and scaled as an FBX import does
            obj = import_bvh(path, global_scale=100.0, axis_forward="Y", axis_up="Z")
            obj.rotation_euler, obj.scale = (math.pi / 2, 0.0, 0.0), (0.01, 0.01, 0.01)
        else:
            obj = import_bvh(path)
        bpy.context.view_layer.update()
        last = int(action_of(obj).frame_range[1])
        assert bpy.ops.strnn.extend_clip(frames=60) == {"FINISHED"}
        extended.append(evaluated_joints(addon, obj, np.arange(last + 1, last + 61)))
    plain, fbx = extended
    assert np.ptp(plain[..., 2]) > 1.0  # a standing body, Z up, in metres
    np.testing.assert_allclose(fbx, plain, atol=1e-4)


def stepped_take(folder):
    """A walk (a real take where the data is unpacked) keyed on twos with Constant interpolation, ending on a key."""
    mocap = find_mocap()
    take = mocap / CLIPS["bandai_namco"] if mocap is not None else None
    obj = import_bvh(take if take is not None and take.exists() else walk_bvh(folder, frames=121),
                     update_scene_fps=True, update_scene_duration=True)
    on_steps(obj, 2)
    if int(action_of(obj).frame_range[1] - action_of(obj).frame_range[0]) % 2:  # end on a key
        for fc in fcurves_of(obj):
            fc.keyframe_points.remove(fc.keyframe_points[-1])
    return obj


def test_an_action_keyed_on_twos_is_continued_on_twos(real_model, addon, tmp_path, capfd):
    """Animation on twos (a key every second frame held by Constant interpolation) is read at its keys and
    continued on twos: new keys every second frame, Constant, the pose held in between, moving on at the clip's
    pace from key to key; read frame by frame (holds and jumps) and keyed on ones, the continuation stuttered."""
    obj = stepped_take(tmp_path)
    end = int(action_of(obj).frame_range[1])
    capfd.readouterr()
    assert bpy.ops.strnn.extend_clip(frames=40) == {"FINISHED"}
    assert "keyed every 2 frames with Constant interpolation" in capfd.readouterr().out
    new = action_of(obj)
    assert new["strnn"]["key_step"] == 2
    hips = obj.strnn_map.hips
    for fc in fcurves_of(obj):
        if not fc.data_path.startswith(f'pose.bones["{hips}"]'):
            continue
        later = [p for p in fc.keyframe_points if p.co[0] > end + 0.5]
        assert [p.co[0] for p in later] == [end + 2.0 * k for k in range(1, 21)]
        assert {p.interpolation for p in later} == {"CONSTANT"}
    pos = evaluated_joints(addon, obj, np.arange(end - 40, end + 41))
    moved = np.linalg.norm(np.diff(pos, axis=0), axis=-1).mean(-1)  # joints' mean move per frame
    held, keyed = moved[0::2], moved[1::2]  # into the frame after each key: none; onto the next key: all of it
    assert held.max() < 1e-6 * keyed.max()
    before, after = keyed[:20], keyed[20:]
    print(f"per key: clip {before.mean():.4f}, new {after.mean():.4f}, new min/max {after.min():.4f}/{after.max():.4f}")
    assert 0.6 < after.mean() / before.mean() < 1.5 and after.min() > 0.3 * before.mean()


def test_keys_on_twos_that_are_not_held_are_read_frame_by_frame(model_calls, addon, tmp_path):
    """Keys every second frame with Bezier interpolation move on every frame: read and continued on ones."""
    obj = mixamo_walk(61)
    on_steps(obj, 2, "BEZIER")
    end = int(action_of(obj).frame_range[1])
    assert bpy.ops.strnn.extend_clip(frames=10) == {"FINISHED"}
    assert "key_step" not in action_of(obj)["strnn"]
    hips = obj.strnn_map.hips
    fc = next(fc for fc in fcurves_of(obj) if fc.data_path.startswith(f'pose.bones["{hips}"]'))
    assert [p.co[0] for p in fc.keyframe_points if p.co[0] > end + 0.5] == [end + 1.0 * k for k in range(1, 11)]


def test_continuing_from_a_held_frame_of_an_action_on_twos_stays_on_twos(model_calls, addon):
    """From the playhead on a frame that holds the key before it: the frames up to it stay, and the new keys go on
    from that key on twos (the first on the frame after the playhead), Constant."""
    obj = mixamo_walk(61)
    on_steps(obj, 2)  # keys on 1, 3, ..., 61
    frames = np.arange(1, 62)
    before = evaluated_joints(addon, obj, frames)
    bpy.context.scene.frame_set(50)  # holds the key on 49
    assert bpy.ops.strnn.extend_clip(frames=10, from_current=True) == {"FINISHED"}
    new = action_of(obj)
    assert new["strnn"]["key_step"] == 2
    assert np.abs(evaluated_joints(addon, obj, frames[:50]) - before[:50]).max() < 1e-5
    hips = obj.strnn_map.hips
    for fc in fcurves_of(obj):
        if fc.data_path.startswith(f'pose.bones["{hips}"]'):
            later = [p for p in fc.keyframe_points if p.co[0] > 50.5]
            assert [p.co[0] for p in later] == [51.0, 53.0, 55.0, 57.0, 59.0, 61.0]
            assert {p.interpolation for p in later} == {"CONSTANT"}


def test_a_walk_in_place_is_extended_in_place(real_model, addon, tmp_path, capfd):
    """A walk in place (the hips held over one spot while the feet step, as game cycles and Mixamo's In Place
    make them) extended by 300 frames: the hips stay within 10 cm of where it leaves them, the legs stepping on."""
    from model_core.io.bvh_export import write_bvh
    from model_core.motion.synthetic import walking_skeleton
    from model_core.rig.rigs import load_clip

    mocap = find_mocap()
    take = mocap / CLIPS["bandai_namco"] if mocap is not None else None
    walk = load_clip(take) if take is not None and take.exists() else walking_skeleton(150, radius=1e6)
    walk = np.array(walk, dtype=np.float64)
    walk[:, :, [0, 2]] -= walk[:, :1, [0, 2]] - walk[:1, :1, [0, 2]]
    obj = import_bvh(write_bvh(tmp_path / "in_place.bvh", walk.astype(np.float32)), update_scene_fps=True,
                     update_scene_duration=True)
    end = int(action_of(obj).frame_range[1])
    capfd.readouterr()
    assert bpy.ops.strnn.extend_clip(frames=300) == {"FINISHED"}
    assert "in place: the clip steps on the spot" in capfd.readouterr().out and action_of(obj)["strnn"]["in_place"]
    pos = evaluated_joints(addon, obj, np.arange(end - 59, end + 301))  # Blender axes: Z up
    hips = pos[:, 0, :2]
    drift = np.linalg.norm(hips[60:] - hips[59], axis=-1).max()
    feet = lambda p: np.linalg.norm(np.diff(p[:, [7, 11], :2] - p[:, :1, :2], axis=0), axis=-1).mean()  # noqa: E731
    print(f"in place: hips within {drift:.3f} m over 300 frames; feet step at {feet(pos[60:]) / feet(pos[:60]):.2f} x")
    assert drift < 0.10 and feet(pos[60:]) > 0.5 * feet(pos[:60])


def test_an_action_stepped_by_a_modifier_is_continued_on_its_steps(real_model, addon, tmp_path):
    """Keys on ones played on twos by a Stepped Interpolation modifier on every F-curve (Graph Editor > Add
    Modifier): read on the modifier's frames, at their rate, and keyed only there, so the modifier holds the new
    poses two frames each as it holds the old."""
    obj = import_bvh(walk_bvh(tmp_path, frames=121), update_scene_fps=True, update_scene_duration=True)
    for fc in fcurves_of(obj):
        mod = fc.modifiers.new("STEPPED")
        mod.frame_step, mod.frame_offset = 2.0, 1.0  # held from frames 1, 3, 5, ...
    end = int(action_of(obj).frame_range[1])
    assert bpy.ops.strnn.extend_clip(frames=40) == {"FINISHED"}
    new = action_of(obj)
    assert new["strnn"]["key_step"] == 2
    hips = obj.strnn_map.hips
    fc = next(fc for fc in fcurves_of(obj) if fc.data_path.startswith(f'pose.bones["{hips}"]'))
    assert [p.co[0] for p in fc.keyframe_points if p.co[0] > end + 0.5] == [end + 2.0 * k for k in range(1, 21)]
    pos = evaluated_joints(addon, obj, np.arange(end - 40, end + 41))
    moved = np.linalg.norm(np.diff(pos, axis=0), axis=-1).mean(-1)
    held, keyed = moved[0::2], moved[1::2]
    assert held.max() < 1e-6 * keyed.max()
    print(f"per step: clip {keyed[:20].mean():.4f}, new {keyed[20:].mean():.4f}")
    assert 0.6 < keyed[20:].mean() / keyed[:20].mean() < 1.5 and keyed[20:].min() > 0.3 * keyed[:20].mean()


def test_frames_before_the_start_read_the_clip_backwards_in_time(model_calls, addon, tmp_path):
    """Before the Start: the new frames come before the action's first, as the model continues the clip read
    backwards in time (Blender plays the model's frames); the original frames
    stay, the original action is kept, and the scene's start moves back to the new first frame."""
    obj = import_bvh(walk_bvh(tmp_path, frames=90))
    for fc in fcurves_of(obj):  # the take from frame 201, so that the frames before it are in the scene
        for p in fc.keyframe_points:
            p.co[0] += 200
            p.handle_left[0] += 200
            p.handle_right[0] += 200
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 201, 290
    frames = np.arange(201, 291)
    before = evaluated_joints(addon, obj, frames)
    old, snapshot = action_of(obj), key_snapshot(obj)
    assert bpy.ops.strnn.extend_clip(frames=40, before_start=True) == {"FINISHED"}
    new = action_of(obj)
    assert new is not old and old.use_fake_user and same_keys(snapshot, key_snapshot(obj, old))
    assert tuple(new.frame_range) == (161.0, 290.0) and scene.frame_start == 161 and scene.frame_end == 290
    assert new["strnn"]["settings"]["before_start"]
    assert np.abs(evaluated_joints(addon, obj, frames) - before).max() < 1e-5
    follows(evaluated_joints(addon, obj, np.arange(161, 201))[::-1], model_calls.extended())  # frame 200 back to 161


def test_frames_before_the_current_frame_replace_the_keys_before_it(model_calls, addon):
    """Before the Start with From Current Frame: the frames from the playhead on stay, the mapped bones' keys before
    it are replaced by the model's (the clip from the playhead read backwards), as many frames as asked: the old
    head (1-30) goes, as From Current Frame's old tail does going forward."""
    obj = mixamo_walk(90)
    frames = np.arange(1, 91)
    before = evaluated_joints(addon, obj, frames)
    bpy.context.scene.frame_set(31)
    assert bpy.ops.strnn.extend_clip(frames=20, before_start=True, from_current=True) == {"FINISHED"}
    new = action_of(obj)
    assert tuple(new.frame_range) == (11.0, 90.0) and new["strnn"]["settings"]["from_frame"] == 31
    after = evaluated_joints(addon, obj, frames)
    assert np.abs(after[30:] - before[30:]).max() < 1e-5  # frames 31 on
    follows(after[10:30][::-1], model_calls.extended())  # frames 30 back to 11: the model's
    hips = obj.strnn_map.hips
    fc = next(fc for fc in fcurves_of(obj) if fc.data_path.startswith(f'pose.bones["{hips}"]'))
    assert [p.co[0] for p in fc.keyframe_points if p.co[0] < 30.5] == [float(f) for f in range(11, 31)]


def test_a_real_walk_gets_a_lead_in_before_its_start(real_model, addon, tmp_path, capfd):
    """A real walk (the unseen subject's where the data is unpacked) given 2 s before its first frame: no jump into
    the take, the lead-in walks at the take's pace, bones keep their lengths; the report says where the frames went."""
    mocap = find_mocap()
    take = mocap / "cmu/iclone/006_01.bvh" if mocap is not None else None
    obj = import_bvh(take if take is not None and take.exists() else walk_bvh(tmp_path, frames=120),
                     update_scene_fps=True, update_scene_duration=True)
    fps = bpy.context.scene.render.fps
    first = int(action_of(obj).frame_range[0])
    capfd.readouterr()
    assert bpy.ops.strnn.extend_clip(frames=2 * fps, before_start=True) == {"FINISHED"}
    assert f"Added {2 * fps} frames before its first frame" in capfd.readouterr().out
    span = np.arange(first - 2 * fps, first + 30)
    pos = evaluated_joints(addon, obj, span)
    steps = np.linalg.norm(np.diff(pos, axis=0), axis=-1).mean(-1)
    new, seam, take_steps = steps[:2 * fps - 1], steps[2 * fps - 1], steps[2 * fps:]
    lengths = bone_length_change(addon, obj, span)
    print(f"lead-in: seam {seam / take_steps.max():.2f}, pace {new.mean() / take_steps.mean():.2f} x, "
          f"bones {lengths:.5f}")
    assert seam < 2.0 * take_steps.max() and 0.6 < new.mean() / take_steps.mean() < 1.5 and lengths < 1e-3


def test_frames_before_the_start_of_an_action_on_twos_are_on_twos(real_model, addon, tmp_path):
    """Before the Start on an action keyed on twos: the lead-in is keyed on twos too, Constant, ending a step before
    the first key."""
    obj = stepped_take(tmp_path)
    first = int(action_of(obj).frame_range[0])
    assert bpy.ops.strnn.extend_clip(frames=20, before_start=True) == {"FINISHED"}
    assert action_of(obj)["strnn"]["key_step"] == 2
    hips = obj.strnn_map.hips
    fc = next(fc for fc in fcurves_of(obj) if fc.data_path.startswith(f'pose.bones["{hips}"]'))
    lead = [p for p in fc.keyframe_points if p.co[0] < first - 0.5]
    assert [p.co[0] for p in lead] == [first - 2.0 * k for k in range(10, 0, -1)]
    assert {p.interpolation for p in lead} == {"CONSTANT"}


def test_frames_added_before_a_key_are_continuous_with_it(addon):
    """Keys written before the action's start meet its first key without a jump in the channels: Euler angles
    unwrapped towards the key after them (a turn of 4 rad ends at 4.0 beside a key at 4.05; unwrapped from its
    first frame, it ended a full turn away), quaternion signs matched to it."""
    pipeline = addon_module(addon, "strnn_addon.scene.pipeline")
    rotations = addon_module(addon, "model_core.motion.rotations")
    yaw = np.linspace(0.0, 4.0, 17)  # turning 230 degrees about Z, up to the key after them
    m = rotations.euler_to_matrix(np.stack([0 * yaw, 0 * yaw, yaw], -1), "XYZ")
    _, angles = pipeline.encode_rotation("XYZ", m, np.array([0.0, 0.0, 4.05]), follows=True)
    assert abs(angles[-1, 2] - 4.0) < 1e-6 and np.abs(np.diff(angles[:, 2])).max() < 0.3
    _, ahead = pipeline.encode_rotation("XYZ", m, np.array([0.0, 0.0, 4.05]))
    assert abs(ahead[-1, 2] - 4.0) > 6.0  # anchored on the first frame: a full turn from the key
    key = -rotations.matrix_to_quat(m[-1:])[0]  # the key after them, stored with the other sign
    _, quats = pipeline.encode_rotation("QUATERNION", m, key, follows=True)
    assert np.dot(quats[-1], key) > 0.99 and (np.sum(quats[1:] * quats[:-1], -1) > 0).all()


def test_bones_an_action_on_twos_never_keyed_get_held_keys_too(model_calls, addon):
    """Extend keys every mapped bone; on an action on twos the channels it has to make (bones the animator never
    keyed: here the spine and the head) hold their poses as the others do, with Constant keys."""
    obj = mixamo_walk(61)  # keys on the hips, legs, knees and arms only
    on_steps(obj, 2)
    before = {fc.data_path for fc in fcurves_of(obj)}
    assert bpy.ops.strnn.extend_clip(frames=10) == {"FINISHED"}
    made = [fc for fc in fcurves_of(obj) if fc.data_path not in before and fc.data_path.startswith("pose.bones")]
    assert any("Spine" in fc.data_path for fc in made) and any("Head" in fc.data_path for fc in made)
    assert all({p.interpolation for p in fc.keyframe_points} == {"CONSTANT"} for fc in made)


def cycled(obj) -> None:
    """Make ``obj``'s action a walk cycle as animators key one: a Cycles modifier on every F-curve, the locations
    repeating with their offset (each cycle walks on from where the last ended)."""
    for fc in fcurves_of(obj):
        mod = fc.modifiers.new("CYCLES")
        if fc.data_path.endswith("location"):
            mod.mode_before = mod.mode_after = "REPEAT_OFFSET"


@pytest.mark.parametrize("from_frame", [None, 60], ids=["after_the_keys", "from_the_playhead"])
def test_a_walk_cycle_repeated_by_cycles_modifiers_is_extended_after_what_it_plays(tmp_path, real_model, addon,
                                                                                  capfd, from_frame):
    """A 34-frame walk keyed as a cycle (Cycles modifiers) plays on forever. Extended, its new keys went into the
    cycled curves, whose modifiers then repeated the whole new range: at its end the body snapped back to the first
    pose (70 cm in a frame), and From Current Frame past the keys was refused although the walk plays there. Now the
    new action has the cycles that played up to where the new frames start as keys and repeats no more: every frame
    up to there plays as it did, and the new frames go on from it without a jump."""
    obj = import_bvh(walk_bvh(tmp_path, frames=34), update_scene_fps=True)
    cycled(obj)
    old = action_of(obj)
    edge = 34 if from_frame is None else from_frame
    played = evaluated_joints(addon, obj, np.arange(1, edge + 1))
    kw = {"frames": 30}
    if from_frame is not None:
        bpy.context.scene.frame_set(from_frame)
        kw["from_current"] = True
    assert bpy.ops.strnn.extend_clip(**kw) == {"FINISHED"}
    new = action_of(obj)
    assert new is not old and all(len(fc.modifiers) for fc in fcurves_of(obj, old))  # the cycle kept as it was
    assert not any(len(fc.modifiers) for fc in fcurves_of(obj))
    assert new.frame_range[1] == edge + 30
    assert list(new["strnn"]["cycles_baked"]) == ([] if from_frame is None else [35, 60])
    joints = evaluated_joints(addon, obj, np.arange(1, edge + 41))
    assert np.abs(joints[:edge] - played).max() < 1e-4  # what played up to the edge plays as it did
    step = np.linalg.norm(np.diff(joints, axis=0), axis=-1).mean(-1)
    assert step[edge - 1] < 1.5 * step[:edge - 1].max() and step[edge:edge + 29].min() > 0.2 * step[:edge - 1].mean()
    assert step[edge + 30:].max() < 1e-6  # after the new frames it holds: no snap back to the first pose
    assert "the action repeated by Cycles modifiers" in capfd.readouterr().out


def test_a_walk_cycle_repeated_by_cycles_modifiers_gets_a_lead_in_before_what_it_plays(tmp_path, real_model, addon):
    """Before the Start on a walk cycle keyed with Cycles modifiers (which repeat before its first key too, from
    frame 40 of a 34-frame cycle that starts at 30): the repeats from the playhead to the first key become keys, the
    lead-in goes before the playhead, and the new action repeats no more."""
    obj = import_bvh(walk_bvh(tmp_path, frames=34), update_scene_fps=True)
    for fc in fcurves_of(obj):  # the cycle keyed from frame 30 on
        for key in fc.keyframe_points:
            key.co[0] += 29
            key.handle_left[0] += 29
            key.handle_right[0] += 29
    cycled(obj)
    bpy.context.scene.frame_start = 1
    played = evaluated_joints(addon, obj, np.arange(10, 64))
    bpy.context.scene.frame_set(10)
    assert bpy.ops.strnn.extend_clip(frames=8, before_start=True, from_current=True) == {"FINISHED"}
    new = action_of(obj)
    assert not any(len(fc.modifiers) for fc in fcurves_of(obj))
    assert list(new["strnn"]["cycles_baked"]) == [10, 29] and new.frame_range[0] == 2
    assert np.abs(evaluated_joints(addon, obj, np.arange(10, 64)) - played).max() < 1e-4
    joints = evaluated_joints(addon, obj, np.arange(2, 12))
    step = np.linalg.norm(np.diff(joints, axis=0), axis=-1).mean(-1)
    assert step.min() > 0.2 * step.max()  # the lead-in moves into the repeats without a hold or a jump


def test_a_walk_up_a_ramp_is_extended_up_it_with_the_ramp_as_ground(real_model, addon, tmp_path, capfd):
    """A walk up a ramp rising 15 cm a metre, extended by 3 s with Foot Lock and the ramp as Ground: the model reads
    it as a walk on a flat floor, and the new frames go on up the ramp, the hips as high over it as in the clip
    (within 5 cm) and the lowest foot each second as near it (within 3 cm). Without Ground, the climb (its floor
    rising 50 cm over what Extend reads) is read the same way and the new frames go on level at the height where
    the clip ends (the lowest foot each second within 3 cm of the clip's last), and the report says so and names
    Ground; read as it was, the climb looked to the model like a
    body held too high, and it came back down (hips 0.48 m lower 3 s on, the feet 0.5 m under the clip's end)."""
    from model_core.io.bvh_export import write_bvh
    from model_core.motion.conventions import CONTACT_JOINTS, zup_to_yup
    from model_core.motion.synthetic import up_a_slope, walking_skeleton
    from model_core.ops.footlock import SETTLE_PASSES, FootLockSettings, foot_lock

    clean = foot_lock(walking_skeleton(90), settings=FootLockSettings(passes=SETTLE_PASSES))  # feet that stand
    climbed, _ = up_a_slope(clean, 0.15)
    obj = import_bvh(write_bvh(tmp_path / "climb.bvh", climbed), update_scene_fps=True)
    height = ramp("Ramp", clean[0, 0], clean[-1, 0] - clean[0, 0], 0.15)
    bpy.context.view_layer.objects.active = obj
    old = action_of(obj)
    got = {}
    for ground in ("Ramp", ""):
        obj.animation_data.action = old
        assert bpy.ops.strnn.extend_clip(frames=90, foot_lock=True, ground=ground) == {"FINISHED"}
        record = action_of(obj)["strnn"]
        assert ("ground" in record) == bool(ground) and ("floor_rise" in record) != bool(ground)
        pos = zup_to_yup(evaluated_joints(addon, obj, np.arange(1, 181)))
        under = height(pos) if ground else np.zeros(pos.shape[:2])  # over the ramp, or as they are
        hips = pos[:, 0, 1] - under[:, 0]
        low = (pos[:, CONTACT_JOINTS, 1] - under[:, CONTACT_JOINTS]).min(axis=1)
        got[ground] = hips, [low[80:90].min()] + [low[s:s + 30].min() for s in range(90, 180, 30)]
    report = capfd.readouterr().out
    for ground, (hips, feet) in got.items():
        print(f"{ground or 'no ground'}: hips {hips[89]:.2f} m at the clip's end, {hips[-1]:.2f} 3 s on; lowest foot "
              f"at the clip's end and each new second {np.round(feet, 3).tolist()}")
    assert "name its mesh as Ground" in report and record["floor_rise"]["cm"] > 40
    for hips, feet in got.values():  # feet: the lowest in the clip's last 10 frames, then each new second's
        assert np.abs(hips[90:] - hips[89]).max() < 0.05
        assert max(abs(f - feet[0]) for f in feet[1:]) < 0.03


def _stall_last_frame(obj, last: int) -> None:
    """Make the action's last frame repeat the one before, as converted motion capture often ends."""
    for fc in fcurves_of(obj):
        points = {int(round(p.co[0])): p for p in fc.keyframe_points}
        if last in points and last - 1 in points:
            points[last].co[1] = points[last - 1].co[1]
            points[last].handle_left[1] = points[last].handle_right[1] = points[last].co[1]
        fc.update()


def test_an_action_that_ends_on_a_stalled_frame_is_continued_from_the_frame_before(model_calls, addon):
    """A walk whose last frame repeats the one before (a stalled frame): Extend goes on from the frame before, the
    first new frame taking the stalled one's place in the new action (the model reads the take up to the frame before
    and Blender plays what it makes from there), so the hips walk on at their pace where they stood still; the record
    and the report say so, the original action keeps its keys and the new one ends where asked; the same with From
    Current Frame and the playhead on the last frame. From a frame before the last, nothing stalls."""
    common = importlib.import_module(addon.__name__ + ".strnn_addon.stages.common")
    obj = mixamo_walk(90)
    assert "stalled_end" not in (_extended(obj, 20) or {})
    bpy.ops.wm.read_homefile(use_empty=True)
    obj = mixamo_walk(90)
    _stall_last_frame(obj, 90)
    old, snapshot = action_of(obj), key_snapshot(obj)
    take = evaluated_joints(addon, obj, np.arange(86, 91))
    assert np.linalg.norm(take[-1] - take[-2], axis=-1).max() < 1e-4  # the take stalls on its last frame
    record = _extended(obj, 20)
    new = action_of(obj)
    assert new is not old and old.use_fake_user and same_keys(snapshot, key_snapshot(obj, old))
    assert new.frame_range[1] == 110 and record["settings"]["frames"] == 20
    assert record["stalled_end"]["frame"] == 90 and "stalled frame" in common.report_note(new)
    pos = evaluated_joints(addon, obj, np.arange(88, 111))
    assert np.abs(model_calls.blender(model_calls.extend[-1]["pos"][-1]) - take[-2]).max() < 1e-4  # read to 89
    follows(pos[2:], model_calls.extended())  # frames 90 to 110, the first in the stalled frame's place
    assert np.linalg.norm(pos[3, 0] - pos[2, 0]) > 0.5 * np.linalg.norm(pos[1, 0] - pos[0, 0])  # walks on
    bpy.ops.wm.read_homefile(use_empty=True)
    obj = mixamo_walk(90)
    _stall_last_frame(obj, 90)
    stalled_walk = action_of(obj)
    for frame, stalls in ((90, True), (80, False)):
        bpy.context.scene.frame_set(frame)
        assert bpy.ops.strnn.extend_clip(frames=20, from_current=True) == {"FINISHED"}
        assert ("stalled_end" in action_of(obj)["strnn"].to_dict()) == stalls
        obj.animation_data.action = stalled_walk


def _extended(obj, frames: int) -> dict:
    """Extend ``obj``'s action by ``frames``; the new action's record."""
    assert bpy.ops.strnn.extend_clip(frames=frames) == {"FINISHED"}
    return action_of(obj)["strnn"].to_dict()


def test_an_unseen_walk_that_ends_on_a_stalled_frame_does_not_stumble_at_the_cut(real_model, addon):
    """The held-out CMU subject's walk 006_03 (60 fps), whose last frame repeats the one before, extended by 1 s: the
    hips' step over the cut and the first new frames is never under 0.6 x their step over the take's last walking
    frames, where the continuation of the stalled frame started at a fifth of it and took 0.3 s to walk again."""
    mocap = find_mocap()
    if mocap is None:
        pytest.skip("needs the motion-capture data (data/mocap)")
    obj = import_bvh(mocap / "cmu/iclone/006_03.bvh", global_scale=0.01, update_scene_fps=True)
    last = int(action_of(obj).frame_range[1])
    take = evaluated_joints(addon, obj, np.arange(last - 6, last + 1))
    step = np.linalg.norm(np.diff(take[:, 0, :2], axis=0), axis=-1)
    assert step[-1] < 0.3 * step[:-1].mean()  # the take stalls
    record = _extended(obj, 60)
    assert record["stalled_end"]["frame"] == last
    pos = evaluated_joints(addon, obj, np.arange(last - 1, last + 12))
    new_step = np.linalg.norm(np.diff(pos[:, 0, :2], axis=0), axis=-1)
    assert new_step.min() > 0.6 * step[:-1].mean(), (new_step / step[:-1].mean()).round(2)


def test_an_action_that_starts_on_a_stalled_frame_gets_a_lead_in_from_the_frame_after(model_calls, addon):
    """Before the Start, where the action's first frame repeats the one after it: the lead-in goes on back from the
    frame after, the first frame replaced in the new action by the lead-in's last, so the body comes in at its pace;
    the new action starts where asked."""
    obj = mixamo_walk(90)
    for fc in fcurves_of(obj):  # frame 1 repeats frame 2
        points = {int(round(p.co[0])): p for p in fc.keyframe_points}
        if 1 in points and 2 in points:
            points[1].co[1] = points[1].handle_left[1] = points[1].handle_right[1] = points[2].co[1]
        fc.update()
    assert bpy.ops.strnn.extend_clip(frames=20, before_start=True) == {"FINISHED"}
    new = action_of(obj)
    assert new["strnn"]["stalled_end"]["frame"] == 1 and new.frame_range[0] == -19
    pos = evaluated_joints(addon, obj, np.arange(-19, 4))[::-1]  # frame 3 back to -19
    assert np.abs(model_calls.blender(model_calls.extend[-1]["pos"][-1]) - pos[1]).max() < 1e-4  # read back to 2
    follows(pos[2:], model_calls.extended())  # frames 1 back to -19, the first in the stalled frame's place
    assert np.linalg.norm(pos[3, 0] - pos[2, 0]) > 0.5 * np.linalg.norm(pos[1, 0] - pos[0, 0])  # comes in walking
