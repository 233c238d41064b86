#!/usr/bin/env bash
# Regenerates eval/baselines/: every stored suite (`mole eval --baselines`: every planner on every
# world family, every estimator on its families), in release, then the README's tables drawn from
# them. Review the diff before committing it: a change in a table is a change in what the
# algorithms do.
# Usage: scripts/eval-baselines.sh [WORLDS (default 50)] [JOBS (default: the cores)]
set -euo pipefail
cd "$(dirname "$0")/.."
worlds="${1:-50}"
jobs="${2:-$(nproc)}"
cargo build --quiet --release --workspace --bins
target/release/mole eval --baselines eval/baselines \
    --worlds "$worlds" --jobs "$jobs" --out target/eval-baselines
MOLE_BLESS=1 cargo test --quiet --test baselines
