#!/usr/bin/env bash
# Soak: tarmacd runs CYCLES ticks with replayed scans at full rate (one scan per tick) and its
# resources are read at the start (after a warm-up) and at the end: resident memory (VmRSS),
# open file descriptors, threads, the scan scheduler's pending scans and the pose buffer
# (DiagnosticArray), and every drop and overrun since start. They must stay flat.
#
#   tools/soak.sh [--cycles N] [--rate-hz HZ] [--warmup N] [--beams N] [--dataset DIR]
#                 [--max-rss-growth-kb KB] [--resident-limit-mb MB] [--out DIR]
#
# Defaults: 10000 cycles at 50 Hz (the shipped 10 Hz, sped up so the run takes minutes; scans
# come at the same rate), 500 warm-up cycles, a 32-beam simulated airside sequence (tarmac-sim)
# looped (tarmac-replay --loop), the shipped config otherwise, except: no real-time setup
# (unprivileged), state in DIR, the cycle budget set to the period, corrections off (each loop
# of the sequence jumps the vehicle back to its start, which would be taken as a pose
# correction and rebuild the window every loop).
# Exit 0 when flat: threads and descriptors equal, pending scans within the quota, RSS grown by
# at most --max-rss-growth-kb (default 16384: the TSDF grows until the loop has covered it).
# --resident-limit-mb sets tsdf.resident_limit_mb (the TSDF paged to DIR/state/tsdf_tiles): a
# long drive (tarmac-sim --scene site) then soaks at site scale.
# Needs a built tree (build/bin). DDS stays on loopback (domain TARMAC_DOMAIN, default 78).
set -euo pipefail
cd "$(dirname "$0")/.."

cycles=10000 rate_hz=50 warmup=500 beams=32 dataset="" max_rss_growth_kb=16384 out=out/soak
resident_limit_mb=0
while [ $# -gt 0 ]; do
  case "$1" in
    --cycles) cycles=$2; shift 2 ;;
    --rate-hz) rate_hz=$2; shift 2 ;;
    --warmup) warmup=$2; shift 2 ;;
    --beams) beams=$2; shift 2 ;;
    --dataset) dataset=$2; shift 2 ;;
    --max-rss-growth-kb) max_rss_growth_kb=$2; shift 2 ;;
    --resident-limit-mb) resident_limit_mb=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    -h|--help) sed -n 2,22p "$0"; exit 0 ;;
    *) echo "soak: unknown option $1" >&2; exit 64 ;;
  esac
done
bin=${TARMAC_BIN:-build/bin}
for b in tarmacd tarmac-replay tarmac-echo tarmac-sim; do
  [ -x "$bin/$b" ] || { echo "soak: $bin/$b missing: build first (tools/test.sh)" >&2; exit 1; }
done
rm -rf "$out" && mkdir -p "$out/state"
if [ -z "$dataset" ]; then
  dataset=$out/sim
  "$bin/tarmac-sim" --out "$dataset" --beams "$beams" --azimuth-steps 1024 --scans 100 \
    > "$out/sim.log"
fi
domain=${TARMAC_DOMAIN:-78}
period_ms=$(python3 -c "print(1000.0 / $rate_hz)")
sed -e "s|^  dir: /var/lib/tarmac |  dir: $out/state |" \
    -e "s|^  # domain_id: 0 .*|  domain_id: $domain|" \
    -e "s|^  rate_hz: 10.0 |  rate_hz: $rate_hz |" \
    -e "s|^  realtime_priority: 10 |  realtime_priority: 0 |" \
    -e "s|^  lock_memory: true |  lock_memory: false |" \
    -e "s|^  cycle_ms: 90.0 |  cycle_ms: $period_ms |" \
    -e "s|^  resident_limit_mb: 0 |  resident_limit_mb: $resident_limit_mb |" \
    -e "/^corrections:/,/^  enabled:/s|^  enabled: true |  enabled: false |" \
    config/tarmac.yaml > "$out/tarmac.yaml"
"$bin/tarmacd" --check-config "$out/tarmac.yaml" > /dev/null

