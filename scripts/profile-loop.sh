#!/usr/bin/env bash
# Where the loop's time goes: per process and per step, the syscalls (count and kernel time),
# the context switches and the CPU migrations of a running stack, as a Markdown table
# (docs/latency.md explains the method and the numbers).
#
# Usage: scripts/profile-loop.sh [MODE] [TICKS] [WINDOW_S] [OUT]
#   MODE      realtime (default) or lockstep
#   TICKS     steps the stack runs (default: 3000 realtime, 60000 lockstep)
#   WINDOW_S  length of each measurement window (default 8)
#   OUT       output directory (default /tmp/mole-profile-MODE)
# Needs a release build (cargo build --release --workspace), strace, and /proc.
#
# Two windows once the stack runs, each bracketed by the tick `mole status` reports:
#   1. untraced: context switches (voluntary, involuntary) and migrations (se.nr_migrations),
#      summed over every thread, from /proc/PID/task/*/{status,sched}; CPU time from
#      /proc/PID/task/*/schedstat (ns) and its kernel share from /proc/PID/stat (clock ticks); syscalls counted in the kernel by `perf stat -e raw_syscalls:sys_enter`
#      when perf is there (a counter, no tracing);
#   2. traced: `strace -c -f -p PID` on every process at once: calls and kernel time per syscall
#      (strace slows the traced processes down, so its window only counts per step, and
#      context switches are taken in the untraced window).
set -euo pipefail
cd "$(dirname "$0")/.."
mode="${1:-realtime}"
case "$mode" in
realtime) ticks="${2:-3000}" ;;
lockstep) ticks="${2:-60000}" ;;
*)
    echo "usage: $0 [realtime|lockstep] [TICKS] [WINDOW_S] [OUT]" >&2
    exit 2
    ;;
esac
window="${3:-8}"
out="${4:-/tmp/mole-profile-$mode}"
mole=target/release/mole
namespace="prof-$mode-$$"
for tool in strace python3; do
    command -v "$tool" >/dev/null || {
        echo "$0: $tool is missing (apt-get install $tool)" >&2
        exit 2
    }
done
[[ -x $mole ]] || {
    echo "$0: build first: cargo build --release --workspace" >&2
    exit 2
}
rm -rf "$out"
mkdir -p "$out"

launcher=""
tracers=()
cleanup() {
    for pid in "${tracers[@]}"; do kill -INT "$pid" 2>/dev/null || true; done
    if [[ -n $launcher ]] && kill -0 "$launcher" 2>/dev/null; then
        kill -INT "$launcher" 2>/dev/null || true
        wait "$launcher" 2>/dev/null || true
    fi
}
trap cleanup EXIT

"$mole" up --mode "$mode" --ticks "$ticks" --namespace "$namespace" --out "$out/run" --quiet \
    >"$out/up.log" 2>&1 &
launcher=$!

# `mole status`: "realtime, tick 207 of 400: world (pid 31937, 0 restarts), sensing (pid ...".
status() { "$mole" status --namespace "$namespace" 2>/dev/null || true; }
tick() { status | sed -n 's/^[a-z]*, tick \([0-9]*\) .*/\1/p'; }

# Wait until the loop runs (tick ≥ 100), then note each role's pid.
for _ in $(seq 1 300); do
    t="$(tick)"
    [[ -n $t && $t -ge 100 ]] && break
    sleep 0.1
done
[[ -n ${t:-} && $t -ge 100 ]] || {
    echo "$0: the stack did not start (see $out/up.log)" >&2
    exit 1
}
status | grep -o '[a-z]* (pid [0-9]*' | sed 's/ (pid / /' >"$out/pids"

