#!/usr/bin/env bash
# Makes (once, cached) a venv with an official Blender build as a Python module (PyPI `bpy`) so that the
# Blender tests also run on the Blender versions users have (docs/design.md §9). Prints the venv's python on
# success. When PyPI cannot be reached or has no such bpy, it says so on stderr, prints nothing and exits 0
# (scripts/test.sh then fails under strict mode, or leaves that Blender out and says so in its summary).
#   scripts/setup_bpy.sh VERSION [venv-dir]      VERSION: 4.2, 4.5, 5.0, 5.2, 5.3 (a Blender major.minor)
# The newest release of that major.minor is installed (e.g. 5.2 -> 5.2.3, the newest 5.2 LTS).
# The venv is ~/.cache/raysplats/bpy<major><minor>-venv (e.g. bpy42-venv) unless venv-dir is given.
set -uo pipefail
version=${1:?usage: scripts/setup_bpy.sh VERSION [venv-dir]   (VERSION e.g. 4.2, 4.5, 5.0)}
[[ $version =~ ^[0-9]+\.[0-9]+$ ]] || { echo "setup_bpy: VERSION must be major.minor (e.g. 4.5), not '$version'" >&2; exit 2; }
venv=${2:-$HOME/.cache/raysplats/bpy${version/./}-venv}
if [[ -x $venv/bin/python ]] && "$venv/bin/python" -c "import bpy, sys; sys.exit(bpy.app.version[:2] != tuple(map(int, '$version'.split('.'))))" >/dev/null 2>&1; then
  echo "$venv/bin/python"
  exit 0
fi
mkdir -p "$(dirname "$venv")"
# Blender 4.2 to 5.0 embed Python 3.11, which is Debian 12's /usr/bin/python3: the bpy wheels and our
# module (built for /usr/bin/python3) are made for it. Blender 5.1+ embeds Python 3.13: its bpy wheels are
# cp313 only, so the venv uses the Python 3.13 that scripts/setup_python313.sh finds (the same interpreter
# the 3.13 native module is built with).
# numpy<2: the bpy 4.x wheels are built against numpy 1.x (Blender's glTF add-on and ours use it); the
# cp313 wheels name the numpy they need themselves.
interpreter=/usr/bin/python3
numpy="numpy<2"
if [[ $version =~ ^([0-9]+)\.([0-9]+)$ ]] && (( BASH_REMATCH[1] * 100 + BASH_REMATCH[2] >= 501 )); then
  interpreter=$("$(dirname "$0")/setup_python313.sh" --interpreter)
  numpy=numpy
  if [[ -z $interpreter ]]; then
    echo "setup_bpy: Blender $version needs Python 3.13 and none was found (python3.13 on PATH, ~/.pyenv/versions/3.13*," \
         "or RAYSPLATS_PYTHON313); Blender $version tests are not run" >&2
    exit 0
  fi
fi
"$interpreter" -m venv "$venv" >&2 || { echo "setup_bpy: could not make a venv in $venv; Blender $version tests are not run" >&2; exit 0; }
if ! "$venv/bin/pip" install -q "bpy==$version.*" "$numpy" >&2; then
  echo "setup_bpy: bpy $version not installed (PyPI unreachable?); Blender $version tests are not run" >&2
  exit 0
fi
echo "$venv/bin/python"
