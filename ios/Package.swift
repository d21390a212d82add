// swift-tools-version:5.9
// Waymark for iOS apps, as a local Swift package (modelled on application-services'
// megazords Package.swift): the Rust library as a binary target, WaymarkFFI.xcframework,
// made by ./build-xcframework.sh, and the uniffi-generated Swift in Sources/Waymark/,
// committed so this package needs no code-generation step.
import PackageDescription

let package = Package(
    name: "Waymark",
    platforms: [.iOS(.v15)],
    products: [
        .library(name: "Waymark", targets: ["Waymark"]),
    ],
    targets: [
        // libwaymark.a for device (arm64) and simulator (arm64 + x86_64), with the generated
        // C header and module map from Sources/WaymarkFFI/include. Not committed: run
        // ./build-xcframework.sh first. For a release, upload the zip the script prints and use
        // .binaryTarget(name: "WaymarkFFI", url: "<zip url>", checksum: "<printed checksum>").
        .binaryTarget(name: "WaymarkFFI", path: "WaymarkFFI.xcframework"),
        .target(name: "Waymark", dependencies: ["WaymarkFFI"], path: "Sources/Waymark"),
    ]
)
