#!/usr/bin/env bash
# CPU per frame of two bench_pipeline binaries on the same scenario, interleaved: A, B, A, B, ...
# and the least per seed over the rounds. On a shared two-core machine a binary's CPU per frame
# moves by 30 % between runs minutes apart; interleaving puts both under the same drift, and the
# least of several runs is the steadiest figure of what the code costs.
#
# usage: bench/ab_cpu.sh BIN_A BIN_B [SCENARIO] [SEEDS] [ROUNDS]
#   BIN_A, BIN_B: bench_pipeline binaries (build one, copy it away, change the code, build again:
#     cargo build --release -p hil-sim --example bench_pipeline; target/release/examples/...).
#   SCENARIO: a name part for --only (default pickup); SEEDS: seeds 1..SEEDS (default 3);
#   ROUNDS: runs of each binary (default 3). Both run laser + wheel without the camera.
# Output: per seed the least CPU ms per frame of A and of B and B / A, then the sums' ratio; and
#   whether the two gave the same trajectories and angles (every column but the times), since a
#   pure speed change must not move them.
set -euo pipefail

if [ $# -lt 2 ]; then
  sed -n '2,15p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
a=$1
b=$2
scenario=${3:-pickup}
seeds=${4:-3}
rounds=${5:-3}
for bin in "$a" "$b"; do
  [ -x "$bin" ] || { echo "error: $bin is not an executable bench_pipeline binary" >&2; exit 2; }
done

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for r in $(seq "$rounds"); do
  for side in A B; do
    bin=$a
    [ "$side" = B ] && bin=$b
    "$bin" "$seeds" --no-depth --only "$scenario" > "$tmp/$side-$r.txt" 2> "$tmp/$side-$r.err" || {
      echo "error: $bin failed (round $r); its stderr:" >&2
      cat "$tmp/$side-$r.err" >&2
      exit 1
    }
  done
done

python3 - "$tmp" "$rounds" <<'EOF'
import collections, pathlib, sys

tmp, rounds = pathlib.Path(sys.argv[1]), int(sys.argv[2])
least = collections.defaultdict(lambda: float("inf"))
results = {}
for side in "AB":
    for r in range(1, rounds + 1):
        rows = []
        for line in (tmp / f"{side}-{r}.txt").read_text().splitlines():
            cells = [c.strip() for c in line.split("|")]
            # Per-seed rows: | scenario | seed | variant | ... | ms/frame | cpu ms/frame | points |
            if len(cells) > 13 and cells[2].isdigit():
                key = (cells[1], cells[2])
                least[(side, key)] = min(least[(side, key)], float(cells[12]))
                rows.append(cells[:11] + cells[13:])
        results.setdefault(side, rows)
keys = sorted({k for (_, k) in least})
if not keys:
    sys.exit("error: no per-seed rows in the benches' output (wrong SCENARIO?)")
total = {"A": 0.0, "B": 0.0}
for key in keys:
    a, b = least[("A", key)], least[("B", key)]
    total["A"] += a
    total["B"] += b
    print(f"{key[0]} seed {key[1]}: A {a:.1f} ms, B {b:.1f} ms, B / A {b / a:.3f}")
print(f"sum: A {total['A']:.1f}, B {total['B']:.1f}, B / A {total['B'] / total['A']:.3f}")
same = results.get("A") == results.get("B")
print("outputs (trajectories, clouds, angles):", "identical" if same else "DIFFERENT")
EOF
