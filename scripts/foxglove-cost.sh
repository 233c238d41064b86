#!/usr/bin/env bash
# What serving Foxglove costs the stack: realtime loop latency (p50/p99) and lockstep steps/s
# without `--foxglove`, with it and no client, and with a client subscribed to every channel
# (tests/support/foxglove_client.mjs, which decodes every JSON message), in alternating rounds,
# as Markdown table rows. Lockstep steps/s is the summary's ticks over its wall time; with a
# client the run is held (--paused) until the client has subscribed and paces it, so its
# steps/s is the client's: the truths' simulated span over the wall time it received them in.
#
# Usage: scripts/foxglove-cost.sh [ROUNDS] [REALTIME_TICKS] [LOCKSTEP_TICKS] [OUT]
#   ROUNDS          rounds of the runs (default 2)
#   REALTIME_TICKS  steps of each realtime run (default 1500, 15 s at 100 Hz)
#   LOCKSTEP_TICKS  steps of each lockstep run (default 20000)
#   OUT             where the runs go (default runs/foxglove-cost)
# Needs a release build (cargo build --release --workspace), node with target/node-env
# (scripts/node-env.sh) and python3.
set -euo pipefail
cd "$(dirname "$0")/.."
rounds="${1:-2}"
realtime_ticks="${2:-1500}"
lockstep_ticks="${3:-20000}"
out="${4:-runs/foxglove-cost}"
mole=target/release/mole
client=(node tests/support/foxglove_client.mjs target/node-env)
if ! [ -x "$mole" ] || ! "${client[@]}" --versions >/dev/null 2>&1; then
    echo "$0: needs $mole (cargo build --release --workspace) and target/node-env (scripts/node-env.sh)" >&2
    exit 2
fi
mkdir -p "$out"
period_ns=10000000

# Runs `mole up` with the rest of the arguments in the background, into $out/$1.
start_served() {
    local name="$1"
    shift
    rm -rf "$out/$name" "$out/$name.stdout"
    "$mole" up --namespace "fc-$name-$$" --out "$out/$name" --quiet --foxglove=0 "$@" \
        >"$out/$name.stdout" 2>"$out/$name.stderr" &
}

# The Foxglove URL the run $1 printed, once it did.
url_of() {
    local name="$1"
    for _ in $(seq 1 600); do
        if grep -q '^foxglove: ' "$out/$name.stdout" 2>/dev/null; then
            grep '^foxglove: ' "$out/$name.stdout" | head -1 | cut -d' ' -f2
            return
        fi
        sleep 0.1
    done
    echo "$0: $name: no Foxglove URL" >&2
    exit 1
}

latency() {
    python3 -c 'import json,sys; l=json.load(open(sys.argv[1]))["loop_latency_us"]; print("%.0f µs | %.2f ms" % (l["p50"], l["p99"] / 1000))' "$1/summary.json"
}
steps_per_s() {
    python3 -c 'import json,sys; s=json.load(open(sys.argv[1])); print(round(s["ticks"]/s["wall_time_s"]))' "$1/summary.json"
}

for round in $(seq 1 "$rounds"); do
    for kind in none server client; do
        name="realtime-$kind-$round"
        args=(--mode realtime --ticks "$realtime_ticks")
        case "$kind" in
        none)
            "$mole" up --namespace "fc-$name-$$" --out "$out/$name" --quiet "${args[@]}" >/dev/null 2>&1
            ;;
        server)
            start_served "$name" "${args[@]}"
            wait
            ;;
        client)
            start_served "$name" "${args[@]}"
            url="$(url_of "$name")"
            "${client[@]}" "$url" --quiet --timeout $((realtime_ticks / 100 + 60)) \
                --until $((realtime_ticks * period_ns)) >"$out/$name.client.json" || true
            wait
            ;;
        esac
        echo "| realtime | $kind | $round | $(latency "$out/$name") |"
    done
    for kind in none server client; do
        name="lockstep-$kind-$round"
        args=(--mode lockstep --ticks "$lockstep_ticks")
        case "$kind" in
        none)
            "$mole" up --namespace "fc-$name-$$" --out "$out/$name" --quiet "${args[@]}" >/dev/null 2>&1
            rate="$(steps_per_s "$out/$name")"
            ;;
        server)
            start_served "$name" "${args[@]}"
            wait
            rate="$(steps_per_s "$out/$name")"
            ;;
        client)
            start_served "$name" "${args[@]}" --paused
            url="$(url_of "$name")"
            "${client[@]}" "$url" --quiet --run --timeout 600 \
                --until $((lockstep_ticks * period_ns)) >"$out/$name.client.json"
            wait
            rate="$(python3 -c 'import json,sys; p=json.load(open(sys.argv[1]))["paced"]; print(round((int(p["lastLogTime"])-int(p["firstLogTime"]))/1e7/((p["lastMs"]-p["firstMs"])/1e3)))' "$out/$name.client.json")"
            ;;
        esac
        echo "| lockstep | $kind | $round | $rate steps/s |"
    done
done
