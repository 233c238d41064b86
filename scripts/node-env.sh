#!/usr/bin/env bash
# Creates target/node-env, a Node.js package directory with Foxglove's published message schemas
# (the `@foxglove/schemas` package, JSON Schema form), a JSON Schema validator (`ajv`) and
# Foxglove's WebSocket protocol client (`@foxglove/ws-protocol`, over `ws`), at the versions
# scripts/node-env/package-lock.json pins (every transitive package too, through `npm ci`):
# tests/export.rs validates every message of a `mole export --foxglove` file against the schemas
# with tests/support/validate_foxglove.mjs; tests/foxglove.rs connects to `mole up --foxglove`
# with tests/support/foxglove_client.mjs.
# Usage: scripts/node-env.sh
# Idempotent: a directory installed from the same lock file is left as it is. It never fails:
# without node, npm or the package registry it says why in one line and exits 0, and the test
# is then skipped with that reason (failed under CI).
set -uo pipefail
cd "$(dirname "$0")/.."

pinned="scripts/node-env"
env_dir="target/node-env"
log="$env_dir/npm.log"

# Whether every package loads from $env_dir.
loads() {
    (cd "$env_dir" && node -e 'require("@foxglove/schemas/jsonschema"); require("ajv"); require("@foxglove/ws-protocol"); require("ws")') >/dev/null 2>&1
}

for tool in node npm; do
    if ! command -v "$tool" >/dev/null 2>&1; then
        echo "node-env: no $tool on PATH, so no $env_dir (the Foxglove schema and client tests will be skipped)"
        exit 0
    fi
done
if cmp -s "$pinned/package-lock.json" "$env_dir/package-lock.json" && loads; then
    exit 0
fi
rm -rf "$env_dir"
mkdir -p "$env_dir"
cp "$pinned/package.json" "$pinned/package-lock.json" "$env_dir/"
if ! (cd "$env_dir" && npm ci --no-audit --no-fund) >"$log" 2>&1; then
    echo "node-env: npm ci could not install $pinned/package-lock.json (no registry? see $log)"
    exit 0
fi
if ! loads; then
    echo "node-env: installed, but @foxglove/schemas, ajv, @foxglove/ws-protocol or ws does not load (see $log)"
    exit 0
fi
echo "node-env: $(cd "$env_dir" && node -p '["@foxglove/schemas", "ajv", "@foxglove/ws-protocol", "ws"].map((p) => p + " " + require(p + "/package.json").version).join(", ")') ready in $env_dir"
