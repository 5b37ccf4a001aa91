"""Operations on every selected armature (a crowd, a cast), not only the active one.

Extend Clip, Fill Gap, Denoise Action and Foot Lock run on each selected armature, the active one first; each
gets its own new action made from its own motion, as if run on it alone. Every armature is read and computed before
any is written: an error on the active armature, or Esc part way, leaves every one as it was. Another selected
armature the operation cannot take is left as it was and the report says which and why.
"""

from __future__ import annotations

import bpy
import numpy as np
import pytest
from scenes import (
    action_of,
    addon_module,
    build_armature,
    evaluated_joints,
    import_bvh,
    key_snapshot,
    makehuman_walk,
    mixamo_bones,
    mixamo_walk,
    same_keys,
    walk_bvh,
)

RECORD = "strnn"


def cast(tmp_path) -> list:
    """Three armatures walking their own walks (a BVH import, a Mixamo and a MakeHuman rig, each moved apart),
    a mesh among them, all selected; the BVH import active."""
    bvh = import_bvh(walk_bvh(tmp_path, frames=90))
    mixamo, makehuman = mixamo_walk(60), makehuman_walk(80)
    mixamo.location, makehuman.location = (3.0, 0.0, 0.0), (-3.0, 1.0, 0.0)
    mesh = bpy.data.objects.new("Ground", bpy.data.meshes.new("Ground"))
    bpy.context.scene.collection.objects.link(mesh)
    for obj in (bvh, mixamo, makehuman, mesh):
        obj.select_set(True)
    bpy.context.view_layer.objects.active = bvh
    return [bvh, mixamo, makehuman]


def walkers(tmp_path, lengths=(90, 70, 110)) -> list:
    """Procedural walks of ``lengths`` frames imported from BVH files, side by side, all selected, the first
    active."""
    objs = []
    for i, frames in enumerate(lengths):
        (tmp_path / str(i)).mkdir()
        obj = import_bvh(walk_bvh(tmp_path / str(i), frames=frames))
        obj.name, obj.location = f"Walker {i}", (1.5 * i, 0.0, 0.0)
        objs.append(obj)
    for obj in objs:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = objs[0]
    return objs


def prop(name: str = "Sword", keyed: bool = True):
    """A two-bone armature that is not a body (a prop), with a keyed action unless ``keyed`` is False."""
    obj = build_armature(name, [("grip", "", (0, 0, 0), (0, 0, 0.2)), ("blade", "grip", (0, 0, 0.2), (0, 0, 1.0))])
    if keyed:
        for f in (1, 30):
            obj.pose.bones["grip"].location = (0.0, 0.0, 0.01 * f)
            obj.pose.bones["grip"].keyframe_insert("location", frame=f)
    return obj


def snapshot(objs) -> dict:
    """Each armature's action and its keys, and the file's actions."""
    return {"actions": sorted(a.name for a in bpy.data.actions),
            **{obj.name: (action_of(obj), key_snapshot(obj)) for obj in objs}}


def unchanged(objs, before: dict) -> bool:
    now = snapshot(objs)
    return now["actions"] == before["actions"] and all(
        now[o.name][0] is before[o.name][0] and same_keys(now[o.name][1], before[o.name][1]) for o in objs)


def test_extend_continues_every_selected_armature_on_its_own_motion(tmp_path, model_calls, addon, capfd):
    objs = cast(tmp_path)
    lasts = {o.name: int(action_of(o).frame_range[1]) for o in objs}
    played = {o.name: evaluated_joints(addon, o, np.arange(lasts[o.name] - 1, lasts[o.name] + 1)) for o in objs}
    before = snapshot(objs)
    assert bpy.ops.strnn.extend_clip(frames=30) == {"FINISHED"}
    out = capfd.readouterr().out
    assert "Extend Clip on 3 armatures ('walk', 'MakeHuman', 'Mixamo')" in out, out
    for obj in objs:
        old, new = before[obj.name][0], action_of(obj)
        assert new is not old and new.name.startswith(old.name) and old.use_fake_user
        assert same_keys(before[obj.name][1], key_snapshot(obj, old)), f"{obj.name}: its original action changed"
        assert new.frame_range[1] == lasts[obj.name] + 30
        assert new[RECORD]["source_action"] == old.name
        # each plays the continuation the model made of its own motion, where that armature stands
        want = model_calls.extension_after(played[obj.name][-1])
        got = evaluated_joints(addon, obj, np.arange(lasts[obj.name] + 1, lasts[obj.name] + 31))
        err = np.linalg.norm(got - want, axis=-1).max()
        assert err < 0.01, (obj.name, err)
        assert f"{obj.name!r}: Added 30 frames in new action {new.name!r}" in out
    assert bpy.context.scene.frame_end >= max(lasts.values()) + 30


