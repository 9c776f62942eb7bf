#!/usr/bin/env bash
# Runs Blender's own extension validator (`blender --command extension validate`) on a zip. The validator is the
# bl_pkg add-on's blender_ext.py, which runs with any Python 3.11 or newer: the newest bpy venv of scripts/setup_bpy.sh
# is used. Without one it says so and succeeds, except under CI=true or RAYSPLATS_STRICT=1, where it fails.
#   scripts/validate_extension_zip.sh ZIP
set -euo pipefail
zip=${1:?usage: scripts/validate_extension_zip.sh ZIP}
validator=$(ls -d "$HOME"/.cache/raysplats/bpy*-venv/lib/python3*/site-packages/bpy/[0-9]*/scripts/addons_core/bl_pkg/cli/blender_ext.py \
            2>/dev/null | sort -V | tail -n 1 || true)
if [[ -z $validator ]]; then
  echo "validate_extension_zip: no bpy venv (scripts/setup_bpy.sh 5.0): Blender's validator not run on $zip" >&2
  [[ ${CI:-} == true || ${RAYSPLATS_STRICT:-0} == 1 ]] && exit 1
  exit 0
fi
venv_python=${validator%%/lib/python3*}/bin/python
"$venv_python" "$validator" validate "$zip"
blender_version=$(basename "$(dirname "$(dirname "$(dirname "$(dirname "$(dirname "$validator")")")")")")
echo "validate_extension_zip: Blender's validator ($blender_version) accepts $(basename "$zip")"
