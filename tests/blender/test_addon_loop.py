"""Make Loop: a stretch of an action made into a cycle that Blender repeats without a seam, on the real model."""

from __future__ import annotations

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
    mixamo_walk,
    object_walk,
    on_steps,
    same_keys,
    walk_bvh,
)

RECORD = "strnn"


def played(addon, obj, cycles: int = 3) -> tuple[dict, np.ndarray]:
    """The new action's cycle record and the joints as Blender plays ``cycles`` cycles of it from its first frame."""
    cycle = action_of(obj)[RECORD]["cycle"]
    frames = np.arange(cycle["first"], cycle["first"] + cycles * cycle["frames"] + 1)
    return cycle, evaluated_joints(addon, obj, frames)


def steps(joints: np.ndarray) -> np.ndarray:
    """Each joint's move from frame to frame ``[F - 1, 21]``."""
    return np.linalg.norm(np.diff(joints, axis=0), axis=-1)


def test_a_walk_becomes_a_cycle_that_repeats_and_walks_on(tmp_path, real_model, addon, capfd):
    """The procedural walk (round a 6 m circle, 13 degrees a stride): a cycle of one stride, unwound to repeat in a
    straight line. (Its knees bend backwards, which Foot Lock's leg IK would bend to the front: off here.)"""
    obj = import_bvh(walk_bvh(tmp_path, frames=60), update_scene_fps=True)
    old, before = action_of(obj), key_snapshot(obj)
    take = evaluated_joints(addon, obj, np.arange(1, 61))
    assert bpy.ops.strnn.make_loop(foot_lock=False) == {"FINISHED"}
    new = action_of(obj)
    assert new is not old and new.name == f"{old.name}.loop" and old.use_fake_user
    assert same_keys(before, key_snapshot(obj, old))
    cycle, joints = played(addon, obj)
    assert cycle["frames"] in (33, 34), cycle  # the walk's stride (0.9 a second at 30 fps), found in the take
    assert new.use_cyclic and new.use_frame_range and tuple(new.frame_range) == (cycle["first"], cycle["seam"])
    curves = fcurves_of(obj)
    assert all(len(fc.keyframe_points) and fc.keyframe_points[-1].co[0] <= cycle["seam"] for fc in curves)
    modes = {fc.data_path.rsplit(".", 1)[-1]: fc.modifiers[0].mode_after for fc in curves}
    assert modes["location"] == "REPEAT_OFFSET" and {m for k, m in modes.items() if k != "location"} == {"REPEAT"}
    # three cycles as Blender plays them: no joint jumps at the seams, and each cycle walks on a stride
    assert steps(joints).max() <= 1.05 * steps(take).max()
    length = cycle["frames"]
    travel = joints[length::length, 0] - joints[:-length:length, 0]
    assert np.allclose(travel, travel[0], atol=1e-4) and 1.3 < np.linalg.norm(travel[0]) < 1.6
    assert abs(np.linalg.norm(travel[0]) - cycle["travel"]) < 1e-3
    out = capfd.readouterr().out
    assert f"Looped frames 1-{cycle['seam']} ({length} frames" in out and "travelling 1.4" in out, out
    assert "the take turns 13 degrees left over the cycle, unwound so that it repeats in a straight line" in out, out


def test_in_place_the_cycle_repeats_on_the_spot(tmp_path, real_model, addon):
    obj = import_bvh(walk_bvh(tmp_path, frames=60), update_scene_fps=True)
    assert bpy.ops.strnn.make_loop(in_place=True, blend=0.3) == {"FINISHED"}
    cycle, joints = played(addon, obj)
    assert cycle["travel"] == 0 and cycle["blend_keys"] == 9
    hips = joints[:, 0]
    assert np.linalg.norm(hips[::cycle["frames"]] - hips[0], axis=-1).max() < 1e-3
    assert np.linalg.norm(hips[:, :2] - hips[0, :2], axis=-1).max() < 0.15  # over the ground (Z up), sway only
    feet = steps(joints[:, [7, 11]] - hips[:, None]).mean() * 30
    assert feet > 0.5  # the feet still step


def test_a_range_as_given_is_carried_into_its_start(tmp_path, real_model, addon):
    """Match the Start off: the range's last frame starts the next cycle, although the walk is half a stride from
    its first pose there; the frames before it are carried into the start and it repeats without a jump."""
    obj = import_bvh(walk_bvh(tmp_path, frames=80), update_scene_fps=True)
    take = evaluated_joints(addon, obj, np.arange(1, 81))
    assert bpy.ops.strnn.make_loop(use_range=True, frame_start=5, frame_end=55, match=False) == {"FINISHED"}
    cycle, joints = played(addon, obj)
    assert (cycle["first"], cycle["seam"], cycle["frames"]) == (5, 55, 50) and cycle["match_cm"] > 10
    assert steps(joints).mean(1).max() < 1.3 * steps(take).mean(1).max()


