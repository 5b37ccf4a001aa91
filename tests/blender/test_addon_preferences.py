"""Preferences: which model each operation uses and its licence, shown before anything runs."""

from __future__ import annotations

import importlib
import importlib.util

import bpy


class Recorder:
    def __init__(self, calls):
        self.calls = calls

    def __getattr__(self, name):
        def call(*args, **kw):
            self.calls.append((name, args, kw))
            return Recorder(self.calls)

        return call


def test_preferences_draw(addon):
    prefs = bpy.context.preferences.addons[addon.__name__].preferences
    calls = []
    type(prefs).draw(type("Fake", (), {"layout": Recorder(calls), "model_folder": "", "denoise_model_folder": "",
                                       "engine": "NUMPY", "threads": 0})(), bpy.context)
    assert any(c[0] == "box" for c in calls)
    labels = [c[2].get("text", "") for c in calls if c[0] == "label"]
    assert "Extend, Follow Curve: strnn_default" in labels and "Denoise: strnn_denoise" in labels
    assert labels.count("Non-commercial use only (its training data's licence)") == 2
    assert any(text.startswith("Licence: CC BY-NC 4.0") for text in labels)
    assert not [c for c in calls if c[0] == "operator"]  # nothing to install: the extension needs only Blender


def test_preferences_name_a_missing_model(addon, tmp_path):
    calls = []
    prefs = type("Fake", (), {"model_folder": str(tmp_path), "denoise_model_folder": str(tmp_path)})()
    importlib.import_module(addon.__name__ + ".strnn_addon.props").draw_models(Recorder(calls), prefs)
    labels = [c[2].get("text", "") for c in calls if c[0] == "label"]
    assert labels == ["Extend, Follow Curve: no model in the Model Folder",
                      "Denoise: no model in the Denoise Model Folder"]


def test_reading_the_engine_setting_does_not_import_torch(addon, monkeypatch):
    """The Engine choice lists PyTorch where it is installed, found without importing it: reading the
    setting (every model call does) must not load PyTorch into a Blender that runs the model with NumPy."""
    import builtins

    imported = []
    real_import = builtins.__import__

    def watch(name, *args, **kwargs):
        imported.append(name)
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", watch)
    prefs = bpy.context.preferences.addons[addon.__name__].preferences
    assert prefs.engine == "NUMPY"
    items = {item[0] for item in importlib.import_module(addon.__name__ + ".strnn_addon.props")._engines(prefs, None)}
    monkeypatch.undo()
    assert not [name for name in imported if name.split(".")[0] == "torch"], imported
    assert ("TORCH" in items) == (importlib.util.find_spec("torch") is not None)
