#!/usr/bin/env bash
# Builds the libFuzzer targets in fuzz/ with the stable toolchain and runs each for a while.
#
#   scripts/fuzz.sh [SECONDS] [TARGET...]     default: 60 s each for the parsers of files
#
# cargo-fuzz is not needed: it only adds these flags (SanitizerCoverage through LLVM's sancov
# pass, all stable `-C` options) and `-Zsanitizer=address`, which is nightly-only and left out.
# Without AddressSanitizer, out-of-bounds reads in safe Rust still panic (and crash the fuzzer);
# libFuzzer's -malloc_limit_mb catches any single allocation above 512 MB. Seeds: the hostile corpus
# in onboard/tests/hostile/ (copied; the growing corpus stays under target/fuzz-corpus/).
set -euo pipefail
cd "$(dirname "$0")/../fuzz"
seconds=${1:-60}
shift || true
targets=("$@")
[[ ${#targets[@]} -eq 0 ]] && targets=(pcap_reader cloud_parse recording_readers)
triple=$(rustc -vV | sed -n 's/^host: //p')
export RUSTFLAGS="-Cpasses=sancov-module -Cllvm-args=-sanitizer-coverage-level=4 \
-Cllvm-args=-sanitizer-coverage-inline-8bit-counters -Cllvm-args=-sanitizer-coverage-pc-table \
-Cllvm-args=-sanitizer-coverage-trace-compares --cfg fuzzing"
# Debug assertions and overflow checks come from fuzz/Cargo.toml's release profile (per package).
bins=()
for t in "${targets[@]}"; do bins+=(--bin "$t"); done
cargo build --release --target "$triple" "${bins[@]}"
hostile=../onboard/tests/hostile
for t in "${targets[@]}"; do
    corpus=target/fuzz-corpus/$t
    mkdir -p "$corpus"
    case $t in
        pcap_reader) cp "$hostile"/*.pcap "$corpus"/ ;;
        cloud_parse) cp "$hostile"/*.ply "$hostile"/*.pcd "$hostile"/*.xyz "$corpus"/ ;;
        recording_readers) cp "$hostile"/*.csv "$corpus"/ ;;
        e57_cloud) cp "$hostile"/*.e57 "$corpus"/ ;;
        las_cloud) cp "$hostile"/*.las "$hostile"/*.laz "$corpus"/ ;;
        signature_sidecar) cp "$hostile"/sidecar-*.sig "$corpus"/ ;;
    esac
    echo "==> $t for $seconds s"
    log=target/fuzz-corpus/$t.log
    rc=0
    "target/$triple/release/$t" "$corpus" -max_total_time="$seconds" -rss_limit_mb=1024 \
        -malloc_limit_mb=512 -print_final_stats=1 >"$log" 2>&1 || rc=$?
    grep -E "^(#[0-9]+ +DONE|stat::number_of_executed_units|stat::peak_rss_mb|==[0-9]+== ERROR|SUMMARY)" "$log" || true
    if [[ $rc -ne 0 ]]; then
        echo "$t: the fuzzer found a failure (exit $rc; see $log and fuzz/crash-*)" >&2
        exit 1
    fi
done
