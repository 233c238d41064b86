#!/usr/bin/env bash
# Installs Debian's chromium, the headless browser tests/view.rs loads `mole view`'s page in.
# Usage: scripts/browser-env.sh
# Idempotent: a chromium already there is left as it is. It never fails: without root, apt-get
# or the package registry it says why in one line and exits 0, and the browser test is then
# skipped with that reason (failed under CI).
set -uo pipefail

for candidate in /usr/bin/chromium chromium chromium-browser; do
    if command -v "$candidate" >/dev/null 2>&1; then
        exit 0
    fi
done
if [ "$(id -u)" != 0 ]; then
    echo "browser-env: chromium is missing and this is not root, so no apt-get install (the browser test will be skipped)"
    exit 0
fi
if ! command -v apt-get >/dev/null 2>&1; then
    echo "browser-env: chromium is missing and there is no apt-get (not Debian), so no browser (the browser test will be skipped)"
    exit 0
fi
log="$(mktemp -t browser-env.XXXXXX.log)"
if ! { apt-get update && DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends chromium; } >"$log" 2>&1; then
    echo "browser-env: apt-get could not install chromium (no network or no package; see $log)"
    exit 0
fi
echo "browser-env: $(/usr/bin/chromium --version 2>/dev/null || echo chromium) ready"