def test_channels_outside_the_bone_map_loop_too(real_model, addon):
    """A custom property keyed rising over the take (a prop's dial, a blend-shape driver) ends the cycle where it
    starts, eased in before the seam, and repeats; the object's own keys repeat with it."""
    obj = mixamo_walk(70)
    obj["dial"] = 0.0
    for f in (1, 70):
        obj["dial"] = f / 70.0
        obj.keyframe_insert('["dial"]', frame=f)
    assert bpy.ops.strnn.make_loop() == {"FINISHED"}
    cycle = action_of(obj)[RECORD]["cycle"]
    dial = next(fc for fc in fcurves_of(obj) if fc.data_path == '["dial"]')
    first, seam = cycle["first"], cycle["seam"]
    values = np.array([dial.evaluate(f) for f in np.arange(first, first + 2 * cycle["frames"] + 1)])
    assert abs(dial.evaluate(seam) - dial.evaluate(first)) < 1e-6
    assert np.abs(np.diff(values)).max() < 4 * np.abs(np.diff(values[:cycle["frames"] // 2])).max()  # no jump
    assert dial.modifiers[0].type == "CYCLES"


def test_an_action_on_twos_loops_on_twos(tmp_path, real_model, addon):
    obj = import_bvh(walk_bvh(tmp_path, frames=80), update_scene_fps=True)
    on_steps(obj, 2)
    assert bpy.ops.strnn.make_loop() == {"FINISHED"}
    new = action_of(obj)
    assert new[RECORD]["key_step"] == 2
    cycle = new[RECORD]["cycle"]
    for fc in fcurves_of(obj):
        frames = np.array([k.co[0] for k in fc.keyframe_points])
        assert ((frames - cycle["first"]) % 2 == 0).all() and {k.interpolation for k in fc.keyframe_points} == {
            "CONSTANT"}


def test_a_real_walk_loops_on_its_stride(real_model, addon):
    """A real Bandai walk: the cycle is one stride, and Blender plays it on without a jump at any seam."""
    root = find_mocap()
    path = root / "bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh" if root else None
    if path is None or not path.exists():
        pytest.skip("needs the motion-capture data (unpack ../shared/mocap into data/mocap)")
    obj = import_bvh(path, update_scene_fps=True)
    take = evaluated_joints(addon, obj, np.arange(60, 121))
    assert bpy.ops.strnn.make_loop(use_range=True, frame_start=60, frame_end=120) == {"FINISHED"}
    cycle, joints = played(addon, obj, 4)
    assert 0.9 <= cycle["seconds"] <= 1.3 and cycle["match_cm"] < 6, cycle
    assert steps(joints).max() <= 1.05 * steps(take).max()


def test_a_range_shorter_than_a_cycle_is_refused(tmp_path, real_model, addon):
    obj = import_bvh(walk_bvh(tmp_path, frames=60), update_scene_fps=True)
    old = action_of(obj)
    with pytest.raises(RuntimeError, match="a loop needs at least 20 at 30 fps: widen the range"):
        bpy.ops.strnn.make_loop(use_range=True, frame_start=10, frame_end=20)
    assert action_of(obj) is old and not bpy.data.actions.get(f"{old.name}.loop")


@pytest.mark.parametrize("in_place", [False, True], ids=["travelling", "in_place"])
def test_a_walk_whose_travel_is_keyed_on_the_object_loops_with_it(real_model, addon, in_place):
    """Root motion on the armature object (its location keyed, the hips walking in place): the object's keys repeat
    with their offset, so the walk goes on travelling; In Place keeps the body over one spot while the object's
    keys still travel (the hips' keys take it back)."""
    obj = object_walk(70)
    take = evaluated_joints(addon, obj, np.arange(1, 71))
    assert bpy.ops.strnn.make_loop(in_place=in_place) == {"FINISHED"}
    cycle, joints = played(addon, obj)
    placed = next(fc for fc in fcurves_of(obj) if fc.data_path == "location" and fc.array_index == 1)
    assert placed.modifiers[0].mode_after == "REPEAT_OFFSET"
    about_hips = lambda j: steps(j - j[:, :1])  # noqa: E731  (in place the body no longer travels as the take did)
    assert about_hips(joints).max() <= 1.1 * about_hips(take).max()
    assert steps(joints[:, :1]).max() <= 1.1 * steps(take[:, :1]).max()
    hips = joints[::cycle["frames"], 0]
    moved = np.linalg.norm(hips[1:] - hips[:-1], axis=-1)
    if in_place:
        assert moved.max() < 1e-3, moved
    else:
        assert np.allclose(moved, moved[0], atol=1e-4) and moved[0] > 0.4, moved


def test_a_range_without_a_whole_stride_says_the_blend_carried_the_seam(tmp_path, real_model, addon, capfd):
    """Frames 1-24 of the procedural walk (a stride is 33): no frame comes round to the first pose, and the report
    says the blend carried it and that a range of a stride or two loops more cleanly."""
    obj = import_bvh(walk_bvh(tmp_path, frames=60), update_scene_fps=True)
    take = action_of(obj)
    assert bpy.ops.strnn.make_loop(use_range=True, frame_start=1, frame_end=24, foot_lock=False) == {"FINISHED"}
    out = capfd.readouterr().out
    assert "no frame of the range's second half comes round to the first frame's pose" in out, out
    obj.animation_data.action = take
    assert bpy.ops.strnn.make_loop(use_range=True, frame_start=1, frame_end=50, foot_lock=False) == {"FINISHED"}
    assert "comes round to the first frame's pose" not in capfd.readouterr().out
