#!/usr/bin/env bash
# One kind of fault, four times, in a realtime run of the default stack, against the unfaulted
# run of the same seed: what that fault costs the estimate and the map. `mole fault ARGS...` is
# injected 5, 10, 15 and 20 s after the world is ready; both runs take TICKS steps (at 100 Hz,
# 3000 is 30 s). Prints one Markdown row: the fault, pose RMSE, mean NEES and map IoU of the
# faulted and the unfaulted run, and the restarts (docs/architecture.md, "Faults on demand").
#
# Usage: scripts/one-fault.sh TICKS SEED FAULT...   e.g. scripts/one-fault.sh 3000 7 kill sensing
# Needs a build (cargo build --workspace --bins; MOLE_BIN=target/release for a release one) and
# python3 (to read the summaries). Runs go to runs/one-fault.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ $# -lt 3 ]; then
    echo "usage: $0 TICKS SEED FAULT..." >&2
    exit 2
fi
ticks="$1"
seed="$2"
shift 2
mole="${MOLE_BIN:-target/debug}/mole"
if ! [ -x "$mole" ]; then
    echo "$0: needs $mole (cargo build --workspace --bins)" >&2
    exit 2
fi
out="runs/one-fault"
rm -rf "$out"
mkdir -p "$out"
for run in plain faulted; do
    ns="onefault$$-$run"
    "$mole" up --quiet --mode realtime --seed "$seed" --ticks "$ticks" --namespace "$ns" \
        --out "$out/$run" >"$out/$run.log" 2>&1 &
    up=$!
    if [ "$run" = faulted ]; then
        for _ in $(seq 1 600); do
            grep -qs "ready" "$out/$run/logs/world.log" && break
            sleep 0.1
        done
        for _ in 1 2 3 4; do
            sleep 5
            "$mole" fault --namespace "$ns" "$@" >>"$out/faults.txt" 2>&1 ||
                echo "$0: mole fault $* failed: $(tail -1 "$out/faults.txt")" >&2
        done
    fi
    wait "$up" || true
done
python3 - "$out" "$*" <<'PY'
import json, sys
out, fault = sys.argv[1], sys.argv[2]
f, p = (json.load(open(f"{out}/{r}/summary.json")) for r in ("faulted", "plain"))
def n(x, d):
    return "–" if x is None else f"{x:.{d}f}"
restarts = sum(f.get("restarts", {}).values())
print(f"| {fault} ×4 | {n(f.get('localization_rmse_m'), 4)} / {n(p.get('localization_rmse_m'), 4)} "
      f"| {n(f.get('mean_nees'), 1)} / {n(p.get('mean_nees'), 1)} "
      f"| {n(f.get('map_iou'), 3)} / {n(p.get('map_iou'), 3)} | {restarts} |")
PY
