#!/usr/bin/env bash
# Decodes the same VLP-16 capture with passangle's decoder and with velodyne-decoder (PyPI), both
# pinned to one core, and prints points per second for both and the ratio.
#
# usage: bench/vlp16_vs_peer.sh [FILE.pcap] [SECONDS]
#   default FILE: ../shared/data/vlp16/veloview_vlp-16-test-90deg-1-50-frames.pcap (1902 packets).
# needs: python3 with `pip install velodyne-decoder` (3.x); taskset (util-linux) if present.
#
# velodyne-decoder refuses packets whose product byte is 0x21 (VLP-16 firmware older than
# 3.0.29.0, as in the VeloView capture) unless it is 0x22, so both decoders read a scratch copy
# with that byte patched to 0x22 in every data packet; nothing else changes.
set -euo pipefail
cd "$(dirname "$0")/.."
file="${1:-../shared/data/vlp16/veloview_vlp-16-test-90deg-1-50-frames.pcap}"
seconds="${2:-4}"
[ -f "$file" ] || { echo "capture not found: $file" >&2; exit 1; }
python3 -c "import velodyne_decoder" 2>/dev/null || {
  echo "velodyne-decoder is not installed: pip install velodyne-decoder" >&2; exit 1; }

scratch="$(mktemp -d)"
trap 'rm -rf "$scratch"' EXIT
python3 - "$file" "$scratch/capture.pcap" <<'PY'
import struct, sys
data = bytearray(open(sys.argv[1], "rb").read())
assert data[:4] == b"\xd4\xc3\xb2\xa1", "classic little-endian pcap expected"
off, patched = 24, 0
while off + 16 <= len(data):
    incl = struct.unpack_from("<I", data, off + 8)[0]
    off += 16
    if incl == 1248 and data[off + 1247] == 0x21:
        data[off + 1247] = 0x22
        patched += 1
    off += incl
open(sys.argv[2], "wb").write(data)
print(f"scratch copy: {patched} data packets patched 0x21 -> 0x22", file=sys.stderr)
PY

pin=()
if command -v taskset >/dev/null; then pin=(taskset -c 0); fi
cargo build --release -q -p vlp16 --example bench_vlp16
# Five interleaved rounds: other load on the machine hits both alike. Reported: the best pass
# of all rounds per side and the median of the rounds' medians per side, and both ratios.
field() { sed -n "s/.*[ ^]$1=\([^ ]*\).*/\1/p"; }
ours_best=0; peer_best=0; ours_medians=(); peer_medians=(); ours_points=0; peer_points=0
for round in 1 2 3 4 5; do
  ours="$("${pin[@]}" "${CARGO_TARGET_DIR:-target}/release/examples/bench_vlp16" "$scratch/capture.pcap" "$seconds" | grep '^end_to_end')"
  peer="$("${pin[@]}" python3 bench/peer_velodyne_decoder.py "$scratch/capture.pcap" "$((seconds / 2))")"
  echo "round $round: $ours"
  echo "round $round: $peer"
  pps="$(echo " $ours" | field points_per_s)"
  if [ "$pps" -gt "$ours_best" ]; then ours_best="$pps"; fi
  ours_medians+=("$(echo " $ours" | field median_points_per_s)")
  ours_points="$(echo " $ours" | field points)"
  pps="$(echo " $peer" | field points_per_s)"
  if [ "$pps" -gt "$peer_best" ]; then peer_best="$pps"; fi
  peer_medians+=("$(echo " $peer" | field median_points_per_s)")
  peer_points="$(echo " $peer" | field points)"
done
python3 - "$ours_best" "$peer_best" "$ours_points" "$peer_points" "${ours_medians[*]}" "${peer_medians[*]}" <<'PY'
import statistics, sys
ours, peer, n_ours, n_peer = map(float, sys.argv[1:5])
ours_med = statistics.median(map(float, sys.argv[5].split()))
peer_med = statistics.median(map(float, sys.argv[6].split()))
print(f"points decoded:       passangle {n_ours:.0f}, velodyne-decoder {n_peer:.0f}")
print(f"best pass:            passangle {ours / 1e6:.1f} Mpoints/s, velodyne-decoder {peer / 1e6:.1f} Mpoints/s, ratio {ours / peer:.1f}x")
print(f"median:               passangle {ours_med / 1e6:.1f} Mpoints/s, velodyne-decoder {peer_med / 1e6:.1f} Mpoints/s, ratio {ours_med / peer_med:.1f}x")
print("goal: at least 10x on one core")
PY
