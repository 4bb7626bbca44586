#!/usr/bin/env bash
# Offline replay of whole recorded runs: `passangle replay RUN_DIR --json` on the lockstep demo's
# run of each built-in vehicle (lidar, wheels and the D435's recorded frames; the pipeline, the
# calculator and every standard's profile), with its wall time, CPU time (user + system) and peak
# memory. The target is a whole run in at most 5 s (issue 30). Use with bench/report.sh for a
# dated report.
#
# usage: bench/replay.sh [VEHICLE ...]      default: sedan suv pickup van offroader
set -euo pipefail
cd "$(dirname "$0")/.."

vehicles=("$@")
[[ ${#vehicles[@]} -gt 0 ]] || vehicles=(sedan suv pickup van offroader)
cargo build --release --bin passangle-sim --bin passangle >&2
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
printf '%-10s %7s %7s %8s %8s %7s %7s %9s\n' vehicle lidar depth points wall_s cpu_s max_mb approach
for v in "${vehicles[@]}"; do
    target/release/passangle-sim demo --vehicle "$v" --json --out "$out/$v" > /dev/null 2>&1
    run=$(ls -d "$out/$v"/runs/run-*/ | head -n 1)
    /usr/bin/time -f '%e %U %S %M' -o "$out/time" \
        target/release/passangle replay "$run" --json > "$out/replay.json" 2> /dev/null
    python3 - "$out/replay.json" "$out/time" "$v" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
wall, user, system, max_kb = (float(x) for x in open(sys.argv[2]).read().split())
a = r.get("approach_deg")
print(f"{sys.argv[3]:<10} {r['lidar_frames']:>7} {r['depth_frames']:>7} {r['cloud_points']:>8} "
      f"{wall:8.2f} {user + system:8.2f} {max_kb / 1024:7.0f} "
      f"{'-' if a is None else f'{a:.2f}':>9}")
PY
done
