"""Preferences > Install PyTorch: refused offline, the pip command it runs, pip in the background
(status, cancel), only a finished install reaching the user folder, the folder on sys.path.

Nothing is downloaded: pip is replaced by ``fake_pip.py``, a real process that prints pip-like
lines and writes a small package into its ``--target``.
"""

from __future__ import annotations

import importlib
import os
import sys
import time
from pathlib import Path

import bpy
import pytest

FAKE_PIP = str(Path(__file__).with_name("fake_pip.py"))


@pytest.fixture
def inst(addon):
    return importlib.import_module(addon.__name__ + ".strnn_addon.torch_install")


@pytest.fixture
def fake_pip(inst, monkeypatch):
    """``fake_pip(*flags)`` makes the add-on run the stand-in with ``flags``; returns the targets pip got."""
    targets = []

    def use(*flags):
        def command(target, python=None):
            targets.append(target)
            return [sys.executable, FAKE_PIP, "--target", str(target), *flags]

        monkeypatch.setattr(inst, "install_command", command)
        return targets

    return use


@pytest.fixture
def user_folder(inst, monkeypatch, tmp_path):
    """An online Blender whose extension user folder is ``tmp_path/site-packages``."""
    target = tmp_path / "site-packages"
    target.mkdir()
    monkeypatch.setattr(inst, "online_access", lambda: True)
    monkeypatch.setattr(inst, "site_packages", lambda create=False: str(target))
    yield target
    inst.remove_from_path()


def leftovers(target: Path) -> list[str]:
    return [p.name for p in target.parent.iterdir() if p.name.startswith(".installing-")]


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
    plain = [sys.executable, "-m", "pip", "install", "--target", "/some/dir", "torch==2.13.0"]
    cpu = plain + ["--index-url", "https://download.pytorch.org/whl/cpu"]  # not PyPI's CUDA build
    assert inst.install_command("/some/dir", platform="linux") == cpu
    assert inst.install_command("/some/dir", platform="win32") == cpu
    assert inst.install_command("/some/dir", platform="darwin") == plain
    assert inst.install_command("/d", python="/blender/python")[0] == "/blender/python"
    folder = inst.site_packages()
    assert folder.endswith(os.path.join(".user", "strnn_test", "strnn_motion", "site-packages"))


def test_refused_offline(inst, fake_pip):
    targets = fake_pip()
    assert bpy.app.online_access is False  # the bpy module runs offline
    folder = inst.site_packages()
    existed, path = os.path.exists(folder), list(sys.path)
    with pytest.raises(RuntimeError, match=r"Online access is off: allow it in Preferences > System"):
        bpy.ops.strnn.install_torch()
    assert targets == [] and sys.path == path and os.path.exists(folder) == existed


def test_install_runs_pip_into_user_folder(inst, fake_pip, user_folder):
    targets = fake_pip()
    (user_folder / "strnn_fake_pkg").mkdir()
    (user_folder / "strnn_fake_pkg" / "old_module.py").write_text("# from an older install\n")
    assert bpy.ops.strnn.install_torch() == {"FINISHED"}
    # pip wrote into a scratch folder beside the user folder, which was moved in and removed
    assert len(targets) == 1 and Path(targets[0]).parent == user_folder.parent
    assert sorted(p.name for p in (user_folder / "strnn_fake_pkg").iterdir()) == ["__init__.py"]
    assert leftovers(user_folder) == []
    assert str(user_folder) in sys.path
    inst.remove_from_path()
    assert str(user_folder) not in sys.path


def test_install_failure_reported_and_nothing_installed(inst, fake_pip, user_folder):
    fake_pip("--fail")
    path = list(sys.path)
    with pytest.raises(RuntimeError, match="Installing PyTorch failed: ERROR: No matching distribution"):
        bpy.ops.strnn.install_torch()
    assert sys.path == path and list(user_folder.iterdir()) == [] and leftovers(user_folder) == []


