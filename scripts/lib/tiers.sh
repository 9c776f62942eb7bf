# Strict mode and the tiers of the test command, sourced by scripts/test.sh and the setup scripts (bash).
#
# Strict mode: RAYSPLATS_STRICT=1, or CI=true (or 1) with RAYSPLATS_STRICT unset; RAYSPLATS_STRICT=0 turns it off
# under CI too. Under strict mode every tier the test command names (a Blender, Python 3.13, a tool, the data set)
# must be set up: one that cannot be is a failure that names it. Outside strict mode a missing tier is recorded
# and printed, loudly, after the test summary (RAYSPLATS_TIERS_FILE).
#
#   tier_unavailable NAME WHY || exit 1     strict: prints the failure, returns 1; else records NAME and WHY, returns 0
#   require_tier NAME WHY CMD...            runs CMD (quietly); when it fails, tier_unavailable NAME WHY
#   raysplats_strict                        returns 0 under strict mode
# A WHY starting with "expected: " is a tier this machine lacks by design (a CPU feature it has not): never a
# failure, and shown as such.

raysplats_strict() {
  case ${RAYSPLATS_STRICT:-} in
    1|true|yes) return 0 ;;
    0|false|no) return 1 ;;
  esac
  [[ ${CI:-} == true || ${CI:-} == 1 ]]
}

tier_unavailable() {
  local name=$1 why=$2
  if [[ $why != expected:* ]] && raysplats_strict; then
    echo "FAILED (strict mode): tier '$name' cannot be set up: $why" >&2
    return 1
  fi
  echo "NOT RUN: tier '$name': $why" >&2
  if [[ -n ${RAYSPLATS_TIERS_FILE:-} ]]; then
    printf '%s\t%s\n' "$name" "$why" >>"$RAYSPLATS_TIERS_FILE"
  fi
  return 0
}

require_tier() {
  local name=$1 why=$2
  shift 2
  "$@" >/dev/null 2>&1 || tier_unavailable "$name" "$why"
}
