"""Foot Lock: the operator on a sliding clip, its frame range, and the Foot lock option of
Extend and Denoise. Skate is measured on the joints Blender evaluates, on the contacts of
the clip before the lock."""

from __future__ import annotations

import bpy
import numpy as np
import pytest
from scenes import (
    action_of,
    addon_module,
    evaluated_joints,
    fcurves_of,
    import_bvh,
    key_snapshot,
    on_steps,
    ramp,
    same_keys,
)

from model_core.io.bvh_export import write_bvh
from model_core.motion.conventions import CONTACT_JOINTS, JOINT_INDEX, zup_to_yup
from model_core.motion.synthetic import up_a_slope, walking_skeleton
from model_core.ops import footlock as fl
from model_core.rig.rigs import leg_length

LEG_WORDS = ("UpLeg", "Leg", "Foot", "Toe")  # Mixamo names of the leg bones a BVH import has
LEG_JOINTS = [JOINT_INDEX[f"{s}_{j}"] for s in "lr" for j in ("knee", "foot", "toe")]


def sliding_walk(frames: int = 90, speed: float = 1.3) -> np.ndarray:
    """A walk ``[F, 21, 3]`` (metres, Y-up, 30 fps) whose whole body drifts, so planted feet slide."""
    t = np.arange(frames) / 30.0
    drift = np.stack([np.sin(2 * np.pi * 1.1 * t), 0 * t, np.cos(2 * np.pi * 0.7 * t)], -1) * 0.05
    return walking_skeleton(frames, speed=speed) + drift[:, None].astype(np.float32)


def import_sliding(tmp_path, frames: int = 90, **kw):
    return import_bvh(write_bvh(tmp_path / "slide.bvh", sliding_walk(frames, **kw)))


def joints(addon, obj, frames) -> np.ndarray:
    """Evaluated world joints ``[F, 21, 3]`` in model axes (Y-up), scene units."""
    return zup_to_yup(evaluated_joints(addon, obj, frames))


def lock(**kw):
    """Run Foot Lock on the active object; check the new action and the untouched original."""
    obj = bpy.context.active_object
    old, before = action_of(obj), key_snapshot(obj)
    assert bpy.ops.strnn.foot_lock(**kw) == {"FINISHED"}
    new = action_of(obj)
    assert new is not old and new.name.startswith(old.name) and old.use_fake_user
    assert same_keys(before, key_snapshot(obj, old))
    assert tuple(new.frame_range) == tuple(old.frame_range)
    return old, new


def leg_lengths(pos: np.ndarray) -> np.ndarray:
    """Thigh and shin lengths ``[F, 4]``."""
    pairs = [(f"{s}_{a}", f"{s}_{b}") for s in "lr" for a, b in (("upleg", "knee"), ("knee", "foot"))]
    return np.stack([np.linalg.norm(pos[:, JOINT_INDEX[a]] - pos[:, JOINT_INDEX[b]], axis=-1) for a, b in pairs], -1)


def test_foot_lock_reduces_skate_on_a_sliding_clip(addon, tmp_path):
    obj = import_sliding(tmp_path)
    frames = np.arange(1, 91)
    before = joints(addon, obj, frames)
    contacts = fl.detect_foot_contacts(before)
    old, new = lock()
    after = joints(addon, obj, frames)
    skate_before, skate_after = fl.foot_skate_cm(before, contacts), fl.foot_skate_cm(after, contacts)
    own = fl.foot_skate_cm(after, fl.detect_foot_contacts(after))  # the lock settles: its own resting feet too
    print(f"skate {skate_before:.2f} -> {skate_after:.2f} cm/frame, on the result's own contacts {own:.3f}")
    assert skate_before > 0.8 and skate_after <= 0.05 and own <= 0.06  # one pass: 0.07 and 0.09
    assert fl.knee_pops(after) <= fl.knee_pops(before)
    np.testing.assert_allclose(leg_lengths(after), leg_lengths(before), atol=1e-4)
    body = np.setdiff1d(np.arange(21), LEG_JOINTS)
    assert np.abs(after[:, body] - before[:, body]).max() < 1e-5, "only the legs move"
    old_keys, new_keys = key_snapshot(obj, old), key_snapshot(obj, new)
    for key, co in old_keys.items():
        if not any(word in key[0] for word in LEG_WORDS):
            assert np.array_equal(co, new_keys[key]), f"{key} changed"


