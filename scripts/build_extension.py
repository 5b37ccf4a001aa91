"""Build the installable STRNN Motion extension zip and validate it with Blender's own tool.

The zip holds the manifest, the entry ``__init__.py``, ``strnn_addon/`` and, beside it,
``model_core/`` and ``models/`` (the bundled model), so the add-on imports the motion
core relatively (``from ..model_core import ...``). Tests, scripts, data and runs stay out.

    python scripts/build_extension.py --out dist/
    python scripts/build_extension.py --out dist/ --model runs/default/release
    python scripts/build_extension.py --out dist/ --split-platforms --wheel torch-....whl [--wheel ...]

``--wheel`` bundles wheels (listed in the staged manifest's ``wheels``); ``--split-platforms``
passes Blender's option of the same name: one zip per platform of the manifest's ``platforms``
(``--platform`` sets them; default: those PyTorch publishes wheels for), each holding only the
wheels for that platform, named ``strnn_motion-VERSION-PLATFORM.zip``.
"""

from __future__ import annotations

import argparse
import importlib.util
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("strnn_addon", "model_core")
FILES = ("blender_manifest.toml", "__init__.py", "README.md", "LICENSE")
BUILD_LEFTOVERS = ("__pycache__", "*.pyc", "*.tmp")
IGNORE = shutil.ignore_patterns(*BUILD_LEFTOVERS)
# a model folder's record of what was tried around it (HISTORY.md) stays in the repository; its card ships
MODEL_IGNORE = shutil.ignore_patterns(*BUILD_LEFTOVERS, "HISTORY.md")
# model_core modules the extension never imports (training, evaluation, writing BVH, test data):
# they stay out of the zip (a test walks the extension's imports to keep this list honest).
NOT_SHIPPED = ("model_core/eval", "model_core/model/training.py", "model_core/model/baseline_training.py",
               "model_core/model/gap_training.py", "model_core/model/baselines.py", "model_core/model/dataset.py",
               "model_core/io/bvh_export.py",
               "model_core/motion/synthetic.py", "model_core/ops/follow_torch.py")
DEFAULT_PLATFORMS = ("linux-x64", "macos-arm64", "windows-x64")


