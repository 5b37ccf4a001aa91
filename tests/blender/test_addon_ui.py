"""The sidebar tab and menus: registered, and every panel draws without error on each kind of object."""

from __future__ import annotations

import bpy
import pytest
from scenes import build_armature, import_bvh, walk_bvh

PANELS = ("STRNN_PT_main", "STRNN_PT_extend", "STRNN_PT_denoise", "STRNN_PT_foot_lock", "STRNN_PT_follow_curve",
          "STRNN_PT_bone_map")


class Layout:
    """Records layout calls; property names are checked against the data they are drawn from."""

    def __init__(self, calls):
        self.calls = calls

    def __getattr__(self, name):
        def call(*args, **kw):
            if name in ("prop", "prop_search"):
                data, prop = args[0], args[1]
                assert prop in data.bl_rna.properties, f"{type(data).__name__} has no property {prop!r}"
            if name == "operator":
                assert hasattr(bpy.ops.strnn, args[0].split(".")[1])
            self.calls.append(name)
            return OperatorProps() if name == "operator" else Layout(self.calls)

        return call


class OperatorProps:
    def __setattr__(self, name, value):
        object.__setattr__(self, name, value)


def draw_all(context) -> list[str]:
    calls: list[str] = []
    for name in PANELS:
        panel = getattr(bpy.types, name)
        if panel.poll(context):
            fake = type("Fake", (), {"layout": Layout(calls)})()
            panel.draw(fake, context)
    return calls


def test_registered_in_sidebar_and_menus(addon):
    for name in PANELS:
        cls = getattr(bpy.types, name)
        assert cls.bl_space_type == "VIEW_3D" and cls.bl_region_type == "UI" and cls.bl_category == "STRNN"
    for op in ("extend_clip", "denoise_action", "foot_lock", "follow_curve", "auto_map"):
        rna = getattr(bpy.ops.strnn, op).get_rna_type()
        assert rna.description, f"{op} has no tooltip"
    assert hasattr(bpy.types, "STRNN_MT_menu")


@pytest.mark.parametrize("scene", ["empty", "mesh", "bare_armature", "animated"])
def test_panels_draw(addon, tmp_path, scene):
    if scene == "mesh":
        bpy.ops.mesh.primitive_cube_add()
    elif scene == "bare_armature":
        build_armature("Bare", [("a", None, (0, 0, 0), (0, 0, 1))])
    elif scene == "animated":
        import_bvh(walk_bvh(tmp_path, frames=30))
    calls = draw_all(bpy.context)
    assert "label" in calls
    if scene == "animated":
        assert calls.count("prop_search") == 21 and "operator" in calls
