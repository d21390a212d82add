#!/usr/bin/env bash
# The whole Waymark test suite, from a fresh Debian machine with Rust (rustup) on it.
# Installs what it needs, then runs every check. CI runs exactly this (.ci/run).
#
#   ./scripts/test.sh
#
# Ends with one line `N passed, N failed` summing the Rust, C, Kotlin and Swift tests.
set -euo pipefail
cd "$(dirname "$0")/.."
target=${CARGO_TARGET_DIR:-$PWD/target}
mkdir -p "$target"
log="$target/test-suite.log"
: > "$log"

# Each step's heading also prints how long the previous one took, so a slow CI run shows where.
step_start=$SECONDS
step_name=""
step() {
    if [[ -n $step_name ]]; then printf '(%s: %d s)\n' "$step_name" $((SECONDS - step_start)); fi
    step_name=$*; step_start=$SECONDS
    printf '\n==> %s\n' "$*"
}
# Runs a command, keeping its output in the log for the final count.
run() { "$@" 2>&1 | tee -a "$log"; }

step "Installing what the tests need"
for component in rustfmt clippy; do
    if ! rustup component list --installed 2>/dev/null | grep -q "^$component"; then
        rustup component add "$component"
    fi
done
command -v chromium >/dev/null || { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium; }

step "Formatting (cargo fmt --check)"
cargo fmt --all -- --check

step "Lints (cargo clippy, warnings denied)"
cargo clippy --workspace --all-targets --all-features --locked -- -D warnings

step "The shipped library as apps build it: no features, no tool crates"
cargo build -p waymark --lib --locked

step "API docs of the whole workspace, warnings denied"
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --locked --quiet

step "Rust tests (unit, integration, property, doc)"
run cargo test --workspace --all-features --locked

step "The library on the declared MSRV and the mobile targets (checked: no NDK or Xcode here)"
./scripts/check-targets.sh

step "The README's main command, as a smoke test (waymark demo --json)"
cargo run --release -p waymark-cli --locked --quiet -- demo --json --walks 20

step "C ABI: header freshness, shared and static library under valgrind"
run bash bindings/c/test.sh

step "Kotlin bindings on the JVM (JNA, JUnit 4)"
run bash bindings/kotlin/test.sh

step "Swift bindings on Linux (XCTest in a Debian trixie chroot)"
run bash bindings/swift/test.sh

step "waymark view in headless Chromium (every floor renders, no console errors)"
run bash scripts/view-test.sh

step "All tests"
echo "(whole run: $SECONDS s)"
python3 - "$log" <<'PY'
import re, sys
text = open(sys.argv[1], errors="replace").read()
passed = failed = 0
for p, f in re.findall(r"test result: \w+\. (\d+) passed; (\d+) failed", text):  # cargo test
    passed += int(p); failed += int(f)
for p, f in re.findall(r"^(\d+) passed, (\d+) failed$", text, re.M):  # C, Kotlin
    passed += int(p); failed += int(f)
m = re.findall(r"Test Suite 'All tests' \w+ at .*\n\s+Executed (\d+) tests?, with (\d+) failures", text)
if m:  # XCTest
    n, f = map(int, m[-1]); passed += n - f; failed += f
print(f"{passed} passed, {failed} failed")
sys.exit(1 if failed else 0)
PY