def test_only_the_active_armature_runs_when_it_is_the_only_one_selected(tmp_path, model_calls, addon):
    objs = cast(tmp_path)
    for obj in objs[1:]:
        obj.select_set(False)
    before = snapshot(objs)
    assert bpy.ops.strnn.extend_clip(frames=10) == {"FINISHED"}
    assert action_of(objs[0]) is not before[objs[0].name][0]
    assert unchanged(objs[1:], {**before, "actions": sorted(a.name for a in bpy.data.actions)})


def test_selected_armatures_the_operation_cannot_take_are_left_and_named(tmp_path, model_calls, addon, capfd):
    objs = cast(tmp_path)
    sword, empty_rig = prop("Sword"), prop("Unkeyed", keyed=False)
    for obj in (sword, empty_rig):
        obj.select_set(True)
    bpy.context.view_layer.objects.active = objs[0]
    before = snapshot([sword])
    assert bpy.ops.strnn.extend_clip(frames=20) == {"FINISHED"}
    out = capfd.readouterr().out
    assert all(action_of(o)[RECORD]["operation"] == "Extend Clip" for o in objs)
    assert action_of(sword) is before["Sword"][0] and same_keys(key_snapshot(sword), before["Sword"][1])
    assert action_of(empty_rig) is None
    summary = next(line for line in out.splitlines() if "Extend Clip on 3 armatures" in line)
    assert "left as they were" in summary and "'Sword' (" in summary and "'Unkeyed' (" in summary, summary
    assert "'Unkeyed' has no action" in summary, summary  # why, in the words the operator uses on its own
    assert "WARNING" in summary.upper()


def test_an_error_on_the_active_armature_changes_no_armature(tmp_path, model_calls, addon):
    objs = cast(tmp_path)
    sword = prop("Sword")
    for obj in objs:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = sword
    before = snapshot([*objs, sword])
    with pytest.raises(RuntimeError, match="'Sword': "):
        bpy.ops.strnn.extend_clip(frames=20)
    assert unchanged([*objs, sword], before)


def test_stopping_part_way_changes_no_armature(tmp_path, model_calls, addon):
    """What Esc does in the operator's modal: the work closed after every armature was read and computed, before
    the first is written, or after the first was written, leaves all of them as they were; run to the end, it writes
    each."""
    objs = cast(tmp_path)
    operators = addon_module(addon, "strnn_addon.operators")
    extend = addon_module(addon, "strnn_addon.stages.extend")

    class Extend(operators._Staged):  # the operator's own work, without Blender's operator around it
        bl_label, many = "Extend Clip", True

        def steps(self, context, obj):
            return extend.extend_steps(context, obj, frames=15)

    before = snapshot(objs)
    op = Extend()
    work, seen = op.work(bpy.context), []
    while not seen or seen[-1][0] != "write":
        seen.append((next(work), op._at[:2]))
    assert seen == [(stage, (i, 3)) for i in range(3) for stage in ("read", "model", "solve")] + [("write", (0, 3))]
    work.close()
    assert unchanged(objs, before)
    # stopped after the first armature was written, before the second: the first is put back too
    scene = bpy.context.scene
    scene.frame_start, scene.frame_end = 5, 50
    before, fake = snapshot(objs), {o.name: action_of(o).use_fake_user for o in objs}
    op = Extend()
    work, seen = op.work(bpy.context), []
    while len(seen) < 2 or seen[-1] != ("write", (1, 3)):
        seen.append((next(work), op._at[:2]))
    assert action_of(objs[0]) is not before[objs[0].name][0] and scene.frame_end > 50  # the first was written
    work.close()
    assert unchanged(objs, before) and (scene.frame_start, scene.frame_end) == (5, 50)
    assert {o.name: action_of(o).use_fake_user for o in objs} == fake
    made = addon_module(addon, "strnn_addon.stages.common").run(Extend().work(bpy.context))
    assert [obj for obj, _ in made] == [objs[0], *sorted(objs[1:], key=lambda o: o.name)]
    assert all(action_of(obj) is new and new is not before[obj.name][0] for obj, new in made)


