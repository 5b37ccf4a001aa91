"""A character linked from a library file with a library override (the usual studio set-up):
Auto-Map stores its map on the override, every operator runs and writes a local action, and the
library file is left as it was."""

from __future__ import annotations

import hashlib

import bpy
import numpy as np
import pytest
from scenes import action_of, import_bvh, walk_bvh


def digest(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def character(addon, tmp_path):
    """(override object, library path): a walking armature in its own collection, saved as a library,
    then linked into an empty file and overridden."""
    obj = import_bvh(walk_bvh(tmp_path, frames=90), update_scene_fps=True)
    coll = bpy.data.collections.new("Character")
    bpy.context.scene.collection.children.link(coll)
    for c in list(obj.users_collection):
        c.objects.unlink(obj)
    coll.objects.link(obj)
    library = tmp_path / "character.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(library))
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.context.scene.render.fps = 30
    with bpy.data.libraries.load(str(library), link=True) as (src, dst):
        dst.collections = ["Character"]
    linked = dst.collections[0]
    instance = bpy.data.objects.new("Character", None)
    instance.instance_type, instance.instance_collection = "COLLECTION", linked
    bpy.context.scene.collection.objects.link(instance)
    override = linked.override_hierarchy_create(bpy.context.scene, bpy.context.view_layer)
    arm = next(o for o in override.objects if o.type == "ARMATURE")
    assert arm.override_library is not None and arm.library is None
    for o in bpy.context.view_layer.objects:
        o.select_set(o is arm)
    bpy.context.view_layer.objects.active = arm
    return arm, library


def test_auto_map_is_stored_on_the_override(character):
    arm, _ = character
    assert bpy.ops.strnn.auto_map() == {"FINISHED"}
    assert arm.strnn_map.hips and arm.strnn_map.l_knee


OPS = [("extend_clip", {"frames": 30}), ("denoise_action", {}), ("foot_lock", {}),
       ("inbetween", {"use_range": True, "frame_start": 40, "frame_end": 50})]


@pytest.mark.parametrize("op, kw", OPS + [("follow_curve", {"frames": 30}), ("transfer_motion", {})],
                         ids=[o for o, _ in OPS] + ["follow_curve", "transfer_motion"])
def test_every_operator_writes_a_local_action(character, real_model, tmp_path, op, kw):
    arm, library = character
    before = digest(library)
    if op == "follow_curve":  # a curve of the shot, from the character's feet along -Y
        data = bpy.data.curves.new("Path", "CURVE")
        spline = data.splines.new("POLY")
        spline.points.add(1)
        spline.points[0].co, spline.points[1].co = (0, 0, 0, 1), (0, -4, 0, 1)
        curve = bpy.data.objects.new("Path", data)
        bpy.context.scene.collection.objects.link(curve)
        kw = {**kw, "curve": curve.name}
    elif op == "transfer_motion":  # a take imported into the shot, moved onto the overridden character
        source = import_bvh(walk_bvh(tmp_path / "take", frames=60))
        kw = {**kw, "source": source.name}
        bpy.context.view_layer.objects.active = arm
    old = action_of(arm)
    assert getattr(bpy.ops.strnn, op)(**kw) == {"FINISHED"}
    new = action_of(arm)
    assert new is not old and new.library is None
    assert old is not None and (old.library is not None or old.override_library is not None or old.use_fake_user)
    bpy.context.scene.frame_set(45)
    assert np.isfinite(np.array([list(pb.head) for pb in arm.pose.bones])).all()
    bpy.ops.wm.save_as_mainfile(filepath=str(library.parent / "shot.blend"))
    assert digest(library) == before
