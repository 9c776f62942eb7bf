#!/usr/bin/env bash
# Cross-builds the native core's C/C++ dependencies for 64-bit Windows, once, into a cached prefix
# (~/.cache/raysplats/windows/prefix, or $RAYSPLATS_WINDOWS_PREFIX). Each comes from the Debian 12 source package the
# Linux build's binary package is made from (the same upstream version, so both platforms run the same code); the
# header-only ones (GLM, tinygltf, nlohmann-json, stb) are the Debian packages' own headers, and pybind11 is PyPI's
# (the 3.13 module needs 2.13; Debian 12 has 2.10). Everything is static: the module links it all in, so it loads no
# DLL of ours and none that Blender for Windows also ships (Blender has its own embree4.dll and tbb.dll; a DLL of the
# same name beside our module would be replaced by Blender's).
#   scripts/windows/build_deps.sh          prints the prefix; quick when the prefix is already built by this script
# The prefix is rebuilt whenever this script, a patch or the toolchain file changes (a stamp records their hash).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
cache=${RAYSPLATS_WINDOWS_CACHE:-$HOME/.cache/raysplats/windows}
prefix=${RAYSPLATS_WINDOWS_PREFIX:-$cache/prefix}
toolchain=$root/cmake/mingw-w64-x86_64.cmake
jobs=$(nproc)

# Debian 12 source packages: name, version of the upstream tarball, SHA-256 of it (as Debian's signed Sources index
# lists it; checked again here so that the cache cannot hold a different file).
SOURCES=(
  "onetbb      2021.8.0      7e9111b8bb59c8800bf6d0b06afe7b0891937443d2dae1ee1101c8e2ede6a7ef onetbb_2021.8.0.orig.tar.xz"
  "embree      3.13.5+dfsg   1b7c5b6144230ad81b92ece884a2017fbbb433bf5416a6fca9257e0109501c63 embree_3.13.5+dfsg.orig.tar.xz"
  "libzstd     1.5.4+dfsg2   8cf4bbb65e77ec348d052c8d6230eba66d435bddf64c8b5be2fcb16880c19953 libzstd_1.5.4+dfsg2.orig.tar.xz"
  "libwebp     1.2.4         7bf5a8a28cc69bcfa8cb214f2c3095703c6b73ac5fba4d5480c205331d9494df libwebp_1.2.4.orig.tar.gz"
  "zlib        1.2.13.dfsg   71feb7947e3c00ef125f83b79a4e529bde31171e5babe48b391f06758d1ab0a1 zlib_1.2.13.dfsg.orig.tar.bz2"
  "openmesh    9.0           4df84295f5cca86b1ae8bfee8ff4db5efb6850e4e5b571ad0199147176dea796 openmesh_9.0.orig.tar.gz"
  "draco       1.5.5+dfsg    0d4ff5b218a2f9d836c6f44202918402591407b5f59a5103ec288c5600ab087f draco_1.5.5+dfsg.orig.tar.xz"
)

