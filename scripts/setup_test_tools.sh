#!/usr/bin/env bash
# Installs the npm test tools (Khronos glTF validator, draco3d decoder, PlayCanvas splat-transform) into a cache folder
# outside the repository, once. splat-transform is pinned to 2.7.1, the last release that runs on Debian's Node 18
# (3.x needs Node 22). Prints the folder. When npm or its registry is unreachable it says so on stderr and exits 0:
# the tests that need the tools then skip with that message.
#   scripts/setup_test_tools.sh            -> $RAYSPLATS_NPM_DIR (default ~/.cache/raysplats/npm)
set -uo pipefail
dir=${RAYSPLATS_NPM_DIR:-$HOME/.cache/raysplats/npm}
packages=(gltf-validator@2.0.0-dev.3.10 draco3d@1.5.7 @playcanvas/splat-transform@2.7.1)
mkdir -p "$dir"
if [[ -f $dir/node_modules/gltf-validator/package.json && -f $dir/node_modules/draco3d/package.json &&
      -f $dir/node_modules/@playcanvas/splat-transform/package.json ]]; then
  echo "$dir"
  exit 0
fi
if ! command -v npm >/dev/null; then
  echo "setup_test_tools: npm is not installed (scripts/install_deps.sh installs it): glTF validator tests will be skipped" >&2
  echo "$dir"
  exit 0
fi
if ! timeout 300 npm install --silent --no-audit --no-fund --prefix "$dir" "${packages[@]}" >"$dir/install.log" 2>&1; then
  echo "setup_test_tools: npm install failed (registry unreachable?), see $dir/install.log: glTF validator tests will be skipped" >&2
fi
echo "$dir"
