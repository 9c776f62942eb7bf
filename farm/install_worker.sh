#!/usr/bin/env bash
# farm/install_worker.py (the installer, for any system) run by this system's Python 3, for the commands that name
# this script. Its options, messages and exit statuses are the Python script's:
#   farm/install_worker.sh [--blender EXE | --bpy-python PYTHON] [ZIP]
here=$(cd "$(dirname "$0")" && pwd)
python=/usr/bin/python3
[[ -x $python ]] || python=$(command -v python3) ||
  { echo "install_worker: no python3 to run $here/install_worker.py (give it to any Python 3.11+)" >&2; exit 1; }
exec "$python" "$here/install_worker.py" "$@"