@pytest.mark.parametrize("op, kw, suffix", [
    ("denoise_action", {}, "denoised"),
    ("foot_lock", {}, "footlocked"),
    ("inbetween", {"use_range": True, "frame_start": 24, "frame_end": 35}, "filled"),
])
def test_other_operations_run_on_every_selected_armature(tmp_path, model_calls, addon, op, kw, suffix):
    objs = walkers(tmp_path)
    before = snapshot(objs)
    assert getattr(bpy.ops.strnn, op)(**kw) == {"FINISHED"}
    for obj in objs:
        new = action_of(obj)
        assert new is not before[obj.name][0] and suffix in new.name, (op, obj.name, new.name)
        assert new[RECORD]["source_action"] == before[obj.name][0].name
        assert same_keys(before[obj.name][1], key_snapshot(obj, before[obj.name][0]))


def test_in_pose_mode_every_armature_in_it_runs(tmp_path, model_calls, addon):
    """Pose mode on several armatures at once (Blender's multi-object editing) takes them all."""
    objs = walkers(tmp_path, (60, 80))
    bpy.ops.object.mode_set(mode="POSE")
    assert {o.name for o in bpy.context.objects_in_mode} == {o.name for o in objs}
    before = snapshot(objs)
    assert bpy.ops.strnn.extend_clip(frames=12) == {"FINISHED"}
    assert bpy.context.mode == "POSE"
    for obj, last in zip(objs, (60, 80)):
        assert action_of(obj) is not before[obj.name][0] and action_of(obj).frame_range[1] == last + 12


def test_transfer_with_a_source_named_puts_its_motion_on_every_selected_armature(tmp_path, model_calls, addon):
    """One take moved onto a cast: with Source named, each selected armature but the source gets the take's motion
    on its own proportions, from where it stands (here a Mixamo rig and a MakeHuman rig with no action yet, and the
    source itself selected too); without Source, three selected armatures do not say which is the source."""
    source = import_bvh(walk_bvh(tmp_path, frames=50))
    mixamo = build_armature("Mixamo", mixamo_bones())
    human = makehuman_walk(20)
    mixamo.location, human.location = (3.0, 0.0, 0.0), (-3.0, 0.0, 0.0)
    for obj in (source, mixamo, human):
        obj.select_set(True)
    bpy.context.view_layer.objects.active = mixamo
    with pytest.raises(RuntimeError, match="Select the armature to take the motion from"):
        bpy.ops.strnn.transfer_motion()
    played = evaluated_joints(addon, source, np.arange(1, 51))
    assert bpy.ops.strnn.transfer_motion(source=source.name, foot_lock=False) == {"FINISHED"}
    for obj, x in ((mixamo, 3.0), (human, -3.0)):
        new = action_of(obj)
        assert new[RECORD]["operation"] == "Transfer Motion" and new[RECORD]["settings"]["source"] == source.name
        joints = evaluated_joints(addon, obj, np.arange(1, 51))
        travel = joints[-1, 0] - joints[0, 0]
        want = played[-1, 0] - played[0, 0]
        assert np.linalg.norm(travel - want) < 0.25 * np.linalg.norm(want), (obj.name, travel, want)
        assert abs(joints[0, 0, 0] - x) < 0.3  # from where it stands
    assert action_of(source).name == "walk" and not action_of(source).get(RECORD)
