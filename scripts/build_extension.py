"""Build the installable STRNN Motion extension zip and validate it with Blender's own tool.

The zip holds the manifest, the entry ``__init__.py``, ``strnn_addon/`` and, beside it,
``model_core/`` and ``models/`` (the bundled model), so the add-on imports the motion
core relatively (``from ..model_core import ...``). Tests, scripts, data and runs stay out.

    python scripts/build_extension.py --out dist/
    python scripts/build_extension.py --out dist/ --model runs/default/release
"""

from __future__ import annotations

import argparse
import importlib.util
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("strnn_addon", "model_core")
FILES = ("blender_manifest.toml", "__init__.py", "README.md", "LICENSE")
IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc", "*.tmp")


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


def stage(dest: Path, model: Path | None) -> None:
    """Copy what the extension ships into ``dest``."""
    for name in FILES:
        if (REPO / name).exists():
            shutil.copy2(REPO / name, dest / name)
    for pkg in PACKAGES:
        shutil.copytree(REPO / pkg, dest / pkg, ignore=IGNORE)
    model = model or REPO / "models" / "strnn_default"
    if (model / "model.json").exists():
        shutil.copytree(model, dest / "models" / "strnn_default", ignore=IGNORE)
    else:
        print(f"warning: no model at {model}; the extension will need a Model Folder in its preferences",
              file=sys.stderr)


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
    parser.add_argument("--blender-ext", type=Path, default=None, help="path to Blender's blender_ext.py")
    parser.add_argument("--no-validate", action="store_true", help="skip validating the built zip")
    args = parser.parse_args(argv)
    tool = args.blender_ext or find_blender_ext()
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "strnn_motion"
        src.mkdir()
        stage(src, args.model)
        run_tool(tool, "validate", str(src))
        run_tool(tool, "build", "--source-dir", str(src), "--output-dir", str(args.out))
    zips = sorted(args.out.glob("strnn_motion-*.zip"), key=lambda p: p.stat().st_mtime)
    if not args.no_validate:
        run_tool(tool, "validate", str(zips[-1]))
    print(zips[-1])
    return zips[-1]


if __name__ == "__main__":
    main()
