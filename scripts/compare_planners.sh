#!/usr/bin/env bash
# Compare planners on the maze: steps to 50 % / 90 % / 95 % coverage and path length, as a
# Markdown table. Needs the stack's summary.json to carry `coverage_steps` ({"0.5": N, "0.9": N,
# "0.95": N}, null when not reached) and `path_length_m`.
# Usage: scripts/compare_planners.sh [TICKS] [PLANNER...]
set -euo pipefail
cd "$(dirname "$0")/.."
ticks="${1:-60000}"
shift || true
planners=("${@:-random-walk frontier}")
read -r -a planners <<<"${planners[*]}"
# The same build as scripts/eval-baselines.sh: `cargo run -p mole-launch` alone unifies other
# features and relinks `mole`, under any eval running beside it.
cargo build --quiet --release --workspace --bins
echo "| planner | steps to 50 % | steps to 90 % | steps to 95 % | final coverage | path length (m) |"
echo "| --- | ---: | ---: | ---: | ---: | ---: |"
for p in "${planners[@]}"; do
    out="runs/compare/$p"
    mkdir -p "$out"
    if ! target/release/mole up --scenario scenarios/maze.toml \
        --mode lockstep --planner "$p" --ticks "$ticks" --out "$out" >"$out/run.log" 2>&1; then
        echo "| $p | run failed (see $out/run.log) | | | | |"
        continue
    fi
    python3 - "$p" "$out/summary.json" <<'PY'
import json, sys
name, path = sys.argv[1], sys.argv[2]
s = json.load(open(path))
cs = s.get("coverage_steps") or {}
f = lambda k: "—" if cs.get(k) is None else str(cs[k])
cov = s.get("coverage")
pl = s.get("path_length_m")
print(f"| {name} | {f('0.5')} | {f('0.9')} | {f('0.95')} | "
      f"{'—' if cov is None else f'{cov:.3f}'} | {'—' if pl is None else f'{pl:.1f}'} |")
PY
done