def test_python_without_pip(inst, user_folder, monkeypatch):
    """Blender's Python may come without pip: the message says how to add it."""
    monkeypatch.setattr(inst, "install_command", lambda target, python=None: [
        sys.executable, "-c", "import sys; sys.exit(sys.executable + ': No module named pip')"])
    with pytest.raises(RuntimeError, match=r"No module named pip \(this Python has no pip: run '.*python.* -m "
                                           r"ensurepip' once, then try again\)"):
        bpy.ops.strnn.install_torch()
    assert list(user_folder.iterdir()) == [] and leftovers(user_folder) == []


def test_pip_missing_reported(inst, user_folder, monkeypatch):
    monkeypatch.setattr(inst, "install_command", lambda target, python=None: ["/no/such/python", "-m", "pip"])
    with pytest.raises(RuntimeError, match=r"Could not run pip .* run '/no/such/python -m pip' in a terminal"):
        bpy.ops.strnn.install_torch()
    assert leftovers(user_folder) == []


def test_background_install_reports_status_and_cancels(inst, fake_pip, user_folder, monkeypatch):
    fake_pip("--sleep", "30")
    job = inst.PipInstall(str(user_folder))
    try:
        assert job.poll()
        deadline = time.monotonic() + 20
        while "Downloading torch" not in job.status and time.monotonic() < deadline:
            time.sleep(0.05)
        assert job.status.startswith("Downloading torch-2.13.0")
        # while it runs: the preferences show its status and a Cancel button, and a second install is refused
        monkeypatch.setattr(inst, "_running", job)
        calls = drawn(inst)
        assert [c[1][0] for c in calls if c[0] == "operator"] == ["strnn.cancel_torch_install"]
        assert any("Installing torch==2.13.0: Downloading" in c[2].get("text", "") for c in calls if c[0] == "label")
        with pytest.raises(RuntimeError, match="already being installed"):
            bpy.ops.strnn.install_torch()
        assert bpy.ops.strnn.cancel_torch_install() == {"FINISHED"}
        assert not job.poll() and job.cancelled
    finally:
        job.cancel()
    assert list(user_folder.iterdir()) == [] and leftovers(user_folder) == []


def test_background_install_finishes(inst, fake_pip, user_folder):
    fake_pip("--sleep", "0.2")
    job = inst.PipInstall(str(user_folder))
    job.wait()
    assert job.status == "Successfully installed strnn_fake_pkg"
    job.finish()
    assert (user_folder / "strnn_fake_pkg" / "__init__.py").read_text() == "VERSION = 2\n"
    assert leftovers(user_folder) == []


def test_cancel_without_install(inst):
    assert bpy.ops.strnn.cancel_torch_install() == {"CANCELLED"}


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
    type(prefs).draw(type("Fake", (), {"layout": Recorder(calls), "model_folder": "", "denoise_model_folder": "",
                                       "engine": "NUMPY", "threads": 0})(), bpy.context)
    assert any(c[0] == "box" for c in calls)
    labels = [c[2].get("text", "") for c in calls if c[0] == "label"]
    assert "Extend, Follow Curve: strnn_default" in labels and "Denoise: strnn_denoise" in labels
    assert labels.count("Non-commercial use only (its training data's licence)") == 2
    assert any(text.startswith("Licence: CC BY-NC 4.0") for text in labels)


def test_preferences_name_a_missing_model(addon, tmp_path):
    calls = []
    prefs = type("Fake", (), {"model_folder": str(tmp_path), "denoise_model_folder": str(tmp_path)})()
    importlib.import_module(addon.__name__ + ".strnn_addon.props").draw_models(Recorder(calls), prefs)
    labels = [c[2].get("text", "") for c in calls if c[0] == "label"]
    assert labels == ["Extend, Follow Curve: no model in the Model Folder",
                      "Denoise: no model in the Denoise Model Folder"]
