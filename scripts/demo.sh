#!/usr/bin/env bash
# Sets everything up and runs the demo: import a real splat scene into Blender, edit it, render it, and
# export it (headless). Outputs go to demo_output/.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/scripts/install_deps.sh"
"$root/scripts/build.sh" "$root/build"
blender -b --factory-startup --python-exit-code 1 --python "$root/examples/demo.py" -- \
  --data-dir "$root/../shared/data" --out-dir "$root/demo_output" "$@"
