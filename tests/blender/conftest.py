"""Blender tests: the BUILT extension installed into the bpy module, a fresh scene per test.

The extension zip is built once per session (scripts/build_extension.py), installed with
``bpy.ops.extensions.package_install_files`` into a temporary user repository and enabled,
the way a user installs it. Each test starts from an empty home file.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from scenes import REPO, release_folder  # noqa: E402

REPO_MODULE = "strnn_test"
sys.path.insert(0, str(REPO / "scripts"))


@pytest.fixture(scope="session")
def extension_zip(tmp_path_factory) -> Path:
    import build_extension

    out = tmp_path_factory.mktemp("dist")
    args = ["--out", str(out)]
    model = release_folder()
    if model is not None:
        args += ["--model", str(model)]
    return build_extension.main(args)


@pytest.fixture(scope="session")
def addon(extension_zip, tmp_path_factory):
    """The installed extension's package (``bl_ext.strnn_test.strnn_motion``)."""
    prefs = bpy.context.preferences
    directory = tmp_path_factory.mktemp("extensions")
    if prefs.extensions.repos.get(REPO_MODULE) is None:
        prefs.extensions.repos.new(name=REPO_MODULE, module=REPO_MODULE, custom_directory=str(directory),
                                   source="USER")
    result = bpy.ops.extensions.package_install_files(filepath=str(extension_zip), repo=REPO_MODULE,
                                                      enable_on_install=True)
    assert result == {"FINISHED"}
    name = f"bl_ext.{REPO_MODULE}.strnn_motion"
    assert name in prefs.addons, f"extension not enabled: {list(prefs.addons.keys())}"
    return importlib.import_module(name)


@pytest.fixture(autouse=True)
def fresh_scene(addon):
    bpy.ops.wm.read_homefile(use_empty=True)
    yield
    bpy.ops.wm.read_homefile(use_empty=True)


class ModelCalls:
    """What the real model was asked and what it made, call by call: Extend's continuations (``extend``), Denoise's
    cleaned takes (``denoise``), Fill Gap's in-betweens (``inbetween``) and Follow Curve's walks (``follow``), each a
    dict of what went in (``pos``: the context, where there is one) and the output ``out`` (model axes, Y-up, scene
    units), ``fps`` and, for Extend, ``frames``; so a test checks what Blender plays against what the model made."""

    def __init__(self, addon):
        self._conventions = importlib.import_module(addon.__name__ + ".model_core.motion.conventions")
        self.extend: list[dict] = []
        self.denoise: list[dict] = []
        self.inbetween: list[dict] = []
        self.follow: list[dict] = []

    def blender(self, pos: np.ndarray) -> np.ndarray:
        """Model-axis positions in Blender's axes (Z up), as :func:`scenes.evaluated_joints` gives them."""
        return self._conventions.yup_to_zup(np.asarray(pos, dtype=np.float64))

    def extended(self, k: int = -1) -> np.ndarray:
        """The ``k``-th continuation the model made (the last by default), in Blender's axes ``[frames, 21, 3]``."""
        assert self.extend, "the model made no continuation"
        return self.blender(self.extend[k]["out"])

    def extension_after(self, last_pose: np.ndarray) -> np.ndarray:
        """The continuation of the context that ends on ``last_pose`` ``[21, 3]`` (Blender's axes): of several
        armatures extended at once, the one that continued that armature."""
        ends = [np.abs(self.blender(call["pos"][-1]) - last_pose).max() for call in self.extend]
        k = int(np.argmin(ends))
        assert ends[k] < 1e-4, f"no continuation starts from that pose (nearest {ends[k]:.2e})"
        return self.extended(k)

    def denoised(self, k: int = -1) -> np.ndarray:
        """The ``k``-th take the denoiser cleaned, in Blender's axes ``[F, 21, 3]``."""
        assert self.denoise, "the model denoised nothing"
        return self.blender(self.denoise[k]["out"])


@pytest.fixture
def model_calls(addon, real_model, monkeypatch):
    """The real model (the bundled release) with its calls recorded (:class:`ModelCalls`): each call runs the real
    engine and its input and output are kept; nothing of the model is replaced."""
    bridge = importlib.import_module(addon.__name__ + ".strnn_addon.engine_bridge")
    calls = ModelCalls(addon)
    extend, denoise, inbetween, follow = bridge.run_extend, bridge.run_denoise, bridge.run_inbetween, \
        bridge.run_follow_curve

    def run_extend(prefs, pos, fps, frames, memory=None, floor=None):
        out = extend(prefs, pos, fps, frames, memory, floor)
        calls.extend.append({"pos": np.array(pos), "out": np.array(out), "fps": fps, "frames": frames})
        return out

    def run_denoise(prefs, pos, fps, strength):
        out = yield from denoise(prefs, pos, fps, strength)
        calls.denoise.append({"pos": np.array(pos), "out": np.array(out), "fps": fps, "strength": strength})
        return out

    def run_inbetween(prefs, before, after, fps, frames, follow_take=True):
        out = inbetween(prefs, before, after, fps, frames, follow_take)
        calls.inbetween.append({"pos": np.array(before), "out": np.array(out), "fps": fps})
        return out

    def run_follow_curve(prefs, points, cyclic, fps, frames, speed, context=None, rest=None):
        out = yield from follow(prefs, points, cyclic, fps, frames, speed, context, rest)
        calls.follow.append({"pos": None if context is None else np.array(context), "out": np.array(out), "fps": fps})
        return out

    monkeypatch.setattr(bridge, "run_extend", run_extend)
    monkeypatch.setattr(bridge, "run_denoise", run_denoise)
    monkeypatch.setattr(bridge, "run_inbetween", run_inbetween)
    monkeypatch.setattr(bridge, "run_follow_curve", run_follow_curve)
    return calls


@pytest.fixture
def real_model(addon):
    """The real engine on the bundled (or a trained) model; skips when there is none."""
    if release_folder() is None:
        pytest.skip("no trained model (models/strnn_default or runs/*/release)")
    pytest.importorskip(addon.__name__ + ".model_core.inference.engine")
    prefs = bpy.context.preferences.addons[addon.__name__].preferences
    prefs.model_folder = str(release_folder())
    yield release_folder()
    prefs.model_folder = ""


# The bpy module can fail at process exit after a full suite: bpy 4.5.15 hangs (its delayed-file-close
# thread and a static destructor wait on each other; seen with gdb) and bpy 4.2 has segfaulted in CI
# after every test passed and the summary was printed. Blender's teardown is not what these tests test,
# so the session ends the process itself once pytest has reported everything, with pytest's status.
_EXIT_STATUS = {}


def pytest_sessionfinish(session, exitstatus):
    _EXIT_STATUS["status"] = int(exitstatus)


@pytest.hookimpl(trylast=True)
def pytest_unconfigure(config):
    if "status" in _EXIT_STATUS:
        import os

        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(_EXIT_STATUS["status"])