"$bin/tarmacd" --config "$out/tarmac.yaml" > "$out/tarmacd.log" 2>&1 &
pid=$!
cleanup() { kill "$pid" "${replay_pid:-}" 2>/dev/null || true; }
trap cleanup EXIT
for _ in $(seq 300); do grep -q "tarmacd: ready" "$out/tarmacd.log" && break; sleep 0.1; done
grep -q "tarmacd: ready" "$out/tarmacd.log" || { echo "soak: tarmacd not ready" >&2; exit 1; }
scans=$(ls "$dataset/scans" | wc -l)
# Skipped ticks (a loaded machine) make cycles slower than scans: enough loops for three times.
loops=$(( 3 * ((cycles + warmup) / scans + 2) ))
"$bin/tarmac-replay" --dataset "$dataset" --config "$out/tarmac.yaml" \
  --rate-scale "$(python3 -c "print($rate_hz / 10.0)")" --loop "$loops" > "$out/replay.log" 2>&1 &
replay_pid=$!
t_start=$(date +%s.%N)

# One sample: cycle index (CycleReport), /proc figures, the DiagnosticArray's values.
sample() {
  local name=$1 report diag
  report=$("$bin/tarmac-echo" rt/tarmac/diagnostics --config "$out/tarmac.yaml" --count 1)
  diag=$("$bin/tarmac-echo" rt/diagnostics --config "$out/tarmac.yaml" --count 1)
  {
    echo "cycle=$(sed -n 's/^cycle \([0-9]*\) .*/\1/p' <<< "$report")"
    echo "rss_kb=$(awk '/^VmRSS:/ {print $2}' /proc/$pid/status)"
    echo "hwm_kb=$(awk '/^VmHWM:/ {print $2}' /proc/$pid/status)"
    echo "fds=$(ls /proc/$pid/fd | wc -l)"
    echo "threads=$(ls /proc/$pid/task | wc -l)"
    for key in pending_scans pose_buffer_samples scans_integrated_total drops_total \
               skipped_ticks_total costmap_age_ms tsdf_resident_mib tsdf_tiles_stored \
               tsdf_tile_loads_late_total tsdf_tile_errors_total; do
      echo "$key=$(tr ' ' '\n' <<< "$diag" | sed -n "s/^$key=//p" | head -1)"
    done
  } > "$out/$name.txt"
  cat "$out/$name.txt" | tr '\n' ' '; echo
}
cycle_now() {
  "$bin/tarmac-echo" rt/tarmac/diagnostics --config "$out/tarmac.yaml" --count 1 |
    sed -n 's/^cycle \([0-9]*\) .*/\1/p'
}
wait_for_cycle() {
  while [ "$(cycle_now)" -lt "$1" ]; do
    kill -0 "$replay_pid" 2>/dev/null || { echo "soak: the replay ended early" >&2; exit 1; }
    sleep 2
  done
}
wait_for_cycle "$warmup"
echo -n "start: "; sample start
wait_for_cycle "$((warmup + cycles))"
echo -n "end:   "; sample end
t_end=$(date +%s.%N)
kill -TERM "$replay_pid" 2>/dev/null || true
wait "$replay_pid" 2>/dev/null || true
kill -TERM "$pid"
wait "$pid" || true
trap - EXIT

v() { sed -n "s/^$2=//p" "$out/$1.txt"; }
{
  echo "| figure | start (cycle $(v start cycle)) | end (cycle $(v end cycle)) |"
  echo "| --- | --- | --- |"
  for k in rss_kb hwm_kb fds threads pending_scans pose_buffer_samples scans_integrated_total \
           drops_total skipped_ticks_total costmap_age_ms tsdf_resident_mib tsdf_tiles_stored \
           tsdf_tile_loads_late_total tsdf_tile_errors_total; do
    echo "| $k | $(v start $k) | $(v end $k) |"
  done
  echo
  echo "$(python3 -c "print(f'{$t_end - $t_start:.0f}')") s for $cycles cycles at $rate_hz Hz after $warmup warm-up cycles."
  grep -o "executor: stopped after.*" "$out/tarmacd.log" || true
  grep -o "executor: dropped or rejected since start.*" "$out/tarmacd.log" || true
} | tee "$out/summary.md"

fail=0
[ "$(v start threads)" = "$(v end threads)" ] || { echo "soak: threads changed" >&2; fail=1; }
[ "$(v start fds)" = "$(v end fds)" ] || { echo "soak: file descriptors changed" >&2; fail=1; }
growth=$(( $(v end rss_kb) - $(v start rss_kb) ))
[ "$growth" -le "$max_rss_growth_kb" ] ||
  { echo "soak: RSS grew $growth kB (> $max_rss_growth_kb)" >&2; fail=1; }
pending=$(v end pending_scans); pending=${pending%.*}
[ "${pending:-99}" -le 9 ] || { echo "soak: $pending scans pending at the end" >&2; fail=1; }
exit $fail
