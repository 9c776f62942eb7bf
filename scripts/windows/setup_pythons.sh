#!/usr/bin/env bash
# The Windows side's Pythons and Python packages, cached in ~/.cache/raysplats/windows (or $RAYSPLATS_WINDOWS_CACHE):
# - cpython-3.11, cpython-3.13: the official Windows CPython builds (python.exe, DLLs, the standard library, headers
#   and import libraries) from Maven Central's org.bytedeco:cpython, classifier windows-x86_64, fetched with mvn.
#   Blender 4.2 to 5.0 embed 3.11, Blender 5.1 and newer 3.13.
# - site-3.11, site-3.13: numpy for each (PyPI win_amd64 wheels, unpacked as pip would install them).
# - pybind11: PyPI's pybind11 headers (2.13: the first release that supports Python 3.13).
# - bpy-4.2: Blender 4.2 LTS for Windows as a Python module (PyPI's bpy win_amd64 wheel, with numpy<2 and zstandard),
#   which runs under Debian 12's Wine 8.0. (Blender 5.3's wheel needs functions Wine 8.0 lacks.)
# Prints the cache folder.
#   scripts/windows/setup_pythons.sh
set -euo pipefail
cache=${RAYSPLATS_WINDOWS_CACHE:-$HOME/.cache/raysplats/windows}
mkdir -p "$cache"
log() { echo "windows pythons: $*" >&2; }
# Maven artifact versions: CPython version - JavaCPP presets version.
declare -A CPYTHON=([3.11]=3.11.3-1.5.9 [3.13]=3.13.5-1.5.12)
# numpy: the last 1.x for 3.11 (as Blender 4.2 to 5.0 bundle); 2.1.3 for 3.13, as numpy 2.2 and newer call a C
# runtime function (crealf) Debian 12's Wine 8.0 does not implement.
declare -A NUMPY=([3.11]=1.26.4 [3.13]=2.1.3)
PYBIND11=2.13.6

# pip of a venv of the system's Python (Debian's python3-venv): it downloads the Windows wheels for another
# platform (--platform win_amd64) and installs nothing into this one.
if [[ ! -x $cache/pip-venv/bin/pip ]]; then
  /usr/bin/python3 -m venv "$cache/pip-venv" >&2 || { log "could not make a venv for pip"; exit 1; }
fi
pip=$cache/pip-venv/bin/pip

for version in 3.11 3.13; do
  root=$cache/cpython-$version
  if [[ ! -f $root/python.exe ]]; then
    command -v mvn >/dev/null || { log "mvn is missing (scripts/install_deps.sh installs maven)"; exit 1; }
    log "fetching Windows CPython $version from Maven Central"
    tmp=$(mktemp -d)
    mvn -q -B -Dstyle.color=never dependency:copy "-Dartifact=org.bytedeco:cpython:${CPYTHON[$version]}:jar:windows-x86_64" \
        "-DoutputDirectory=$tmp" >&2 || { log "mvn could not fetch org.bytedeco:cpython:${CPYTHON[$version]}"; exit 1; }
    (cd "$tmp" && unzip -q ./*.jar 'org/bytedeco/cpython/windows-x86_64/*')
    rm -rf "$root"
    mv "$tmp/org/bytedeco/cpython/windows-x86_64" "$root"
    rm -rf "$tmp"
  fi
  site=$cache/site-$version
  if [[ ! -d $site/numpy-${NUMPY[$version]}.dist-info ]]; then
    log "installing numpy ${NUMPY[$version]} for Windows Python $version"
    rm -rf "$site"
    "$pip" install -q --no-deps --only-binary=:all: --platform win_amd64 --python-version "$version" \
        --target "$site" "numpy==${NUMPY[$version]}" >&2 || { log "pip could not install numpy for Windows Python $version"; exit 1; }
  fi
done
if [[ ! -f $cache/pybind11/include/pybind11/pybind11.h ]]; then
  tmp=$(mktemp -d)
  "$pip" download -q --no-deps -d "$tmp" "pybind11==$PYBIND11" >&2 || { log "pip could not download pybind11 $PYBIND11"; exit 1; }
  rm -rf "$cache/pybind11"
  mkdir -p "$cache/pybind11"
  (cd "$tmp" && unzip -q ./pybind11-*.whl 'pybind11/include/*' && mv pybind11/include "$cache/pybind11/include")
  rm -rf "$tmp"
fi
bpy_site=$cache/bpy-4.2
if [[ ! -d $bpy_site/bpy ]]; then
  log "installing Blender 4.2 for Windows (bpy, about 320 MB)"
  rm -rf "$bpy_site"
  "$pip" install -q --no-deps --only-binary=:all: --platform win_amd64 --python-version 3.11 --target "$bpy_site" \
      "bpy==4.2.*" "numpy<2" zstandard >&2 || { log "pip could not install bpy 4.2 for Windows"; exit 1; }
fi
echo "$cache"
