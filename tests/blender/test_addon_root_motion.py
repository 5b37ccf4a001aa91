"""Root motion: a game rig whose root bone (above the hips, as Unreal's ``root``) carries the action's travel over
the ground. Extend Clip carries the root on with the body over the new frames, keyed, so that an engine reading the
root's motion moves the character on; a root the action does not move is left unkeyed, as before."""

from __future__ import annotations

import bpy
import numpy as np
import pytest
from scenes import (
    action_of,
    build_armature,
    evaluated_joints,
    fcurves_of,
    key_snapshot,
    key_walk,
    mixamo_bones,
    same_keys,
)

STEP = 0.02  # metres a frame the walk travels


def root_rig(frames: int = 60, travel: bool = True):
    """A Mixamo-named body under a ``root`` bone on the floor (pointing along +Y), with a crude walk: the legs and arms
    swing, the hips sway, and the root carries the travel along -Y, the way the body faces (``travel`` False: the
    hips carry it, the root stays)."""
    bones = [("root", None, (0.0, 0.0, 0.0), (0.0, 0.3, 0.0))]
    bones += [(n, p or "root", h, t) for n, p, h, t in mixamo_bones()]
    obj = build_armature("RootRig", bones)
    n = lambda *names: tuple("mixamorig:" + x for x in names)  # noqa: E731
    key_walk(obj, frames, "mixamorig:Hips", n("LeftUpLeg", "RightUpLeg"), n("LeftLeg", "RightLeg"),
             n("LeftArm", "RightArm"), step=0.0 if travel else STEP)
    root = obj.pose.bones["root"]
    for f in range(1, frames + 1) if travel else ():
        root.location = (0.0, -STEP * f, 0.0)  # the root points along +Y: its location is the world's
        root.keyframe_insert("location", frame=f)
    bpy.context.scene.frame_set(1)
    return obj


def root_heads(obj, frames) -> np.ndarray:
    scene, out = bpy.context.scene, []
    for f in frames:
        scene.frame_set(int(f))
        out.append(np.array(obj.matrix_world @ obj.pose.bones["root"].head))
    return np.array(out)


def test_extend_carries_a_moving_root_on_under_the_body(addon, model_calls, capfd):
    obj = root_rig()
    assert np.ptp(root_heads(obj, [1, 60])[:, 1]) > 1.0  # the root carries the walk
    before = key_snapshot(obj)
    old_joints = evaluated_joints(addon, obj, np.arange(1, 61))
    capfd.readouterr()
    assert bpy.ops.strnn.extend_clip(frames=30) == {"FINISHED"}
    assert "the root 'root' carries the travel, keyed with the body" in capfd.readouterr().out
    new = action_of(obj)
    assert same_keys(before, key_snapshot(obj, bpy.data.actions[new["strnn"]["source_action"]]))
    assert new["strnn"]["root_motion"].to_dict() == {"bone": "root"}
    keyed = {fc.data_path for fc in fcurves_of(obj, new)
             if any(k.co[0] > 60.5 for k in fc.keyframe_points)}
    assert {'pose.bones["root"].location', 'pose.bones["root"].rotation_quaternion'} <= keyed
    np.testing.assert_allclose(evaluated_joints(addon, obj, np.arange(1, 61)), old_joints, atol=1e-5)
    # the body goes on as the model puts it, and the root goes on with it, still under it
    joints = evaluated_joints(addon, obj, np.arange(59, 91))
    assert np.linalg.norm(joints[2:] - model_calls.extended(), axis=-1).max() < 0.01
    roots = root_heads(obj, np.arange(60, 91))
    assert np.all(np.diff(roots[:, 1]) < -0.5 * STEP)  # on along -Y, every frame
    under = (roots[:, :2] - joints[1:, 0, :2]) - (roots[0, :2] - joints[1, 0, :2])
    # where it stood against the hips at the clip's end, within their sway (2 cm each way), which stays off the root
    assert np.linalg.norm(under, axis=-1).max() < 0.05
    assert np.abs(roots[:, 2] - roots[0, 2]).max() < 1e-6  # on the floor


def test_a_root_the_action_does_not_move_is_not_keyed(addon, model_calls):
    obj = root_rig(travel=False)
    assert bpy.ops.strnn.extend_clip(frames=30) == {"FINISHED"}
    new = action_of(obj)
    assert "root_motion" not in new["strnn"]
    assert not [fc for fc in fcurves_of(obj, new) if fc.data_path.startswith('pose.bones["root"]')]


