#!/usr/bin/env bash
# The whole Waymark test suite, from a fresh Debian machine with Rust (rustup) on it.
# Installs what it needs, then runs every check. CI runs exactly this (.ci/run).
#
#   ./scripts/test.sh
#
set -euo pipefail
cd "$(dirname "$0")/.."

step() { printf '\n==> %s\n' "$*"; }

step "Installing what the tests need"
for component in rustfmt clippy; do
    if ! rustup component list --installed 2>/dev/null | grep -q "^$component"; then
        rustup component add "$component"
    fi
done

step "Formatting (cargo fmt --check)"
cargo fmt --all -- --check

step "Lints (cargo clippy, warnings denied)"
cargo clippy --all-targets --all-features --locked -- -D warnings

step "Rust tests (unit, integration, property, doc)"
cargo test --all-features --locked

step "The README's main command, as a smoke test (waymark demo --json)"
cargo run --release --features cli --locked --quiet -- demo --json --walks 20

step "C ABI: header freshness, shared and static library under valgrind"
bash bindings/c/test.sh

step "Kotlin bindings on the JVM (JNA, JUnit 4)"
bash bindings/kotlin/test.sh
