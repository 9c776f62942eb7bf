#!/usr/bin/env bash
# Installs the npm test tools (Khronos glTF validator, draco3d decoder, PlayCanvas splat-transform) into a cache folder
# outside the repository, once. splat-transform is pinned to 2.7.1, the last release that runs on Debian's Node 18
# (3.x needs Node 22). Prints the folder. When npm or its registry is unreachable it fails under strict mode
# (scripts/lib/tiers.sh: CI=true or RAYSPLATS_STRICT=1); otherwise it says so on stderr and exits 0, and the tests that
# need the tools skip with that message.
#   scripts/setup_test_tools.sh            -> $RAYSPLATS_NPM_DIR (default ~/.cache/raysplats/npm)
set -uo pipefail
source "$(dirname "$0")/lib/tiers.sh"
dir=${RAYSPLATS_NPM_DIR:-$HOME/.cache/raysplats/npm}
packages=(gltf-validator@2.0.0-dev.3.10 draco3d@1.5.7 @playcanvas/splat-transform@2.7.1)
mkdir -p "$dir"
if [[ -f $dir/node_modules/gltf-validator/package.json && -f $dir/node_modules/draco3d/package.json &&
      -f $dir/node_modules/@playcanvas/splat-transform/package.json ]]; then
  echo "$dir"
  exit 0
fi
if ! command -v npm >/dev/null; then
  tier_unavailable "npm test tools" "npm is not installed (scripts/install_deps.sh installs it): glTF validator tests skip" || exit 1
  echo "$dir"
  exit 0
fi
if ! timeout 300 npm install --silent --no-audit --no-fund --prefix "$dir" "${packages[@]}" >"$dir/install.log" 2>&1; then
  tier_unavailable "npm test tools" "npm install failed (registry unreachable?), see $dir/install.log: glTF validator tests skip" || exit 1
fi
echo "$dir"
