#!/usr/bin/env bash
# Sets everything up and runs all tests: dependencies, build, then ctest (GoogleTest for the core and the
# Blender tests, which run in `blender -b --factory-startup --python-exit-code 1`).
#   scripts/test.sh [extra ctest arguments]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/install_deps.sh"
"$root/scripts/build.sh" "$root/build"
cd "$root/build"
ctest --output-on-failure -j 2 "$@"
