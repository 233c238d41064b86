#!/usr/bin/env bash
# Regenerates eval/baselines/: every stored suite (`mole eval --baselines`: every planner on every
# world family, every estimator on its families), in release, then the README's tables drawn from
# them. Review the diff before committing it: a change in a table is a change in what the
# algorithms do.
# Usage: scripts/eval-baselines.sh [WORLDS (default 50)] [JOBS (default: the cores)] [FAMILY...]
# (with families, only their suites run; the tables are drawn from every stored suite).
set -euo pipefail
cd "$(dirname "$0")/.."
worlds="${1:-50}"
jobs="${2:-$(nproc)}"
cargo build --quiet --release --workspace --bins
families=("${@:3}")
if [ ${#families[@]} -eq 0 ]; then families=(""); fi
for family in "${families[@]}"; do
    target/release/mole eval --baselines eval/baselines ${family:+--family "$family"} \
        --worlds "$worlds" --jobs "$jobs" --out target/eval-baselines
done
MOLE_BLESS=1 cargo test --quiet --test baselines
