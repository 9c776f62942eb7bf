#!/usr/bin/env bash
# Builds the installable Blender extension for Windows x64: dist/raysplats-<version>-windows_x64.zip, beside the
# Linux zip of scripts/package_extension.sh. It holds the add-on and the native module for Python 3.11 (Blender 4.2
# to 5.0) and 3.13 (Blender 5.1 and newer), each a single static .pyd: no DLL travels with it, so none can clash with
# the ones Blender for Windows ships. Checked by scripts/windows/check_windows_zip.py and Blender's validator.
#   scripts/windows/package.sh [--no-build] [build-dir]      (default build-windows/)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
build_first=1
if [[ ${1:-} == --no-build ]]; then build_first=0; shift; fi
build=$(realpath -m "${1:-$root/build-windows}")
die() { echo "windows package: $*" >&2; exit 1; }
if ((build_first)); then "$here/build.sh" "$build" >/dev/null; fi

addon=$root/addon/raysplats
modules=("$build"/native/python/python311/_native.cp311-win_amd64.pyd "$build"/native/python/python313/_native.cp313-win_amd64.pyd)
for module in "${modules[@]}"; do
  [[ -f $module ]] || die "$module was not built (scripts/windows/build.sh)"
done
version=$(sed -n 's/^version *= *"\(.*\)"/\1/p' "$addon/blender_manifest.toml")
[[ -n $version ]] || die "no version in $addon/blender_manifest.toml"

stage=$build/extension/raysplats
rm -rf "$stage"
mkdir -p "$stage" "$root/dist"
# The add-on's sources as they are in the repository (no caches, no Linux modules).
(cd "$addon" && find . -type f \( -name '*.py' -o -name '*.toml' -o -name '*.md' \) -not -path '*/__pycache__/*' \
   -exec cp --parents {} "$stage/" \;)
cp "${modules[@]}" "$stage/"
x86_64-w64-mingw32-strip --strip-unneeded "$stage"/_native.*.pyd

zip=$root/dist/raysplats-$version-windows_x64.zip
"$root/scripts/write_extension_zip.py" "$stage" "$zip" windows-x64
"$here/check_windows_zip.py" "$zip" || die "$zip fails its checks (above)"
"$root/scripts/validate_extension_zip.sh" "$zip" || die "Blender's extension validator rejects $zip (above)"
echo "windows package: $zip ($(du -h "$zip" | cut -f1))"
