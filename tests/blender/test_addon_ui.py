"""The sidebar tab and menus: registered, and every panel draws without error on each kind of object."""

from __future__ import annotations

import bpy
import pytest
from scenes import (
    action_of,
    addon_module,
    build_armature,
    fcurves_of,
    fewer_torso_bones,
    import_bvh,
    key_snapshot,
    same_keys,
    walk_bvh,
)

PANELS = ("STRNN_PT_main", "STRNN_PT_extend", "STRNN_PT_fill_gap", "STRNN_PT_denoise", "STRNN_PT_foot_lock",
          "STRNN_PT_loop", "STRNN_PT_follow_curve", "STRNN_PT_transfer", "STRNN_PT_bone_map", "STRNN_PT_controls")


OPERATOR_PANELS = ("STRNN_PT_extend", "STRNN_PT_fill_gap", "STRNN_PT_denoise", "STRNN_PT_foot_lock",
                   "STRNN_PT_loop", "STRNN_PT_follow_curve", "STRNN_PT_transfer")


class Layout:
    """Records layout calls as (name, data, property); property names are checked against the data they are
    drawn from, and an operator button must not set options of its own."""

    def __init__(self, calls):
        self.calls = calls

    def __getattr__(self, name):
        def call(*args, **kw):
            data = prop = None
            if name in ("prop", "prop_search"):
                data, prop = args[0], args[1]
                assert prop in data.bl_rna.properties, f"{type(data).__name__} has no property {prop!r}"
            if name == "operator":
                assert hasattr(bpy.ops.strnn, args[0].split(".")[1])
            self.calls.append((name, data, prop))
            return OperatorButton(args[0]) if name == "operator" else Layout(self.calls)

        return call


class OperatorButton:
    """An operator button: it takes the operator's remembered options, so a panel sets none on it."""

    def __init__(self, idname: str):
        object.__setattr__(self, "idname", idname)

    def __setattr__(self, name, value):
        raise AssertionError(f"the panel sets {name!r} on its {self.idname} button: the sidebar must edit the "
                             "operator's remembered options instead")


def fake_panel(panel, layout):
    """A stand-in for an instance of ``panel`` (Blender makes those only when it draws) with ``layout``."""
    own = {k: getattr(panel, k) for k in ("operator", "icon", "draw_options") if hasattr(panel, k)}
    return type("Fake", (), {"layout": layout, **own})()


def draw_all(context) -> list[str]:
    calls = []
    for name in PANELS:
        panel = getattr(bpy.types, name)
        if panel.poll(context):
            panel.draw(fake_panel(panel, Layout(calls)), context)
    return [c[0] for c in calls]


def test_registered_in_sidebar_and_menus(addon):
    for name in PANELS:
        cls = getattr(bpy.types, name)
        assert cls.bl_space_type == "VIEW_3D" and cls.bl_region_type == "UI" and cls.bl_category == "STRNN"
    for op in ("extend_clip", "inbetween", "denoise_action", "foot_lock", "make_loop", "follow_curve", "auto_map",
               "check_motion"):
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


def test_the_sidebar_edits_each_operators_remembered_options(addon, tmp_path):
    """Each operator panel draws the options the operator remembers (what F3, the menus and the redo panel
    use), every option an animator sets, and a button that sets nothing of its own."""
    import_bvh(walk_bvh(tmp_path, frames=30))
    wm = bpy.context.window_manager
    for name in OPERATOR_PANELS:
        panel = getattr(bpy.types, name)
        calls = []
        panel.draw(fake_panel(panel, Layout(calls)), bpy.context)
        remembered = wm.operator_properties_last(panel.operator)
        drawn = {prop for kind, data, prop in calls if kind == "prop"}
        assert all(data.as_pointer() == remembered.as_pointer() for kind, data, _ in calls if kind == "prop"), name
        options = {p.identifier for p in remembered.bl_rna.properties} - {"rna_type", "scene_range"}
        assert drawn == options, f"{name}: not drawn {options - drawn}"
        assert ("operator", None, None) in calls


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

    cls = getattr(bpy.types, panel)
    cls.draw(fake_panel(cls, Labels()), context)
    return labels