def as_root_motion(addon, obj, root: str = "root") -> None:
    """Give ``obj`` (an imported take, its hips bone the top) a root bone on the floor and move the take's travel onto
    it, as a game engine's root-motion take has it: on every frame the root stands under the hips, turned as the
    body faces, and the hips are keyed against it so that the body plays as before."""
    from mathutils import Matrix

    hips = obj.pose.bones[0]
    action = obj.animation_data.action
    frames = np.arange(int(action.frame_range[0]), int(action.frame_range[1]) + 1)
    joints = evaluated_joints(addon, obj, frames)  # Blender world axes
    facing = np.cross(joints[:, 1] - joints[:, 5], [0.0, 0.0, 1.0])  # square to the thighs: left x up
    yaw = np.arctan2(facing[:, 1], facing[:, 0])
    scene, inv = bpy.context.scene, np.array(obj.matrix_world.inverted())
    played = []
    for f in frames:
        scene.frame_set(int(f))
        played.append(hips.matrix.copy())
    bpy.ops.object.mode_set(mode="EDIT")
    eb = obj.data.edit_bones.new(root)
    eb.head, eb.tail = (0.0, 0.0, 0.0), (0.0, 10.0, 0.0)
    obj.data.edit_bones[hips.name].parent = eb
    bpy.ops.object.mode_set(mode="OBJECT")
    hips, pbr = obj.pose.bones[hips.name], obj.pose.bones[root]
    pbr.rotation_mode = hips.rotation_mode = "QUATERNION"
    for k, f in enumerate(frames):
        scene.frame_set(int(f))
        under = inv @ np.r_[joints[k, 0, :2], 0.0, 1.0]  # the hips' place on the floor, in the armature's space
        pbr.matrix = Matrix.Translation(under[:3].tolist()) @ Matrix.Rotation(float(yaw[k] - yaw[0]), 4, "Z")
        bpy.context.view_layer.update()
        hips.matrix = played[k]
        for pb in (pbr, hips):
            pb.keyframe_insert("location", frame=int(f))
            pb.keyframe_insert("rotation_quaternion", frame=int(f))
    scene.frame_set(int(frames[0]))


def test_a_real_walk_with_root_motion_extended_by_the_model_takes_its_root_along(addon, real_model, tmp_path):
    """A walk (real motion capture when unpacked) made a root-motion take, extended 3 s by the bundled model: the
    root goes on under the body at the body's pace and turns as it faces."""
    from scenes import import_bvh, walk_bvh
    from test_addon_rigify import WALK, find_mocap

    mocap = find_mocap()
    path = mocap / WALK if mocap is not None and (mocap / WALK).exists() else walk_bvh(tmp_path, frames=120)
    obj = import_bvh(path, update_scene_fps=True, update_scene_duration=True)
    as_root_motion(addon, obj)
    last = int(action_of(obj).frame_range[1])
    played = evaluated_joints(addon, obj, np.arange(1, last + 1))
    fps = bpy.context.scene.render.fps
    assert bpy.ops.strnn.extend_clip(frames=3 * fps) == {"FINISHED"}
    new = action_of(obj)
    assert new["strnn"]["root_motion"]["bone"] == "root"
    np.testing.assert_allclose(evaluated_joints(addon, obj, np.arange(1, last + 1)), played, atol=1e-4)
    frames = np.arange(last, last + 3 * fps + 1)
    joints, roots = evaluated_joints(addon, obj, frames), root_heads(obj, frames)
    hips_way = np.linalg.norm(joints[-1, 0, :2] - joints[0, 0, :2])
    root_way = np.linalg.norm(roots[-1, :2] - roots[0, :2])
    under = np.linalg.norm(roots[:, :2] - joints[:, 0, :2], axis=-1)
    print(f"root motion: the hips go {hips_way:.2f}, the root {root_way:.2f}; the root {under.max():.3f} at most "
          "from under the hips")
    height = np.ptp(played[:, :, 2])
    assert hips_way > height and 0.8 < root_way / hips_way < 1.2  # on at the body's pace
    assert under.max() < 0.1 * height  # under the body: within a tenth of its height


