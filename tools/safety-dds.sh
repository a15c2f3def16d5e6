#!/usr/bin/env bash
# Scores tarmacd's costmaps as a planner receives them: tarmac-replay publishes a simulated
# sequence over loopback DDS into tarmacd (shipped config, empty state) at 10 Hz, and
# tarmac-audit --score scores every costmap it receives against the simulator's ground truth
# (obstacle_columns.txt, dynamic_boxes.txt), each as the map of the latest scan stamped at or
# before it. Then tarmac-map maps the same sequence with the same config offline and scores its
# costmap after every scan. Prints both "safety (...)" lines and whether they agree.
#
#   tools/safety-dds.sh [--dataset DIR] [--beams N] [--scans N] [--sensor-height M]
#                       [--dropout P] [--cyclone LAYOUT [--ring] [--marker nan|zero]]
#
# Without --dataset the parked-aircraft loop is simulated (tarmac-sim --scene aircraft, 64 beams
# unless --beams; --scans N: the first N scans only; --dropout P: that share of the returns lost
# at random, as real sensors lose them).
# --cyclone LAYOUT: the scans come from tarmac-cyclone-replay instead, a Cyclone DDS client over
# UDP as a LiDAR driver in another process: the simulator's organised sweeps sent as 'beams'
# (ouster-ros), 'firings' (velodyne's organize_cloud) or 'list' (the returns only, as Hesai's
# driver), with a ring field (--ring), a beam without return as NaN or (0, 0, 0) (--marker). It
# sends on the period's grid without waiting for the daemon.
# --sensor-height M puts the sensor M above the vehicle base: sensors[0].extrinsic z for tarmacd,
# --sensor-height for tarmac-map (default 0: the shipped identity extrinsic, the "base" is the
# sensor; the simulator's sensor is 2 m above its base).
# Needs a built tree (tools/test.sh or tools/demo.sh). DDS stays on loopback (the shipped
# `transport: localhost`), on domain TARMAC_DOMAIN (default 78). Results in out/safety-dds/.
set -euo pipefail
cd "$(dirname "$0")/.."

dataset="" beams=64 scans="" sensor_height=0 dropout=0 cyclone="" ring=() marker=()
while [ $# -gt 0 ]; do
  case "$1" in
    --dropout) dropout=$2; shift 2 ;;
    --cyclone) cyclone=$2; shift 2 ;;
    --ring) ring=(--ring); shift ;;
    --marker) marker=(--marker "$2"); shift 2 ;;
    --dataset) dataset=$2; shift 2 ;;
    --beams) beams=$2; shift 2 ;;
    --scans) scans=$2; shift 2 ;;
    --sensor-height) sensor_height=$2; shift 2 ;;
    -h|--help) sed -n 2,26p "$0"; exit 0 ;;
    *) echo "safety-dds: unknown option $1" >&2; exit 64 ;;
  esac
done
bin=build/bin
for b in tarmacd tarmac-replay tarmac-audit tarmac-map tarmac-sim tarmac-cyclone-replay; do
  [ -x "$bin/$b" ] || { echo "safety-dds: $bin/$b missing: build first (tools/test.sh)" >&2; exit 1; }
done
out=out/safety-dds
rm -rf "$out" && mkdir -p "$out"
if [ -z "$dataset" ]; then
  dataset=$out/sim
  "$bin/tarmac-sim" --out "$dataset" --scene aircraft --beams "$beams" ${scans:+--scans "$scans"} \
    --dropout "$dropout" > "$out/sim.log"
fi
[ -f "$dataset/obstacle_columns.txt" ] || { echo "safety-dds: $dataset has no obstacle_columns.txt (not a tarmac-sim dataset?)" >&2; exit 65; }
domain=${TARMAC_DOMAIN:-78}
# The shipped config, with its state in out/ (empty map every run), a fixed domain and the
# sensor's height above the base; DDS on loopback as shipped (checked, not assumed).
sed -e "s|^  dir: /var/lib/tarmac |  dir: $out/state |" \
    -e "s|^  # domain_id: 0 .*|  domain_id: $domain|" \
    -e "s|^      translation_m: {x: 0.0, y: 0.0, z: 0.0} |      translation_m: {x: 0.0, y: 0.0, z: $sensor_height} |" \
    config/tarmac.yaml > "$out/tarmac.yaml"
