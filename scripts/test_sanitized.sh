#!/usr/bin/env bash
# Builds the core and its GoogleTest binary with AddressSanitizer + UndefinedBehaviorSanitizer (RAYSPLATS_SANITIZE) in
# build-sanitize/ and runs the core tests (ctest -L core). Not part of scripts/test.sh: the sanitized build and run take
# several times as long as the normal ones.
#   scripts/test_sanitized.sh [extra ctest arguments]
# RAYSPLATS_SANITIZE_BUILD: the build folder (default build-sanitize/).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${RAYSPLATS_SANITIZE_BUILD:-$root/build-sanitize}
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
cmake -S "$root" -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DRAYSPLATS_SANITIZE=ON \
  -DRAYSPLATS_BUILD_PYTHON=OFF -DRAYSPLATS_BLENDER_TESTS=OFF >/dev/null
cmake --build "$build" -j "$(nproc)" --target raysplats_tests
cd "$build"
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1}
ctest --output-on-failure -j 2 -L core "$@"