def test_follow_curve_takes_a_moving_root_along_the_curve(addon, real_model):
    from test_addon_curve import add_curve, follow

    obj = root_rig(frames=60)
    path = add_curve("poly", points=[(0.0, -1.2, 0.0), (3.0, -4.0, 0.0)])
    bpy.context.view_layer.objects.active = obj
    _, new = follow(curve=path.name)
    assert new["strnn"]["root_motion"]["bone"] == "root"
    frames = np.arange(60, int(new.frame_range[1]) + 1)
    joints, roots = evaluated_joints(addon, obj, frames), root_heads(obj, frames)
    under = np.linalg.norm(roots[:, :2] - joints[:, 0, :2], axis=-1)
    assert np.linalg.norm(roots[-1, :2] - roots[0, :2]) > 2.0 and under.max() < 0.15, under.max()


def test_frames_before_the_start_take_the_root_back_with_the_body(addon, model_calls):
    obj = root_rig()
    bpy.context.scene.frame_start = 1
    assert bpy.ops.strnn.extend_clip(frames=30, before_start=True) == {"FINISHED"}
    new = action_of(obj)
    assert new["strnn"]["root_motion"]["bone"] == "root"
    frames = np.arange(-29, 2)
    joints, roots = evaluated_joints(addon, obj, frames), root_heads(obj, frames)
    assert np.all(np.diff(roots[:, 1]) < -0.5 * STEP)  # it walked in along -Y
    under = (roots[:, :2] - joints[:, 0, :2]) - (roots[-1, :2] - joints[-1, 0, :2])
    assert np.linalg.norm(under, axis=-1).max() < 0.05


def game_rig_and_walk(path):
    """(source, target): the walk at ``path`` imported 2 m aside, and a game rig (the Mixamo body under a ``root`` bone
    on the floor), both selected, the rig active, ready for Transfer Motion."""
    from scenes import import_bvh

    source = import_bvh(path, update_scene_fps=True, update_scene_duration=True)
    source.location.x = -2.0
    bones = [("root", None, (0.0, 0.0, 0.0), (0.0, 0.3, 0.0))]
    bones += [(n, p or "root", h, t) for n, p, h, t in mixamo_bones()]
    target = build_armature("GameRig", bones)
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in (source, target))
    bpy.context.view_layer.objects.active = target
    return source, target


def test_transfer_with_root_motion_keys_the_travel_on_the_targets_root(addon, tmp_path):
    """A walk moved onto a game rig (a root bone on the floor above its hips) with Root Motion: the root goes with the
    body, on the floor under it, turned as it faces, and the hips move against it; without Root Motion the root is
    not keyed. A rig with no bone above its hips is refused with what to do, and nothing changes."""
    from scenes import walk_bvh
    from test_addon_rigify import WALK, find_mocap

    mocap = find_mocap()
    path = mocap / WALK if mocap is not None and (mocap / WALK).exists() else walk_bvh(tmp_path, frames=120)
    source, target = game_rig_and_walk(path)
    assert bpy.ops.strnn.transfer_motion(root_motion=True) == {"FINISHED"}
    new = action_of(target)
    assert new["strnn"]["root_motion"].to_dict() == {"bone": "root"}
    frames = np.arange(int(new.frame_range[0]), int(new.frame_range[1]) + 1)
    joints, roots = evaluated_joints(addon, target, frames), root_heads(target, frames)
    assert np.linalg.norm(roots[-1, :2] - roots[0, :2]) > 1.0  # it travels
    assert np.linalg.norm(roots[:, :2] - joints[:, 0, :2], axis=-1).max() < 0.15  # under the body
    assert np.abs(roots[:, 2]).max() < 1e-6  # on the floor
    scene, ahead = bpy.context.scene, []
    for f in frames:  # the root's +Y, its own forward at rest
        scene.frame_set(int(f))
        ahead.append(np.array(target.pose.bones["root"].matrix.col[1][:3]))
    ahead, facing = np.array(ahead), np.cross(joints[:, 1] - joints[:, 5], [0.0, 0.0, 1.0])
    angle = lambda v: np.unwrap(np.arctan2(v[:, 1], v[:, 0]))  # noqa: E731
    half = bpy.context.scene.render.fps // 2  # the body's facing sways with each step: half a second's mean
    body_turn = angle(facing)[-half:].mean() - angle(facing)[:half].mean()
    assert abs((angle(ahead)[-1] - angle(ahead)[0]) - body_turn) < 0.2, body_turn  # it turns as the body does
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in (source, target))
    assert bpy.ops.strnn.transfer_motion(root_motion=False) == {"FINISHED"}
    assert not [fc for fc in fcurves_of(target, action_of(target)) if fc.data_path.startswith('pose.bones["root"]')]

    plain = build_armature("Plain", mixamo_bones())
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj in (source, plain))
    bpy.context.view_layer.objects.active = plain
    with pytest.raises(RuntimeError, match="hips bone 'mixamorig:Hips' has none: add a root bone"):
        bpy.ops.strnn.transfer_motion(root_motion=True)
    assert action_of(plain) is None


