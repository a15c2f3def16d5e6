#!/bin/sh
# systemd-analyze verify on a copy of the unit whose ExecStart points at the built tarmacd
# (verify fails when the binary does not exist). Any diagnostic about the unit fails the test.
set -eu
unit=$1
binary=$2
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
sed "s#/usr/bin/tarmacd#$binary#g" "$unit" > "$dir/tarmacd.service"
out=$(systemd-analyze verify "$dir/tarmacd.service" 2>&1) || { echo "$out"; exit 1; }
echo "$out"
if echo "$out" | grep -q "tarmacd.service"; then
  echo "systemd-analyze reported problems with the unit" >&2
  exit 1
fi
echo "tarmacd.service verifies"
