#!/usr/bin/env bash
# The end-to-end demo of each built-in vehicle in lockstep and in real time, one after the other on
# the same machine: wall time of each (the lockstep run is bounded by CPU; the real-time run by the
# simulated drive), the robot-at-rest -> result time the handheld saw in real time (lockstep runs the
# processing inline at no simulated time, so only the wall clock has this figure), the lidar data
# packets the service did not receive (none in lockstep by construction), and the angle errors of
# both. Use with bench/report.sh for a dated report.
#
# usage: bench/demo.sh [VEHICLE ...]      default: sedan suv pickup van offroader
set -euo pipefail
cd "$(dirname "$0")/.."

vehicles=("$@")
[[ ${#vehicles[@]} -gt 0 ]] || vehicles=(sedan suv pickup van offroader)
cargo build --release --bin passangle-sim >&2
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
printf '%-10s %-9s %8s %14s %13s %10s %10s %10s\n' vehicle mode wall_s stop_result_s lidar_dropped approach departure breakover
for v in "${vehicles[@]}"; do
    for mode in lockstep realtime; do
        flag=""
        [[ $mode == realtime ]] && flag="--realtime"
        start=$(date +%s.%N)
        target/release/passangle-sim demo --vehicle "$v" --json --out "$out/$mode" \
            --radio-loss 0.2 --radio-corrupt 0.05 $flag > "$out/r.json" 2>/dev/null
        end=$(date +%s.%N)
        python3 - "$out/r.json" "$v" "$mode" "$start" "$end" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
m, t = r["measured"], r["truth"]
err = [m[k] - t[k] for k in ("approach_deg", "departure_deg", "breakover_deg")]
s2r = r["stop_to_result_s"]
print(f"{sys.argv[2]:<10} {sys.argv[3]:<9} {float(sys.argv[5]) - float(sys.argv[4]):8.1f} "
      f"{'-' if s2r is None or sys.argv[3] == 'lockstep' else f'{s2r:.2f}':>14} "
      f"{r['lidar_packets_sent'] - r['lidar_packets_received']:>13} "
      + " ".join(f"{e:+10.2f}" for e in err))
PY
    done
done
