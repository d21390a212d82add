#!/usr/bin/env bash
# Builds ios/WaymarkFFI.xcframework, the binary target of the root Package.swift: the Rust
# library (release, static) for iPhone (aarch64-apple-ios) and for the simulator on Apple
# silicon and Intel (aarch64-apple-ios-sim + x86_64-apple-ios, merged with lipo), each with the
# generated C header and module map of Sources/WaymarkFFI/include/. Then its zip, the zip's
# SwiftPM checksum, and ios/WaymarkFFI.bundle: the privacy manifest for apps that link the
# XCFramework without SwiftPM (SwiftPM apps get it from the Waymark target's resources).
#
# Needs macOS with Xcode (xcodebuild, lipo, plutil) and the three rustup targets:
#   rustup target add aarch64-apple-ios aarch64-apple-ios-sim x86_64-apple-ios
#   ios/build-xcframework.sh             # from anywhere; try it with WAYMARK_LOCAL_XCFRAMEWORK=1
#   ios/build-xcframework.sh --release-url https://…/WaymarkFFI.xcframework.zip
#                                        # also writes that URL and the checksum into Package.swift
#
# The Swift in Sources/Waymark/ is committed and must match the library; bindings/swift/test.sh
# fails when it is stale. Only the `waymark` package is built here, so the shipped library
# never links uniffi's CLI (that is the separate uniffi-bindgen crate).
set -euo pipefail
release_url=""
if [[ "${1:-}" == --release-url ]]; then
    release_url="${2:?--release-url needs the URL the zip will be uploaded to}"
fi

IOS="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$IOS/.." && pwd)"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$REPO/target}"
TARGET="$CARGO_TARGET_DIR"
BUILD="$IOS/build"
OUT="$IOS/WaymarkFFI.xcframework"
# Rust and Package.swift agree on the oldest iOS supported.
export IPHONEOS_DEPLOYMENT_TARGET="${IPHONEOS_DEPLOYMENT_TARGET:-15.0}"

for tool in cargo lipo xcodebuild plutil; do
    command -v "$tool" >/dev/null || { echo "build-xcframework.sh: $tool not found (needs macOS + Xcode)" >&2; exit 1; }
done

for target in aarch64-apple-ios aarch64-apple-ios-sim x86_64-apple-ios; do
    echo "== cargo build --release -p waymark --lib --target $target" >&2
    cargo build --manifest-path "$REPO/Cargo.toml" --release -p waymark --lib --target "$target"
done

# An invalid privacy manifest makes App Store Connect reject the app: check it first.
plutil -lint "$IOS/Sources/Waymark/PrivacyInfo.xcprivacy"

rm -rf "$BUILD" "$OUT" "$OUT.zip" "$IOS/WaymarkFFI.bundle"
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

# A static library carries no resources: apps that add the XCFramework by hand copy this
# bundle (Apple: "Placing content in a bundle", static libraries) for the privacy manifest.
mkdir -p "$IOS/WaymarkFFI.bundle"
cp "$IOS/Sources/Waymark/PrivacyInfo.xcprivacy" "$IOS/WaymarkFFI.bundle/"
plutil -create xml1 "$IOS/WaymarkFFI.bundle/Info.plist"
plutil -insert CFBundleIdentifier -string dev.waymark.WaymarkFFI "$IOS/WaymarkFFI.bundle/Info.plist"
plutil -insert CFBundlePackageType -string BNDL "$IOS/WaymarkFFI.bundle/Info.plist"

# For a release: the zip (the XCFramework at its top, as SwiftPM expects) and its checksum,
# for .binaryTarget(url:checksum:).
(cd "$IOS" && ditto -c -k --sequesterRsrc --keepParent WaymarkFFI.xcframework WaymarkFFI.xcframework.zip)
checksum="$(cd "$IOS" && swift package compute-checksum WaymarkFFI.xcframework.zip)"
echo "== $OUT" >&2
echo "== $IOS/WaymarkFFI.bundle (privacy manifest, for apps not using SwiftPM)" >&2
echo "== checksum of $OUT.zip: $checksum" >&2
if [[ -n "$release_url" ]]; then
    "$IOS/set-package-release.sh" "$release_url" "$checksum" "$REPO/Package.swift"
    echo "== upload $OUT.zip to $release_url, then commit Package.swift and tag the release" >&2
fi
