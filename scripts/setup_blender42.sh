#!/usr/bin/env bash
# Create .venv-blender42/ (repository root): the bpy 4.2 LTS module (legacy action API) and
# pytest, to run the Blender tests a second time against Blender 4.2:
#   bash scripts/setup_blender42.sh && .venv-blender42/bin/python -m pytest tests/blender -q
# Idempotent: when .venv-blender42 already holds exactly requirements-blender42.txt, it returns
# at once. bpy 4.2 is about 500 MB; point pip at a downloaded wheel with PIP_FIND_LINKS=DIR.
#   STRNN_PYTHON=/path/python3.11 bash scripts/setup_blender42.sh   # choose the interpreter
set -euo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
venv="$repo/.venv-blender42"
req="$repo/requirements-blender42.txt"
stamp="$venv/.strnn-requirements.sha256"

pick_python() {
  if [ -n "${STRNN_PYTHON:-}" ]; then echo "$STRNN_PYTHON"; return; fi
  if command -v python3.11 >/dev/null 2>&1; then echo python3.11; return; fi
  echo "setup_blender42: no python3.11 on PATH; bpy 4.2 needs Python 3.11" >&2
  exit 1
}

want=$(sha256sum "$req" | cut -d' ' -f1)
if [ -x "$venv/bin/python" ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
  echo "setup_blender42: .venv-blender42 is up to date ($("$venv/bin/python" --version))"
  exit 0
fi

if [ ! -x "$venv/bin/python" ]; then
  py=$(pick_python)
  version=$("$py" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
  if [ "$version" != "3.11" ]; then
    echo "setup_blender42: $py is Python $version; bpy==4.2.0 needs Python 3.11" >&2
    exit 1
  fi
  echo "setup_blender42: creating .venv-blender42 with $py"
  "$py" -m venv "$venv"
fi

# One pip command for everything, so that bpy cannot pull in a numpy other than the pinned one.
echo "setup_blender42: installing bpy 4.2 and the test dependencies from requirements-blender42.txt"
"$venv/bin/python" -m pip install --disable-pip-version-check -q -r "$req"
echo "$want" > "$stamp"
echo "setup_blender42: done ($("$venv/bin/python" --version), $venv)"
