#!/usr/bin/env bash
# Makes (once) a venv with the official Blender 4.2 LTS build as a Python module (PyPI `bpy`, Python 3.11)
# so the Blender tests also run on 4.x. Prints the venv's python on success; prints nothing and exits 0
# when PyPI cannot be reached, so the 3.4 tests still run.
#   scripts/setup_bpy4.sh [venv-dir]
set -uo pipefail
venv=${1:-${RAYSPLATS_BPY4_VENV:-$HOME/.cache/raysplats/bpy42-venv}}
if [[ ! -x $venv/bin/python ]] || ! "$venv/bin/python" -c "import bpy" >/dev/null 2>&1; then
  mkdir -p "$(dirname "$venv")"
  # Debian's Python 3.11 is the version the bpy 4.2 wheel and our module are built for.
  /usr/bin/python3 -m venv "$venv" >&2 || exit 0
  "$venv/bin/pip" install -q "bpy==4.2.*" "numpy<2" >&2 || { echo "setup_bpy4: bpy not installed; Blender 4.x tests skipped" >&2; exit 0; }
fi
echo "$venv/bin/python"
