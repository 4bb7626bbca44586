#!/usr/bin/env bash
# Runs a benchmark and writes what it printed as a dated report in docs/reports/, headed with the
# date, the commit (marked when the tree has uncommitted changes), the command, the machine (CPU
# model, cores, load average at the start) and the wall time. The benchmark's own output is kept
# verbatim, so its figures and any peer's stay side by side as the bench printed them.
#
# usage: bench/report.sh NAME -- COMMAND [ARGS ...]
#   e.g. bench/report.sh pipeline -- cargo run --release -p hil-sim --example bench_pipeline -- 3 --no-depth
#        bench/report.sh vlp16-vs-peer -- bench/vlp16_vs_peer.sh
# Writes docs/reports/YYYY-MM-DD-COMMIT-NAME.md and adds it to docs/reports/README.md.
set -euo pipefail
cd "$(dirname "$0")/.."

if [[ $# -lt 3 || "$2" != "--" ]]; then
    sed -n '2,10p' "$0" | sed 's/^# \{0,1\}//'
    exit 2
fi
name="$1"
shift 2
[[ "$name" =~ ^[a-z0-9-]+$ ]] || { echo "report name must be lower-case letters, digits and dashes: $name" >&2; exit 2; }

commit=$(git rev-parse --short HEAD)
dirty=""
git diff --quiet HEAD -- . ':!docs/reports' || dirty=" (with uncommitted changes)"
date=$(date -u +%Y-%m-%d)
cpu=$(sed -n 's/^model name\s*: //p' /proc/cpuinfo | head -1)
load=$(cut -d' ' -f1-3 /proc/loadavg)
out="docs/reports/${date}-${commit}-${name}.md"

start=$(date +%s)
log=$(mktemp)
trap 'rm -f "$log"' EXIT
status=0
"$@" 2>&1 | tee "$log" || status=$?
wall=$(( $(date +%s) - start ))

{
    echo "# ${name}, ${date}, ${commit}${dirty}"
    echo
    echo "Written by \`bench/report.sh\`."
    echo
    echo "- command: \`$*\`"
    echo "- machine: ${cpu:-unknown CPU}, $(nproc) cores, load average at the start ${load}"
    echo "- wall time: ${wall} s; exit status ${status}"
    echo
    echo '```text'
    cat "$log"
    echo '```'
} > "$out"
if ! grep -q "$(basename "$out")" docs/reports/README.md; then
    echo "- [${name}, ${date}, ${commit}]($(basename "$out"))" >> docs/reports/README.md
fi
echo "report: $out" >&2
exit "$status"
