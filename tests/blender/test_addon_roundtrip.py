"""Positions-to-rotations solve on real clips imported with Blender's BVH importer:
solving the rig's own joint positions from a HELD reference pose (the first frame, not
the original frames) and keying the result reproduces the mapped joints within 1 cm."""

from __future__ import annotations

import importlib

import bpy
import numpy as np
import pytest
from scenes import action_of, evaluated_joints, find_mocap, import_bvh

from model_core.motion.conventions import STANDARD_LEG_LENGTH
from model_core.rig.rigs import leg_length

CLIPS = {
    "bandai_namco": "bandai-namco/dataset-2/dataset-2_walk_normal_001.bvh",
    "iclone_cc_base": "cmu/iclone/002_01.bvh",
    "acrnn": "cmu/acrnn-dance/salsa/01.bvh",
    "cmu_cgspeed": "cmu/cgspeed/tmoco_02_01.bvh",
}
MAX_FRAMES = 90


@pytest.mark.parametrize("family", sorted(CLIPS))
def test_solve_round_trip_real_clip(addon, family):
    root = find_mocap()
    if root is None or not (root / CLIPS[family]).exists():
        pytest.skip("motion capture not unpacked (data/mocap or ../shared/mocap)")
    obj = import_bvh(root / CLIPS[family], update_scene_fps=True)
    pkg = addon.__name__
    pipeline = importlib.import_module(pkg + ".strnn_addon.scene.pipeline")
    rig_io = importlib.import_module(pkg + ".strnn_addon.scene.rig_io")
    solve = importlib.import_module(pkg + ".model_core.rig.solve")
    clip = pipeline.prepare(bpy.context, obj)
    assert clip.mapping and len(clip.mapping) == 21
    frames = np.arange(clip.first, min(clip.last, clip.first + MAX_FRAMES - 1) + 1, dtype=np.float64)
    pos = pipeline.joint_positions(bpy.context, clip, frames)
    # Reference: bones the solve sets hold their first-frame pose; the others keep their own
    # animation (the new action keeps their keys).
    ref_loc, ref_rot, _ = rig_io.read_local_pose(obj, clip.rig, clip.channels.fcurves, frames)
    solved = pipeline.written_bones(clip)
    ref_loc[:, solved], ref_rot[:, solved] = ref_loc[:1, solved], ref_rot[:1, solved]
    loc, rot = solve.solve(clip.rig, clip.anchors, pipeline.to_armature(clip, pos), ref_loc, ref_rot)
    new = pipeline.new_action_from(clip, "roundtrip")
    drive = importlib.import_module(pkg + ".model_core.inference.steps").drive
    drive(pipeline.write_pose(bpy.context, clip, new, frames, loc, rot, {}, (frames[0], frames[-1])))
    pipeline.finish(bpy.context, clip, new)
    assert action_of(obj) == new
    conv = importlib.import_module(pkg + ".model_core.motion.conventions")
    got = conv.zup_to_yup(evaluated_joints(addon, obj, frames))
    to_metres = STANDARD_LEG_LENGTH / leg_length(pos)
    err_cm = np.linalg.norm(got - pos, axis=-1) * to_metres * 100
    print(f"{family}: mean {err_cm.mean():.3f} cm, max {err_cm.max():.3f} cm", err_cm.mean(0).round(2))
    assert err_cm.mean() < 1.0
