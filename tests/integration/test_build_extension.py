"""scripts/build_extension.py --wheel / --split-platforms with tiny wheels made here (no torch)."""

from __future__ import annotations

import shutil
import sys
import zipfile
from pathlib import Path

import pytest

pytest.importorskip("bpy")  # Blender's blender_ext.py comes with the bpy wheel

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "scripts"))

import build_extension  # noqa: E402


def make_wheel(folder: Path, name: str, tag: str) -> Path:
    path = folder / f"{name}-0.1-{tag}.whl"
    info = f"{name}-0.1.dist-info"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr(f"{name}/__init__.py", "VALUE = 1\n")
        z.writestr(f"{info}/METADATA", f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1\n")
        z.writestr(f"{info}/WHEEL", f"Wheel-Version: 1.0\nGenerator: test\nRoot-Is-Purelib: true\nTag: {tag}\n")
        z.writestr(f"{info}/RECORD", "")
    return path


def manifest_of(zip_path: Path) -> str:
    with zipfile.ZipFile(zip_path) as z:
        return z.read("blender_manifest.toml").decode()


def names_of(zip_path: Path) -> set[str]:
    with zipfile.ZipFile(zip_path) as z:
        return set(z.namelist())


def test_wheel_listed_in_manifest(tmp_path):
    wheel = make_wheel(tmp_path, "tinypkg", "py3-none-any")
    out = build_extension.main(["--out", str(tmp_path / "dist"), "--model", str(tmp_path / "none"),
                                "--wheel", str(wheel)])
    assert out.name == "strnn_motion-0.1.0.zip"
    assert 'wheels = ["./wheels/tinypkg-0.1-py3-none-any.whl"]' in manifest_of(out)
    assert "wheels/tinypkg-0.1-py3-none-any.whl" in names_of(out)
    assert "LICENSE" in names_of(out) and "GNU GENERAL PUBLIC LICENSE" in zipfile.ZipFile(out).read("LICENSE").decode()
    assert "wheels" not in (REPO / "blender_manifest.toml").read_text()  # only the staged copy changes


def test_split_platforms(tmp_path):
    pure = make_wheel(tmp_path, "tinypkg", "py3-none-any")
    linux = make_wheel(tmp_path, "tinyplat", "cp311-cp311-manylinux_2_28_x86_64")
    outs = build_extension.main(["--out", str(tmp_path / "dist"), "--model", str(tmp_path / "none"),
                                 "--split-platforms", "--platform", "linux-x64", "--platform", "windows-x64",
                                 "--wheel", str(pure), "--wheel", str(linux)])
    assert [p.name for p in outs] == ["strnn_motion-0.1.0-linux_x64.zip", "strnn_motion-0.1.0-windows_x64.zip"]
    lin, win = (names_of(p) for p in outs)
    assert f"wheels/{pure.name}" in lin and f"wheels/{linux.name}" in lin
    assert f"wheels/{pure.name}" in win and f"wheels/{linux.name}" not in win
    assert 'platforms = ["linux-x64"]' in manifest_of(outs[0])


def test_bad_wheel(tmp_path):
    with pytest.raises(SystemExit, match="not a .whl"):
        build_extension.main(["--out", str(tmp_path / "dist"), "--model", str(tmp_path / "none"),
                              "--wheel", str(tmp_path / "missing.whl")])


def test_manifest_declares_what_the_extension_reaches():
    """Blender shows these before install: model folders are read from disk. Nothing is downloaded or
    installed at run time: no network permission, and no code of the extension runs pip, a subprocess or
    edits sys.path."""
    import tomllib

    permissions = tomllib.loads((REPO / "blender_manifest.toml").read_text())["permissions"]
    assert set(permissions) == {"files"}
    import re

    for path in (REPO / "strnn_addon").rglob("*.py"):
        text = path.read_text()
        for word in (r"\bpip\b", r"\bsubprocess\b", r"\bsys\.path\b", r"\burllib\b", r"\bensurepip\b"):
            assert not re.search(word, text), f"{path.relative_to(REPO)} mentions {word}"
    assert all(len(text) <= 64 and not text.endswith(".") for text in permissions.values())


def test_the_zip_holds_only_what_the_extension_imports(tmp_path):
    """Every model_core module the extension's code imports (directly or through others) is in the
    zip, and none of the modules left out is imported by anything that is in it."""
    import ast

    out = build_extension.main(["--out", str(tmp_path / "dist"), "--model", str(tmp_path / "none")])
    names = names_of(out)
    shipped = {n for n in names if n.endswith(".py")}
    for rel in build_extension.NOT_SHIPPED:
        assert not any(n.startswith(rel) for n in names), rel
    for name in shipped:
        tree = ast.parse(zipfile.ZipFile(out).read(name).decode())
        package = name.split("/")[:-1]
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level and node.module:
                target = "/".join(package[:len(package) - node.level + 1] + node.module.split("."))
                assert f"{target}.py" in shipped or f"{target}/__init__.py" in shipped, f"{name} imports {target}"


def test_the_zip_ships_each_models_card_and_leaves_its_history_in_the_repository(tmp_path):
    """The bundled models come with their cards; a model folder's record of runs not shipped (HISTORY.md) does not
    travel to every user's Blender."""
    model = tmp_path / "model"
    shutil.copytree(REPO / "models" / "strnn_default", model)
    assert (model / "HISTORY.md").is_file()
    out = build_extension.main(["--out", str(tmp_path / "dist"), "--model", str(model)])
    names = names_of(out)
    assert "models/strnn_default/MODEL_CARD.md" in names and "models/strnn_default/model.safetensors" in names
    assert "models/strnn_default/companion/model.safetensors" in names
    assert "models/strnn_default/regularised/model.safetensors" in names
    assert not any(n.endswith("HISTORY.md") for n in names)


INSTALL_FROM_URL = """
import bpy, json, pathlib, sys
bpy.ops.wm.read_factory_settings(use_empty=True)
prefs = bpy.context.preferences
prefs.system.use_online_access = True  # installing from a repository URL asks for it, even for file://
repo = prefs.extensions.repos.new(name="local", module="local_repo", custom_directory=sys.argv[2],
                                  remote_url=sys.argv[1], source="USER")
index = list(prefs.extensions.repos).index(repo)
synced = bpy.ops.extensions.repo_sync(repo_directory=repo.directory, repo_index=index)
done = bpy.ops.extensions.package_install(repo_directory=repo.directory, repo_index=index, pkg_id="strnn_motion",
                                          enable_on_install=True)
import bl_ext.local_repo.strnn_motion as ext
model = pathlib.Path(ext.__file__).parent / "models" / "strnn_default" / "model.json"
print(json.dumps({"synced": list(synced), "installed": list(done),
                  "enabled": "bl_ext.local_repo.strnn_motion" in prefs.addons,
                  "operators": bpy.ops.strnn.extend_clip.idname() == "STRNN_OT_extend_clip",
                  "model": model.is_file()}))
"""


def test_a_built_repository_installs_the_extension_from_its_url(tmp_path):
    """--repository writes a static extension repository (Blender's server-generate); Blender installs and
    enables the extension from its index.json URL."""
    import json
    import subprocess

    repo = tmp_path / "repo"
    build_extension.main(["--out", str(tmp_path / "dist"), "--repository", str(repo)])
    index = json.loads((repo / "index.json").read_text())
    [entry] = index["data"]
    assert entry["id"] == "strnn_motion" and (repo / entry["archive_url"]).is_file()
    assert (repo / "index.html").is_file()
    done = subprocess.run([sys.executable, "-c", INSTALL_FROM_URL, (repo / "index.json").as_uri(),
                           str(tmp_path / "installed")],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    got = json.loads(done.stdout.strip().splitlines()[-1])
    assert got == {"synced": ["FINISHED"], "installed": ["FINISHED"], "enabled": True, "operators": True,
                   "model": True}
