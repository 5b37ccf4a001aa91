"""Preferences > Install PyTorch: refused offline, the pip command it runs, the folder on sys.path.

Nothing is downloaded: pip is replaced by a stand-in wherever the operator would run it.
"""

from __future__ import annotations

import importlib
import os
import subprocess
import sys

import bpy
import pytest


@pytest.fixture
def inst(addon):
    return importlib.import_module(addon.__name__ + ".strnn_addon.torch_install")


@pytest.fixture
def pip_calls(inst, monkeypatch):
    calls = []

    def run(cmd):
        calls.append(cmd)
        return subprocess.CompletedProcess(cmd, 0, "Successfully installed torch-2.13.0\n", "")

    monkeypatch.setattr(inst, "_run", run)
    return calls


class Recorder:
    def __init__(self, calls):
        self.calls = calls

    def __getattr__(self, name):
        def call(*args, **kw):
            self.calls.append((name, args, kw))
            return Recorder(self.calls)

        return call


def drawn(inst) -> list:
    calls = []
    inst.draw_preferences(Recorder(calls))
    return calls


def test_install_command(inst):
    assert inst.install_command("/some/dir") == [sys.executable, "-m", "pip", "install", "--target", "/some/dir",
                                                 "torch==2.13.0"]
    assert inst.install_command("/d", python="/blender/python")[0] == "/blender/python"
    folder = inst.site_packages()
    assert folder.endswith(os.path.join(".user", "strnn_test", "strnn_motion", "site-packages"))


def test_refused_offline(inst, pip_calls, monkeypatch):
    assert bpy.app.online_access is False  # the bpy module runs offline
    folder = inst.site_packages()
    existed, path = os.path.exists(folder), list(sys.path)
    with pytest.raises(RuntimeError, match=r"Online access is off: allow it in Preferences > System"):
        bpy.ops.strnn.install_torch()
    assert pip_calls == [] and sys.path == path and os.path.exists(folder) == existed


def test_install_runs_pip_into_user_folder(inst, pip_calls, monkeypatch, tmp_path):
    target = tmp_path / "site-packages"
    monkeypatch.setattr(inst, "online_access", lambda: True)
    monkeypatch.setattr(inst, "site_packages", lambda create=False: (target.mkdir(exist_ok=True), str(target))[1])
    try:
        assert bpy.ops.strnn.install_torch() == {"FINISHED"}
        assert pip_calls == [inst.install_command(str(target))]
        assert str(target) in sys.path
    finally:
        inst.remove_from_path()
    assert str(target) not in sys.path


def test_install_failure_reported(inst, monkeypatch, tmp_path):
    monkeypatch.setattr(inst, "online_access", lambda: True)
    monkeypatch.setattr(inst, "site_packages", lambda create=False: str(tmp_path))
    monkeypatch.setattr(inst, "_run", lambda cmd: subprocess.CompletedProcess(
        cmd, 1, "", "Collecting torch==2.13.0\nERROR: No matching distribution found for torch==2.13.0\n"))
    path = list(sys.path)
    with pytest.raises(RuntimeError, match="Installing PyTorch failed: ERROR: No matching distribution"):
        bpy.ops.strnn.install_torch()
    assert sys.path == path


def test_folder_on_path_at_register(inst, monkeypatch, tmp_path):
    monkeypatch.setattr(inst, "site_packages", lambda create=False: str(tmp_path))
    try:
        inst.add_to_path()
        assert sys.path.count(str(tmp_path)) == 1
        inst.add_to_path()
        assert sys.path.count(str(tmp_path)) == 1
    finally:
        inst.remove_from_path()
    assert str(tmp_path) not in sys.path


def test_preferences_button_only_online(inst, monkeypatch):
    monkeypatch.setattr(inst, "torch_available", lambda: False)
    offline = drawn(inst)
    assert not [c for c in offline if c[0] == "operator"]
    assert any("Online access is off" in c[2].get("text", "") for c in offline if c[0] == "label")
    monkeypatch.setattr(inst, "online_access", lambda: True)
    online = drawn(inst)
    assert [c[1][0] for c in online if c[0] == "operator"] == ["strnn.install_torch"]
    monkeypatch.setattr(inst, "torch_available", lambda: True)
    assert not [c for c in drawn(inst) if c[0] == "operator"]


def test_preferences_draw(addon):
    prefs = bpy.context.preferences.addons[addon.__name__].preferences
    calls = []
    type(prefs).draw(type("Fake", (), {"layout": Recorder(calls), "model_folder": "", "engine": "NUMPY",
                                       "threads": 0})(), bpy.context)
    assert any(c[0] == "box" for c in calls)
