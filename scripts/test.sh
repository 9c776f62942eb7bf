#!/usr/bin/env bash
# Sets everything up and runs all tests: dependencies, build, then ctest (GoogleTest for the core and the
# Blender tests, which run in `blender -b --factory-startup --python-exit-code 1`).
#   scripts/test.sh [extra ctest arguments]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/install_deps.sh"
# npm test tools (glTF validator, draco3d) into ~/.cache/raysplats/npm; ctest's setup.test_tools does it too.
"$root/scripts/setup_test_tools.sh" >/dev/null
# Blender 4.2 LTS (PyPI bpy) beside Debian's 3.4, when PyPI is reachable: registers the bpy4.* tests.
bpy4_python=$("$root/scripts/setup_bpy4.sh")
"$root/scripts/build.sh" "$root/build" -DRAYSPLATS_BPY4_PYTHON="$bpy4_python"
cd "$root/build"
ctest --output-on-failure -j 2 "$@"
