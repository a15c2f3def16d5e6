#!/usr/bin/env bash
# Runs the whole test suite RUNS times with stress-ng loading the cores beside it, to find tests
# whose verdict depends on the machine's speed (docs/testing.md, "The suite under load").
#
#   tools/stress-suite.sh RUNS [--cpu N] [--jobs J] [--build DIR] [-- CTEST_ARGS...]
#
# --cpu N    stress-ng CPU workers beside each run (default 1; 0 runs without load)
# --jobs J   ctest -j (default: nproc, as tools/test.sh)
# --build D  the build folder (default build/); it is configured and built first, as tools/test.sh does
# Each run's log is kept in D/stress/run-K.log. Prints one line per run (time, failed tests) and
# exits non-zero when any test failed in any run. Never retries a test.
set -euo pipefail
cd "$(dirname "$0")/.."

usage() { sed -n '2,11p' "$0" | sed 's/^# \{0,1\}//'; }
[ $# -ge 1 ] || { usage >&2; exit 64; }
case "$1" in -h | --help) usage; exit 0 ;; esac
runs=$1
shift
[[ $runs =~ ^[1-9][0-9]*$ ]] || { echo "stress-suite: RUNS must be a positive integer, got '$runs'" >&2; exit 64; }
cpu=1
jobs=$(nproc)
build=build
ctest_args=()
while [ $# -gt 0 ]; do
  case "$1" in
    --cpu) cpu=$2; shift 2 ;;
    --jobs) jobs=$2; shift 2 ;;
    --build) build=$2; shift 2 ;;
    --) shift; ctest_args=("$@"); break ;;
    *) echo "stress-suite: unknown argument '$1'" >&2; exit 64 ;;
  esac
done
[[ $cpu =~ ^[0-9]+$ ]] || { echo "stress-suite: --cpu needs a number, got '$cpu'" >&2; exit 64; }

tools/install-deps.sh
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build "$build" -j "$(nproc)"
mkdir -p "$build/stress"

stress_pid=
stop_stress() {
  if [ -n "$stress_pid" ]; then
    kill "$stress_pid" 2>/dev/null || true
    wait "$stress_pid" 2>/dev/null || true
    stress_pid=
  fi
}
trap stop_stress EXIT

failed_runs=0
summary=()
for ((k = 1; k <= runs; ++k)); do
  if [ "$cpu" -gt 0 ]; then
    stress-ng --cpu "$cpu" --quiet &
    stress_pid=$!
  fi
  log="$build/stress/run-$k.log"
  start=$SECONDS
  set +e
  (cd "$build" && ctest -j "$jobs" --output-on-failure "${ctest_args[@]}") >"$log" 2>&1
  rc=$?
  set -e
  stop_stress
  took=$((SECONDS - start))
  failed=$(sed -n '/^The following tests FAILED:/,$p' "$log" | grep -E '^[[:space:]]+[0-9]+ - ' |
    sed -E 's/^[[:space:]]+[0-9]+ - //' | tr '\n' ';' || true)
  line="run $k/$runs (stress-ng --cpu $cpu, ctest -j $jobs): $(grep -E 'tests passed, [0-9]+ tests? failed' "$log" || echo "no ctest summary (exit $rc)") in ${took} s"
  [ -n "$failed" ] && line+=" — FAILED: $failed"
  echo "$line"
  summary+=("$line")
  [ "$rc" -eq 0 ] || failed_runs=$((failed_runs + 1))
done

echo
echo "stress-suite: $((runs - failed_runs)) of $runs runs passed every test (logs in $build/stress/)"
[ "$failed_runs" -eq 0 ]
