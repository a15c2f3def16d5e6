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
mkdir -p out
if [ -d "$data/mulran_kaist03" ]; then
  echo
  echo "== tarmac-map: real LiDAR (MulRan KAIST03, Ouster OS1-64) -> occupancy, costmap, ESDF, latency table =="
  # MulRan's scans are unorganised (no beams without return): the whole-envelope free rule would
  # leave everything above the sensor unknown, so this run takes free_rule: any_voxel
  # (docs/mapping.md, "Safety argument").
  sed 's/^  free_rule: whole_envelope/  free_rule: any_voxel     /' config/tarmac.yaml > out/unorganised.yaml
  build/bin/tarmac-map --dataset "$data/mulran_kaist03" --config out/unorganised.yaml --threads 2 --out out/mulran
  echo "costmap image: out/mulran/costmap.png  (ESDF slice: out/mulran/esdf_slice.png)"
else
  # A user's machine has no ../shared/data: map the simulator's sequence instead, and say so.
  echo
  echo "== tarmac-map: no real data at $data/mulran_kaist03 (set TARMAC_DATA_DIR to a KITTI-layout"
  echo "   data folder to map MulRan); mapping the simulator's 64-beam airside sequence instead =="
  build/bin/tarmac-sim --out out/sim --beams 64
  build/bin/tarmac-map --dataset out/sim --config config/tarmac.yaml --threads 2 --out out/sim-map
  echo "costmap image: out/sim-map/costmap.png  (ESDF slice: out/sim-map/esdf_slice.png)"
fi

echo
echo "== tarmacd on loopback DDS: a simulated airside sequence (64-beam LiDAR) replayed at 10 Hz =="
rm -rf out/daemon && mkdir -p out/daemon
build/bin/tarmac-sim --out out/sim --beams 64
# The shipped config with its state directory in out/daemon/state (the demo starts with an empty
# static map every time, and never touches /var/lib/tarmac's).
sed 's|^  dir: /var/lib/tarmac |  dir: out/daemon/state |' config/tarmac.yaml > out/daemon/tarmac.yaml
grep -q '^  dir: out/daemon/state ' out/daemon/tarmac.yaml
# The shipped config: one LiDAR 'front' on rt/tarmac/lidar/front/points, poses on rt/tarmac/pose,
# localhost-only DDS, SCHED_FIFO/mlockall attempted (logged and skipped when not permitted).
build/bin/tarmacd --config out/daemon/tarmac.yaml > out/daemon/tarmacd.log 2>&1 &
daemon_pid=$!
trap 'kill -TERM "$daemon_pid" 2>/dev/null || true' EXIT
# READY=1 comes after mlockall and the worker pool: from then on a tick runs every period.
for _ in $(seq 100); do grep -q "tarmacd: ready" out/daemon/tarmacd.log && break; sleep 0.1; done
build/bin/tarmac-audit --config out/daemon/tarmac.yaml --idle-s 2 --timeout-s 120 \
  --json out/daemon/audit.json --png out/daemon/costmap.png > out/daemon/audit.txt \
  2> out/daemon/audit.log &
audit_pid=$!
# The replay starts once the audit has matched tarmacd, so the first (cold) cycles are counted.
for _ in $(seq 100); do grep -q "tarmac-audit: matched" out/daemon/audit.log && break; sleep 0.1; done
# Scans stamped on the 100 ms grid, as a LiDAR phase-locked to PTP would (executor.sensor_phase_ms:
# 0): tarmacd ticks input_delay_ms after each, so no scan waits longer for its tick.
build/bin/tarmac-replay --dataset out/sim --config out/daemon/tarmac.yaml --align-ms 100
wait "$audit_pid"
cat out/daemon/audit.txt
kill -TERM "$daemon_pid"
rc=0; wait "$daemon_pid" || rc=$?
trap - EXIT
echo "tarmacd stopped on SIGTERM with exit code $rc; log: out/daemon/tarmacd.log"
grep -E "stopped after|state:" out/daemon/tarmacd.log | sed 's/^/  /'
echo "costmap image: out/daemon/costmap.png  (audit as JSON: out/daemon/audit.json)"
echo
echo "== determinism: the daemon's last costmap against tarmac-map on the same sequence and config =="
daemon_digest=$(sed -n 's/^last costmap: .*digest \([0-9a-f]*\)$/\1/p' out/daemon/audit.txt)
build/bin/tarmac-map --dataset out/sim --config out/daemon/tarmac.yaml --threads 2 \
  --out out/daemon/offline > out/daemon/offline.txt 2>&1
offline_digest=$(sed -n 's/^digest: .* costmap \([0-9a-f]*\) .*$/\1/p' out/daemon/offline.txt)
if [ -n "$daemon_digest" ] && [ "$daemon_digest" = "$offline_digest" ]; then
  echo "costmap digest $daemon_digest: tarmacd over DDS = tarmac-map offline, bit for bit"
else
  echo "costmap digests differ: tarmacd '$daemon_digest', tarmac-map '$offline_digest'" \
    "(a scan lost or late at start-up? see out/daemon/audit.txt)"
fi

echo
echo "== DDS on loopback: tarmac <-> Cyclone DDS interop, every field compared =="
build/bin/interop_tests --gtest_brief=1

echo
echo "demo: done."