def test_make_loop_carries_the_root_with_the_cycle_and_in_place_keeps_it_still(addon, real_model):
    """A root-motion walk made a cycle: the root is keyed with the cycle and walks on with it (Cycles modifiers)
    under the body; In Place keeps it where the cycle starts, with the body."""
    for in_place in (False, True):
        obj = root_rig(frames=90)
        assert bpy.ops.strnn.make_loop(in_place=in_place) == {"FINISHED"}
        new = action_of(obj)
        assert new["strnn"]["root_motion"]["bone"] == "root"
        first, seam = new["strnn"]["cycle"]["first"], new["strnn"]["cycle"]["seam"]
        frames = np.arange(first, 2 * seam - first + 1)  # the cycle and its first repeat
        joints, roots = evaluated_joints(addon, obj, frames), root_heads(obj, frames)
        way = np.linalg.norm(roots[-1, :2] - roots[0, :2])
        under = np.linalg.norm(roots[:, :2] - joints[:, 0, :2], axis=-1)
        if in_place:
            assert way < 0.02 and np.linalg.norm(joints[-1, 0, :2] - joints[0, 0, :2]) < 0.05, way
        else:
            assert way > 0.5 and np.ptp(under) < 0.06, (way, np.ptp(under))
        bpy.data.objects.remove(obj)


def test_a_root_that_only_rises_carries_no_travel(addon, model_calls):
    obj = root_rig(travel=False)
    root = obj.pose.bones["root"]
    for f in range(1, 61):  # the root bobs up and down (pointing along +Y, its local Z is the world's)
        root.location = (0.0, 0.0, 0.3 * np.sin(f / 5.0))
        root.keyframe_insert("location", frame=f)
    heights = root_heads(obj, range(1, 61))
    assert np.ptp(heights[:, 2]) > 0.3 and np.ptp(heights[:, 0]) + np.ptp(heights[:, 1]) < 1e-6
    assert bpy.ops.strnn.extend_clip(frames=30) == {"FINISHED"}
    assert "root_motion" not in action_of(obj)["strnn"]


def test_a_root_carried_over_a_ground_rides_it_with_the_body(addon, tmp_path):
    """Transfer Motion with Root Motion and a Ground (a ramp rising 15 cm a metre the way the walk goes): the root
    goes up the ramp with the body, by as much as the body is carried up (within 5 cm of the ramp under it, 3.6 cm
    at the ends, where the body's ride is smoothed; it kept the floor's height before), and stays under the body."""
    from scenes import ramp, walk_bvh

    _, target = game_rig_and_walk(walk_bvh(tmp_path, frames=120))
    assert bpy.ops.strnn.transfer_motion(root_motion=True) == {"FINISHED"}
    frames = np.arange(int(action_of(target).frame_range[0]), int(action_of(target).frame_range[1]) + 1)
    flat = evaluated_joints(addon, target, frames)
    start, travel = flat[0, 0], flat[-1, 0] - flat[0, 0]  # the ramp rises the way the walk goes (given Y-up)
    height = ramp("Ramp", [start[0], 0.0, -start[1]], [travel[0], 0.0, -travel[1]], 0.15)
    target.animation_data.action = None
    for pb in target.pose.bones:
        pb.matrix_basis.identity()
    assert bpy.ops.strnn.transfer_motion(root_motion=True, ground="Ramp") == {"FINISHED"}
    joints, roots = evaluated_joints(addon, target, frames), root_heads(target, frames)
    under = height(np.stack([roots[:, 0], roots[:, 2], -roots[:, 1]], -1))  # the ramp's height under the root
    assert roots[-1, 2] > 0.15 * np.linalg.norm(travel[:2]) * 0.8  # up the ramp
    print(f"root over the ramp under it: {100 * np.abs(roots[:, 2] - under).max():.2f} cm at most")
    assert np.abs(roots[:, 2] - under).max() < 0.05, np.abs(roots[:, 2] - under).max()
    assert np.linalg.norm(roots[:, :2] - joints[:, 0, :2], axis=-1).max() < 0.15  # under the body