stamp_of() {
  cat "$0" "$toolchain" "$here"/patches/* "$here"/minizip/CMakeLists.txt | sha256sum | cut -c1-16
}
stamp=$(stamp_of)
if [[ -f $prefix/.raysplats-stamp && $(cat "$prefix/.raysplats-stamp") == "$stamp" ]]; then
  echo "$prefix"
  exit 0
fi

log() { echo "windows deps: $*" >&2; }
for tool in x86_64-w64-mingw32-g++-posix cmake ninja curl; do
  command -v "$tool" >/dev/null || { log "$tool is missing (scripts/windows/install_tools.sh installs it)"; exit 1; }
done

# A private source list: deb-src for bookworm without touching the machine's own apt configuration.
apt_dir=$cache/apt
mkdir -p "$apt_dir/lists/partial" "$apt_dir/archives/partial" "$cache/tarballs"
echo "deb-src http://deb.debian.org/debian bookworm main" > "$apt_dir/sources.list"
apt_opts=(-o "Dir::Etc::SourceList=$apt_dir/sources.list" -o "Dir::Etc::SourceParts=/dev/null"
          -o "Dir::State::Lists=$apt_dir/lists" -o "Dir::Cache=$apt_dir")
# apt drops to its _apt user to download, which cannot write into root's home: download as the caller instead.
(( $(id -u) == 0 )) && apt_opts+=(-o "APT::Sandbox::User=root")
apt_updated=0
fetch() {  # fetch NAME VERSION SHA256 FILE: the upstream tarball of a Debian source package, checked
  local name=$1 version=$2 sha=$3 file=$4 target=$cache/tarballs/$4
  if [[ -f $target ]] && echo "$sha  $target" | sha256sum -c --quiet 2>/dev/null; then return; fi
  if (( ! apt_updated )); then
    apt-get "${apt_opts[@]}" update -qq >&2 || { log "apt-get update of the private source list failed"; exit 1; }
    apt_updated=1
  fi
  local uri
  # The source package's current bookworm version; its upstream tarball is the pinned one (checked below).
  uri=$(apt-get "${apt_opts[@]}" --print-uris source "$name" 2>/dev/null | tr -d "'" |
        awk -v f="$file" '$2 == f {print $1}' | head -1) || true
  [[ -n $uri ]] || { log "Debian's archive lists no $file (source package $name)"; exit 1; }
  curl -fsSL -o "$target.part" "$uri" || { log "could not download $uri"; exit 1; }
  echo "$sha  $target.part" | sha256sum -c --quiet || { log "$file: SHA-256 differs from the pinned one"; exit 1; }
  mv "$target.part" "$target"
}

work=$cache/work
rm -rf "$work" "$prefix"
mkdir -p "$work" "$prefix"
export RAYSPLATS_WINDOWS_PREFIX=$prefix   # read by the toolchain file: the prefix is a find root
unpack() {  # unpack FILE -> prints the source folder
  local dir=$work/src-${1%%_*}
  mkdir -p "$dir"
  tar -xf "$cache/tarballs/$1" -C "$dir" --strip-components=1
  echo "$dir"
}
cmake_build() {  # cmake_build NAME SOURCE [cmake options...]
  local name=$1 src=$2
  shift 2
  log "building $name"
  local start=$SECONDS
  cmake -S "$src" -B "$work/build-$name" -G Ninja -DCMAKE_TOOLCHAIN_FILE="$toolchain" -DCMAKE_BUILD_TYPE=Release \
        -DCMAKE_INSTALL_PREFIX="$prefix" -DCMAKE_PREFIX_PATH="$prefix" -DBUILD_SHARED_LIBS=OFF "$@" \
        > "$work/$name.configure.log" 2>&1 || { tail -30 "$work/$name.configure.log" >&2; exit 1; }
  cmake --build "$work/build-$name" -j "$jobs" > "$work/$name.build.log" 2>&1 ||
    { grep -m5 -B2 -A8 "error" "$work/$name.build.log" >&2 || tail -30 "$work/$name.build.log" >&2; exit 1; }
  cmake --install "$work/build-$name" > /dev/null
  log "built $name in $((SECONDS - start)) s"
}

for entry in "${SOURCES[@]}"; do
  read -r name version sha file <<< "$entry"
  fetch "$name" "$version" "$sha" "$file"
done
file_of() { local e; for e in "${SOURCES[@]}"; do read -r n _ _ f <<< "$e"; [[ $n == "$1" ]] && echo "$f"; done; }

# oneTBB: the renderer's parallel loops, and Embree's tasking system as on Linux (Debian builds Embree on TBB).
cmake_build onetbb "$(unpack "$(file_of onetbb)")" -DTBB_TEST=OFF -DTBB_EXAMPLES=OFF -DTBB_STRICT=OFF \
  -DTBBMALLOC_BUILD=OFF -DTBBMALLOC_PROXY_BUILD=OFF

# Embree 3: Debian's configuration (TBB tasking, ray masks, filter functions, no backface culling) with the kernels
# every x86-64 Windows CPU may pick (SSE2, SSE4.2, AVX, AVX2; AVX-512 is left out: GCC cannot keep 64-byte stack
# alignment on Windows, and nothing here could run it) and only the geometry types the renderer makes (triangles,
# user geometry for the Gaussians, instances). The patch: MinGW taken for GCC rather than MSVC, no ELF-only
# -z link flags, no UTF-16 version resource in a static library, the static TBB's Threads dependency found, and the
# sources of the geometry types left out (curves, points, quads, grids) not compiled: upstream compiles their
# intersectors for every instruction set whatever the options, the costliest files of the whole build.
src=$(unpack "$(file_of embree)")
patch -d "$src" -p1 --quiet < "$here/patches/embree-mingw.patch"
cmake_build embree "$src" -DEMBREE_STATIC_LIB=ON -DEMBREE_TASKING_SYSTEM=TBB -DTBB_DIR="$prefix/lib/cmake/TBB" \
  -DEMBREE_ISPC_SUPPORT=OFF -DEMBREE_TUTORIALS=OFF -DEMBREE_MAX_ISA=NONE -DEMBREE_ISA_SSE2=ON -DEMBREE_ISA_SSE42=ON \
  -DEMBREE_ISA_AVX=ON -DEMBREE_ISA_AVX2=ON -DEMBREE_ISA_AVX512=OFF -DEMBREE_RAY_MASK=ON -DEMBREE_FILTER_FUNCTION=ON \
  -DEMBREE_BACKFACE_CULLING=OFF -DEMBREE_GEOMETRY_TRIANGLE=ON -DEMBREE_GEOMETRY_USER=ON -DEMBREE_GEOMETRY_INSTANCE=ON \
  -DEMBREE_GEOMETRY_QUAD=OFF -DEMBREE_GEOMETRY_CURVE=OFF -DEMBREE_GEOMETRY_SUBDIVISION=OFF \
  -DEMBREE_GEOMETRY_POINT=OFF -DEMBREE_GEOMETRY_GRID=OFF

# zstd (SPZ v4 reading), libwebp (SOG images), zlib and minizip (SPZ, SOG archives).
src=$(unpack "$(file_of libzstd)")
cmake_build zstd "$src/build/cmake" -DZSTD_BUILD_SHARED=OFF -DZSTD_BUILD_STATIC=ON -DZSTD_BUILD_PROGRAMS=OFF \
  -DZSTD_BUILD_TESTS=OFF -DZSTD_LEGACY_SUPPORT=ON
cmake_build webp "$(unpack "$(file_of libwebp)")" -DWEBP_BUILD_ANIM_UTILS=OFF -DWEBP_BUILD_CWEBP=OFF \
  -DWEBP_BUILD_DWEBP=OFF -DWEBP_BUILD_GIF2WEBP=OFF -DWEBP_BUILD_IMG2WEBP=OFF -DWEBP_BUILD_VWEBP=OFF \
  -DWEBP_BUILD_WEBPINFO=OFF -DWEBP_BUILD_WEBPMUX=OFF -DWEBP_BUILD_EXTRAS=OFF
# zlib's own build makes a DLL; the library and minizip (zlib's contrib, Debian's libminizip) are built static by a
# small CMake file of ours.
cmake_build zlib "$here/minizip" -DZLIB_SOURCE_DIR="$(unpack "$(file_of zlib)")"

# OpenMesh (OBJ/PLY writers) and Draco (glTF mesh compression): the libraries only.
cmake_build openmesh "$(unpack "$(file_of openmesh)")" -DBUILD_APPS=OFF -DOPENMESH_DOCS=OFF \
  -DOPENMESH_BUILD_UNIT_TESTS=OFF -DOPENMESH_BUILD_SHARED=OFF -DOPENMESH_BUILD_PYTHON_BINDINGS=OFF
cmake_build draco "$(unpack "$(file_of draco)")" -DDRACO_TESTS=OFF -DDRACO_JS_GLUE=OFF \
  -DDRACO_TRANSCODER_SUPPORTED=OFF

# Header-only libraries: the Debian packages' headers and CMake files (architecture-independent).
mkdir -p "$prefix/include" "$prefix/share/cmake"
cp -r /usr/include/glm /usr/include/nlohmann /usr/include/stb "$prefix/include/"
cp /usr/include/tiny_gltf.h "$prefix/include/"
cp -r /usr/share/cmake/glm /usr/share/cmake/nlohmann_json "$prefix/share/cmake/"

rm -rf "$work"
echo "$stamp" > "$prefix/.raysplats-stamp"
log "done: $prefix"
echo "$prefix"