def test_main_panel_says_what_each_object_allows(addon, tmp_path):
    bpy.ops.mesh.primitive_cube_add()
    assert panel_labels("STRNN_PT_main", bpy.context) == [("'Cube' is a mesh, not an armature", "ERROR")]
    build_armature("Bare", [("a", None, (0, 0, 0), (0, 0, 1))])
    assert panel_labels("STRNN_PT_main", bpy.context) == [("Bare: no action", "INFO"),
                                              ("Follow Curve can start one; the others need an action", "NONE")]
    walk = import_bvh(walk_bvh(tmp_path, frames=30))
    assert panel_labels("STRNN_PT_main", bpy.context) == [("walk: walk (frames 1-30)", "ACTION")]
    cycles = [fc.modifiers.new("CYCLES") for fc in fcurves_of(walk)]  # a walk cycle keyed as animators key one
    assert panel_labels("STRNN_PT_main", bpy.context) == [
        ("walk: walk (frames 1-30)", "ACTION"), ("Repeats (Cycles modifiers) past its keys", "FILE_REFRESH")]
    for fc, mod in zip(fcurves_of(walk), cycles):
        fc.modifiers.remove(mod)
    # other selected armatures with an action: the panel says the operations run on each (the bare one has none)
    (tmp_path / "b").mkdir()
    for obj in (import_bvh(walk_bvh(tmp_path / "b", frames=40)), bpy.data.objects["Bare"], bpy.data.objects["Cube"]):
        obj.select_set(True)
    bpy.context.view_layer.objects.active = walk
    assert panel_labels("STRNN_PT_main", bpy.context) == [
        ("walk: walk (frames 1-30)", "ACTION"), ("+ 1 more selected armature with an action", "OUTLINER_OB_ARMATURE"),
        ("Extend Clip, Fill Gap, Denoise Action, Foot Lock and Make Loop run on each", "NONE")]


def test_bone_map_panel_says_which_joints_a_rig_with_fewer_torso_bones_has_placed(addon):
    """A rig with one spine bone and no neck bone: the panel counts the joints mapped and says where the chest and
    the neck are placed, rather than calling them missing; a map left empty lists what is missing instead."""
    build_armature("Game", fewer_torso_bones(("Spine1", "Spine2", "Neck")))
    labels = panel_labels("STRNN_PT_bone_map", bpy.context)
    assert labels[0][1] == "ERROR" and "Spine 1" not in labels[0][0] and "Neck" not in labels[0][0] and len(labels) == 1
    assert bpy.ops.strnn.auto_map() == {"FINISHED"}
    assert panel_labels("STRNN_PT_bone_map", bpy.context) == [
        ("19 joints mapped (generic)", "CHECKMARK"), ("No Spine 1 bone: placed between Spine and Head", "INFO"),
        ("No Neck bone: placed between Spine and Head", "INFO")]


def test_main_panel_keeps_the_reports_notes_in_view(addon, tmp_path, real_model):
    """After an operation the main panel says which one made the active action and, where its report warned,
    the same notes (a procedural walk is unlike any capture), wrapped into lines; a take it did not make shows
    none of that."""
    import_bvh(walk_bvh(tmp_path, frames=40))
    assert [text for text, _ in panel_labels("STRNN_PT_main", bpy.context)] == ["walk: walk (frames 1-40)"]
    assert bpy.ops.strnn.extend_clip(frames=10) == {"FINISHED"}
    labels = panel_labels("STRNN_PT_main", bpy.context)
    assert labels[1] == ("Made by Extend Clip: check it", "ERROR")
    notes = addon_module(addon, "strnn_addon.stages.common").record_notes(action_of(bpy.context.active_object))
    assert notes and " ".join(text for text, _ in labels[2:]) == " ".join(notes)
    assert all(len(text) <= 60 for text, _ in labels[2:])


def as_from_the_ui(op: str, **handed):
    """Run ``strnn.<op>`` as a button, F3 or a menu runs it: every option not handed takes the operator's
    remembered value (Blender's ``WM_operator_last_properties_init`` for a run from the interface; headless
    bpy has no window to invoke from, so its copy is made here, option by option)."""
    remembered = bpy.context.window_manager.operator_properties_last(f"strnn.{op}")
    options = {p.identifier: getattr(remembered, p.identifier) for p in remembered.bl_rna.properties
               if p.identifier != "rna_type" and not p.is_skip_save}
    return getattr(bpy.ops.strnn, op)(**(options | handed))


