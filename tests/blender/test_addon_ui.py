"""The sidebar tab and menus: registered, and every panel draws without error on each kind of object."""

from __future__ import annotations

import bpy
import pytest
from scenes import build_armature, import_bvh, walk_bvh

PANELS = ("STRNN_PT_main", "STRNN_PT_extend", "STRNN_PT_fill_gap", "STRNN_PT_denoise", "STRNN_PT_foot_lock",
          "STRNN_PT_follow_curve", "STRNN_PT_transfer", "STRNN_PT_bone_map", "STRNN_PT_controls")


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
            return OperatorProps(args[0]) if name == "operator" else Layout(self.calls)

        return call


class OperatorProps:
    """What a panel hands to an operator button: only properties the operator has."""

    def __init__(self, idname: str):
        object.__setattr__(self, "rna", getattr(bpy.ops.strnn, idname.split(".")[1]).get_rna_type())

    def __setattr__(self, name, value):
        assert name in self.rna.properties, f"{self.rna.identifier} has no property {name!r}"


# sidebar setting (per scene) -> the operator property it is handed to
HANDED = {
    "extend_frames": ("extend_clip", "frames"), "context_frames": ("extend_clip", "context_frames"),
    "extend_foot_lock": ("extend_clip", "foot_lock"), "extend_from_current": ("extend_clip", "from_current"),
    "denoise_strength": ("denoise_action", "strength"),
    "denoise_use_range": ("denoise_action", "use_range"), "denoise_start": ("denoise_action", "frame_start"),
    "denoise_end": ("denoise_action", "frame_end"), "denoise_foot_lock": ("denoise_action", "foot_lock"),
    "lock_blend": ("foot_lock", "blend"), "lock_use_range": ("foot_lock", "use_range"),
    "lock_start": ("foot_lock", "frame_start"), "lock_end": ("foot_lock", "frame_end"),
    "curve_frames": ("follow_curve", "frames"), "curve_speed": ("follow_curve", "speed"),
    "curve_foot_lock": ("follow_curve", "foot_lock"),
    "fill_use_range": ("inbetween", "use_range"), "fill_start": ("inbetween", "frame_start"),
    "fill_end": ("inbetween", "frame_end"), "fill_foot_lock": ("inbetween", "foot_lock"),
    "transfer_foot_lock": ("transfer_motion", "foot_lock"), "output": ("extend_clip", "output"),
    "simplify": ("denoise_action", "simplify"),
}


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
    for op in ("extend_clip", "inbetween", "denoise_action", "foot_lock", "follow_curve", "auto_map"):
        rna = getattr(bpy.ops.strnn, op).get_rna_type()
        assert rna.description, f"{op} has no tooltip"
    assert hasattr(bpy.types, "STRNN_MT_menu")
    nla = "NLA_MT_strips" if hasattr(bpy.types, "NLA_MT_strips") else "NLA_MT_edit"  # its name in 4.2
    for menu, entry in (("DOPESHEET_MT_key", "key_menu_entry"), ("GRAPH_MT_key", "key_menu_entry"),
                        (nla, "key_menu_entry"), ("GRAPH_MT_key_smoothing", "smoothing_menu_entry")):
        drawn = [f.__name__ for f in getattr(bpy.types, menu)._dyn_ui_initialize()]
        assert entry in drawn, menu


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


def test_sidebar_settings_agree_with_their_operators(addon):
    """A setting and the operator option it feeds have one name, default, range and tooltip."""
    settings = bpy.context.scene.strnn.bl_rna.properties
    assert set(HANDED) == {p.identifier for p in settings} - {"rna_type", "name", "curve", "transfer_source"}
    for setting, (op, option) in HANDED.items():
        a, b = settings[setting], getattr(bpy.ops.strnn, op).get_rna_type().properties[option]
        for attr in ("type", "name", "description", "default", "subtype", "unit", "hard_min", "hard_max",
                     "soft_min", "soft_max"):
            assert getattr(a, attr, None) == getattr(b, attr, None), f"{setting} / {op}.{option}: {attr}"


def panel_labels(panel: str, context) -> list[tuple[str, str]]:
    """(text, icon) of each label the panel draws."""
    labels = []

    class Labels:
        def __getattr__(self, name):
            def call(*args, **kw):
                if name == "label":
                    labels.append((kw.get("text", ""), kw.get("icon", "NONE")))
                return self

            return call

    getattr(bpy.types, panel).draw(type("Fake", (), {"layout": Labels()})(), context)
    return labels


def test_main_panel_says_what_each_object_allows(addon, tmp_path):
    bpy.ops.mesh.primitive_cube_add()
    assert panel_labels("STRNN_PT_main", bpy.context) == [("'Cube' is a mesh, not an armature", "ERROR")]
    build_armature("Bare", [("a", None, (0, 0, 0), (0, 0, 1))])
    assert panel_labels("STRNN_PT_main", bpy.context) == [("Bare: no action", "INFO"),
                                              ("Follow Curve can start one; the others need an action", "NONE")]
    import_bvh(walk_bvh(tmp_path, frames=30))
    assert panel_labels("STRNN_PT_main", bpy.context) == [("walk: walk (frames 1-30)", "ACTION")]


def test_follow_curve_panel_says_when_pytorch_is_missing(addon, monkeypatch):
    import importlib

    inst = importlib.import_module(addon.__name__ + ".strnn_addon.torch_install")
    for available in (True, False):
        monkeypatch.setattr(inst, "torch_available", lambda available=available: available)
        texts = [text for text, _ in panel_labels("STRNN_PT_follow_curve", bpy.context)]
        assert any(t.startswith("Needs PyTorch: Preferences > Add-ons") for t in texts) is not available


def test_an_unset_frame_range_comes_from_the_preview_or_scene_range(addon, tmp_path):
    """Run from F3, a menu or a script, Frame Range starts as the scene's preview range (else its
    range); a range handed to the operator (as the sidebar does) is kept. (Headless Blender runs
    execute directly, the path scripts take; a window's invoke goes through the same method.)"""
    import_bvh(walk_bvh(tmp_path, frames=60))
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 5, 50
    seen = []
    cls = bpy.types.STRNN_OT_denoise_action
    original = cls.steps

    def spy(self, context):
        seen.append((self.frame_start, self.frame_end))
        return original(self, context)

    cls.steps = spy
    try:
        bpy.ops.strnn.denoise_action("INVOKE_DEFAULT", use_range=True)
        scene.use_preview_range, scene.frame_preview_start, scene.frame_preview_end = True, 10, 30
        bpy.ops.strnn.denoise_action("INVOKE_DEFAULT", use_range=True)
        bpy.ops.strnn.denoise_action("INVOKE_DEFAULT", use_range=True, frame_start=2, frame_end=40)
    finally:
        cls.steps = original
    assert seen == [(5, 50), (10, 30), (2, 40)]
