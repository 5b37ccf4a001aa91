#!/usr/bin/env bash
# Create .venv-blender42/ (repository root): the bpy 4.2 LTS module (legacy action API) and
# pytest, to run the Blender tests a second time against Blender 4.2:
#   bash scripts/setup_blender42.sh && .venv-blender42/bin/python -m pytest tests/blender -q
# Idempotent like scripts/setup.sh, which does the work. bpy 4.2 is about 500 MB; point pip
# at a downloaded wheel with PIP_FIND_LINKS=DIR. bpy 4.2 wheels exist for Python 3.11 only.
set -euo pipefail
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
STRNN_VENV=.venv-blender42 STRNN_REQUIREMENTS=requirements-blender42.txt exec bash "$here/setup.sh"
