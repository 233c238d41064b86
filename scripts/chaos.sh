#!/usr/bin/env bash
# A chaos session on the default stack, in each clock mode, against the unfaulted run: `mole fault
# chaos` injects a seeded random sequence of kills, stops, delays, drops and corruptions for
# SECONDS while the stack runs; then the same seed runs unfaulted for as many ticks as the
# faulted run made. Prints a Markdown table: faults by kind, restarts and hangs, samples dropped
# and caught invalid, pose RMSE and map IoU of both runs, how each run ended, and what the stacks
# left in /dev/shm and /tmp/iceoryx2 (docs/architecture.md, "Faults on demand", explains it).
#
# Usage: scripts/chaos.sh [SECONDS] [SEED] [OUT]
#   SECONDS  how long faults are injected in each mode (default 180)
#   SEED     the seed of the runs and of the fault sequence (default 7)
#   OUT      where the runs go (default runs/chaos)
# Needs a build (cargo build --workspace --bins; MOLE_BIN=target/release for a release one) and
# python3 (to read the summaries).
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${1:-180}"
seed="${2:-7}"
out="${3:-runs/chaos}"
mole="${MOLE_BIN:-target/debug}/mole"
if ! [ -x "$mole" ]; then
    echo "$0: needs $mole (cargo build --workspace --bins)" >&2
    exit 2
fi
command -v python3 >/dev/null || {
    echo "$0: python3 is missing" >&2
    exit 2
}
rm -rf "$out"
mkdir -p "$out"
ours() { ls /dev/shm /tmp/iceoryx2/nodes /tmp/iceoryx2/services 2>/dev/null | grep -c "chaos$$" || true; }

for mode in lockstep realtime; do
    ns="chaos$$-$mode"
    # The faulted run: longer than the session, interrupted when the session is over.
    "$mole" up --quiet --mode "$mode" --seed "$seed" --ticks 100000000 --namespace "$ns" \
        --out "$out/$mode-faulted" >"$out/$mode-faulted.log" 2>&1 &
    up=$!
    for _ in $(seq 1 600); do
        grep -qs "ready" "$out/$mode-faulted/logs/world.log" && break
        sleep 0.1
    done
    "$mole" fault --namespace "$ns" chaos --duration "$seconds" --seed "$seed" \
        --json "$out/$mode-faults.json" >"$out/$mode-faults.txt" 2>&1 || {
        echo "$0: mole fault chaos failed ($mode):" >&2
        cat "$out/$mode-faults.txt" >&2
    }
    kill -INT "$up" 2>/dev/null || true
    wait "$up" || true
    ticks="$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["ticks"])' \
        "$out/$mode-faulted/summary.json")"
    # The unfaulted run: the same seed, as many ticks.
    "$mole" up --quiet --mode "$mode" --seed "$seed" --ticks "$ticks" --namespace "$ns-plain" \
        --out "$out/$mode-plain" >"$out/$mode-plain.log" 2>&1 || true
done
left="$(ours)"

python3 - "$out" "$seconds" "$seed" "$left" <<'EOF'
import collections, json, pathlib, sys
out, seconds, seed, left = sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4]
def load(name):
    with open(f"{out}/{name}/summary.json") as f:
        return json.load(f)
def panics(name):
    logs = pathlib.Path(out, name, "logs").glob("*.log")
    return sum(log.read_text(errors="replace").count("panicked") for log in logs)
def number(x, digits):
    return "–" if x is None else f"{x:.{digits}f}"
print(f"chaos session: {seconds} s of faults per mode, seed {seed}\n")
print("| mode | faults (kill/stop/delay/drop/corrupt) | restarts | hangs | dropped | invalid "
      "| RMSE faulted / unfaulted (m) | ratio | IoU faulted / unfaulted | ticks | ended | panics |")
print("| --- | --- | ---: | ---: | ---: | ---: | --- | ---: | --- | ---: | --- | ---: |")
for mode in ("lockstep", "realtime"):
    f, p = load(f"{mode}-faulted"), load(f"{mode}-plain")
    kinds = collections.Counter(x["kind"] for x in f.get("faults", []))
    by_kind = "/".join(str(kinds.get(k, 0)) for k in ("kill", "stop", "delay", "drop", "corrupt"))
    dropped = sum(t.get("dropped", 0) for t in f["topics"].values())
    invalid = sum(t.get("invalid", 0) for t in f["topics"].values())
    rf, rp = f.get("localization_rmse_m"), p.get("localization_rmse_m")
    ratio = number(rf / rp, 2) if rf is not None and rp else "–"
    print(f"| {mode} | {sum(kinds.values())} ({by_kind}) | {sum(f['restarts'].values())} "
          f"| {sum(f.get('hangs', {}).values())} | {dropped} | {invalid} "
          f"| {number(rf, 3)} / {number(rp, 3)} | {ratio} "
          f"| {number(f.get('map_iou'), 3)} / {number(p.get('map_iou'), 3)} | {f['ticks']} "
          f"| {f['exit_reason']}, {p['exit_reason']} | {panics(f'{mode}-faulted')} |")
print(f"\nleft in /dev/shm and /tmp/iceoryx2 by the stacks: {left} files")
EOF