def find_blender_ext() -> Path:
    """``blender_ext.py`` inside the installed ``bpy`` wheel (found without importing bpy)."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise SystemExit("bpy is not installed: pip install bpy (or pass --blender-ext PATH)")
    root = Path(list(spec.submodule_search_locations)[0])
    hits = sorted(root.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not hits:
        raise SystemExit(f"no bl_pkg/cli/blender_ext.py under {root}; pass --blender-ext PATH")
    return hits[-1]


def stage(dest: Path, model: Path | None, denoiser: Path | None = None) -> None:
    """Copy what the extension ships into ``dest``: the code, the model and the denoising model."""
    for name in FILES:
        if (REPO / name).exists():
            shutil.copy2(REPO / name, dest / name)
    for pkg in PACKAGES:
        shutil.copytree(REPO / pkg, dest / pkg, ignore=IGNORE)
    for rel in NOT_SHIPPED:
        path = dest / rel
        shutil.rmtree(path) if path.is_dir() else path.unlink()
    model = model or REPO / "models" / "strnn_default"
    if (model / "model.json").exists():
        shutil.copytree(model, dest / "models" / "strnn_default", ignore=MODEL_IGNORE)
    else:
        print(f"warning: no model at {model}; the extension will need a Model Folder in its preferences",
              file=sys.stderr)
    denoiser = denoiser or REPO / "models" / "strnn_denoise"
    if (denoiser / "model.json").exists():
        shutil.copytree(denoiser, dest / "models" / "strnn_denoise", ignore=MODEL_IGNORE)
    else:
        print(f"warning: no denoising model at {denoiser}; Denoise will use the main model", file=sys.stderr)


def toml_list(values) -> str:
    return "[" + ", ".join(f'"{v}"' for v in values) + "]"


def add_to_manifest(dest: Path, wheels: list[Path], platforms: list[str]) -> None:
    """Copy ``wheels`` into ``dest/wheels/`` and list them (and ``platforms``) in the staged manifest."""
    manifest = dest / "blender_manifest.toml"
    text = manifest.read_text()
    keys = []
    if wheels:
        (dest / "wheels").mkdir(exist_ok=True)
        for wheel in wheels:
            if not wheel.is_file() or wheel.suffix != ".whl":
                raise SystemExit(f"--wheel {wheel}: not a .whl file")
            shutil.copy2(wheel, dest / "wheels" / wheel.name)
        keys.append(f"wheels = {toml_list(f'./wheels/{w.name}' for w in wheels)}")
    if platforms:
        keys.append(f"platforms = {toml_list(platforms)}")
    for key in keys:  # top-level keys go before the first table
        name = key.split(" ", 1)[0]
        if re.search(rf"^{name}\s*=", text, re.M):
            raise SystemExit(f"blender_manifest.toml already sets {name}; edit it there instead")
        first_table = re.search(r"^\[", text, re.M)
        at = first_table.start() if first_table else len(text)
        text = text[:at] + key + "\n\n" + text[at:]
    manifest.write_text(text)


def manifest_field(text: str, name: str) -> str:
    found = re.search(rf'^{name}\s*=\s*"([^"]*)"', text, re.M)
    return found.group(1) if found else ""


def run_tool(tool: Path, *args: str) -> None:
    result = subprocess.run([sys.executable, str(tool), *args], capture_output=True, text=True)
    print(result.stdout.strip())
    if result.returncode != 0:
        raise SystemExit(f"blender_ext {args[0]} failed:\n{result.stderr.strip() or result.stdout.strip()}")


def main(argv: list[str] | None = None) -> Path:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=REPO / "dist", help="output folder (default: dist/)")
    parser.add_argument("--model", type=Path, default=None,
                        help="release folder to bundle as models/strnn_default (default: models/strnn_default)")
    parser.add_argument("--denoiser", type=Path, default=None,
                        help="release folder to bundle as models/strnn_denoise, the model Denoise uses "
                             "(default: models/strnn_denoise)")
    parser.add_argument("--blender-ext", type=Path, default=None, help="path to Blender's blender_ext.py")
    parser.add_argument("--no-validate", action="store_true", help="skip validating the built zip")
    parser.add_argument("--wheel", type=Path, action="append", default=[], metavar="PATH",
                        help="a wheel to bundle (repeatable), e.g. the CPU torch wheel of each platform")
    parser.add_argument("--split-platforms", action="store_true",
                        help="one zip per platform, each with only its wheels (Blender's --split-platforms)")
    parser.add_argument("--platform", action="append", default=[], metavar="NAME",
                        help="a platform for the manifest (repeatable), e.g. linux-x64; with --split-platforms "
                             f"the default is {', '.join(DEFAULT_PLATFORMS)}")
    parser.add_argument("--repository", type=Path, default=None, metavar="DIR",
                        help="also put the zip(s) in DIR and write its index (Blender's server-generate: "
                             "index.json and index.html), a static extension repository: host DIR and add its "
                             "index.json URL in Preferences > Get Extensions > Repositories to install and update")
    args = parser.parse_args(argv)
    tool = args.blender_ext or find_blender_ext()
    args.out.mkdir(parents=True, exist_ok=True)
    platforms = args.platform or (list(DEFAULT_PLATFORMS) if args.split_platforms else [])
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "strnn_motion"
        src.mkdir()
        stage(src, args.model, args.denoiser)
        add_to_manifest(src, [w.resolve() for w in args.wheel], platforms)
        text = (src / "blender_manifest.toml").read_text()
        run_tool(tool, "validate", str(src))
        split = ["--split-platforms"] if args.split_platforms else []
        run_tool(tool, "build", "--source-dir", str(src), "--output-dir", str(args.out), *split)
    stem = f"{manifest_field(text, 'id')}-{manifest_field(text, 'version')}"
    if args.split_platforms:
        zips = [args.out / f"{stem}-{p.replace('-', '_')}.zip" for p in platforms]
    else:
        zips = [args.out / f"{stem}.zip"]
    for path in zips:
        if not path.is_file():
            raise SystemExit(f"blender_ext build did not write {path}")
        if not args.no_validate:
            run_tool(tool, "validate", str(path))
        print(path)
    if args.repository is not None:
        publish(tool, zips, args.repository)
    return zips if args.split_platforms else zips[0]


def publish(tool: Path, zips: list[Path], repository: Path) -> Path:
    """Copy ``zips`` into ``repository`` and (re)write its index; returns the index.json path."""
    repository.mkdir(parents=True, exist_ok=True)
    for path in zips:
        shutil.copy2(path, repository / path.name)
    run_tool(tool, "server-generate", "--repo-dir", str(repository), "--html")
    index = repository / "index.json"
    if not index.is_file():
        raise SystemExit(f"blender_ext server-generate did not write {index}")
    return index


if __name__ == "__main__":
    main()