def test_a_frame_range_comes_from_the_preview_or_scene_range_unless_set(addon, tmp_path):
    """A script's call without Start starts from the scene's preview range (else its range); so does a run
    with Frame Range off, so that turning it on starts there; a range set with Frame Range on is kept,
    whether handed to the call or remembered (the sidebar's) when invoked as F3 and buttons do."""
    import_bvh(walk_bvh(tmp_path, frames=60))
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 5, 50
    seen = []
    cls = bpy.types.STRNN_OT_denoise_action
    original = cls.steps

    def spy(self, context, obj):
        seen.append((self.use_range, self.frame_start, self.frame_end))
        return original(self, context, obj)

    remembered = bpy.context.window_manager.operator_properties_last("strnn.denoise_action")
    cls.steps = spy
    try:
        bpy.ops.strnn.denoise_action(use_range=True)
        scene.use_preview_range, scene.frame_preview_start, scene.frame_preview_end = True, 10, 30
        bpy.ops.strnn.denoise_action(use_range=True)
        bpy.ops.strnn.denoise_action(use_range=True, frame_start=2, frame_end=40)
        remembered.use_range, remembered.frame_start, remembered.frame_end = True, 3, 33
        as_from_the_ui("denoise_action")
        remembered.use_range = False
        as_from_the_ui("denoise_action")
    finally:
        cls.steps = original
    assert seen == [(True, 5, 50), (True, 10, 30), (True, 2, 40), (True, 3, 33), (False, 10, 30)]


# operator -> options an animator sets in its sidebar panel (none of them the defaults)
SET_IN_SIDEBAR = {
    "extend_clip": {"frames": 12, "foot_lock": True, "context_frames": 30},
    "denoise_action": {"strength": 0.6, "use_range": True, "frame_start": 5, "frame_end": 40},
    "foot_lock": {"blend": 0.3, "use_range": True, "frame_start": 3, "frame_end": 50},
    "inbetween": {"use_range": True, "frame_start": 20, "frame_end": 30, "foot_lock": False},
}


@pytest.mark.parametrize("op", sorted(SET_IN_SIDEBAR))
def test_f3_and_the_sidebar_run_with_the_same_options(addon, tmp_path, real_model, op):
    """Options edited in the sidebar are the operator's remembered ones: run as F3, a menu or the sidebar's
    button runs it (no options handed), it makes the same action as a call handed those options."""
    obj = import_bvh(walk_bvh(tmp_path, frames=60))
    source = action_of(obj)
    options = SET_IN_SIDEBAR[op]
    remembered = bpy.context.window_manager.operator_properties_last(f"strnn.{op}")
    for name, value in options.items():
        setattr(remembered, name, value)
    assert as_from_the_ui(op) == {"FINISHED"}
    from_sidebar = action_of(obj)
    obj.animation_data.action = source
    assert getattr(bpy.ops.strnn, op)(**options) == {"FINISHED"}
    from_script = action_of(obj)
    assert from_sidebar != from_script and from_sidebar != source
    assert same_keys(key_snapshot(obj, from_sidebar), key_snapshot(obj, from_script))
    settings = from_sidebar["strnn"].to_dict()["settings"]
    assert settings == from_script["strnn"].to_dict()["settings"]
    for name, value in options.items():
        if name in settings:
            assert settings[name] == pytest.approx(value), name


def test_the_batch_cli_and_the_operators_share_each_options_default(addon, tmp_path):
    """Both are built from one declaration (model_core/ops/options.py): a batch run without options does what
    the operator does without options."""
    import importlib.util

    from scenes import REPO

    spec = importlib.util.spec_from_file_location("strnn_batch", REPO / "scripts" / "strnn_batch.py")
    batch = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(batch)
    parser = batch.build_parser()
    for command in ("extend", "denoise", "footlock", "inbetween", "follow"):
        args = parser.parse_args([command, str(tmp_path / "take.bvh")])
        op, kwargs = batch.operator_call(args)
        rna = getattr(bpy.ops.strnn, op).get_rna_type().properties
        for name, value in kwargs.items():
            if name in ("use_range", "frame_start", "frame_end", "from_current"):
                continue  # the batch decides these from --gap / --from-frame
            assert rna[name].default == pytest.approx(value), f"{command} --{name}: {value} != {rna[name].default}"


def test_transfer_panel_says_a_named_source_goes_onto_each_selected_armature(addon, tmp_path):
    source = import_bvh(walk_bvh(tmp_path, frames=30))
    targets = [build_armature(name, [("a", None, (0, 0, 0), (0, 0, 1))]) for name in ("A", "B")]
    opts = bpy.context.window_manager.operator_properties_last("strnn.transfer_motion")
    opts.source = ""
    for obj in (source, *targets):
        obj.select_set(True)
    assert ("Or select the source, then the target", "INFO") in panel_labels("STRNN_PT_transfer", bpy.context)
    opts.source = source.name
    try:
        assert ("Onto each selected armature but the source", "INFO") in panel_labels("STRNN_PT_transfer",
                                                                                       bpy.context)
        targets[1].select_set(False)
        assert ("Onto each selected armature but the source", "INFO") not in panel_labels("STRNN_PT_transfer",
                                                                                           bpy.context)
    finally:
        opts.source = ""
