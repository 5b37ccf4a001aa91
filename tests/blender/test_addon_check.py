"""Check Motion: how familiar the active armature's motion is to the model, said before anything runs; it changes
nothing (no action, key, map or undo step)."""

from __future__ import annotations

import bpy
import pytest
from scenes import action_of, addon_module, find_mocap, import_bvh, key_snapshot, same_keys, walk_bvh


def checked(addon, capfd, obj) -> str:
    """Run Check Motion on ``obj``; its report, after checking that nothing in the file changed."""
    bpy.context.view_layer.objects.active = obj
    before = ({a.name for a in bpy.data.actions}, action_of(obj).name, key_snapshot(obj), obj.strnn_map.hips)
    capfd.readouterr()
    assert bpy.ops.strnn.check_motion() == {"FINISHED"}
    out = capfd.readouterr().out
    after = ({a.name for a in bpy.data.actions}, action_of(obj).name, key_snapshot(obj), obj.strnn_map.hips)
    assert before[:2] == after[:2] and same_keys(before[2], after[2]) and before[3] == after[3]
    shown = addon_module(addon, "strnn_addon.operators").CHECKED  # what the sidebar shows under the button
    key = addon_module(addon, "strnn_addon.operators").checked_key(obj)
    assert shown[key][1] in out
    return out


def test_check_motion_says_how_far_the_model_knows_the_motion(addon, real_model, capfd, tmp_path):
    """A procedural walk, stiffer than any capture, reads as unlike what the model learnt (a warning); the report
    names the action and the frames judged (its last 10 s), and the sidebar keeps the message for that action."""
    obj = import_bvh(walk_bvh(tmp_path, frames=400))
    out = checked(addon, capfd, obj)
    first = 400 - round(10 * bpy.context.scene.render.fps)  # its last 10 s, at the keys' rate (the scene's)
    assert f"'{action_of(obj).name}', frames {first}-400: this motion is unlike what the model learnt" in out, out


def test_check_motion_tells_a_capture_the_model_knows_from_a_fight_it_does_not(addon, real_model, capfd):
    """Real takes: a Bandai walk is motion the model knows; a CMU martial-arts take (an action family kept out of
    training) is not."""
    root = find_mocap()
    if root is None:
        pytest.skip("no motion-capture data (unpack ../shared/mocap into data/mocap)")
    walk = import_bvh(root / "bandai-namco" / "dataset-2" / "dataset-2_walk_normal_001.bvh")
    assert "motion the model knows (its rebuild error is " in checked(addon, capfd, walk)
    fight = import_bvh(root / "cmu" / "acrnn-dance" / "martial" / "03.bvh")
    assert "this motion is unlike what the model learnt" in checked(addon, capfd, fight)


def test_the_sidebar_keeps_the_last_check_of_the_action_in_view(addon, real_model, capfd, tmp_path):
    """The main panel has the Check Motion button, and after a check the message under it, for that action only (not
    for another action, nor for an action of the same name in a file opened after)."""
    obj = import_bvh(walk_bvh(tmp_path, frames=60))
    obj_name, action_name = obj.name, obj.animation_data.action.name
    texts = []

    class Layout:  # records the labels and buttons the panel draws
        def __getattr__(self, name):
            def call(*args, **kw):
                texts.append(kw.get("text", args[0] if name == "operator" and args else ""))
                return Layout()
            return call

    def drawn() -> str:
        texts.clear()
        bpy.types.STRNN_PT_main.draw(type("Panel", (), {"layout": Layout()})(), bpy.context)
        return " ".join(texts)

    assert "strnn.check_motion" in drawn() and "unlike what the model learnt" not in drawn()
    checked(addon, capfd, obj)
    assert "unlike what the model learnt" in drawn()
    obj.animation_data.action = obj.animation_data.action.copy()  # another action: its check is not shown
    assert "unlike what the model learnt" not in drawn()
    bpy.ops.wm.read_homefile(use_empty=True)  # another file whose armature and action have the same names
    again = import_bvh(walk_bvh(tmp_path, frames=60))
    assert (again.name, again.animation_data.action.name) == (obj_name, action_name)
    assert "unlike what the model learnt" not in drawn()


def test_check_motion_says_when_the_keys_are_at_another_rate_than_the_take(addon, real_model, capfd, tmp_path):
    """A 60 fps walk imported into a 24 fps scene without scaling time plays 2.5 x slow: Check Motion warns, with the
    Keys per Second to set, before any operator would make a slow result of it; at that rate the warning goes."""
    obj = import_bvh(walk_bvh(tmp_path, frames=240, fps=60.0), update_scene_fps=False, use_fps_scale=False)
    assert bpy.context.scene.render.fps == 24
    assert "Warning" in (out := checked(addon, capfd, obj)) and "set Keys per Second to 60" in out, out
    obj.strnn_keys_per_second = 60.0
    assert "Keys per Second" not in checked(addon, capfd, obj)
