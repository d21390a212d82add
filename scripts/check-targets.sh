#!/usr/bin/env bash
# The shipped library (package `waymark`, and with it the engine crate it is built on) on what
# it promises beyond this machine's toolchain:
# - a build on the declared MSRV (Cargo.toml `rust-version`), so an app team on an older
#   stable toolchain can build it;
# - `cargo check` for Android (aarch64-linux-android) and iOS (aarch64-apple-ios). Linking for
#   them needs the NDK and Xcode, which CI does not have: docs/android.md and docs/ios.md give
#   the packaging commands a mobile developer runs.
# Installs the toolchain and targets with rustup when missing.
set -euo pipefail
cd "$(dirname "$0")/.."
msrv=$(sed -n 's/^rust-version = "\(.*\)"/\1/p' Cargo.toml | head -n1)
[ -n "$msrv" ] || { echo "check-targets.sh: no rust-version in Cargo.toml" >&2; exit 1; }

if ! rustup run "$msrv" rustc --version >/dev/null 2>&1; then
    rustup toolchain install "$msrv" --profile minimal
fi
echo "-- cargo +$msrv build -p waymark --lib"
cargo "+$msrv" build -p waymark --lib --locked --quiet

for target in aarch64-linux-android aarch64-apple-ios; do
    if ! rustup target list --installed | grep -qx "$target"; then
        rustup target add "$target"
    fi
    echo "-- cargo check -p waymark --lib --target $target"
    cargo check -p waymark --lib --locked --quiet --target "$target"
done
