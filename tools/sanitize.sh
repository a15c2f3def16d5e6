#!/usr/bin/env bash
# Builds the whole suite with a GCC sanitizer in its own build folder and runs it with ctest.
#   tools/sanitize.sh address   ASan + UBSan (and LeakSanitizer) in build-asan/
#   tools/sanitize.sh thread    TSan in build-tsan/
#   tools/sanitize.sh address --quick
#                               what CI runs: only the test binaries of the code that takes
#                               outside input or holds the maps (quick_binaries below: parsers,
#                               config, core, TSDF, executor, the tarmacd process), without the
#                               tests in tools/sanitizers/long-tests.txt (each over a minute
#                               under ASan on 2 cores). The tools' own tests (tarmac-map, -bench,
#                               -audit, -echo command lines) run in the full suites.
#   tools/sanitize.sh MODE [--quick] --build-only
#                               configures and builds only (.ci/run builds beside the main suite).
# Ends with ctest's summary line. Third-party libraries (Fast DDS, OpenVDB, TBB, yaml-cpp) come
# from Debian uninstrumented; tools/sanitizers/*.supp hide only reports inside them, each with
# its reason. Tests get TARMAC_TEST_TIMEOUT_S (default 600 s here) because sanitized code runs
# several times slower; no assertion is relaxed.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)

usage() {
  echo "usage: tools/sanitize.sh address|thread [--quick] [--build-only]" >&2
  exit 2
}
mode=${1:-}
[ $# -gt 0 ] && shift
quick=0
build_only=0
for arg in "$@"; do
  case "$arg" in
    --quick) quick=1 ;;
    --build-only) build_only=1 ;;
    *) usage ;;
  esac
done
case "$mode" in
  address)
    build=build-asan
    # UBSan stays recoverable so ubsan.supp can apply; halt_on_error=1 makes the rest fatal.
    flags="-fsanitize=address,undefined -fno-omit-frame-pointer"
    ;;
  thread)
    build=build-tsan
    flags="-fsanitize=thread -fno-omit-frame-pointer"
    ;;
  *) usage ;;
esac

supp="$root/tools/sanitizers"
# Also needed at build time: gtest_discover_tests runs each test binary to list its tests.
# new_delete_type_mismatch=0: Fast DDS 2.9 deletes its statistics writer (StatisticsWriterImpl,
# created in RTPSWriter) through a base without a virtual destructor, on every writer's
# destruction, inside libfastrtps. ASan cannot suppress that check by frame, so it is off; our
# own code is covered at compile time by -Wdelete-non-virtual-dtor (-Wall -Werror).
export ASAN_OPTIONS="detect_leaks=1:strict_init_order=1:check_initialization_order=1:detect_stack_use_after_return=1:new_delete_type_mismatch=0"
export LSAN_OPTIONS="suppressions=$supp/lsan.supp:print_suppressions=0"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1:suppressions=$supp/ubsan.supp"
export TSAN_OPTIONS="suppressions=$supp/tsan.supp:second_deadlock_stack=1:history_size=4"

tools/install-deps.sh
launcher=()
if command -v ccache >/dev/null; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
fi
# -O1 (NDEBUG as in the normal build): the sanitizers' usual level, lighter to build than -O2.
# -g1: line tables only, which is all a sanitizer's report needs (file:line per frame); full
# debug info of OpenVDB's templates is much of the build's time, and CI counts it.
cmake -S . -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo "${launcher[@]}" \
  -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -g1 -DNDEBUG" \
  -DCMAKE_C_FLAGS="$flags" -DCMAKE_CXX_FLAGS="$flags" \
  -DCMAKE_EXE_LINKER_FLAGS="$flags" -DCMAKE_SHARED_LINKER_FLAGS="$flags" \
  -DTARMAC_TEST_TIMEOUT_S="${TARMAC_TEST_TIMEOUT_S:-600}"
# The binaries --quick builds and runs (ctest labels each test with its binary): fewer to
# build is most of what it saves, as the instrumented build is most of a sanitizer run's time.
quick_binaries=(core_tests transport_tests config_tests tsdf_tests tsdf_paging_tests pose_correction_tests
  daemon_tests tarmacd_process_tests interop_tests)
select=()
if [ "$quick" -eq 1 ]; then
  cmake --build "$build" -j "$(nproc)" --target "${quick_binaries[@]}"
  # One regex of the listed names (comments and blank lines skipped).
  select=(-L "^($(IFS='|' && echo "${quick_binaries[*]}"))\$"
    -E "$(grep -v -e '^#' -e '^$' "$supp/long-tests.txt" | paste -sd '|')")
else
  cmake --build "$build" -j "$(nproc)"
fi
[ "$build_only" -eq 1 ] && exit 0
# DDS tests use distinct domains and stay on loopback (support/test_env.hpp, STACK.md).
cd "$build" && ctest -j "$(nproc)" --output-on-failure "${select[@]}"
