#!/usr/bin/env bash
# Runs the held-out protocol (hil-sim/evaluation.toml): every tuning and held-out run through the
# simulated VLP-16, the pipeline and the angle calculator at their defaults, printing one table per
# set. Arguments go to the bench (--set tuning|held-out|both, --jobs N, --only TEXT).
#
# usage: bench/evaluate.sh [--set both]
#        bench/report.sh evaluate -- bench/evaluate.sh          # with a dated report
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -q -p hil-sim --example evaluate
exec target/release/examples/evaluate "$@"
