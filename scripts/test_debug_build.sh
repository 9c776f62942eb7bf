#!/usr/bin/env bash
# Builds the core's GoogleTest binary unoptimised (CMAKE_BUILD_TYPE=Debug, -O0) in its own folder and runs the render
# tests that check images against independent references (RenderGaussian: brute-force compositing, exact alphas)
# and across Embree's instruction sets (RenderEmbreeIsa), on both SIMD paths of the Gaussian test. At -O0 nothing is
# inlined but always_inline functions, so this is where a vector passed between code built for different
# instruction sets (the AVX2 callbacks and their helpers) would show. scripts/test.sh runs it through ctest
# (core.debug_build).
#   scripts/test_debug_build.sh [build-dir (default build-debug/)]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-$root/build-debug}
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
cmake -S "$root" -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=Debug -DRAYSPLATS_BUILD_PYTHON=OFF \
  -DRAYSPLATS_BLENDER_TESTS=OFF >/dev/null
cmake --build "$build" -j "$(nproc)" --target raysplats_tests
tests=$build/native/tests/raysplats_tests
filter='RenderGaussian.*:RenderEmbreeIsa.*'
"$tests" --gtest_filter="$filter" --gtest_brief=1
RAYSPLATS_SIMD=sse "$tests" --gtest_filter="$filter" --gtest_brief=1
