#!/usr/bin/env bash
# Runs a Windows CPython of scripts/windows/setup_pythons.sh under Wine, headless, as a test runner needs it: its own
# Wine prefix (~/.cache/raysplats/windows/wineprefix, made on first use), no Wine debug output, standard input from
# /dev/null and standard output through a pipe (a console handle Wine cannot give makes Python fail at start with
# "Invalid handle"), the exit status of Python. PYTHONPATH holds wine_site/ (what Wine 8.0 cannot run, stepped
# around: see its sitecustomize.py), that Python's numpy and, with --site DIR, DIR too
# (an unpacked bpy for Windows).
#   scripts/windows/wine_python.sh VERSION [--site DIR] [python arguments...]      (VERSION: 3.11 or 3.13)
# Paths: Wine maps Z: to /, so a Linux path works as it is and Z:\work\... is the same file.
set -euo pipefail
version=${1:?usage: scripts/windows/wine_python.sh VERSION [--site DIR] [python arguments...]}
shift
cache=${RAYSPLATS_WINDOWS_CACHE:-$HOME/.cache/raysplats/windows}
python=$cache/cpython-$version/python.exe
[[ -f $python ]] || { echo "wine_python: no Windows Python $version in $cache (scripts/windows/setup_pythons.sh)" >&2; exit 1; }
wine=$(command -v wine64 || ls /usr/lib/wine/wine64 2>/dev/null || true)
[[ -n $wine ]] || { echo "wine_python: Wine is missing (scripts/install_deps.sh installs wine64)" >&2; exit 1; }
here=$(cd "$(dirname "$0")" && pwd)
site="$here/wine_site;$cache/site-$version"
if [[ ${1:-} == --site ]]; then site="$2;$site"; shift 2; fi
export WINEPREFIX=${RAYSPLATS_WINEPREFIX:-$cache/wineprefix} WINEDEBUG=-all WINEDLLOVERRIDES="mscoree,mshtml="
export PYTHONPATH=$site PYTHONIOENCODING=utf-8 PYTHONUTF8=1 PYTHONDONTWRITEBYTECODE=1
if [[ ! -f $WINEPREFIX/system.reg ]]; then
  "$wine" wineboot --init </dev/null >/dev/null 2>&1 || true
fi
set +e
"$wine" "$python" "$@" </dev/null 2>&1 | cat
status=${PIPESTATUS[0]}
exit "$status"
