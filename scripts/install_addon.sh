#!/usr/bin/env bash
# Links addon/raysplats into Blender's user add-on folder and enables it in the user preferences, so that
# the GUI and plain `blender -b` have File > Import/Export > Gaussian Splats. Run scripts/build.sh first.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
blender=${BLENDER:-blender}
if ! ls "$root"/addon/raysplats/_native*.so >/dev/null 2>&1; then
  echo "install_addon: the native module is not built; run scripts/build.sh first" >&2
  exit 1
fi
addons=$("$blender" -b --factory-startup --python-expr \
  "import bpy; print('ADDONS=' + bpy.utils.user_resource('SCRIPTS', path='addons', create=True))" 2>/dev/null \
  | sed -n 's/^ADDONS=//p')
[[ -n $addons ]] || { echo "install_addon: could not ask Blender for its add-on folder" >&2; exit 1; }
mkdir -p "$addons"
ln -sfn "$root/addon/raysplats" "$addons/raysplats"
"$blender" -b --python-expr \
  "import bpy; bpy.ops.preferences.addon_enable(module='raysplats'); bpy.ops.wm.save_userpref()" >/dev/null 2>&1
echo "install_addon: raysplats linked into $addons and enabled"
