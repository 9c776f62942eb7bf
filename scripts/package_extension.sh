#!/usr/bin/env bash
# Builds the installable Blender extension: dist/raysplats-<version>-linux_x64.zip (Blender 4.2 and newer:
# Edit > Preferences > Get Extensions > Install from Disk). It holds the add-on, the native module for
# Python 3.11 (Blender 4.2 to 5.0) and for Python 3.13 (Blender 5.1 and newer), and every shared library they
# need beside them with RPATH $ORIGIN, so that it needs nothing from the system but glibc and libstdc++.
# Then it checks that (scripts/check_extension_libraries.py) and, when a bpy venv of scripts/setup_bpy.sh is
# there, runs Blender's own extension validator on the zip.
#   scripts/package_extension.sh [--no-build] [build-dir]
# --no-build: package the modules as they are (ctest's extension.package, which runs inside a finished build).
# Run scripts/install_deps.sh first (patchelf, binutils). Idempotent: the zip is made anew every time.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build_first=1
if [[ ${1:-} == --no-build ]]; then build_first=0; shift; fi
build=$(realpath -m "${1:-$root/build}")
die() { echo "package_extension: $*" >&2; exit 1; }

for tool in patchelf readelf strip ldd; do
  command -v "$tool" >/dev/null || die "'$tool' is missing; run scripts/install_deps.sh"
done
if ((build_first)); then
  python313=$("$root/scripts/setup_python313.sh")
  [[ -n $python313 ]] || die "the zip needs the module for Python 3.13 (Blender 5.1+), and no Python 3.13 was found (see above)"
  # Incremental: a no-op when scripts/test.sh or a developer already built both modules in this build directory.
  "$root/scripts/build.sh" "$build" -DRAYSPLATS_EXTRA_PYTHON="$python313"
fi

addon=$root/addon/raysplats
modules=("$addon"/_native.cpython-311-x86_64-linux-gnu.so "$addon"/_native.cpython-313-x86_64-linux-gnu.so)
for module in "${modules[@]}"; do
  [[ -f $module ]] || die "$module was not built (see the build output above)"
done
version=$(sed -n 's/^version *= *"\(.*\)"/\1/p' "$addon/blender_manifest.toml")
[[ -n $version ]] || die "no version in $addon/blender_manifest.toml"

stage=$build/extension/raysplats
rm -rf "$stage"
mkdir -p "$stage" "$root/dist"
# The add-on's sources as they are in the repository (no caches, no modules of other Python versions).
(cd "$addon" && find . -type f \( -name '*.py' -o -name '*.toml' -o -name '*.md' \) -not -path '*/__pycache__/*' \
   -exec cp --parents {} "$stage/" \;)
cp "${modules[@]}" "$stage/"
strip --strip-unneeded "$stage"/_native.*.so

# Every library the modules load, directly or through another library (ldd lists the whole closure), except
# the system's own (the list check_extension_libraries.py allows), copied under its SONAME.
allowed='^(libc\.so\.6|libm\.so\.6|libpthread\.so\.0|libdl\.so\.2|librt\.so\.1|ld-linux-x86-64\.so\.2|libstdc\+\+\.so\.6|libgcc_s\.so\.1|linux-vdso\.so\.1)$'
for module in "${modules[@]}"; do
  ldd "$module" | while read -r name arrow path _; do
    [[ $name =~ $allowed || $arrow != "=>" ]] && continue
    [[ -f $path ]] || die "$module needs $name, which the loader does not find"
    cp -L "$path" "$stage/$name"
  done
done
# $ORIGIN: each object finds its libraries in its own folder. DT_RPATH (--force-rpath) rather than DT_RUNPATH,
# so that an LD_LIBRARY_PATH with other builds of the same libraries (another Embree 3) cannot take over.
for object in "$stage"/*.so*; do
  chmod u+w "$object"
  patchelf --force-rpath --set-rpath '$ORIGIN' "$object"
done

zip=$root/dist/raysplats-$version-linux_x64.zip
"$root/scripts/write_extension_zip.py" "$stage" "$zip" linux-x64

"$root/scripts/check_extension_libraries.py" "$zip" || die "$zip needs libraries it does not carry (see above)"

"$root/scripts/validate_extension_zip.sh" "$zip" || die "Blender's extension validator rejects $zip (above)"
echo "package_extension: $zip ($(du -h "$zip" | cut -f1))"
