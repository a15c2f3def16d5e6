#!/usr/bin/env bash
# Measures tarmacd as an outside ROS 2 stack sees it: tarmac-cyclone-replay (Cyclone DDS, UDP on
# loopback, ROS 2 types and QoS) replays a sequence into tarmacd (shipped config, empty state)
# and reads the costmaps back. Prints, per run, scans sent / integrated / lost and the latency
# from scan stamp to costmap received (p50, p99, max), then all runs as one table.
#
#   tools/client-latency.sh [--dataset DIR] [--runs N] [--scans N] [--receive-buffer BYTES]
#
# --receive-buffer sets dds.udp_receive_buffer_bytes (e.g. 212992, a stock kernel's default, to
# see what the shipped 4 MiB buffer prevents).
# Without --dataset a 64-beam airside sequence of ~1.1 MB clouds is simulated (tarmac-sim).
# Needs a built tree (tools/test.sh or tools/demo.sh). DDS stays on loopback.
set -euo pipefail
cd "$(dirname "$0")/.."

dataset="" runs=3 scans=150 receive_buffer=
while [ $# -gt 0 ]; do
  case "$1" in
    --dataset) dataset=$2; shift 2 ;;
    --runs) runs=$2; shift 2 ;;
    --scans) scans=$2; shift 2 ;;
    --receive-buffer) receive_buffer=$2; shift 2 ;;
    -h|--help) sed -n 2,13p "$0"; exit 0 ;;
    *) echo "client-latency: unknown option $1" >&2; exit 64 ;;
  esac
done
bin=build/bin
for b in tarmacd tarmac-cyclone-replay tarmac-sim; do
  [ -x "$bin/$b" ] || { echo "client-latency: $bin/$b missing: build first (tools/test.sh)" >&2; exit 1; }
done
out=out/client-latency
rm -rf "$out" && mkdir -p "$out"
if [ -z "$dataset" ]; then
  dataset=$out/sim
  "$bin/tarmac-sim" --out "$dataset" --beams 64 --azimuth-steps 2048 --scans "$scans" > "$out/sim.log"
fi
export CYCLONEDDS_URI="file://$PWD/config/cyclonedds_localhost.xml"
domain=${TARMAC_DOMAIN:-77}
printf '%-4s %-8s %-11s %-5s %-9s %-9s %-9s\n' run sent integrated lost p50_ms p99_ms max_ms > "$out/table.txt"
for run in $(seq "$runs"); do
  dir=$out/run$run && mkdir -p "$dir"
  sed -e "s|^  dir: /var/lib/tarmac |  dir: $dir/state |" \
      -e "s|^  # domain_id: 0 .*|  domain_id: $domain|" \
      -e "s|^  udp_receive_buffer_bytes: [0-9]*|  udp_receive_buffer_bytes: ${receive_buffer:-4194304}|" \
      config/tarmac.yaml > "$dir/tarmac.yaml"
  "$bin/tarmacd" --config "$dir/tarmac.yaml" > "$dir/tarmacd.log" 2>&1 &
  pid=$!
  for _ in $(seq 100); do grep -q "tarmacd: ready" "$dir/tarmacd.log" && break; sleep 0.1; done
  "$bin/tarmac-cyclone-replay" --dataset "$dataset" --domain "$domain" --rate-hz 10 \
    --tail-scans 5 --json "$dir/replay.json" | tee "$dir/replay.txt"
  kill -TERM "$pid"; wait "$pid" || true
  integrated=$(sed -n 's/.* \([0-9]*\) scans integrated$/\1/p' "$dir/tarmacd.log")
  python3 - "$dir/replay.json" "$run" "$integrated" >> "$out/table.txt" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
print(f"{sys.argv[2]:<4} {j['scans_sent']:<8} {sys.argv[3]:<11} {j['transport_lost']:<5} "
      f"{j['latency_ms']['p50']:<9.1f} {j['latency_ms']['p99']:<9.1f} {j['latency_ms']['max']:<9.1f}")
PY
done
echo
echo "dataset: $dataset"
cat "$out/table.txt"
