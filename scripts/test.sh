#!/usr/bin/env bash
# Sets everything up and runs all tests: dependencies, build, then ctest (GoogleTest for the core, the Python
# tests of the module, the Blender tests, which run in `blender -b --factory-startup --python-exit-code 1` on
# Debian's Blender 3.4 and as the PyPI `bpy` module of official builds, and the extension zip's install test).
#   scripts/test.sh [extra ctest arguments]
# Blender versions: RAYSPLATS_TEST_BLENDERS (official builds besides Debian's 3.4) is by default "4.2 4.5 5.0 5.2 5.3"
# (5.2 and 5.3 embed Python 3.13: their venvs use the interpreter scripts/setup_python313.sh finds).
# Strict mode (CI=true, or RAYSPLATS_STRICT=1; RAYSPLATS_STRICT=0 turns it off): a Blender, Python 3.13, tool or data
# set named here that cannot be set up fails the run, naming it, and so does any skip whose reason does not start with
# "expected: ". Otherwise a tier that cannot be set up is left out and named, loudly, after the summary.
# The run ends with one summary (scripts/lib/summarize_tests.py, from ctest's JUnit report build/test-results.xml):
# "N passed, N failed, N skipped", then the reason of each skip.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
source "$root/scripts/lib/tiers.sh"
mkdir -p "$root/build"
# The tiers not set up, for the summary; the setup scripts ctest runs (setup.test_tools, farm.setup_openjd) add theirs.
export RAYSPLATS_TIERS_FILE=$root/build/test-tiers.txt
: >"$RAYSPLATS_TIERS_FILE"
if raysplats_strict; then
  echo "test.sh: strict mode (CI=${CI:-} RAYSPLATS_STRICT=${RAYSPLATS_STRICT:-}): every tier must run" >&2
fi
"$root/scripts/install_deps.sh"
for tool in blender xvfb-run node npm; do
  require_tier "$tool" "$tool is not on PATH (scripts/install_deps.sh installs it)" command -v "$tool" || exit 1
done
data=${RAYSPLATS_DATA_DIR:-$root/../shared/data}
if [[ -z $(ls -A "$data" 2>/dev/null) ]]; then
  tier_unavailable "data set" "no real scenes in $data (the README's ../shared/data)" || exit 1
fi
# The Windows tier's dependencies (scripts/windows/build_deps.sh: compiling, on a first run) are built in the
# background while the Blenders and Pythons below download; quick when its cache is already built.
windows_deps_pid=
stop_windows_deps() { [[ -z $windows_deps_pid ]] || kill -- "-$windows_deps_pid" 2>/dev/null || true; }
if [[ ${RAYSPLATS_TEST_WINDOWS:-1} != 0 ]]; then
  setsid -w "$root/scripts/windows/build_deps.sh" >"$root/build/windows-deps.log" 2>&1 &
  windows_deps_pid=$!
  trap stop_windows_deps EXIT
fi
# npm test tools (glTF validator, draco3d) into ~/.cache/raysplats/npm; ctest's setup.test_tools does it too.
"$root/scripts/setup_test_tools.sh" >/dev/null
# One cached venv per official Blender (PyPI bpy).
bpy_pythons=()
for version in ${RAYSPLATS_TEST_BLENDERS-4.2 4.5 5.0 5.2 5.3}; do
  python=$("$root/scripts/setup_bpy.sh" "$version") || python=
  if [[ -n $python ]]; then
    bpy_pythons+=("$version=$python")
  else
    tier_unavailable "Blender $version (PyPI bpy)" "scripts/setup_bpy.sh $version could not set it up (its reason is above)" ||
      exit 1
  fi
done
# The second native module (Python 3.13, Blender 5.1+) and with it the extension zip's tests.
python313=$("$root/scripts/setup_python313.sh") || python313=
if [[ -z $python313 ]]; then
  tier_unavailable "Python 3.13" "scripts/setup_python313.sh found none: no module for Blender 5.1+, no extension zip" ||
    exit 1
fi
# The Windows tier (ctest label windows): the module and zip cross-built for Windows x64 and tested in Windows'
# Python and Blender 4.2 for Windows under Wine (docs/building.md). The first run builds the dependencies from Debian's
# sources into ~/.cache/raysplats/windows; RAYSPLATS_TEST_WINDOWS=0 leaves the tier out. Windows' Pythons download
# while the dependencies still compile.
windows=(-DRAYSPLATS_WINDOWS_BUILD= -DRAYSPLATS_WINDOWS_BLENDER_SITE=)
if [[ ${RAYSPLATS_TEST_WINDOWS:-1} == 0 ]]; then
  tier_unavailable "Windows" "RAYSPLATS_TEST_WINDOWS=0 left it out" || exit 1
else
  windows_cache=$("$root/scripts/windows/setup_pythons.sh") || windows_cache=
  deps_status=0
  wait "$windows_deps_pid" || deps_status=$?
  windows_deps_pid=
  if [[ -z $windows_cache ]]; then
    tier_unavailable "Windows" "scripts/windows/setup_pythons.sh could not set up Windows' Pythons (above)" || exit 1
  elif ((deps_status)); then
    tail -n 30 "$root/build/windows-deps.log" >&2
    tier_unavailable "Windows" "scripts/windows/build_deps.sh failed (status $deps_status; build/windows-deps.log)" ||
      exit 1
  elif ! windows_build=$("$root/scripts/windows/build.sh" "$root/build-windows"); then
    tier_unavailable "Windows" "scripts/windows/build.sh could not cross-build the module (its reason is above)" ||
      exit 1
  else
    windows=(-DRAYSPLATS_WINDOWS_BUILD="$windows_build" -DRAYSPLATS_WINDOWS_BLENDER_SITE="$windows_cache/bpy-4.2")
  fi
fi
"$root/scripts/build.sh" "$root/build" "-DRAYSPLATS_BPY_PYTHONS=$(IFS=';'; echo "${bpy_pythons[*]}")" \
  -DRAYSPLATS_BPY4_PYTHON= -DRAYSPLATS_EXTRA_PYTHON="$python313" -DRAYSPLATS_DATA_DIR="$(realpath -m "$data")" \
  "${windows[@]}"
cd "$root/build"
# Passed tests' output is kept (its end, where the reporters print their skips) for the summary.
status=0
ctest --output-on-failure -j 2 --output-junit "$root/build/test-results.xml" --test-output-truncation tail \
  --test-output-size-passed 262144 --test-output-size-failed 1048576 "$@" || status=$?
strict=()
raysplats_strict && strict=(--strict)
echo
"$root/scripts/lib/summarize_tests.py" "$root/build/test-results.xml" --tiers "$RAYSPLATS_TIERS_FILE" "${strict[@]}" ||
  status=1
exit "$status"
