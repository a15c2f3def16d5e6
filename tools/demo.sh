#!/usr/bin/env bash
# The README's run command: installs dependencies, builds, and runs the main job that exists at
# this stage of the project. See README.md "Status" for what runs and what is coming.
set -euo pipefail
cd "$(dirname "$0")/.."

tools/install-deps.sh
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build build -j "$(nproc)"

echo
echo "== tarmacd validates the shipped config =="
build/bin/tarmacd --check-config config/tarmac.yaml

data=${TARMAC_DATA_DIR:-../shared/data}
echo
echo "== tarmac-map: real LiDAR (MulRan KAIST03, Ouster OS1-64) -> occupancy, costmap, ESDF, latency table =="
build/bin/tarmac-map --dataset "$data/mulran_kaist03" --config config/tarmac.yaml --threads 2 --out out/mulran
echo "costmap image: out/mulran/costmap.png  (ESDF slice: out/mulran/esdf_slice.png)"

echo
echo "== DDS on loopback: tarmac <-> Cyclone DDS interop, every field compared =="
build/bin/interop_tests --gtest_brief=1

echo
echo "demo: done. The daemon (tarmacd executor over DDS) arrives with issue 5 (README.md, Status)."
