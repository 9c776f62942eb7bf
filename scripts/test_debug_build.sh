#!/usr/bin/env bash
# Builds the core and its Gaussian render tests unoptimised (CMAKE_BUILD_TYPE=Debug, -O0) in its own folder and runs the render
# tests that check Gaussian images against independent references (an exact alpha, brute-force compositing, flat
# against volumetric) with the machine's group test (AVX2 + FMA where the CPU has them). At -O0 nothing is inlined
# but always_inline functions, so this is where a vector passed between code built for different instruction sets
# (the AVX2 callbacks and their helpers) shows: with the helpers not always_inline, the first test crashes.
# scripts/test.sh runs it through ctest (core.debug_build).
#   scripts/test_debug_build.sh [build-dir (default build-debug/)]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-$root/build-debug}
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
cmake -S "$root" -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=Debug -DRAYSPLATS_BUILD_PYTHON=OFF \
  -DRAYSPLATS_BLENDER_TESTS=OFF >/dev/null
cmake --build "$build" -j "$(nproc)" --target raysplats_render_gaussian_tests
tests=$build/native/tests/raysplats_render_gaussian_tests
# The tests it runs, by name: a filter that matches fewer (one renamed, one removed) must fail, not pass on nothing.
names=(RenderGaussian.SingleGaussianHeadOnAlphaIsExact RenderGaussian.SortedGatherEqualsBruteForce
       RenderGaussian.FlatAndVolumetricDifferObliquely)
filter=$(IFS=:; echo "${names[*]}")
# --gtest_list_tests prints each suite ("Suite.") and then its tests indented.
listed=$("$tests" --gtest_filter="$filter" --gtest_list_tests | awk '/^[^ ]/ { suite = $1 } /^  / { print suite $1 }')
for name in "${names[@]}"; do
  grep -qx "$name" <<<"$listed" || { echo "test_debug_build: no test $name in $tests (renamed?)" >&2; exit 1; }
done
# Every one of them ran and passed (a skip is not a pass here).
"$root/scripts/lib/run_gtest.py" "$tests" --gtest_filter="$filter" --gtest_brief=1 | tee "$build/debug-tests.txt"
summary=$(tail -n 1 "$build/debug-tests.txt")
if [[ $summary != "${#names[@]} passed, 0 failed, 0 skipped" ]]; then
  echo "test_debug_build: expected ${#names[@]} tests to pass, got: $summary" >&2
  exit 1
fi