def test_an_action_on_twos_is_locked_at_its_keys_and_stays_on_twos(addon, tmp_path):
    """A sliding walk keyed on twos with Constant interpolation: the feet are found and pinned on its keys (read at
    their rate, not as holds and jumps) and the legs keyed on the same frames, Constant, so every pose is still held
    for two frames."""
    obj = import_sliding(tmp_path, frames=91)
    on_steps(obj, 2)  # keys on 1, 3, ..., 91
    frames = np.arange(1, 92)
    before = joints(addon, obj, frames)
    contacts = fl.detect_foot_contacts(before[::2], fps=15.0)  # on the keys, at their rate
    _, new = lock()
    assert new["strnn"]["key_step"] == 2
    after = joints(addon, obj, frames)
    assert np.abs(after[1::2] - after[0:-1:2]).max() < 1e-6  # each even frame holds the key before it
    legs = [fc for fc in fcurves_of(obj) if any(f'"{w}' in fc.data_path or f"{w}\"" in fc.data_path
                                                for w in ("LeftUpLeg", "RightUpLeg", "LeftLeg", "RightLeg"))]
    assert legs and all({int(p.co[0]) % 2 for p in fc.keyframe_points} == {1} for fc in legs)
    assert all({p.interpolation for p in fc.keyframe_points} == {"CONSTANT"} for fc in legs)
    skate_before, skate_after = fl.foot_skate_cm(before[::2], contacts), fl.foot_skate_cm(after[::2], contacts)
    print(f"skate per key {skate_before:.2f} -> {skate_after:.2f} cm")
    assert skate_before > 1.5 and skate_after <= 0.1


def test_frame_range_changes_only_its_frames(addon, tmp_path):
    obj = import_sliding(tmp_path)
    frames = np.arange(1, 91)
    before = joints(addon, obj, frames)
    contacts = fl.detect_foot_contacts(before)
    lock(use_range=True, frame_start=31, frame_end=70, blend=0.1)
    after = joints(addon, obj, frames)
    assert np.abs(after[:30] - before[:30]).max() < 1e-5 and np.abs(after[70:] - before[70:]).max() < 1e-5
    inside = slice(30, 70)
    assert fl.foot_skate_cm(after[inside], contacts[inside]) < 0.5 * fl.foot_skate_cm(before[inside], contacts[inside])


def test_operator_is_undoable_and_searchable(addon):
    cls = bpy.types.STRNN_OT_foot_lock  # undo itself needs a window; background Blender has none
    assert {"REGISTER", "UNDO"} <= set(cls.bl_options)
    assert bpy.ops.strnn.foot_lock.get_rna_type().description


def test_extend_option(addon, tmp_path, model_calls):
    """Extend a walk whose feet slide (the clip drifts) with Foot Lock off and on: with it on, the new frames' planted
    feet hold (skate at most 0.2 cm a frame, under half of what the model's frames have), the model's motion is kept
    elsewhere (the hips within 1 cm), and the seam moves no joint further than the clip's own frames do."""
    obj = import_sliding(tmp_path, frames=60)
    walk = action_of(obj)
    skates, hips = {}, {}
    for foot_lock in (False, True):
        obj.animation_data.action = walk
        assert bpy.ops.strnn.extend_clip(frames=60, foot_lock=foot_lock) == {"FINISHED"}
        pos = joints(addon, obj, np.arange(1, 121))
        contacts = fl.detect_foot_contacts(pos)[60:]  # on the whole clip: a raised foot is not on the ground
        assert contacts.any()
        skates[foot_lock] = fl.foot_skate_cm(pos[60:], contacts)  # frames 61..120
        hips[foot_lock] = pos[60:, 0]
        steps = np.linalg.norm(np.diff(pos, axis=0), axis=-1).max(-1)  # the quickest joint's move each frame
        print(f"foot lock {foot_lock}: skate {skates[foot_lock]:.2f} cm/frame, seam step {100 * steps[59]:.2f} cm "
              f"(the clip's largest {100 * steps[:59].max():.2f})")
        assert steps[59] < 1.2 * steps[:59].max()
    assert skates[True] <= 0.2 and skates[True] < 0.5 * skates[False], skates
    assert np.linalg.norm(hips[True] - hips[False], axis=-1).max() < 0.01


def test_denoise_option(addon, tmp_path, model_calls):
    obj = import_sliding(tmp_path, frames=60)
    frames = np.arange(1, 61)
    before = joints(addon, obj, frames)
    contacts = fl.detect_foot_contacts(before)
    assert bpy.ops.strnn.denoise_action(foot_lock=True) == {"FINISHED"}
    after = joints(addon, obj, frames)
    assert fl.foot_skate_cm(before, contacts) > 0.8 and fl.foot_skate_cm(after, contacts) <= 0.5


