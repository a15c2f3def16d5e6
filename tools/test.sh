#!/usr/bin/env bash
# The README's test command: installs dependencies (Debian packages), configures, builds and runs
# the whole GoogleTest/ctest suite. Ends with ctest's summary line. Used by .ci/run.
set -euo pipefail
cd "$(dirname "$0")/.."

tools/install-deps.sh
jobs=$(nproc)
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo
cmake --build build -j "$jobs"
tools/check-format.sh
# DDS tests use distinct domains and stay on loopback (support/test_env.hpp, STACK.md).
cd build && ctest -j "$jobs" --output-on-failure
