#!/usr/bin/env bash
# Sets everything up and runs all tests: dependencies, build, then ctest (GoogleTest for the core, the Python
# tests of the module, the Blender tests, which run in `blender -b --factory-startup --python-exit-code 1` on
# Debian's Blender 3.4 and as the PyPI `bpy` module of official builds, and the extension zip's install test).
#   scripts/test.sh [extra ctest arguments]
# Blender versions: RAYSPLATS_TEST_BLENDERS (official builds besides Debian's 3.4) is by default "4.2 4.5 5.0 5.2 5.3"
# (5.2 and 5.3 embed Python 3.13: their venvs use the interpreter scripts/setup_python313.sh finds).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/install_deps.sh"
# npm test tools (glTF validator, draco3d) into ~/.cache/raysplats/npm; ctest's setup.test_tools does it too.
"$root/scripts/setup_test_tools.sh" >/dev/null
# One cached venv per official Blender (PyPI bpy); a version PyPI cannot give is skipped with a message.
bpy_pythons=()
for version in ${RAYSPLATS_TEST_BLENDERS-4.2 4.5 5.0 5.2 5.3}; do
  python=$("$root/scripts/setup_bpy.sh" "$version")
  [[ -n $python ]] && bpy_pythons+=("$version=$python")
done
# The second native module (Python 3.13, Blender 5.1+), when this machine has a Python 3.13.
python313=$("$root/scripts/setup_python313.sh")
# The Windows tier (ctest label windows): the module and zip cross-built for Windows x64 and tested in Windows'
# Python and Blender 4.2 for Windows under Wine (docs/building.md). The first run builds the dependencies from Debian's
# sources into ~/.cache/raysplats/windows; RAYSPLATS_TEST_WINDOWS=0 leaves the tier out.
windows=()
if [[ ${RAYSPLATS_TEST_WINDOWS:-1} != 0 ]]; then
  windows_build=$("$root/scripts/windows/build.sh" "$root/build-windows")
  windows_cache=$("$root/scripts/windows/setup_pythons.sh")
  windows=(-DRAYSPLATS_WINDOWS_BUILD="$windows_build" -DRAYSPLATS_WINDOWS_BLENDER_SITE="$windows_cache/bpy-4.2")
else
  echo "test.sh: RAYSPLATS_TEST_WINDOWS=0: the Windows tier is NOT run" >&2
  windows=(-DRAYSPLATS_WINDOWS_BUILD= -DRAYSPLATS_WINDOWS_BLENDER_SITE=)
fi
"$root/scripts/build.sh" "$root/build" "-DRAYSPLATS_BPY_PYTHONS=$(IFS=';'; echo "${bpy_pythons[*]}")" \
  -DRAYSPLATS_BPY4_PYTHON= -DRAYSPLATS_EXTRA_PYTHON="$python313" "${windows[@]}"
cd "$root/build"
ctest --output-on-failure -j 2 "$@"
