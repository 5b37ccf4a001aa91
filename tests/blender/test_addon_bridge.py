"""The add-on's one door to the model (``engine_bridge``): a redo or a second run on the same frames takes
the kept model result instead of running the model again, and the Threads preference holds only for the
length of a model call."""

from __future__ import annotations

import bpy
import pytest
from scenes import action_of, addon_module, import_bvh, key_snapshot, same_keys, walk_bvh


def counted(monkeypatch, module, name: str) -> list:
    """Count the calls to ``module.name`` (the real function still runs)."""
    calls, real = [], getattr(module, name)

    def spy(*args, **kw):
        calls.append(args)
        return real(*args, **kw)

    monkeypatch.setattr(module, name, spy)
    return calls


def test_a_redo_of_what_follows_the_model_does_not_run_it_again(addon, tmp_path, real_model, monkeypatch):
    bridge = addon_module(addon, "strnn_addon.engine_bridge")
    monkeypatch.setattr(bridge, "_RESULTS", type(bridge._RESULTS)())
    extends = counted(monkeypatch, bridge, "extend_positions")
    denoises = counted(monkeypatch, bridge, "denoise_positions_steps")
    obj = import_bvh(walk_bvh(tmp_path, frames=60))
    source = action_of(obj)
    assert bpy.ops.strnn.extend_clip(frames=20) == {"FINISHED"}
    first = key_snapshot(obj)
    for options in ({"simplify": 0.5}, {"foot_lock": True}, {"output": "NLA"}, {}):  # as the redo panel does
        obj.animation_data.action = source
        assert bpy.ops.strnn.extend_clip(frames=20, **options) == {"FINISHED"}
    assert len(extends) == 1
    assert same_keys(first, key_snapshot(obj))  # the last run, with the first's options, made the same keys
    obj.animation_data.action = source
    assert bpy.ops.strnn.extend_clip(frames=25) == {"FINISHED"}  # another input: the model runs
    assert len(extends) == 2
    for _ in range(2):
        obj.animation_data.action = source
        assert bpy.ops.strnn.denoise_action(simplify=0.2) == {"FINISHED"}
    assert len(denoises) == 1


def test_the_threads_preference_holds_only_during_a_model_call(addon, tmp_path, real_model):
    torch = pytest.importorskip("torch")
    prefs = bpy.context.preferences.addons[addon.__name__].preferences
    before = torch.get_num_threads()
    prefs.engine, prefs.threads = "TORCH", max(1, before - 1) if before > 1 else 2
    try:
        import_bvh(walk_bvh(tmp_path, frames=60))
        seen = []
        bridge = addon_module(addon, "strnn_addon.engine_bridge")
        real = bridge.extend_positions
        bridge.extend_positions = lambda *a: (seen.append(torch.get_num_threads()), real(*a))[1]
        try:
            assert bpy.ops.strnn.extend_clip(frames=12) == {"FINISHED"}
        finally:
            bridge.extend_positions = real
        assert seen == [prefs.threads] and torch.get_num_threads() == before
    finally:
        prefs.engine, prefs.threads = "NUMPY", 0