# One line per process: role pid vol invol migrations run_ns user_ticks kernel_ticks (summed
# over its threads).
counters() {
    while read -r role pid; do
        local vol=0 invol=0 mig=0 run=0 v i m r
        for task in /proc/"$pid"/task/*; do
            r=$(awk '{print $1}' "$task/schedstat" 2>/dev/null || echo 0)
            run=$((run + ${r:-0}))
            v=$(awk '/^voluntary_ctxt_switches/ {print $2}' "$task/status" 2>/dev/null || echo 0)
            i=$(awk '/^nonvoluntary_ctxt_switches/ {print $2}' "$task/status" 2>/dev/null || echo 0)
            m=$(awk '/^se.nr_migrations/ {print $3}' "$task/sched" 2>/dev/null || echo 0)
            vol=$((vol + ${v:-0})) invol=$((invol + ${i:-0})) mig=$((mig + ${m:-0}))
        done
        local cpu
        cpu=$(awk '{print $14, $15}' /proc/"$pid"/stat 2>/dev/null || echo 0 0)
        echo "$role $pid $vol $invol $mig $run $cpu"
    done <"$out/pids"
}

# Window 1: untraced counters.
if command -v perf >/dev/null; then
    while read -r role pid; do
        perf stat -x, -e raw_syscalls:sys_enter -p "$pid" -o "$out/perf.$role" 2>/dev/null &
        tracers+=($!)
    done <"$out/pids"
    sleep 0.5
fi
tick >"$out/ticks.counters"
counters >"$out/counters.before"
sleep "$window"
counters >"$out/counters.after"
tick >>"$out/ticks.counters"
for pid in "${tracers[@]}"; do kill -INT "$pid" 2>/dev/null || true; done
for pid in "${tracers[@]}"; do wait "$pid" 2>/dev/null || true; done
tracers=()

# Window 2: strace on every process at once.
while read -r role pid; do
    strace -c -f -q -p "$pid" -o "$out/strace.$role" 2>/dev/null &
    tracers+=($!)
done <"$out/pids"
sleep 0.5
tick >"$out/ticks.strace"
sleep "$window"
tick >>"$out/ticks.strace"
for pid in "${tracers[@]}"; do kill -INT "$pid" 2>/dev/null || true; done
for pid in "${tracers[@]}"; do wait "$pid" 2>/dev/null || true; done
tracers=()
cleanup
launcher=""

python3 - "$out" "$mode" <<'PY'
import sys
from pathlib import Path

out, mode = Path(sys.argv[1]), sys.argv[2]
c0, c1 = (int(x) for x in (out / "ticks.counters").read_text().split())
s0, s1 = (int(x) for x in (out / "ticks.strace").read_text().split())
steps_c, steps_s = max(c1 - c0, 1), max(s1 - s0, 1)

def table(path):
    rows = {}
    for line in path.read_text().splitlines():
        f = line.split()
        rows[f[0]] = [int(x) for x in f[2:]]
    return rows

before, after = table(out / "counters.before"), table(out / "counters.after")

def strace(role):
    # strace -c: % time, seconds, usecs/call, calls, [errors], syscall; then a total line.
    calls, failed, secs = {}, 0, 0.0
    path = out / f"strace.{role}"
    if not path.exists():
        return calls, failed, secs
    for line in path.read_text().splitlines():
        f = line.split()
        if len(f) < 5 or not f[0][0].isdigit() or f[-1] == "total":
            continue
        calls[f[-1]] = calls.get(f[-1], 0) + int(f[3])
        failed += int(f[4]) if len(f) == 6 else 0
        secs += float(f[1])
    return calls, failed, secs

print(f"{mode}: {steps_c} steps in the untraced window, {steps_s} in the traced one\n")
def perf_syscalls(role):
    # perf stat -x,: "count,unit,event,..."; the perf window is the untraced one (±0.5 s).
    path = out / f"perf.{role}"
    if not path.exists():
        return None
    for line in path.read_text().splitlines():
        f = line.split(",")
        if len(f) > 2 and f[2] == "raw_syscalls:sys_enter" and f[0].isdigit():
            return int(f[0])
    return None

print("| process | syscalls/step, top 5 (strace) | syscalls/step: strace (failed) / perf "
      "| kernel µs in syscalls/step (strace) | CPU µs/step (kernel share) "
      "| ctx switches/step vol + invol | migrations/step |")
print("| --- | --- | ---: | ---: | ---: | ---: | ---: |")
for role in before:
    b, a = before[role], after.get(role, before[role])
    vol, invol, mig = ((a[i] - b[i]) / steps_c for i in range(3))
    cpu_us = (a[3] - b[3]) / 1e3 / steps_c
    user, kernel = a[4] - b[4], a[5] - b[5]
    share = f"{100 * kernel / (user + kernel):.0f}%" if user + kernel else "—"
    calls, failed, secs = strace(role)
    top = sorted(calls.items(), key=lambda kv: -kv[1])[:5]
    top_s = ", ".join(f"{name} {n / steps_s:.1f}" for name, n in top)
    total = sum(calls.values()) / steps_s
    counted = perf_syscalls(role)
    perf_s = "—" if counted is None else f"{counted / steps_c:.1f}"
    print(f"| {role} | {top_s} | {total:.1f} ({failed / steps_s:.1f}) / {perf_s} "
          f"| {secs * 1e6 / steps_s:.0f} | {cpu_us:.0f} ({share}) "
          f"| {vol:.2f} + {invol:.2f} | {mig:.2f} |")
PY
