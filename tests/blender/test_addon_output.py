"""Where a result goes: a new action (the default) or, with Result = NLA Strip, a strip on a new
NLA track, the active action staying active and unchanged."""

from __future__ import annotations

import bpy
import pytest
from scenes import action_of, import_bvh, key_snapshot, same_keys, walk_bvh

OPS = [("extend_clip", {"frames": 20}), ("foot_lock", {}), ("denoise_action", {}),
       ("inbetween", {"use_range": True, "frame_start": 30, "frame_end": 40})]


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
