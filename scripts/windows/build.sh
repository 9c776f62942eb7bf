#!/usr/bin/env bash
# Cross-builds the native module for Windows x64 on this Linux machine: _native.cp311-win_amd64.pyd (Blender 4.2 to
# 5.0) and _native.cp313-win_amd64.pyd (Blender 5.1 and newer), and raysplats.exe (the command line), with MinGW-w64
# (cmake/mingw-w64-x86_64.cmake) against the dependencies of scripts/windows/build_deps.sh and the Windows CPythons
# of scripts/windows/setup_pythons.sh. Everything is linked statically: each file needs only Windows' DLLs (and
# python3XY.dll, which Blender provides).
#   scripts/windows/build.sh [build-dir]        (default build-windows/)
# Prints the build folder; the modules land in <build>/native/python/python3XY/, the command line in <build>/native/tools/.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
build=$(realpath -m "${1:-$root/build-windows}")
prefix=$("$here/build_deps.sh")
cache=$("$here/setup_pythons.sh")
export RAYSPLATS_WINDOWS_PREFIX=$prefix
# pkg-config (zstd, libwebp, minizip) answers from the Windows prefix only.
export PKG_CONFIG_LIBDIR=$prefix/lib/pkgconfig PKG_CONFIG_PATH=
cmake -S "$root" -B "$build" -G Ninja -DCMAKE_TOOLCHAIN_FILE="$root/cmake/mingw-w64-x86_64.cmake" \
  -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH="$prefix" -DBUILD_TESTING=OFF -DRAYSPLATS_BLENDER_TESTS=OFF \
  -DZLIB_LIBRARY="$prefix/lib/libz.a" -DZLIB_INCLUDE_DIR="$prefix/include" -DTBB_DIR="$prefix/lib/cmake/TBB" \
  "-DRAYSPLATS_WINDOWS_PYTHONS=3.11=$cache/cpython-3.11;3.13=$cache/cpython-3.13" \
  -DRAYSPLATS_PYBIND11_INCLUDE="$cache/pybind11/include" >&2
cmake --build "$build" -j "$(nproc)" --target _native_py311 _native_py313 raysplats >&2
echo "$build"
