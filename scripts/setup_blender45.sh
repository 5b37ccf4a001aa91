#!/usr/bin/env bash
# Create .venv-blender45/ (repository root): the bpy 4.5 LTS module (layered actions beside the
# legacy API) and pytest, to run the Blender tests again against Blender 4.5:
#   bash scripts/setup_blender45.sh && .venv-blender45/bin/python -m pytest tests/blender -q
# Idempotent like scripts/setup.sh, which does the work. bpy 4.5 is about 500 MB; point pip
# at a downloaded wheel with PIP_FIND_LINKS=DIR. bpy 4.5 wheels exist for Python 3.11 only.
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
STRNN_VENV=.venv-blender45 STRNN_REQUIREMENTS=requirements-blender45.txt exec bash "$here/setup.sh"
