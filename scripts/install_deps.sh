#!/usr/bin/env bash
# Installs every Debian package RaySplats needs to build, run and test (docs/design.md §3).
# Idempotent and quick when everything is already there: apt is only called for missing packages.
set -euo pipefail

PACKAGES=(
  build-essential cmake ninja-build pkg-config
  blender python3-numpy python3-dev python3-venv pybind11-dev
  libembree-dev libglm-dev libtbb-dev
  libopenmesh-dev libtinygltf-dev nlohmann-json3-dev libstb-dev libdraco-dev draco
  libzstd-dev zlib1g-dev libwebp-dev libminizip-dev
  libgtest-dev libbenchmark-dev assimp-utils
  xvfb xauth libgl1-mesa-dri
  patchelf binutils
  # clang and libFuzzer: the fuzz targets (scripts/fuzz.sh, ctest fuzz.smoke)
  clang libclang-rt-14-dev
  # The Windows build and its tests (scripts/windows/): MinGW-w64's GCC 12 with POSIX threads, Wine to run Windows'
  # Python and Blender, Maven to fetch the Windows CPython builds, curl and unzip for Debian's source tarballs.
  g++-mingw-w64-x86-64-posix wine64 maven curl unzip
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]})); then
  echo "install_deps: installing ${missing[*]}"
  SUDO=""
  if [[ $(id -u) -ne 0 ]]; then SUDO="sudo"; fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "install_deps: all ${#PACKAGES[@]} packages present"
fi

# Node.js and npm run the test tools (Khronos glTF validator, draco3d; scripts/setup_test_tools.sh). Any
# existing installation is kept (e.g. NodeSource's nodejs, which bundles npm and conflicts with Debian's npm).
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
  echo "install_deps: installing nodejs npm (test tools)"
  SUDO=""
  if [[ $(id -u) -ne 0 ]]; then SUDO="sudo"; fi
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends nodejs npm
fi
