#!/usr/bin/env bash
# The README's test command: installs dependencies (Debian packages), configures, builds and runs
# the whole GoogleTest/ctest suite. Ends with ctest's summary line. Used by .ci/run.
set -euo pipefail
cd "$(dirname "$0")/.."

tools/install-deps.sh
jobs=$(nproc)
start=$SECONDS
# CI (CI=true) builds with line tables only (-g1): enough for a backtrace's file:line, and full
# debug info of OpenVDB's templates is about a third of those translation units' compile time.
# The same optimisation (-O2) as a developer's build, so the same code is tested.
debug_info=()
if [ "${CI:-}" = true ]; then
  debug_info=(-DCMAKE_C_FLAGS_RELWITHDEBINFO="-O2 -g1 -DNDEBUG" -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g1 -DNDEBUG")
fi
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo "${debug_info[@]}"
cmake --build build -j "$jobs"
tools/check-format.sh
build_s=$((SECONDS - start))
# DDS tests use distinct domains and stay on loopback (support/test_env.hpp, STACK.md).
# ctest's output is kept so that the ten slowest tests can be listed above its summary, which
# stays the last lines of the run (CI reads it there).
log=build/ctest-output.log
set +e
(cd build && ctest -j "$jobs" --output-on-failure) 2>&1 | tee "$log" | sed -u '/tests passed, [0-9]* tests* failed out of/,$d'
rc=${PIPESTATUS[0]}
set -e
echo
echo "The ten slowest tests (wall time under ctest -j $jobs):"
grep -E '^ *[0-9]+/[0-9]+ Test +#[0-9]+: ' "$log" |
  sed -E 's/^ *[0-9]+\/[0-9]+ Test +#[0-9]+: ([^ ]+) .* ([0-9.]+) sec$/\2 \1/' |
  sort -rn | awk 'NR <= 10 { printf "  %8.1f s  %s\n", $1, $2 }' || true  # never hides the summary
echo
echo "test.sh: configure, build and format check took ${build_s} s, the tests $((SECONDS - start - build_s)) s"
echo
sed -n '/tests passed, [0-9]* tests* failed out of/,$p' "$log"
exit "$rc"
