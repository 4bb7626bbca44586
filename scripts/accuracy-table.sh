#!/usr/bin/env bash
# Writes the demo vehicles' accuracy report: runs the end-to-end demo of each built-in simulated
# vehicle (lockstep, so the table is the same on any machine; laser + wheel odometry, clean radio)
# and compares the angles the handheld received with the ones computed from the vehicle model.
# The table goes to docs/reports/ with the date and commit. (The README's accuracy table is the
# held-out set's, from bench/evaluate.sh.)
#
#   scripts/accuracy-table.sh [VEHICLE ...]      default: sedan suv pickup van offroader
set -euo pipefail
cd "$(dirname "$0")/.."

vehicles=("$@")
[[ ${#vehicles[@]} -gt 0 ]] || vehicles=(sedan suv pickup van offroader)

cargo build --release --bin passangle-sim
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
for v in "${vehicles[@]}"; do
    echo "demo: $v" >&2
    target/release/passangle-sim demo --vehicle "$v" --json --out "$out/runs" > "$out/$v.json"
done

commit=$(git rev-parse --short HEAD)
dirty=$(git diff --quiet HEAD -- . ':!README.md' ':!docs/reports' || echo " (with uncommitted changes)")
date=$(date -u +%Y-%m-%d)
python3 - "$out" "$commit$dirty" "$date" "${vehicles[@]}" <<'PY'
import json, pathlib, sys
out, commit, date, vehicles = pathlib.Path(sys.argv[1]), sys.argv[2], sys.argv[3], sys.argv[4:]
rows = []
for v in vehicles:
    r = json.loads((out / f"{v}.json").read_text())
    m, t = r["measured"], r["truth"]
    cells = []
    for k in ("approach_deg", "departure_deg", "breakover_deg"):
        if m.get(k) is None:
            cells.append(f"not measured ({t[k]:.2f})")
        else:
            cells.append(f"{m[k]:.2f} ({t[k]:.2f}) {m[k] - t[k]:+.2f}")
    rows.append(f"| {v} | " + " | ".join(cells) + f" | {r['cloud_points']:,} |")
table = (f"Lockstep demo runs at {commit}, {date}: measured (true) error, degrees.\n\n"
         "| vehicle | approach | departure | breakover | cloud points |\n|---|---|---|---|---|\n"
         + "\n".join(rows) + "\n")
report = pathlib.Path("docs/reports") / f"{date}-{commit.split()[0]}-accuracy.md"
report.write_text(f"# Accuracy, demo runs at {commit}\n\nWritten by `scripts/accuracy-table.sh` on {date}.\n\n" + table)
index = pathlib.Path("docs/reports/README.md")
if report.name not in index.read_text():
    with index.open("a") as f:
        f.write(f"- [accuracy, {date}, {commit.split()[0]}]({report.name})\n")
print(table)
PY