def refused(match: str, **kw) -> None:
    """Foot Lock must fail with ``match`` and leave the keys, the actions and the assignment as they were."""
    obj = bpy.context.active_object
    action, before, names = action_of(obj), key_snapshot(obj), sorted(a.name for a in bpy.data.actions)
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.strnn.foot_lock(**kw)
    assert action_of(obj) is action and same_keys(before, key_snapshot(obj))
    assert sorted(a.name for a in bpy.data.actions) == names and not action.use_fake_user


def test_too_short_range_is_refused(addon, tmp_path):
    import_sliding(tmp_path, frames=40)
    refused("needs at least 3", use_range=True, frame_start=10, frame_end=11)


def test_clip_without_contacts_is_refused(addon, tmp_path):
    import_bvh(write_bvh(tmp_path / "run.bvh", walking_skeleton(40, speed=4.0)))  # the feet never rest
    refused("No foot touches the ground")


def test_only_selected_bones_lock_only_those_legs(addon, tmp_path):
    """With Only Selected Bones and the left leg selected, only left-leg keys change."""
    obj = import_sliding(tmp_path)
    left = {pb.name for pb in obj.pose.bones if pb.name.startswith(("LeftUpLeg", "LeftLeg", "LeftFoot"))}
    assert left
    for pb in obj.pose.bones:
        if hasattr(pb, "select"):  # Blender 5 keeps pose selection on the pose bone, 4.x on the bone
            pb.select = pb.name in left
        else:
            pb.bone.select = pb.name in left
    old, new = lock(only_selected=True)
    old_keys, new_keys = key_snapshot(obj, old), key_snapshot(obj, new)
    changed = {key[0].split('"')[1] for key, co in old_keys.items() if not np.array_equal(co, new_keys[key])}
    assert changed and changed <= left



SLOPE = 0.15  # rise per unit along the way


def climbing(addon, tmp_path, frames: int = 120):
    """A sliding walk up a ramp that rises :data:`SLOPE` along its way (:func:`synthetic.up_a_slope`), imported,
    with the ramp as a mesh under it (``Ramp``): the armature, the contacts the sliding walk has on the flat and the
    ramp's height under points ``[..., 3]`` (Y-up, scene units)."""
    clean, slid = walking_skeleton(frames), sliding_walk(frames)
    climbed, _ = up_a_slope(clean, SLOPE)
    obj = import_bvh(write_bvh(tmp_path / "climb.bvh", climbed + (slid - clean)))
    scale = leg_length(joints(addon, obj, np.arange(1, frames + 1))) / leg_length(clean)
    height = ramp("Ramp", clean[0, 0] * scale, clean[-1, 0] - clean[0, 0], SLOPE)  # as up_a_slope lays the slope
    bpy.context.view_layer.objects.active = obj
    return obj, fl.detect_foot_contacts(slid), height


def test_feet_are_pinned_on_the_ground_mesh_under_them(addon, tmp_path):
    """Foot Lock with Ground set to a ramp the take walks up: every step is found and pinned on the ramp, each
    contact as high over it as the take's contacts stand (the take's median, within 4 cm: its heel rises in a
    contact, and its BVH, written with the bones' lengths, stands the steps 1.6 to 3.6 cm from it). On one flat
    floor, the take's own, the steps up the ramp are too high to count as contacts: they keep sliding."""
    obj, contacts, height = climbing(addon, tmp_path)
    frames = np.arange(1, 121)
    on = contacts > 0.5

    def over_ramp(p):
        return p[:, CONTACT_JOINTS, 1] - height(p[:, CONTACT_JOINTS])

    before = joints(addon, obj, frames)
    stands = np.array([np.median(over_ramp(before)[on[:, k], k]) for k in range(4)])
    old, new = lock(ground="Ramp")
    after = joints(addon, obj, frames)
    skate_before, skate_after = fl.foot_skate_cm(before, contacts), fl.foot_skate_cm(after, contacts)
    print(f"on the ramp: skate {skate_before:.2f} -> {skate_after:.2f} cm/frame")
    assert skate_before > 0.8 and skate_after <= 0.06
    assert np.abs(over_ramp(after) - stands)[on].max() < 0.04
    np.testing.assert_allclose(leg_lengths(after), leg_lengths(before), atol=1e-4)
    assert new["strnn"]["ground"]["object"] == "Ramp" and new["strnn"]["ground"]["frames_without"] == 0
    obj.animation_data.action = old
    _, flat = lock()
    assert "ground" not in flat["strnn"]
    flat_skate = fl.foot_skate_cm(joints(addon, obj, frames), contacts)
    print(f"on one flat floor: skate {skate_before:.2f} -> {flat_skate:.2f} cm/frame")
    assert flat_skate > 10 * skate_after


