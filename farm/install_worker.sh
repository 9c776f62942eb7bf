#!/usr/bin/env bash
# Installs RaySplats into a render-farm worker's Blender, headless, then checks in a fresh Blender process that the
# worker can render with it (farm/check_worker.py: add-on enabled, RAYSPLATS engine registered, native module loaded
# for that Blender's Python, a tiny render through the engine).
#   farm/install_worker.sh [--blender EXE | --bpy-python PYTHON] [ZIP]
# ZIP is the extension zip of scripts/package_extension.sh (dist/raysplats-<version>-linux_x64.zip).
#   Blender 4.2+ (EXE, default `blender`): Blender's own `EXE --command extension install-file -r user_default -e ZIP`.
#   Blender as a Python module (PyPI bpy 4.2+, --bpy-python): the implementation of that same command, through bpy.
#   Blender 3.x (Debian 12's 3.4, which has no extensions): ZIP unpacked into the user add-on folder as raysplats/
#   and enabled; without ZIP, scripts/install_addon.sh links this source tree's add-on (built by scripts/build.sh).
# The user folder is Blender's default for the user running this; BLENDER_USER_RESOURCES picks another (one per
# worker slot, or a shared read-only one), and the jobs must then run with the same.
# Exit status: 0 installed and checked; 1 the install or the check failed (the reason on stderr); 2 bad arguments.
set -uo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(dirname "$here")
die() { echo "install_worker: $*" >&2; exit 1; }
usage() { echo "usage: farm/install_worker.sh [--blender EXE | --bpy-python PYTHON] [ZIP]" >&2; exit 2; }

blender=${BLENDER:-blender}
bpy_python=
zip=
while (($#)); do
  case $1 in
    --blender) [[ $# -ge 2 ]] || usage; blender=$2; shift 2 ;;
    --bpy-python) [[ $# -ge 2 ]] || usage; bpy_python=$2; shift 2 ;;
    -h|--help) sed -n '2,15p' "$0"; exit 0 ;;
    -*) usage ;;
    *) [[ -z $zip ]] || usage; zip=$1; shift ;;
  esac
done
if [[ -n $zip ]]; then
  [[ -f $zip ]] || die "$zip: no such file (make it with scripts/package_extension.sh)"
  zip=$(cd "$(dirname "$zip")" && pwd)/$(basename "$zip")
  /usr/bin/python3 - "$zip" <<'EOF' || exit 1
import sys, zipfile
path = sys.argv[1]
try:
    names = set(zipfile.ZipFile(path).namelist())
except (OSError, zipfile.BadZipFile) as error:
    sys.exit(f"install_worker: {path} is not a zip file ({error})")
missing = {"__init__.py", "blender_manifest.toml"} - names
if missing:
    sys.exit(f"install_worker: {path} is not the RaySplats extension zip: no {', '.join(sorted(missing))} at its root")
EOF
fi

check() {  # the worker's Blender, started as a job starts it: its preferences, no source tree on sys.path
  if [[ -n $bpy_python ]]; then
    "$bpy_python" "$here/check_worker.py"
  else
    "$blender" -b -noaudio --python-exit-code 1 --python "$here/check_worker.py"
  fi > "$log" 2>&1
  local status=$?
  grep '^check_worker:' "$log" >&2
  ((status == 0)) || { echo "install_worker: the worker cannot render with RaySplats (above; full log: $log)" >&2; exit 1; }
  rm -f "$log"
}
log=$(mktemp "${TMPDIR:-/tmp}/raysplats_install_worker.XXXXXX")

if [[ -n $bpy_python ]]; then
  [[ -n $zip ]] || die "--bpy-python needs the extension ZIP"
  # bl_pkg's `extension install-file` handler: what `blender --command extension install-file` runs.
  "$bpy_python" - "$zip" > "$log" 2>&1 <<'EOF'
import os, sys
import bpy
if bpy.app.version < (4, 2, 0):
    sys.exit(f"install_worker: Blender {bpy.app.version_string} has no extensions (4.2+); use its add-on folder")
from bl_pkg import bl_extension_cli
status = bl_extension_cli.cli_extension_handler(["install-file", "--repo", "user_default", "--enable", sys.argv[1]])
sys.stdout.flush()
sys.stderr.flush()
os._exit(status)  # bpy as a module crashes at exit while the enabled add-on's classes are registered
EOF
  status=$?
  ((status == 0)) || { cat "$log" >&2; die "installing $zip into $bpy_python's Blender failed (status $status)"; }
  check
  exit 0
fi

command -v "$blender" >/dev/null || die "no Blender '$blender' (give --blender EXE)"
info=$("$blender" -b --factory-startup -noaudio --python-expr "import bpy; print('RAYSPLATS_WORKER', '%d.%d' % \
bpy.app.version[:2], bpy.utils.user_resource('SCRIPTS', path='addons', create=True))" 2>/dev/null | sed -n 's/^RAYSPLATS_WORKER //p')
read -r version addons <<<"$info"
[[ -n $version && -n $addons ]] || die "could not ask $blender for its version and add-on folder"

if [[ $(printf '%s\n4.2\n' "$version" | sort -V | head -n 1) == 4.2 ]]; then
  [[ -n $zip ]] || die "Blender $version installs extensions: give the extension ZIP"
  "$blender" --command extension install-file --repo user_default --enable "$zip" > "$log" 2>&1 ||
    { cat "$log" >&2; die "Blender $version: extension install-file $zip failed"; }
elif [[ -n $zip ]]; then
  # Unpacked beside the add-on folder, then moved into place: a failed unpack leaves the old install as it was.
  mkdir -p "$addons"
  stage=$(mktemp -d "$addons/.raysplats_install.XXXXXX")
  /usr/bin/python3 -c "import sys, zipfile; zipfile.ZipFile(sys.argv[1]).extractall(sys.argv[2])" "$zip" "$stage" ||
    { rm -rf "$stage"; die "could not unpack $zip into $addons"; }
  chmod -R u+rwX,go+rX "$stage"
  rm -rf "$addons/raysplats"
  mv "$stage" "$addons/raysplats"
  "$blender" -b -noaudio --python-expr "import bpy, sys
bpy.ops.preferences.addon_enable(module='raysplats')
bpy.ops.wm.save_userpref()" > "$log" 2>&1 || { cat "$log" >&2; die "Blender $version: enabling raysplats failed"; }
else
  BLENDER="$blender" "$root/scripts/install_addon.sh" > "$log" 2>&1 || { cat "$log" >&2; die "scripts/install_addon.sh failed"; }
fi
check