grep -q '^  transport: localhost$' "$out/tarmac.yaml"
grep -q "^  domain_id: $domain$" "$out/tarmac.yaml"
grep -q "z: $sensor_height} " "$out/tarmac.yaml"

"$bin/tarmacd" --config "$out/tarmac.yaml" > "$out/tarmacd.log" 2>&1 &
daemon_pid=$!
trap 'kill -TERM "$daemon_pid" 2>/dev/null || true' EXIT
for _ in $(seq 100); do grep -q "tarmacd: ready" "$out/tarmacd.log" && break; sleep 0.1; done
"$bin/tarmac-audit" --config "$out/tarmac.yaml" --score "$dataset" --idle-s 2 --timeout-s 600 \
  --json "$out/audit.json" > "$out/audit.txt" 2> "$out/audit.log" &
audit_pid=$!
# The replay starts once the audit has matched tarmacd, and waits until the audit reads the pose
# topic too (--pose-readers 2): the audit learns each scan's stamp from its pose.
for _ in $(seq 100); do grep -q "tarmac-audit: matched" "$out/audit.log" && break; sleep 0.1; done
if [ -n "$cyclone" ]; then
  # Cyclone on loopback only (config/cyclonedds_localhost.xml), over UDP as another process's.
  CYCLONEDDS_URI="file://$PWD/config/cyclonedds_localhost.xml" "$bin/tarmac-cyclone-replay" \
    --dataset "$dataset" --domain "$domain" --rate-hz 10 --layout "$cyclone" "${ring[@]}" \
    --sensor-height "$sensor_height" \
    "${marker[@]}" --pose-readers 2 ${scans:+--scans "$scans"} --idle-s 3 \
    --json "$out/cyclone.json" > "$out/replay.txt" 2> "$out/replay.log"
else
  "$bin/tarmac-replay" --dataset "$dataset" --config "$out/tarmac.yaml" --align-ms 100 \
    --pose-readers 2 ${scans:+--scans "$scans"} > "$out/replay.txt" 2> "$out/replay.log"
fi
audit_rc=0; wait "$audit_pid" || audit_rc=$?
kill -TERM "$daemon_pid"
daemon_rc=0; wait "$daemon_pid" || daemon_rc=$?
trap - EXIT
[ "$audit_rc" -eq 0 ] || { cat "$out/audit.log" >&2; echo "safety-dds: tarmac-audit exited $audit_rc" >&2; exit 1; }

"$bin/tarmac-map" --dataset "$dataset" --config "$out/tarmac.yaml" --threads 2 \
  --sensor-height "$sensor_height" ${scans:+--scans "$scans"} --out "$out/offline" > "$out/offline.txt" 2>&1

echo "dataset: $dataset ($(wc -l < "$dataset/poses.txt") scans), sensor $sensor_height m above the base"
if [ -n "$cyclone" ]; then
  echo "tarmac-cyclone-replay --layout $cyclone ${ring[*]} ${marker[*]}:"
  sed 's/^/  /' "$out/replay.txt"
else
  sed -n 's/^tarmac-replay: //p' "$out/replay.txt"
fi
echo "tarmacd (exit $daemon_rc): $(sed -n 's/.*stopped after \(.*\)$/\1/p' "$out/tarmacd.log")"
echo
echo "== tarmacd over DDS (tarmac-audit --score) =="
grep -E '^(safety|scored|small objects) ' "$out/audit.txt"
echo
echo "== tarmac-map offline, same sequence and config =="
grep '^safety ' "$out/offline.txt"
echo
python3 - "$out/audit.json" "$out/offline/timing.json" <<'PY'
import json, sys
dds = json.load(open(sys.argv[1]))["safety"]
off = json.load(open(sys.argv[2]))["safety"]
offline = {c[0]: c for c in off["per_cycle"]}
same = sum(1 for c in dds["per_cycle"] if offline.get(c[0]) == c)
print(f"per cycle: {same} of the {len(dds['per_cycle'])} costmaps scored over DDS have the figures "
      f"of tarmac-map's costmap after the same scan")
PY
echo "details: $out/audit.txt, $out/audit.json, $out/offline/timing.json"
