#!/usr/bin/env bash
# Configures and builds everything (core, pybind11 module for Blender's Python, CLI, tests, benchmarks).
# The module lands in addon/raysplats/, so the add-on folder is complete after this.
#   scripts/build.sh [build-dir] [extra cmake -D options]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=${1:-$root/build}
shift || true
# Blender embeds the system Python; the module must be built for exactly that interpreter.
python=/usr/bin/python3
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
cmake -S "$root" -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release -DPython_EXECUTABLE="$python" "$@" >/dev/null
cmake --build "$build" -j "$(nproc)"
