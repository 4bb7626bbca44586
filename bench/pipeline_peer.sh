#!/usr/bin/env bash
# KISS-ICP (PyPI kiss-icp, pinned) against passangle's pipeline on the same simulated VLP-16 runs:
# trajectory error (ATE, drift per metre) and time per frame, one markdown table.
#
# usage: bench/pipeline_peer.sh [SEEDS] [--duration-s S] [--only NAME]
#   SEEDS: seeds 1..SEEDS of every scenario in hil-sim/scenarios/ (default 1).
#   --duration-s S: only the first S seconds of each run (quick checks); --only NAME: scenarios
#   whose file name contains NAME.
# needs: python3 with the venv module (Debian: python3-venv) and PyPI for the first run; it sets
#   up its own venv under target/peer-venv (override with PEER_VENV=DIR). taskset (util-linux) if
#   present, to pin both sides to core 0. BENCH_BIN=PATH uses a bench_pipeline binary built
#   beforehand (e.g. from a clean `git archive` of a commit) instead of building this tree's.
#
# Per scenario and seed, in this order so that both sides see the same machine load:
#   1. bench_pipeline SEEDS --peer --export: simulates the run, runs ours (laser only, laser +
#      wheel), prints the bench's table rows, writes the frames, the truth and our trajectories
#      (layout: hil-sim/examples/bench_pipeline.rs, export_frames);
#   2. bench/pipeline_peer.py run: KISS-ICP on the same frames, both sides' errors from the same
#      definitions (our figures recomputed from the files must equal the bench's), a check that
#      the files' frame conventions put the points where the exact truth does.
# Output: the table on stdout; the raw rows in target/pipeline-peer/results.jsonl and the bench's
# own output in target/pipeline-peer/bench.log.
set -euo pipefail
cd "$(dirname "$0")/.."

kiss_version=1.3.0
seeds=1
extra=()
while [ $# -gt 0 ]; do
  case "$1" in
    --duration-s) extra+=(--duration-s "$2"); shift 2 ;;
    --only) only="$2"; shift 2 ;;
    [0-9]*) seeds="$1"; shift ;;
    *) echo "unknown argument: $1 (usage: bench/pipeline_peer.sh [SEEDS] [--duration-s S] [--only NAME])" >&2; exit 2 ;;
  esac
done

venv="${PEER_VENV:-target/peer-venv}"
if [ ! -x "$venv/bin/python" ]; then
  python3 -m venv "$venv" || {
    echo "could not create a Python venv at $venv: install python3 with the venv module (Debian: apt-get install python3-venv)" >&2
    exit 1
  }
fi
if ! "$venv/bin/python" -c "import kiss_icp, sys; sys.exit(kiss_icp.__version__ != '$kiss_version')" 2>/dev/null; then
  echo "installing kiss-icp==$kiss_version into $venv" >&2
  "$venv/bin/pip" install -q "kiss-icp==$kiss_version" || {
    echo "pip could not install kiss-icp==$kiss_version from PyPI into $venv (network to PyPI, or no wheel for this Python: $("$venv/bin/python" --version))" >&2
    exit 1
  }
fi

pin=()
if command -v taskset >/dev/null; then pin=(taskset -c 0); else echo "taskset not found: not pinned to one core" >&2; fi
if [ -n "${BENCH_BIN:-}" ]; then
  bench="$BENCH_BIN"
else
  cargo build --release -q -p hil-sim --example bench_pipeline
  bench="${CARGO_TARGET_DIR:-target}/release/examples/bench_pipeline"
fi

out=target/pipeline-peer
rm -rf "$out"
mkdir -p "$out"
echo "load before: $(cut -d' ' -f1-3 /proc/loadavg) (1/5/15 min; 2 cores)" >&2
for scenario in hil-sim/scenarios/*.toml; do
  name="$(basename "$scenario" .toml)"
  if [ -n "${only:-}" ] && [[ "$name" != *"$only"* ]]; then continue; fi
  echo "== $name: ours (bench_pipeline --peer), seeds 1..$seeds" >&2
  "${pin[@]}" "$bench" "$seeds" --peer --only "$name" --export "$out" "${extra[@]}" >>"$out/bench.log" 2>&1 || {
    echo "bench_pipeline failed on $name: see $out/bench.log" >&2
    exit 1
  }
  for seed in $(seq 1 "$seeds"); do
    echo "== $name seed $seed: KISS-ICP" >&2
    "${pin[@]}" "$venv/bin/python" bench/pipeline_peer.py run "$out/$name-$seed" >>"$out/results.jsonl"
  done
done
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)" >&2
"$venv/bin/python" bench/pipeline_peer.py table "$out/results.jsonl"
