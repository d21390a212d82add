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
# Every Debian package the steps below use, in one apt run (two at once would fight over its lock).
packages=(chromium gcc valgrind python3 python3-venv libjna-java junit4 debootstrap)
missing=()
for pkg in "${packages[@]}"; do dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg"); done
if (( ${#missing[@]} )); then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

step "Formatting (cargo fmt --check)"
cargo fmt --all -- --check

# Docs say what is true now (no dates, commit hashes or patch links in docs/), every docs
# section cited anywhere resolves, and nothing shipped links into the research notes.
step "Docs: a reference, and every cited section resolves (scripts/check-docs.py)"
python3 scripts/check-docs.py

# Lints, docs and tests leave out crates/uniffi-bindgen, one line that calls uniffi's own
# main: checking it means checking uniffi_bindgen, the longest unit of each of those builds
# (about 2 minutes each, docs/testing.md#how-long-it-takes). The Kotlin and Swift steps build
# and run it.
step "Lints (cargo clippy, warnings denied)"
cargo clippy --workspace --exclude uniffi-bindgen --all-targets --all-features --locked -- -D warnings

step "The shipped library as apps build it: no features, no tool crates, warnings denied"
cargo clippy -p waymark -p waymark-engine --lib --locked -- -D warnings

step "API docs of the whole workspace, warnings denied"
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --exclude uniffi-bindgen --no-deps --locked --quiet

step "docs/api.md lists the engine's public items, each with a user (scripts/check-api.py)"
python3 scripts/check-api.py --check

step "Rust tests (unit, integration, property, doc)"
# Real-data tests skip without the data, and fail without it where it is expected: CI sets
# WAYMARK_REQUIRE_DATA=1 (.ci/run), and so does this script when it finds a data folder
# (WAYMARK_DATA, or data/ in a folder beside the checkout, docs/testing.md#real-data).
if [[ -z ${WAYMARK_REQUIRE_DATA:-} ]]; then
    if [[ -n ${WAYMARK_DATA:-} ]] || compgen -G "../*/data/ilc20-site1" > /dev/null; then
        export WAYMARK_REQUIRE_DATA=1
    fi
fi
if [[ -n ${WAYMARK_REQUIRE_DATA:-} ]]; then
    echo "real-data tests: the data is required (WAYMARK_REQUIRE_DATA=$WAYMARK_REQUIRE_DATA)"
else
    echo "real-data tests: no data folder found, they skip"
fi
run cargo test --workspace --exclude uniffi-bindgen --all-features --locked

step "The library on the declared MSRV and the mobile targets (checked: no NDK or Xcode here)"
./scripts/check-targets.sh

step "The README's main command, as a smoke test (waymark demo --json)"
# The Kotlin compiler and the Swift chroot are downloads and unpacking: they are made in the
# background from the demo step on, whose release build links on one core, and the binding
# steps wait for them. Started with clippy, they slowed it as much as they saved.
# Each in its own process group, so that a failing run stops them too.
setsid bash bindings/kotlin/test.sh --tools-only > "$target/kotlin-tools.log" 2>&1 &
kotlin_tools=$!
setsid bash bindings/swift/test.sh --tools-only > "$target/swift-tools.log" 2>&1 &
swift_tools=$!
trap 'kill -- -$kotlin_tools -$swift_tools 2>/dev/null || true' EXIT
# Waits for one of those; on failure shows its log and stops.
tools_ready() {
    wait "$1" || { cat "$2" >&2; echo "test.sh: making the tools failed (above)" >&2; exit 1; }
}
cargo run --release -p waymark-cli --locked --quiet -- demo --json --walks 20

# Map evidence made walk by walk on a Dask cluster and merged refits a site byte for byte as
# one machine does (docs/evidence.md#at-scale); F1's walks, unpacked by the Rust tests above.
step "Map evidence on a Dask LocalCluster (scripts/distributed/test.sh)"
run bash scripts/distributed/test.sh "$target/release/waymark"

# docs/results.md is generated from the committed JSON in docs/results/; a page that differs
# from what the JSON makes fails here, with the command that regenerates it.
step "docs/results.md is what docs/results/*.json makes (waymark results --check)"
cargo run --release -p waymark-cli --locked --quiet -- results --check docs/results.md docs/results/*.json

step "C ABI: header freshness, shared and static library under valgrind"
run bash bindings/c/test.sh

step "Kotlin bindings on the JVM (JNA, JUnit 4)"
tools_ready "$kotlin_tools" "$target/kotlin-tools.log"
run bash bindings/kotlin/test.sh

step "Swift bindings on Linux (XCTest in a Debian trixie chroot)"
tools_ready "$swift_tools" "$target/swift-tools.log"
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
