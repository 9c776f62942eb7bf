#!/usr/bin/env bash
# The ctest test that stands for a tier CMake could not register (cmake/RaySplatsTiers.cmake): under strict mode
# (scripts/lib/tiers.sh) it fails naming the tier; otherwise it prints why and exits 77, which ctest counts as a skip.
# A reason starting with "expected: " (this machine lacks it by design) skips under strict mode too.
#   scripts/lib/tier_not_run.sh NAME WHY
set -uo pipefail
source "$(dirname "$0")/tiers.sh"
name=$1 why=$2
if [[ $why != expected:* ]] && raysplats_strict; then
  echo "FAILED (strict mode): tier '$name' was not set up: $why"
  exit 1
fi
echo "SKIPPED $name: $why"
exit 77
