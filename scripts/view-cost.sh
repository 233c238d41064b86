#!/usr/bin/env bash
# What watching costs the stack: realtime loop latency (p50/p99) and lockstep steps/s without the
# view, with `--view` and no page open, and with a headless Chromium showing the page, in
# alternating rounds, as a Markdown table (docs/view.md "What it costs" explains the numbers);
# and the view's own frame rate in each run with a view: the frames it made over the time it
# served, from the line its log ends with (`view finished frames=N elapsed_s=S`).
#
# Usage: scripts/view-cost.sh [PAIRS] [REALTIME_S] [LOCKSTEP_TICKS] [OUT]
#   PAIRS           rounds of the three runs, per clock mode (default 2)
#   REALTIME_S      length of each realtime run (default 20)
#   LOCKSTEP_TICKS  steps of each lockstep run (default 50000)
#   OUT             where the reports go (default runs/view-cost)
# Needs a release build (cargo build --release --workspace), chromium (scripts/browser-env.sh)
# and python3 (to read the JSON reports).
set -euo pipefail
cd "$(dirname "$0")/.."
pairs="${1:-2}"
realtime_s="${2:-20}"
lockstep_ticks="${3:-50000}"
out="${4:-runs/view-cost}"
mole=target/release/mole
browser="$(command -v chromium || command -v chromium-browser || true)"
for need in "$mole" "$browser"; do
    if [ -z "$need" ] || ! [ -x "$need" ]; then
        echo "$0: needs $mole (cargo build --release --workspace) and chromium (scripts/browser-env.sh)" >&2
        exit 2
    fi
done
command -v python3 >/dev/null || {
    echo "$0: python3 is missing" >&2
    exit 2
}
mkdir -p "$out"
port=$((20000 + $$ % 20000))
profile="$(mktemp -d -t mole-view-cost.XXXXXX)"
browser_pid=""
stop_browser() {
    if [ -n "$browser_pid" ]; then
        kill "$browser_pid" 2>/dev/null || true
        wait "$browser_pid" 2>/dev/null || true
        browser_pid=""
    fi
}
trap 'stop_browser; rm -rf "$profile"' EXIT

# Opens the page once the view serves it; the browser stays until stop_browser.
open_page() {
    local url="http://127.0.0.1:$port/"
    for _ in $(seq 1 200); do
        if python3 -c "import urllib.request,sys; urllib.request.urlopen(sys.argv[1], timeout=1)" "$url" 2>/dev/null; then
            "$browser" --headless --no-sandbox --disable-gpu --disable-quic --no-first-run \
                --disable-background-networking --disable-component-update --disable-sync \
                --user-data-dir="$profile" "$url" >/dev/null 2>&1 &
            browser_pid=$!
            return 0
        fi
        sleep 0.1
    done
    echo "$0: the view never served $url" >&2
    return 1
}

# run MODE WITH_VIEW N: one `mole bench stack` run, its report in $out.
run() {
    local mode="$1" view="$2" n="$3" length
    if [ "$mode" = realtime ]; then length="--duration=$realtime_s"; else length="--ticks=$lockstep_ticks"; fi
    local name="$mode-$view-$n" extra=()
    [ "$view" != none ] && extra=("--view=$port")
    "$mole" bench stack --mode "$mode" "$length" --namespace "viewcost-$name-$$" \
        --out "$out/$name" --json "$out/$name.json" "${extra[@]}" >/dev/null &
    local bench=$!
    [ "$view" = browser ] && open_page
    wait "$bench"
    stop_browser
}

for n in $(seq 1 "$pairs"); do
    for mode in realtime lockstep; do
        for view in none view browser; do
            run "$mode" "$view" "$n"
        done
    done
done

python3 - "$out" "$pairs" <<'EOF'
import json, re, sys
out, pairs = sys.argv[1], int(sys.argv[2])
def load(name):
    with open(f"{out}/{name}.json") as f:
        return json.load(f)
def frame_rate(name):
    """The view's frames a second in run `name` ("" without a view)."""
    try:
        with open(f"{out}/{name}/logs/view.log", encoding="utf-8", errors="replace") as f:
            log = f.read()
    except OSError:
        return ""
    log = re.sub(r"\x1b\[[0-9;]*m", "", log)  # the log's colours
    found = re.findall(r"view finished.*?frames=(\d+).*?elapsed_s=([0-9.]+)", log)
    if not found:
        return "?"
    frames, seconds = found[-1]
    return f"{int(frames) / float(seconds):.1f}"
print("| run | realtime loop p50 (µs) | p99 (µs) | lockstep steps/s | view frames/s (realtime, lockstep) |")
print("| --- | ---: | ---: | ---: | ---: |")
for n in range(1, pairs + 1):
    for view in ("none", "view", "browser"):
        rt, ls = load(f"realtime-{view}-{n}"), load(f"lockstep-{view}-{n}")
        lat = rt["loop_latency_us"]
        label = {"none": "without the view", "view": "`--view`, no page open",
                 "browser": "`--view` + headless Chromium"}[view]
        rates = ", ".join(r for r in (frame_rate(f"realtime-{view}-{n}"),
                                      frame_rate(f"lockstep-{view}-{n}")) if r)
        print(f"| {n}: {label} | {lat['p50']:.0f} | {lat['p99']:.0f} | {ls['steps_per_s']:.0f} | {rates} |")
EOF
