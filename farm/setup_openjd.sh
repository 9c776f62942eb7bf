#!/usr/bin/env bash
# Makes (once, cached) a venv with the Open Job Description CLI (PyPI openjd-cli, pinned) that runs the templates of
# farm/openjd/ locally the way a worker does (the farm tests use it). Prints the venv's `openjd` on success; when
# PyPI cannot be reached it fails under strict mode (scripts/lib/tiers.sh); otherwise it says so on stderr, prints
# nothing and exits 0 (the tests that need it then skip).
#   farm/setup_openjd.sh [venv-dir]        default ~/.cache/raysplats/openjd-venv
set -uo pipefail
source "$(dirname "$0")/../scripts/lib/tiers.sh"
# 0.8.0: the TASK_CHUNKING (render chunks) and EXPR (LIST[PATH] inputs) extensions the templates use.
version=0.8.0
venv=${1:-$HOME/.cache/raysplats/openjd-venv}
if [[ -x $venv/bin/openjd ]] && [[ $("$venv/bin/python" -m pip show openjd-cli 2>/dev/null | sed -n 's/^Version: //p') == "$version" ]]; then
  echo "$venv/bin/openjd"
  exit 0
fi
mkdir -p "$(dirname "$venv")"
if ! /usr/bin/python3 -m venv "$venv" >&2; then
  tier_unavailable "openjd-cli" "could not make a venv in $venv (farm/setup_openjd.sh)" || exit 1
  exit 0
fi
if ! "$venv/bin/pip" install -q "openjd-cli==$version" >&2; then
  tier_unavailable "openjd-cli" "openjd-cli $version not installed (PyPI unreachable?); the OpenJD template tests skip" || exit 1
  exit 0
fi
echo "$venv/bin/openjd"