def connected_root_bvh(folder, frames: int = 90):
    """A walk written as Character Creator writes a take (``RL_BoneRoot`` on the floor, position channels only, with
    the hips its one child 0.9 m up): Blender's importer puts the root's tail on the hips and connects them."""
    from scenes import walk_bvh

    head, motion = walk_bvh(folder, frames=frames).read_text().split("MOTION")
    lines = head.splitlines()
    at = next(i for i, line in enumerate(lines) if line.startswith("ROOT"))
    offset = np.array(lines[at + 2].split()[1:], float) + [0.0, 0.9, 0.0]
    lines[at:at + 4] = ["ROOT RL_BoneRoot", "{", "  OFFSET 0.0 0.0 0.0", "  CHANNELS 3 Xposition Yposition Zposition",
                        "  JOINT " + lines[at].split()[1], "  {", "  OFFSET {:.6f} {:.6f} {:.6f}".format(*offset),
                        "  CHANNELS 3 " + " ".join(lines[at + 3].split()[5:])]
    lines.insert(len(lines), "}")
    header, values = motion.strip().split("\n", 2)[:2], motion.strip().split("\n", 2)[2].splitlines()
    rows = [np.array(v.split(), float) for v in values]
    out = [" ".join(f"{x:.6f}" for x in np.r_[r[:3] - [0.0, 0.9, 0.0], r[3:]]) for r in rows]
    path = folder / "rooted.bvh"
    path.write_text("\n".join(lines) + "\nMOTION\n" + "\n".join(header + out) + "\n")
    return path


@pytest.mark.parametrize("operation", ["extend", "extend_baked", "denoise", "fill_gap"])
def test_hips_connected_to_a_root_bone_play_where_the_model_put_them(addon, model_calls, tmp_path, operation):
    """A take whose root is a bone on the floor with the hips its one child (Character Creator's and iClone's BVH)
    imports with the hips connected to the root, where Blender leaves the hips' location out: Extend played a real
    take of that kind up to 4 cm from the model's (the root carried smoothly under the body, the hips' sway and bob
    lost with it). The root now takes the hips' place, and every joint plays where the model put it; so too where a
    forearm that does not inherit its parent's rotation has the pose set by the visual bake (3.2 cm off before)."""
    from scenes import import_bvh

    obj = import_bvh(connected_root_bvh(tmp_path), update_scene_fps=True, update_scene_duration=True)
    assert obj.data.bones["Hips"].use_connect and obj.data.bones["Hips"].parent.name == "RL_BoneRoot"
    if operation == "extend_baked":
        obj.data.bones["LeftForeArm"].use_inherit_rotation = False
    last = int(action_of(obj).frame_range[1])
    if operation.startswith("extend"):
        assert bpy.ops.strnn.extend_clip(frames=40) == {"FINISHED"}
        frames, made = np.arange(last + 1, last + 41), model_calls.extended()
    elif operation == "denoise":
        assert bpy.ops.strnn.denoise_action() == {"FINISHED"}
        frames, made = np.arange(1, last + 1), model_calls.denoised()
    else:
        assert bpy.ops.strnn.inbetween(use_range=True, frame_start=41, frame_end=60, foot_lock=False) == {"FINISHED"}
        frames, made = np.arange(41, 61), model_calls.blender(model_calls.inbetween[-1]["out"])
    err = np.linalg.norm(evaluated_joints(addon, obj, frames) - made, axis=-1)
    assert err.max() < 0.005, (err.max(), np.unravel_index(err.argmax(), err.shape))
    keyed = {fc.data_path for fc in fcurves_of(obj) if fc.data_path.endswith("location")}
    assert 'pose.bones["RL_BoneRoot"].location' in keyed and 'pose.bones["Hips"].location' not in keyed
