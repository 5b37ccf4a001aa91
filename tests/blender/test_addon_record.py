"""Every new action records how it was made (custom property ``strnn``): the operation, the
extension's version, the action it came from, the model folder and the settings."""

from __future__ import annotations

import tomllib

import bpy
import pytest
from scenes import REPO, action_of, addon_module, import_bvh, walk_bvh

VERSION = tomllib.loads((REPO / "blender_manifest.toml").read_text())["version"]


def record(obj) -> dict:
    return action_of(obj)["strnn"].to_dict()


def test_extend_then_denoise_then_lock(addon, tmp_path, real_model):
    obj = import_bvh(walk_bvh(tmp_path, frames=60))
    source = action_of(obj)
    need = addon_module(addon, "strnn_addon.scene.pipeline").min_scene_frames(bpy.context.scene.render.fps)
    assert bpy.ops.strnn.extend_clip(frames=30, foot_lock=True) == {"FINISHED"}
    assert "strnn" not in source  # the original is left as it was
    made = record(obj)
    assert set(made.pop("familiarity")) >= {"reconstruction_cm", "usual_cm_p90"}
    assert made == {"operation": "Extend Clip", "version": VERSION, "source_action": "walk",
                    "model": str(real_model),
                    "settings": {"frames": 30, "context_frames": need, "follow_clip_frames": 60, "foot_lock": True},
                    "keys_per_second": 24.0, "frames_written": [61, 90]}
    extended = action_of(obj).name
    assert bpy.ops.strnn.denoise_action(strength=0.5, use_range=True, frame_start=5, frame_end=70) == {"FINISHED"}
    denoised = record(obj)
    assert denoised["operation"] == "Denoise Action" and denoised["source_action"] == extended
    assert set(denoised["familiarity"]) >= {"reconstruction_cm", "usual_cm_p90"}  # judged on the denoised motion
    assert denoised["model"].endswith("strnn_denoise")  # the bundled denoising model
    assert denoised["settings"] == {"frame_start": 5, "frame_end": 70, "strength": 0.5, "foot_lock": False,
                                    "only_selected": False}
    assert bpy.ops.strnn.foot_lock(blend=0.2) == {"FINISHED"}
    locked = record(obj)
    assert locked["operation"] == "Foot Lock" and "model" not in locked
    assert locked["settings"] == {"frame_start": 1, "frame_end": 90, "blend": pytest.approx(0.2),
                                  "only_selected": False}
