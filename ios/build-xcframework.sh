#!/usr/bin/env bash
# Builds ios/WaymarkFFI.xcframework, the binary target of ios/Package.swift: the Rust library
# (release, static) for iPhone (aarch64-apple-ios) and for the simulator on Apple silicon and
# Intel (aarch64-apple-ios-sim + x86_64-apple-ios, merged with lipo), each with the generated
# C header and module map of Sources/WaymarkFFI/include/.
#
# Needs macOS with Xcode (xcodebuild, lipo) and the three rustup targets:
#   rustup target add aarch64-apple-ios aarch64-apple-ios-sim x86_64-apple-ios
#   ios/build-xcframework.sh             # from anywhere
#
# The Swift in Sources/Waymark/ is committed and must match the library; bindings/swift/test.sh
# fails when it is stale. Only the `waymark` package is built here, so the shipped library
# never links uniffi's CLI (that is the separate uniffi-bindgen crate).
set -euo pipefail

IOS="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$IOS/.." && pwd)"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$REPO/target}"
TARGET="$CARGO_TARGET_DIR"
BUILD="$IOS/build"
OUT="$IOS/WaymarkFFI.xcframework"
# Rust and Package.swift agree on the oldest iOS supported.
export IPHONEOS_DEPLOYMENT_TARGET="${IPHONEOS_DEPLOYMENT_TARGET:-15.0}"

for tool in cargo lipo xcodebuild; do
    command -v "$tool" >/dev/null || { echo "build-xcframework.sh: $tool not found (needs macOS + Xcode)" >&2; exit 1; }
done

for target in aarch64-apple-ios aarch64-apple-ios-sim x86_64-apple-ios; do
    echo "== cargo build --release -p waymark --lib --target $target" >&2
    cargo build --manifest-path "$REPO/Cargo.toml" --release -p waymark --lib --target "$target"
done

rm -rf "$BUILD" "$OUT" "$OUT.zip"
mkdir -p "$BUILD/ios-simulator" "$BUILD/Headers/WaymarkFFI"

# One fat simulator library: an xcframework holds one library per platform variant.
lipo -create \
    "$TARGET/aarch64-apple-ios-sim/release/libwaymark.a" \
    "$TARGET/x86_64-apple-ios/release/libwaymark.a" \
    -output "$BUILD/ios-simulator/libwaymark.a"

# Header and module map (module WaymarkFFI) in a subfolder named after the module: Xcode copies
# the Headers of every static xcframework into one include/ folder, where two module.modulemap
# files at the top level would collide; clang also looks in include/<Module>/.
cp "$IOS/Sources/WaymarkFFI/include/WaymarkFFI.h" "$IOS/Sources/WaymarkFFI/include/module.modulemap" \
    "$BUILD/Headers/WaymarkFFI/"

xcodebuild -create-xcframework \
    -library "$TARGET/aarch64-apple-ios/release/libwaymark.a" -headers "$BUILD/Headers" \
    -library "$BUILD/ios-simulator/libwaymark.a" -headers "$BUILD/Headers" \
    -output "$OUT"

# For a release: a zip and its SwiftPM checksum, for .binaryTarget(url:checksum:).
(cd "$IOS" && ditto -c -k --sequesterRsrc --keepParent WaymarkFFI.xcframework WaymarkFFI.xcframework.zip)
echo "== $OUT" >&2
echo "== checksum of WaymarkFFI.xcframework.zip: $(cd "$IOS" && swift package compute-checksum WaymarkFFI.xcframework.zip)" >&2
