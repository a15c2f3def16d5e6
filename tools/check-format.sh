#!/usr/bin/env bash
# Fails when a C/C++ source we own is not clang-format clean (.clang-format at the root).
set -euo pipefail
cd "$(dirname "$0")/.."
files=$(git ls-files '*.cpp' '*.hpp' '*.c' '*.h' 2>/dev/null || find core transport config daemon tools tests -name '*.[ch]pp' -o -name '*.c')
[ -n "$files" ] || exit 0
if ! clang-format --dry-run --Werror $files; then
  echo "check-format: run 'clang-format -i' on the files above" >&2
  exit 1
fi
echo "check-format: $(echo "$files" | wc -w) files clean"
