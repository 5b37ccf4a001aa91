"""Every bad input gets a clear message (what is wrong, how to fix it) and changes nothing."""

from __future__ import annotations

from pathlib import Path

import bpy
import pytest
from scenes import action_of, build_armature, fcurves_of, import_bvh, key_snapshot, same_keys, walk_bvh


def state() -> tuple:
    """Everything an operator could change: actions with their keys, assignments, scene range."""
    keys = {a.name: (a.use_fake_user, key_snapshot_of(a)) for a in bpy.data.actions}
    assigned = {o.name: (action_of(o).name if action_of(o) else None) for o in bpy.data.objects}
    maps = {o.name: o.strnn_map.hips for o in bpy.data.objects if o.type == "ARMATURE"}
    return keys, assigned, maps, bpy.context.scene.frame_end


def key_snapshot_of(action) -> dict:
    users = [o for o in bpy.data.objects if action_of(o) == action]
    return key_snapshot(users[0], action) if users else {}


def refuse(op_name: str, match: str) -> None:
    """The operator must fail with ``match`` in its message and leave the file as it was."""
    before = state()
    with pytest.raises(RuntimeError, match=match):
        getattr(bpy.ops.strnn, op_name)()
    after = state()
    assert after[1:] == before[1:] and before[0].keys() == after[0].keys()
    assert all(before[0][k][0] == after[0][k][0] and same_keys(before[0][k][1], after[0][k][1]) for k in before[0])


MODEL_OPS = ["extend_clip", "denoise_action", "make_loop", "check_motion"]
ACTION_OPS = MODEL_OPS + ["foot_lock"]
OPS = ACTION_OPS + ["follow_curve"]  # Follow Curve also starts an armature that has no action


@pytest.mark.parametrize("op", OPS)
def test_no_active_object(addon, op):
    refuse(op, "No active object")


@pytest.mark.parametrize("op", OPS)
def test_not_an_armature(addon, op):
    bpy.ops.mesh.primitive_cube_add()
    refuse(op, "not an armature")


@pytest.mark.parametrize("op", ACTION_OPS)
def test_armature_without_action(addon, op):
    build_armature("Bare", [("a", None, (0, 0, 0), (0, 0, 1))])
    refuse(op, "has no action")


@pytest.mark.parametrize("op", MODEL_OPS)  # foot lock needs no 20-frame context
def test_fewer_than_20_frames(addon, tmp_path, op):
    import_bvh(walk_bvh(tmp_path, frames=15))
    refuse(op, "needs at least 20")


@pytest.mark.parametrize("op", OPS)
def test_rig_that_cannot_be_mapped_lists_missing_joints(addon, tmp_path, op):
    obj = import_bvh(walk_bvh(tmp_path, frames=40))
    for i, bone in enumerate(obj.data.bones):
        bone.name = f"bone{i}"
    refuse(op, r"no bone found for .*Left Knee")


@pytest.mark.parametrize("op", OPS)
@pytest.mark.parametrize("scale", [(0, 1, 1), (1, -1, 1)], ids=["zero", "negative"])
def test_zero_or_negative_scale(addon, tmp_path, op, scale):
    obj = import_bvh(walk_bvh(tmp_path, frames=40))
    obj.scale = scale
    refuse(op, "zero or negative scale")


@pytest.mark.parametrize("op", ["denoise_action", "foot_lock"])
@pytest.mark.parametrize("start, end, match", [
    (50, 10, r"Start 50 is after End 10: swap them"),
    (500, 600, r"Frames 500-600 lie outside the action 'walk' \(frames 1-40\): pick a range inside it"),
    (38, 39, r"The frame range 38-39 of 'walk' has 2 frames; .* needs at least .*: widen the range"),
], ids=["reversed", "outside", "too_short"])
def test_bad_frame_range(addon, tmp_path, op, start, end, match):
    import_bvh(walk_bvh(tmp_path, frames=40))
    before = state()
    with pytest.raises(RuntimeError, match=match):
        getattr(bpy.ops.strnn, op)(use_range=True, frame_start=start, frame_end=end)
    assert state()[1:] == before[1:] and state()[0].keys() == before[0].keys()


@pytest.mark.parametrize("op", ACTION_OPS)
@pytest.mark.parametrize("how", ["object", "collection", "rest_position"])
def test_a_rig_disabled_in_viewports_that_needs_evaluating_is_refused(addon, tmp_path, op, how):
    """Disabled in viewports (itself or its collection), an armature is left out of Blender's evaluation, and in
    Rest Position every frame evaluates to the rest pose, so a rig read or written frame by frame through Blender
    (here a bone with a constraint) kept one pose at every frame (Denoise at strength 0 moved its joints 0.95 m).
    Refused with the way out; hidden with H it is still evaluated, and a rig whose keys alone say its pose runs."""
    obj = import_bvh(walk_bvh(tmp_path, frames=40))
    bone = obj.pose.bones[0]
    con = bone.constraints.new("LIMIT_ROTATION")
    if how == "object":
        obj.hide_viewport = True
    elif how == "rest_position":
        obj.data.pose_position = "REST"
    else:
        coll = bpy.data.collections.new("Rigs")
        bpy.context.scene.collection.children.link(coll)
        coll.objects.link(obj)
        bpy.context.scene.collection.objects.unlink(obj)
        coll.hide_viewport = True
    refuse(op, r"Rest Position.*has constraints.*Pose Position" if how == "rest_position" else
           r"disabled in viewports.*has constraints.*Show in Viewports")
    bone.constraints.remove(con)
    assert getattr(bpy.ops.strnn, op)() == {"FINISHED"}


