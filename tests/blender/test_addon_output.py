"""The pace of the keys (Keys per Second), and where a result goes: a new action (the default) or,
with Result = NLA Strip, a strip on a new NLA track, the active action staying active and unchanged."""

from __future__ import annotations

import bpy
import numpy as np
import pytest
from scenes import action_of, import_bvh, key_snapshot, same_keys, walk_bvh

OPS = [("extend_clip", {"frames": 20}), ("foot_lock", {}), ("denoise_action", {}),
       ("inbetween", {"use_range": True, "frame_start": 30, "frame_end": 40}), ("make_loop", {})]


@pytest.mark.parametrize("op, kw", OPS, ids=[o for o, _ in OPS])
def test_nla_strip_output_keeps_the_active_action(addon, tmp_path, real_model, op, kw):
    obj = import_bvh(walk_bvh(tmp_path, frames=90), update_scene_fps=True)
    old = action_of(obj)
    before = key_snapshot(obj)
    assert getattr(bpy.ops.strnn, op)(output="NLA", **kw) == {"FINISHED"}
    assert action_of(obj) is old and same_keys(before, key_snapshot(obj, old))
    tracks = obj.animation_data.nla_tracks
    assert len(tracks) == 1 and len(tracks[0].strips) == 1
    strip = tracks[0].strips[0]
    assert strip.action is not old and strip.action["strnn"]["source_action"] == old.name
    assert tracks[0].name == strip.action.name
    assert int(strip.frame_start) == int(strip.action.frame_range[0])


def test_new_action_output_is_the_default(addon, tmp_path, real_model):
    obj = import_bvh(walk_bvh(tmp_path, frames=90), update_scene_fps=True)
    old = action_of(obj)
    assert bpy.ops.strnn.extend_clip(frames=10) == {"FINISHED"}
    assert action_of(obj) is not old and not obj.animation_data.nla_tracks


def hips_speed(addon, obj, frames) -> float:
    """Mean ground speed of the hips per frame over ``frames``."""
    from scenes import evaluated_joints

    hips = evaluated_joints(addon, obj, frames)[:, 0, :2]
    return float(np.linalg.norm(np.diff(hips, axis=0), axis=-1).mean())


def extended_pace(addon, path, scene_fps: int, keys_per_second: float, native: bool) -> tuple[float, dict]:
    """Hips ground speed per frame of 120 frames Extend adds to the take at ``path`` with the model alone (Follow
    the Clip off: leaning on the take's own motion as it was read keeps its pace, right or wrong), and the pace
    the new action's record read from the take."""
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.context.scene.render.fps = scene_fps
    obj = import_bvh(path, update_scene_fps=native)
    obj.strnn_keys_per_second = keys_per_second
    last = int(action_of(obj).frame_range[1])
    assert bpy.ops.strnn.extend_clip(frames=120, follow_clip=False) == {"FINISHED"}
    record = action_of(obj)["strnn"].to_dict()
    assert record["keys_per_second"] == (keys_per_second or bpy.context.scene.render.fps)
    return hips_speed(addon, obj, range(last + 1, last + 121)), record["pace"]


def test_keys_per_second_reads_a_60_fps_take_imported_at_24_fps_at_its_own_pace(addon, tmp_path, real_model):
    """Blender's BVH importer leaves the scene at 24 fps by default: with Keys per Second 60 the extension
    moves as it does for the same take imported at 60 fps; read at 24 keys per second it does not, and
    the report warns, naming the rate to set (the walk's strides take 1.1 s)."""
    path = walk_bvh(tmp_path, frames=240, fps=60.0)
    native, native_pace = extended_pace(addon, path, 60, 0.0, True)
    fixed, fixed_pace = extended_pace(addon, path, 24, 60.0, False)
    wrong, wrong_pace = extended_pace(addon, path, 24, 0.0, False)
    print(f"hips speed per frame: imported at 60 fps {native:.4f}, at 24 with 60 keys/s {fixed:.4f}, at 24 {wrong:.4f}")
    assert abs(fixed / native - 1.0) < 0.1
    assert abs(wrong / native - 1.0) > 0.2
    for pace in (native_pace, fixed_pace):
        assert pace["stride_s"] == pytest.approx(1.11, abs=0.05) and "note" not in pace
    assert wrong_pace["stride_s"] == pytest.approx(2.5 * 1.11, abs=0.15)
    assert "set Keys per Second to 60" in wrong_pace["note"]


def test_simplify_keys_keeps_the_joints_within_the_tolerance(addon, tmp_path, real_model):
    """Denoise of a real take (the procedural walk without the data), once keyed on every frame and once
    simplified at 0.5 cm: the joints Blender evaluates stay within 0.5 cm of the full result, with at
    least 3 x fewer keys."""
    from scenes import evaluated_joints, fcurves_of, find_mocap

    mocap = find_mocap()
    take = mocap / "bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh" if mocap else walk_bvh(tmp_path, 200)
    results = {}
    for tol in (0.0, 0.5):
        bpy.ops.wm.read_homefile(use_empty=True)
        obj = import_bvh(take, global_scale=0.01 if mocap else 1.0, update_scene_fps=True)
        assert bpy.ops.strnn.denoise_action(simplify=tol) == {"FINISHED"}
        new = action_of(obj)
        first, last = (int(f) for f in new.frame_range)
        keys = sum(len(fc.keyframe_points) for fc in fcurves_of(obj, new))
        results[tol] = (evaluated_joints(addon, obj, np.arange(first, last + 1)), keys, new["strnn"].to_dict())
    full, simple = results[0.0], results[0.5]
    err = np.linalg.norm(simple[0] - full[0], axis=-1).max()
    record = simple[2]["simplify"]
    print(f"simplify 0.5 cm: {record['keys']} of {record['full']} keys on the written channels ({full[1]} -> "
          f"{simple[1]} in the action), joints within {100 * err:.2f} cm")
    assert err <= 0.005 + 1e-4 and record["max_error_cm"] <= 0.5
    assert full[1] - simple[1] == record["full"] - record["keys"]  # the keys the record says went, went
    assert record["full"] >= 3 * record["keys"]
