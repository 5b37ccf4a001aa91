#!/usr/bin/env bash
# Create the virtual environment at .venv/ (repository root) with the pinned dependencies.
# Idempotent: when .venv already holds exactly requirements.txt, it returns at once.
#   bash scripts/setup.sh            # set up (or check) .venv
#   STRNN_PYTHON=/path/python3.11 bash scripts/setup.sh   # choose the interpreter
# STRNN_VENV and STRNN_REQUIREMENTS (paths relative to the repository) set up another
# environment the same way (scripts/setup_blender42.sh does).
set -euo pipefail
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
venv="$repo/${STRNN_VENV:-.venv}"
req="$repo/${STRNN_REQUIREMENTS:-requirements.txt}"
stamp="$venv/.strnn-requirements.sha256"

pick_python() {
  if [ -n "${STRNN_PYTHON:-}" ]; then echo "$STRNN_PYTHON"; return; fi
  for py in python3.11 python3; do
    if command -v "$py" >/dev/null 2>&1; then echo "$py"; return; fi
  done
  echo "setup: no python3.11 or python3 on PATH; install Python 3.11" >&2
  exit 1
}

want=$(sha256sum "$req" | cut -d' ' -f1)
if [ -x "$venv/bin/python" ] && [ -f "$stamp" ] && [ "$(cat "$stamp")" = "$want" ]; then
  echo "setup: ${venv##*/} is up to date ($("$venv/bin/python" --version))"
  exit 0
fi

if [ ! -x "$venv/bin/python" ]; then
  py=$(pick_python)
  version=$("$py" -c 'import sys; print("%d.%d" % sys.version_info[:2])')
  if [ "$version" != "3.11" ]; then
    echo "setup: warning: $py is Python $version; the pinned bpy needs Python 3.11" >&2
  fi
  echo "setup: creating ${venv##*/} with $py (Python $version)"
  "$py" -m venv "$venv"
fi

# One pip command for everything, so that bpy cannot pull in a numpy other than the pinned one.
# torch==2.13.0 resolves to a CPU build where one is available to pip (find-links or an extra index).
echo "setup: installing pinned dependencies from ${req##*/}"
"$venv/bin/python" -m pip install --disable-pip-version-check -q -r "$req"
echo "$want" > "$stamp"
echo "setup: done ($("$venv/bin/python" --version), $venv)"
