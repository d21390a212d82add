#!/usr/bin/env bash
# The C ABI test: checks the committed header is what cbindgen makes from src/ffi/c.rs, builds
# the library, compiles bindings/c/test.c, robustness.c, threads.c, callbacks.c and hostile.c
# against the header and the library (shared and static), and runs them under valgrind: zero
# errors, zero leaks. Then checks that the shared library imports no networking function
# (scripts/check-no-network.sh).
set -euo pipefail
repo=$(cd "$(dirname "$0")/../.." && pwd)
cd "$repo"
target=${CARGO_TARGET_DIR:-$repo/target}
work="$target/c-test"
mkdir -p "$work"

need() { command -v "$1" >/dev/null 2>&1; }
if ! need gcc || ! need valgrind || ! need python3; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq gcc valgrind python3 >/dev/null
fi
if ! need cbindgen || [ "$(cbindgen --version)" != "cbindgen 0.29.4" ]; then
    cargo install cbindgen --version 0.29.4 --locked
fi

echo "-- header is fresh"
cbindgen --config cbindgen.toml --quiet --output "$work/waymark.h"
if ! diff -u bindings/c/waymark.h "$work/waymark.h"; then
    echo "bindings/c/waymark.h is stale: run cbindgen --config cbindgen.toml --output bindings/c/waymark.h" >&2
    exit 1
fi
crate_version=$(sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -n1)
if ! grep -q "#define WAYMARK_VERSION \"$crate_version\"" bindings/c/waymark.h; then
    echo "WAYMARK_VERSION in cbindgen.toml does not match Cargo.toml ($crate_version)" >&2
    exit 1
fi

echo "-- build"
# The test's inputs come from the release CLI, the build the demo, Kotlin and Swift steps of
# scripts/test.sh use too (one CLI build for the whole suite).
cargo build --release -p waymark-cli --locked --quiet
waymark="$target/release/waymark"
"$waymark" sim-export --walk-length-m 40 --out "$work"
# The same site with its transmitter ids hashed, under a fixed test salt.
echo 5a1f00d0c0ffee00112233445566778899aabbccddeeff0123456789abcdef01 > "$work/salt.hex"
"$waymark" site hash --salt-file "$work/salt.hex" "$work/site.json" "$work/site-hashed.json" >/dev/null
# The same site in the binary encoding an app ships.
"$waymark" site pack "$work/site.json" "$work/site.wmsite" >/dev/null
# A test build: a scan at UINT64_MAX - 7 panics inside the engine (feature fault-injection).
cargo build -p waymark --lib --locked --quiet --features fault-injection
python3 bindings/c/walk_to_text.py "$work/walk.json" "$work/walk.txt"
flags=(-std=c11 -Wall -Wextra -Werror -O1 -g -pthread -I bindings/c)
# The README's C quickstart, compiled as the tests are (a function, so an object file only).
python3 scripts/readme-snippet.py c-quickstart > "$work/readme_quickstart.c"
gcc "${flags[@]}" -c "$work/readme_quickstart.c" -o "$work/readme_quickstart.o"
echo "README C quickstart compiles"
for test in test robustness threads callbacks hostile; do
    gcc "${flags[@]}" "bindings/c/$test.c" -L "$target/debug" -lwaymark -lm -o "$work/${test}_shared"
    gcc "${flags[@]}" "bindings/c/$test.c" "$target/debug/libwaymark.a" -lpthread -ldl -lm -o "$work/${test}_static"
done

# Valgrind runs one thread at a time, so the shared and static runs go side by side, each
# into its own log, printed in order once both are done.
valgrind_suite() {
    local kind=$1
    local vg=(valgrind --quiet --error-exitcode=1 --leak-check=full
        --errors-for-leak-kinds=definite,indirect --show-leak-kinds=definite,indirect)
    echo "-- $kind library under valgrind"
    LD_LIBRARY_PATH="$target/debug" "${vg[@]}" \
        "$work/test_$kind" "$work/site.json" "$work/walk.txt" "$work/site-hashed.json" "$work/salt.hex" \
        "$work/site.wmsite"
    echo "-- bad input, $kind library under valgrind"
    LD_LIBRARY_PATH="$target/debug" "${vg[@]}" "$work/robustness_$kind" "$work/site.json"
    echo "-- hostile input: failing storage, times far ahead, $kind library under valgrind"
    LD_LIBRARY_PATH="$target/debug" "${vg[@]}" "$work/hostile_$kind" "$work/site.json"
    echo "-- threads pushing at once, $kind library under valgrind"
    LD_LIBRARY_PATH="$target/debug" "${vg[@]}" "$work/threads_$kind" "$work/site.json"
    echo "-- callbacks that free the engine, call it from the log hook, $kind library under valgrind"
    LD_LIBRARY_PATH="$target/debug" "${vg[@]}" "$work/callbacks_$kind" "$work/site.json"
}
pids=()
for kind in shared static; do
    valgrind_suite "$kind" > "$work/valgrind-$kind.log" 2>&1 &
    pids+=($!)
done
status=0
for i in 0 1; do
    wait "${pids[$i]}" || status=1
done
cat "$work/valgrind-shared.log" "$work/valgrind-static.log"
[ "$status" = 0 ] || { echo "test.sh: a valgrind run failed (above)" >&2; exit 1; }

echo "-- no networking"
bash scripts/check-no-network.sh "$target/debug/libwaymark.so"
