#!/usr/bin/env bash
# Builds the libFuzzer targets (native/fuzz: one per splat reader and one for the polygon bridge) with clang, ASan
# and UBSan in their own build folder, and runs each for the given time from its seed corpus (written at build time
# from shared/data) and its growing corpus (kept in the build folder between runs). Prints executions, executions per
# second and coverage per target; fails if any target finds a crash, a sanitizer report, a broken contract
# (native/fuzz/fuzz_contract.h), a leak, a hang (> 30 s on one input) or an allocation over 2 GB. Findings are saved as
# <build>/findings/<target>-crash-*: re-run one with `<build>/native/fuzz/fuzz_<target> <file>`.
#   scripts/fuzz.sh [seconds-per-target (default 60)] [targets... (default all)]
# RAYSPLATS_FUZZ_BUILD: the build folder (default build-fuzz/; the ctest fuzz.smoke uses one under its build tree).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
seconds=${1:-60}
shift || true
build=${RAYSPLATS_FUZZ_BUILD:-$root/build-fuzz}
clang=$(command -v clang++ || true)
if [[ -z $clang ]]; then
  echo "fuzz.sh: clang++ not found (scripts/install_deps.sh installs clang and libclang-rt-14-dev)" >&2
  exit 2
fi
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
# RelWithDebInfo: optimised like the release, with line numbers in the sanitizer reports.
cmake -S "$root" -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_COMPILER="$clang" \
  -DRAYSPLATS_FUZZ=ON -DRAYSPLATS_BUILD_PYTHON=OFF -DRAYSPLATS_BLENDER_TESTS=OFF -DBUILD_TESTING=OFF >/dev/null
cmake --build "$build" -j "$(nproc)"

targets=("$@")
if ((${#targets[@]} == 0)); then mapfile -t targets < "$build/native/fuzz/targets.txt"; fi
mkdir -p "$build/findings" "$build/logs"
failed=()
printf '%-16s %12s %10s %8s  %s\n' target executions exec/s cov result
for t in "${targets[@]}"; do
  [[ -n $t ]] || continue
  binary=$build/native/fuzz/fuzz_$t
  if [[ ! -x $binary ]]; then
    echo "fuzz.sh: no fuzz target '$t' (built: $(tr '\n' ' ' < "$build/native/fuzz/targets.txt"))" >&2
    exit 2
  fi
  corpus=$build/corpus/$t
  mkdir -p "$corpus"
  log=$build/logs/$t.log
  status=0
  # -rss_limit_mb also caps single allocations (malloc_limit_mb): a reader allocating what a header claims fails.
  ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1} UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1} \
    "$binary" -max_total_time="$seconds" -print_final_stats=1 -timeout=30 -rss_limit_mb=2048 \
    -artifact_prefix="$build/findings/$t-" "$corpus" "$build/native/fuzz/seeds/$t" >"$log" 2>&1 || status=$?
  executions=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  speed=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
  cov=$( (grep -o 'cov: [0-9]*' "$log" || true) | tail -1 | cut -d' ' -f2)
  result=ok
  if ((status != 0)); then
    result="FAILED (exit $status; log $log)"
    failed+=("$t")
  fi
  printf '%-16s %12s %10s %8s  %s\n' "$t" "${executions:--}" "${speed:--}" "${cov:--}" "$result"
done
if ((${#failed[@]})); then
  for t in "${failed[@]}"; do
    echo "---- $t: $build/logs/$t.log (tail)"
    tail -n 40 "$build/logs/$t.log"
  done
  echo "fuzz.sh: findings in ${failed[*]} (inputs: $build/findings/)" >&2
  exit 1
fi
