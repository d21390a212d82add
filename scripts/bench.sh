#!/usr/bin/env bash
# Speed and memory at building scale, as one JSON object on stdout (`waymark bench --json`).
# Builds the CLI, then the plain release library whose stripped size is reported (building
# the CLI builds the library with the `plot` feature, which the shipped library does not
# have), and runs the bench. Takes ~10 minutes on one core; needs ~6 GB of memory for the
# 50 000-state site and the 10 000-state dense reference.
#
#   ./scripts/bench.sh [waymark bench options]     e.g. --states 1000,10000
set -euo pipefail
cd "$(dirname "$0")/.."
target=${CARGO_TARGET_DIR:-$PWD/target}
cargo build --release --locked -p waymark-cli --quiet
cargo build --release --locked -p waymark --lib --quiet
exec "$target/release/waymark" bench --json --cdylib "$target/release/libwaymark.so" "$@"
