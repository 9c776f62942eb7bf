#!/usr/bin/env bash
# Makes (once, cached) a Python 3.13 venv with pybind11 and numpy, for the second native module: Blender 5.1
# and newer embed Python 3.13, so the extension zip carries `_native` built for 3.11 and for 3.13. Debian 12
# has no Python 3.13 and its pybind11 (2.10) predates 3.13 support (2.13), so the interpreter comes from the
# machine (python3.13 on PATH, e.g. from pyenv, or RAYSPLATS_PYTHON313=/path/to/python3.13) and pybind11
# from PyPI. Prints the venv's python; prints nothing and exits 0, saying why on stderr, when there is no
# Python 3.13 or PyPI cannot be reached (the 3.13 module is then not built).
#   scripts/setup_python313.sh [venv-dir]
#   scripts/setup_python313.sh --interpreter     prints the Python 3.13 interpreter found (or nothing), no venv
set -uo pipefail
find_only=0
[[ ${1:-} == --interpreter ]] && { find_only=1; shift; }
venv=${1:-$HOME/.cache/raysplats/py313-venv}
ok() { "$1" -c "import sys, pybind11, numpy; sys.exit(sys.version_info[:2] != (3, 13))" >/dev/null 2>&1; }
if (( ! find_only )) && [[ -x $venv/bin/python ]] && ok "$venv/bin/python"; then
  echo "$venv/bin/python"
  exit 0
fi
interpreter=${RAYSPLATS_PYTHON313:-}
if [[ -z $interpreter ]]; then
  for candidate in "$(command -v python3.13 2>/dev/null)" "$HOME"/.pyenv/versions/3.13*/bin/python3.13; do
    # pyenv's shim exists even where 3.13 is not the selected version; ask the interpreter itself.
    if [[ -n $candidate && -x $candidate ]] && "$candidate" -c "import sys; sys.exit(sys.version_info[:2] != (3, 13))" 2>/dev/null; then
      interpreter=$candidate
      break
    fi
  done
fi
if (( find_only )); then
  [[ -n $interpreter ]] && echo "$interpreter"
  exit 0
fi
if [[ -z $interpreter ]]; then
  echo "setup_python313: no Python 3.13 found (python3.13 on PATH, ~/.pyenv/versions/3.13*, or RAYSPLATS_PYTHON313);" \
       "the module for Blender 5.1+ is not built" >&2
  exit 0
fi
mkdir -p "$(dirname "$venv")"
"$interpreter" -m venv "$venv" >&2 || { echo "setup_python313: could not make a venv with $interpreter" >&2; exit 0; }
# pybind11 2.13 is the first release that supports Python 3.13.
if ! "$venv/bin/pip" install -q "pybind11>=2.13" numpy >&2; then
  echo "setup_python313: pybind11/numpy not installed (PyPI unreachable?); the module for Blender 5.1+ is not built" >&2
  exit 0
fi
echo "$venv/bin/python"
