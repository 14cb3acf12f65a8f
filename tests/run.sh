#!/usr/bin/env bash
# The whole test suite, on a fresh machine as on CI (.ci/run calls this): it
# installs what the tests check against (the Python packages of
# tests/requirements.txt and GarmentCode's pygarment, the Python package of
# python/ built as a wheel, Foxglove's own decoders and the Khronos glTF
# validator from npm, ROS 2 Jazzy's
# rclpy on Fast DDS from PyPI in a venv with garment_sim_msgs built for it),
# builds the physics core on its own (the garment_core crate must build
# without ROS, bags, the command line and PNG), then runs every test of the
# workspace, and the node's DDS Security test with the feature `security` on.
set -euo pipefail
cd "$(dirname "$0")/.."
# OpenSSL for the node's DDS Security (cargo feature `security`, tests/ros_security.rs)
if ! pkg-config --exists openssl 2>/dev/null; then
    apt-get update -qq && apt-get install -y libssl-dev pkg-config
fi
python3 -m pip install --quiet --disable-pip-version-check -r tests/requirements.txt
# GarmentCode's pygarment, without the meshing and GUI stack it pins
python3 -m pip install --quiet --disable-pip-version-check --no-deps pygarment==2.0.2
# the Python package (python/, an abi3 wheel built by maturin with the workspace's target dir)
rm -rf target/wheels
CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$PWD/target}" python3 -m maturin build --release \
    --manifest-path python/Cargo.toml --out target/wheels
python3 -m pip install --quiet --disable-pip-version-check --force-reinstall --no-deps target/wheels/garment_sim-*.whl
npm ci --prefix tests/foxglove --no-audit --no-fund --loglevel=error
npm ci --prefix tests/gltf --no-audit --no-fund --loglevel=error
bash tests/ros2_venv.sh
cargo build --release -p garment_core
forbidden=$(cargo tree -p garment_core -e normal --prefix none \
    | grep -E '^(ros2-client|rustdds|mcap|clap|indicatif|png|serde_yaml|serde_json) ' || true)
if [ -n "$forbidden" ]; then
    echo "garment_core must not depend on: $forbidden" >&2
    exit 1
fi
cargo test --release --workspace --no-fail-fast
# the node with DDS Security (SROS2), a feature off in the default build
cargo test --release --features security --test ros_security