def test_a_collection_of_meshes_is_a_ground_its_highest_surface_under_each_foot(addon, tmp_path):
    """Ground names a collection: the ramp split in two meshes (its lower and upper halves, as a floor and the
    stairs on it are two), with the character's own body in it too, a level sheet at the ramp's height half way up
    the walk that the armature deforms. The feet are pinned on the ramp as with the ramp alone: the body is no
    ground (taken for one, it would be the floor of the walk's first half), and each half is found where it is."""
    obj, contacts, height = climbing(addon, tmp_path)
    frames = np.arange(1, 121)
    ramp_obj = bpy.data.objects["Ramp"]
    terrain = bpy.data.collections.new("Terrain")
    bpy.context.scene.collection.children.link(terrain)
    verts = [v.co.copy() for v in ramp_obj.data.vertices]  # corners 0-3, the way from 0-3 (-) to 1-2 (+)
    halves = (([verts[0], (verts[0] + verts[1]) / 2, (verts[3] + verts[2]) / 2, verts[3]]),
              ([(verts[0] + verts[1]) / 2, verts[1], verts[2], (verts[3] + verts[2]) / 2]))
    for k, corners in enumerate(halves):
        mesh = bpy.data.meshes.new(f"Half{k}")
        mesh.from_pydata([tuple(c) for c in corners], [], [(0, 1, 2, 3)])
        terrain.objects.link(bpy.data.objects.new(f"Half{k}", mesh))
    middle = float(height(joints(addon, obj, frames[60:61])[0, 0]))  # the ramp's height half way up the walk
    sheet = bpy.data.meshes.new("Body")
    sheet.from_pydata([(v.x, v.y, middle) for v in verts], [], [(0, 1, 2, 3)])
    body = bpy.data.objects.new("Body", sheet)
    terrain.objects.link(body)
    body.modifiers.new("Armature", "ARMATURE").object = obj
    old, alone = lock(ground="Ramp")
    on_ramp = joints(addon, obj, frames)
    obj.animation_data.action = old
    _, split = lock(ground="Terrain")
    assert split["strnn"]["ground"]["object"] == "Terrain" and split["strnn"]["ground"]["frames_without"] == 0
    assert np.abs(joints(addon, obj, frames) - on_ramp).max() < 1e-4


def test_a_ground_that_is_no_mesh_or_under_no_foot_is_refused(addon, tmp_path):
    obj = import_sliding(tmp_path)
    refused("No object or collection named 'Nowhere'", ground="Nowhere")
    refused(f"'{obj.name}' is an armature, not a mesh", ground=obj.name)
    mesh = bpy.data.meshes.new("Far")
    mesh.from_pydata([(100, 100, 0), (101, 100, 0), (101, 101, 0), (100, 101, 0)], [], [(0, 1, 2, 3)])
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("Far", mesh))
    refused("The ground 'Far' is under neither foot", ground="Far")
    for name, shown in (("Away", False), ("Off", True)):  # not in the scene; in it, disabled in viewports
        flat = bpy.data.objects.new(name, bpy.data.meshes.new(name))
        flat.data.from_pydata([(-50, -50, 0), (50, -50, 0), (50, 50, 0), (-50, 50, 0)], [], [(0, 1, 2, 3)])
        if shown:
            bpy.context.scene.collection.objects.link(flat)
            flat.hide_viewport = True
        refused(f"The mesh '{name}' is not in the scene's view layer, or is disabled in viewports", ground=name)
    body = bpy.data.objects.new("Body", bpy.data.meshes.new("Body"))  # the character's own skin is no ground
    bpy.context.scene.collection.objects.link(body)
    body.modifiers.new("Armature", "ARMATURE").object = obj
    refused(f"'Body' is the character's own body \\('{obj.name}' deforms it\\)", ground="Body")
    skin = bpy.data.collections.new("Skin")  # a collection with no mesh but the body
    bpy.context.scene.collection.children.link(skin)
    skin.objects.link(body)
    refused("The collection 'Skin' holds no mesh to stand on", ground="Skin")
    listed = addon_module(addon, "strnn_addon.props")._objects_of("MESH", exclude_body=True)(None, bpy.context, "")
    assert "Far" in listed and "Body" not in listed and "Skin" not in listed  # Ground's drop-down leaves the body out
