#!/usr/bin/env bash
# Creates target/python-env, a Python virtual environment with the iceoryx2 package that
# examples/python_planner needs (tests/python.rs uses it when it is there), at the version the
# Rust side is built against (Cargo.lock): iceoryx2 services refuse another version; and the mcap
# package, an MCAP implementation independent of the Rust crate, that tests/record.rs reads
# recordings with; and the gtsam package (GTSAM, BSD), the reference optimiser that
# processes/localization/tests/g2o.rs compares GraphSLAM's optimum on g2o graphs with
# (scripts/gtsam-reference.py); and mcap-ros2-support, the CDR decoder tests/export.rs reads a ROS 2
# export with.
# Usage: scripts/python-env.sh
# Idempotent: an environment that already has all four packages is left as it is. It never fails:
# without python3, venv or the package registry it says why in one line and exits 0, and the
# Python tests are then skipped with that reason.
set -uo pipefail
cd "$(dirname "$0")/.."

version="$(sed -n '/^name = "iceoryx2"$/{n;s/^version = "\(.*\)"$/\1/p;}' Cargo.lock 2>/dev/null)"
env_dir="target/python-env"
mcap_version="1.6.0"
mcap_ros2_version="0.6.0"
gtsam_version="4.3.0"
python="$env_dir/bin/python3"
log="$env_dir/pip.log"

has_iceoryx2() {
    "$python" -c "import sys, importlib.metadata as m, iceoryx2
sys.exit(m.version('iceoryx2') != '$version')" >/dev/null 2>&1
}

has_mcap() {
    "$python" -c "import sys, importlib.metadata as m, mcap.reader, lz4, mcap_ros2.decoder
sys.exit(m.version('mcap') != '$mcap_version' or m.version('mcap-ros2-support') != '$mcap_ros2_version')" >/dev/null 2>&1
}

has_gtsam() {
    "$python" -c "import sys, importlib.metadata as m, gtsam
sys.exit(m.version('gtsam') != '$gtsam_version')" >/dev/null 2>&1
}

if [ -z "$version" ]; then
    echo "python-env: Cargo.lock names no iceoryx2 version, so no $env_dir"
    exit 0
fi
if [ -x "$python" ] && has_iceoryx2 && has_mcap && has_gtsam; then
    exit 0
fi
if ! command -v python3 >/dev/null 2>&1; then
    echo "python-env: no python3 on PATH, so no $env_dir (the Python planner test will be skipped)"
    exit 0
fi
if [ ! -x "$python" ] && ! python3 -m venv "$env_dir" >/dev/null 2>&1; then
    rm -rf "$env_dir"
    echo "python-env: \`python3 -m venv\` failed (Debian: apt-get install python3-venv), so no $env_dir"
    exit 0
fi
if ! "$python" -m pip install --disable-pip-version-check --timeout 30 --retries 2 \
    "iceoryx2==$version" "mcap==$mcap_version" "mcap-ros2-support==$mcap_ros2_version" \
    "gtsam==$gtsam_version" >"$log" 2>&1; then
    echo "python-env: pip could not install iceoryx2==$version, mcap==$mcap_version, mcap-ros2-support==$mcap_ros2_version and gtsam==$gtsam_version (no network or no wheel for this platform; see $log)"
    exit 0
fi
if ! has_iceoryx2; then
    echo "python-env: iceoryx2==$version installed but does not import (see $log)"
    exit 0
fi
if ! has_mcap; then
    echo "python-env: mcap==$mcap_version or mcap-ros2-support==$mcap_ros2_version installed but does not import (see $log)"
    exit 0
fi
if ! has_gtsam; then
    echo "python-env: gtsam==$gtsam_version installed but does not import (see $log)"
    exit 0
fi
echo "python-env: iceoryx2 $version, mcap $mcap_version, mcap-ros2-support $mcap_ros2_version and gtsam $gtsam_version ready in $env_dir"
