"""The Python package: ``pip install .`` gives the ``strnn_motion`` import package with the shipped models
and configuration inside it and the ``strnn-*`` commands, and it works away from the checkout."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SKIP = shutil.ignore_patterns(".git", ".venv*", "data", "runs", "dist", "build", "out", "*.egg-info", "__pycache__",
                              ".pytest_cache", ".ruff_cache", "tests")


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """The wheel built from a copy of the checkout (the build writes its own folders next to the sources)."""
    source = tmp_path_factory.mktemp("source") / "strnn-motion"
    shutil.copytree(REPO, source, ignore=SKIP)
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q",
                    "-w", str(out), str(source)], check=True, cwd=out)
    (built,) = out.glob("strnn_motion-*.whl")
    return built


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory) -> Path:
    target = tmp_path_factory.mktemp("site")
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--no-index", "-q", "--target", str(target),
                    str(wheel)], check=True)
    return target


def run(installed: Path, *cmd: str, cwd: Path) -> subprocess.CompletedProcess:
    """``cmd`` with only the installed package importable (the checkout is not on the path)."""
    env = {**os.environ, "PYTHONPATH": str(installed)}
    return subprocess.run(list(cmd), capture_output=True, text=True, cwd=cwd, env=env, timeout=300)


def test_the_wheel_is_one_namespaced_package_with_its_models_and_commands(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"strnn_motion"}
    for model in ("strnn_default", "strnn_denoise", "baseline_simlpe", "baseline_residual_gru"):
        assert f"strnn_motion/models/{model}/model.safetensors" in names
        assert f"strnn_motion/models/{model}/MODEL_CARD.md" in names
    assert not [n for n in names if n.endswith("HISTORY.md")]  # the record of what was tried stays in the repository
    assert "strnn_motion/configs/data.toml" in names and "strnn_motion/model_core/inference/engine.py" in names
    meta = zipfile.ZipFile(wheel)
    (entry,) = [n for n in names if n.endswith("entry_points.txt")]
    scripts = meta.read(entry).decode()
    for command in ("strnn-batch", "strnn-train", "strnn-evaluate", "strnn-demo", "strnn-check-extend"):
        assert f"{command} = strnn_motion.scripts." in scripts
    (metadata,) = [n for n in names if n.endswith("METADATA")]
    text = meta.read(metadata).decode()
    assert "Requires-Dist: numpy==1.26.4" in text
    for extra, pin in (("torch", "torch==2.13.0"), ("blender", "bpy==5.0.1"), ("plots", "matplotlib==3.11.2")):
        assert f'Requires-Dist: {pin}; extra == "{extra}"' in text
    assert not any("torch" in line and "extra" not in line for line in text.splitlines() if "Requires-Dist" in line)


def test_installed_the_bundled_model_loads_away_from_the_checkout(installed, tmp_path):
    code = ("import importlib.util, sys\n"
            "from strnn_motion.model_core.inference.engine import Engine\n"
            "engine = Engine.load()\n"
            "print(engine.m, engine.n, importlib.util.find_spec('model_core') is None, 'bpy' in sys.modules)\n")
    done = run(installed, sys.executable, "-c", code, cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == ["20", "20", "True", "False"]  # no top-level model_core; bpy not needed


@pytest.mark.parametrize("command", ["strnn-batch", "strnn-train", "strnn-evaluate", "strnn-demo",
                                     "strnn-check-extend"])
def test_installed_commands_answer_help(installed, tmp_path, command):
    done = run(installed, str(installed / "bin" / command), "--help", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert f"usage: {command}" in done.stdout


def test_installed_demo_runs_on_the_bundled_model(installed, tmp_path):
    done = run(installed, str(installed / "bin" / "strnn-demo"), "--frames", "30", "--path-frames", "25",
               "--no-blend", "--out", str(tmp_path / "out"), cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert "denoise: 3 cm of jitter" in done.stdout
    assert (tmp_path / "out" / "demo.bvh").is_file()
