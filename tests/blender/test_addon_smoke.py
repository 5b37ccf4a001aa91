"""The installed extension registers, and its operators run from scripts (EXEC and INVOKE)."""

import bpy
from scenes import action_of, import_bvh, key_snapshot, same_keys, walk_bvh


def test_registered(addon):
    assert hasattr(bpy.ops.strnn, "extend_clip") and hasattr(bpy.ops.strnn, "denoise_action")
    assert hasattr(bpy.types, "STRNN_PT_main")
    assert bpy.context.preferences.addons[addon.__name__].preferences.model_folder == ""


def test_auto_map_then_extend(tmp_path, model_calls):
    obj = import_bvh(walk_bvh(tmp_path))
    assert bpy.ops.strnn.auto_map() == {"FINISHED"}
    before = key_snapshot(obj)
    old = action_of(obj)
    assert bpy.ops.strnn.extend_clip(frames=30) == {"FINISHED"}
    new = action_of(obj)
    assert new != old and old.use_fake_user and new.name == "walk.extended"
    assert same_keys(before, key_snapshot(obj, old))
    assert new.frame_range[1] == 120
    for expected in ("walk.extended.001", "walk.extended.002"):  # run again on the result: numbered
        assert bpy.ops.strnn.extend_clip(frames=5) == {"FINISHED"}
        assert action_of(obj).name == expected
    assert bpy.ops.strnn.denoise_action() == {"FINISHED"}
    assert action_of(obj).name == "walk.extended.002.denoised"


def test_invoke_without_a_window_runs_at_once(tmp_path, model_calls):
    obj = import_bvh(walk_bvh(tmp_path))
    assert bpy.ops.strnn.denoise_action("INVOKE_DEFAULT") == {"FINISHED"}
    assert action_of(obj).name == "walk.denoised"


def test_scene_range_is_widened_only_when_asked_and_reported(tmp_path, model_calls, addon):
    import importlib

    operators = importlib.import_module(addon.__name__ + ".strnn_addon.operators")
    import_bvh(walk_bvh(tmp_path))  # 90 frames
    scene = bpy.context.scene
    scene.frame_end = 90
    assert bpy.ops.strnn.extend_clip(frames=10, scene_range=False) == {"FINISHED"}
    assert scene.frame_end == 90
    assert operators.range_note(action_of(bpy.context.active_object)) == \
        "; the scene still ends at frame 90 (the new action runs to 100)"
    assert bpy.ops.strnn.extend_clip(frames=10) == {"FINISHED"}
    assert scene.frame_end == 110
    assert operators.range_note(action_of(bpy.context.active_object)) == "; the scene now ends at frame 110"
