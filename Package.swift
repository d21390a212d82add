// swift-tools-version:5.9
// Waymark for iOS apps, added by this repository's git URL (Xcode: File ▸ Add Package
// Dependencies…; a package: .package(url: "<repository>", from: "0.1.0")). Modelled on
// application-services' megazords Package.swift: the Rust library as a binary target,
// WaymarkFFI, and the Swift wrapper target Waymark over it, from ios/Sources/Waymark (the
// uniffi-generated Swift, committed, and the location client), with the privacy manifest.
//
// The binary target is the XCFramework zip of a release (ios/build-xcframework.sh builds it,
// prints its checksum and writes both lines below; docs/ios.md#releasing), or the XCFramework
// that script built locally, at ios/WaymarkFFI.xcframework, before the first release or when
// WAYMARK_LOCAL_XCFRAMEWORK is set in the environment of `xcodebuild` or `swift build`.
//
// On Linux, where SwiftPM takes no XCFramework, WaymarkFFI is the C header and module map of
// the same library (ios/Sources/WaymarkFFI) linked to libwaymark.so: the Linux tests
// (bindings/swift) build this package's Waymark target through it.
import Foundation
import PackageDescription

/// The release's XCFramework zip and its SwiftPM checksum, written by
/// `ios/build-xcframework.sh --release-url URL`; nil until the first release is published.
let release: (url: String, checksum: String)? = nil

let waymark = Target.target(
    name: "Waymark",
    dependencies: ["WaymarkFFI"],
    path: "ios/Sources/Waymark",
    resources: [.copy("PrivacyInfo.xcprivacy")]
)

#if os(Linux)
let ffi = Target.target(
    name: "WaymarkFFI",
    path: "ios/Sources/WaymarkFFI",
    linkerSettings: [.linkedLibrary("waymark")]
)
#else
let ffi: Target = {
    if let release, ProcessInfo.processInfo.environment["WAYMARK_LOCAL_XCFRAMEWORK"] == nil {
        return .binaryTarget(name: "WaymarkFFI", url: release.url, checksum: release.checksum)
    }
    // Before the first release, or to try a local build: ios/build-xcframework.sh makes it.
    return .binaryTarget(name: "WaymarkFFI", path: "ios/WaymarkFFI.xcframework")
}()
#endif

let package = Package(
    name: "Waymark",
    platforms: [.iOS(.v15)],
    products: [
        .library(name: "Waymark", targets: ["Waymark"]),
    ],
    targets: [ffi, waymark]
)
