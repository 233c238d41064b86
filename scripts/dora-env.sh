#!/usr/bin/env bash
# Installs dora-rs for `mole bench peers` into target/dora-env:
# - bin/dora: the CLI and daemon, from PyPI's dora-rs-cli, in a virtual environment of its own;
# - bin/mole-dora-peer: the loop's node (processes/bench/peers/dora), built in release against
#   crates.io's dora-node-api at the same version, with that crate's own Cargo.lock (about
#   6 minutes on 2 cores the first time: dora brings arrow, zenoh and tokio).
# Usage: scripts/dora-env.sh
# Idempotent: an environment with this version and a node built from the current source is left
# as it is. It never fails: without python3, venv, PyPI or crates.io it says why in one line and
# exits 0; `mole bench peers` then skips the dora rows with the reason, and tests/peers.rs
# skips (or fails, under CI).
set -uo pipefail
cd "$(dirname "$0")/.."

version="1.1.0"
env_dir="target/dora-env"
crate="processes/bench/peers/dora"
node="$env_dir/bin/mole-dora-peer"
log="$env_dir/setup.log"

has_cli() { "$env_dir/bin/dora" --version 2>/dev/null | grep -q "$version"; }
has_node() {
    [ -x "$node" ] && [ "$node" -nt "$crate/src/main.rs" ] && [ "$node" -nt "$crate/Cargo.lock" ]
}

if has_cli && has_node; then
    exit 0
fi
mkdir -p "$env_dir/bin"
if ! has_cli; then
    if ! command -v python3 >/dev/null 2>&1; then
        echo "dora-env: no python3 on PATH, so no dora (mole bench peers skips its rows)"
        exit 0
    fi
    rm -rf "$env_dir/venv"
    if ! python3 -m venv "$env_dir/venv" >"$log" 2>&1; then
        echo "dora-env: python3 -m venv failed (see $log), so no dora"
        exit 0
    fi
    if ! "$env_dir/venv/bin/pip" install --quiet --disable-pip-version-check \
        "dora-rs-cli==$version" >>"$log" 2>&1; then
        echo "dora-env: pip could not install dora-rs-cli==$version (see $log), so no dora"
        exit 0
    fi
    ln -sf ../venv/bin/dora "$env_dir/bin/dora"
fi
if ! has_node; then
    echo "dora-env: building mole-dora-peer on dora-node-api $version (once, several minutes)"
    if ! cargo build --release --locked --quiet --manifest-path "$crate/Cargo.toml" \
        --target-dir "$env_dir/target" >>"$log" 2>&1; then
        echo "dora-env: building $crate failed (see $log), so no dora node"
        exit 0
    fi
    cp "$env_dir/target/release/mole-dora-peer" "$node"
fi
echo "dora-env: $("$env_dir/bin/dora" --version) and $node ready"
