#!/usr/bin/env bash
# How the stack's cost grows: the realtime loop's latency (p50, p99)
# and the stack's CPU at 100 Hz, and lockstep steps/s, against
#   - observers reading every topic (mole-observer): 0, 1, 4, 8;
#   - the arena: 10, 20, 30, 40 m a side (the default scenario scaled, obstacles, beacons and
#     start with it; cells of 0.05 m until the grid reaches its cap of 512² cells at 25.6 m,
#     then side/512, so the grid stops growing);
#   - the particle filter's particles: 1k, 3k, 10k, 30k, 100k, without and with KLD-sampling
#     (with it, the count is the most; the plot draws both).
# Writes runs/cost-growth/cost.json and docs/img/cost-{observers,grid,particles}.png.
#
#   scripts/cost-growth.sh           # 15 s a point in realtime, 2,000 lockstep steps (≈ 10 min)
#   scripts/cost-growth.sh --quick   # 3 s and 300 steps a point: checks that the script works
#
# A benchmark, not a test: the numbers depend on the machine and on what else runs on it (each
# point records the load average). CARGO_TARGET_DIR is honoured.
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
cd "$root"

seconds=15
lockstep_ticks=2000
case "${1:-}" in
    "") ;;
    --quick) seconds=3 lockstep_ticks=300 ;;
    *) echo "usage: $0 [--quick]" >&2; exit 2 ;;
esac

# The launcher, the stack's processes, mole-observer and mole-plot.
cargo build --release --bins -p mole-launch -p mole-world -p mole-sensing -p mole-localization \
    -p mole-mapping -p mole-planning -p mole-monitor -p mole-bench
bin="${CARGO_TARGET_DIR:-$root/target}/release"
out="$root/runs/cost-growth"
img="$root/docs/img"
mkdir -p "$out" "$img"
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
points="$work/points.tsv"
: >"$points"

# The default launch file with N observers added, each a role of its own.
launch_with_observers() {
    local n=$1 file="$work/launch-$1.toml"
    cp launch/stacks/default.toml "$file"
    for ((i = 1; i <= n; i++)); do
        printf '\n[[process]]\nrole = "observer-%d"\ncommand = "mole-observer"\nargs = ["--role", "observer-%d"]\n' \
            "$i" "$i" >>"$file"
    done
    echo "$file"
}

# The default scenario scaled to an arena SIDE metres a side, with the cell size the grid cap
# allows: max(0.05, side/512).
scaled_scenario() {
    local side=$1 file="$work/arena-$1.toml"
    awk -v side="$side" '
        function scaled(line,   out, pair, kv) {
            out = ""
            while (match(line, /(x|y|side) = [0-9.]+/)) {
                pair = substr(line, RSTART, RLENGTH)
                split(pair, kv, " = ")
                out = out substr(line, 1, RSTART - 1) kv[1] " = " sprintf("%.4f", kv[2] * f)
                line = substr(line, RSTART + RLENGTH)
            }
            return out line
        }
        BEGIN { f = side / 10; res = side / 512; if (res < 0.05) res = 0.05 }
        /^\[/ { section = $1 }
        /^name *=/ { print "name = \"default-" side "m\""; next }
        /^ *\{/ { print scaled($0); next }
        section == "[arena]" && /^(width|height) *=/ { print $1 " = " side; next }
        section == "[start]" && /^(x|y) *=/ { print $1 " = " sprintf("%.4f", $3 * f); next }
        section == "[grid]" && /^resolution *=/ { print "resolution = " sprintf("%.8f", res); next }
        { print }
    ' scenarios/default.toml >"$file"
    echo "$file"
}

# One point: SWEEP X LAUNCH SCENARIO [mole up options...]; a realtime run, then a lockstep one.
measure() {
    local sweep=$1 x=$2 launch=$3 scenario=$4
    shift 4
    local name="$sweep-$x" ns="cost$$${sweep:0:1}$x"
    echo "== $sweep = $x"
    for mode in realtime lockstep; do
        local length=(--duration "$seconds")
        [[ $mode == lockstep ]] && length=(--ticks "$lockstep_ticks")
        "$bin/mole" bench stack "$launch" --scenario "$scenario" "$@" --mode "$mode" \
            "${length[@]}" --namespace "$ns${mode:0:1}" --out "$work/$name-$mode" \
            --json "$work/$name-$mode.json" >"$work/$name-$mode.txt" 2>&1 ||
            { cat "$work/$name-$mode.txt" >&2; exit 1; }
    done
    printf '%s\t%s\t%s\t%s\t%s\n' "$sweep" "$x" "$work/$name-realtime.json" \
        "$work/$name-lockstep.json" "$(cut -d' ' -f1 /proc/loadavg)" >>"$points"
}

echo "load average at the start: $(cut -d' ' -f1-3 /proc/loadavg)"
default_scenario="$root/scenarios/default.toml"
for n in 0 1 4 8; do
    measure observers "$n" "$(launch_with_observers "$n")" "$default_scenario"
done
# Every observer read every step's truth and the stack's statistics (its log's last line).
grep -h "read:" "$work/observers-8-realtime/logs/observer-8.log" | tail -n 1
for side in 10 20 30 40; do
    measure grid "$side" "$(launch_with_observers 0)" "$(scaled_scenario "$side")"
done
for n in 1000 3000 10000 30000 100000; do
    measure particles "$n" "$(launch_with_observers 0)" "$default_scenario" --estimator pf \
        --set "localization.pf.n_particles=$n"
    measure particles-kld "$n" "$(launch_with_observers 0)" "$default_scenario" --estimator pf \
        --set "localization.pf.n_particles=$n" --set localization.pf.kld=true
done
echo "load average at the end: $(cut -d' ' -f1-3 /proc/loadavg)"

"$bin/mole-plot" --points "$points" --json "$out/cost.json" --img-dir "$img"
jq -r '.sweeps[] | .name as $s | .points[] |
    [$s, .x, (.loop_p50_us | round), (.loop_p99_us | round), (.cpu_percent * 10 | round / 10),
     (.lockstep_steps_per_s // 0 | round), .load_average] | @tsv' "$out/cost.json" |
    column -t -N "sweep,x,p50 µs,p99 µs,CPU %,lockstep steps/s,load"