@pytest.mark.parametrize("op", OPS)
def test_nla_tweak_mode(addon, tmp_path, op):
    """Editing a strip's action in the NLA: the action cannot be reassigned, so nothing may start."""
    obj = import_bvh(walk_bvh(tmp_path, frames=40))
    bpy.ops.curve.primitive_nurbs_path_add()
    bpy.context.view_layer.objects.active = obj
    ad = obj.animation_data
    track = ad.nla_tracks.new()
    strip = track.strips.new("walk", 1, ad.action)
    ad.action = None
    ad.nla_tracks.active, track.select, strip.select = track, True, True
    ad.use_tweak_mode = True
    assert ad.action is strip.action
    refuse(op, r"NLA tweak mode.*Stop Tweaking Strip Actions")
    assert ad.use_tweak_mode


@pytest.mark.parametrize("op", OPS)
def test_linked_armature(addon, tmp_path, op):
    obj = import_bvh(walk_bvh(tmp_path, frames=40))
    name = obj.name
    library = tmp_path / "library.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(library))
    bpy.ops.wm.read_homefile(use_empty=True)
    with bpy.data.libraries.load(str(library), link=True) as (src, dst):
        dst.objects = [name]
    linked = dst.objects[0]
    bpy.context.scene.collection.objects.link(linked)
    bpy.context.view_layer.objects.active = linked
    assert linked.library is not None
    assert not getattr(bpy.ops.strnn, op).poll()  # greyed out, with the reason below
    refuse(op, "linked from")


def test_extend_refuses_a_denoise_only_model(addon, tmp_path):
    denoiser = Path(addon.__file__).parent / "models" / "strnn_denoise"
    if not (denoiser / "model.json").exists():
        pytest.skip("the extension ships no denoising model")
    import_bvh(walk_bvh(tmp_path, frames=40))
    prefs = bpy.context.preferences.addons[addon.__name__].preferences
    prefs.model_folder = str(denoiser)
    try:
        refuse("extend_clip", "trained for Denoise alone.*Model Folder")
    finally:
        prefs.model_folder = ""


@pytest.mark.parametrize(("op", "setting"),
                         [("extend_clip", "model_folder"), ("denoise_action", "denoise_model_folder")])
def test_a_model_folder_without_a_model_names_its_preference(addon, tmp_path, op, setting):
    import_bvh(walk_bvh(tmp_path, frames=40))
    prefs = bpy.context.preferences.addons[addon.__name__].preferences
    setattr(prefs, setting, str(tmp_path / "empty"))
    label = {"model_folder": "Model Folder", "denoise_model_folder": "Denoise Model Folder"}[setting]
    try:
        refuse(op, f"No model at .*empty.*STRNN Motion > {label}$")
    finally:
        setattr(prefs, setting, "")


POLLED = ["extend_clip", "inbetween", "denoise_action", "foot_lock", "make_loop", "follow_curve", "transfer_motion",
          "auto_map", "check_motion"]


@pytest.mark.parametrize("op", POLLED)
@pytest.mark.parametrize("scene", ["nothing", "cube", "bare_armature"])
def test_poll_is_false_with_a_reason(addon, op, scene):
    """Like Blender's own operators, ours grey out (poll False) and say why, up front."""
    if scene == "cube":
        bpy.ops.mesh.primitive_cube_add()
    elif scene == "bare_armature":
        build_armature("Bare", [("a", None, (0, 0, 0), (0, 0, 1))])
    runs = scene == "bare_armature" and op in ("follow_curve", "transfer_motion", "auto_map")  # take it as it is
    assert getattr(bpy.ops.strnn, op).poll() == runs
    if not runs:
        with pytest.raises(RuntimeError, match="armature|active object|action"):
            getattr(bpy.ops.strnn, op)()


@pytest.mark.parametrize("op", ACTION_OPS + ["inbetween"])
@pytest.mark.parametrize("value", [float("nan"), float("inf")], ids=["nan", "inf"])
def test_a_nan_or_inf_key_is_named_with_its_bone_and_frame(addon, tmp_path, op, value):
    obj = import_bvh(walk_bvh(tmp_path, frames=40))
    fc = next(f for f in fcurves_of(obj) if "rotation_euler" in f.data_path)
    fc.keyframe_points[12].co[1] = value
    refuse(op, r"has a key of (nan|inf|3\.4\d*e\+38) at frame 13 \(bone '.+', rotation_euler\[\d\]\): fix or delete")
