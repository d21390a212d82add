// swift-tools-version:5.9
// The Linux test package of the Swift bindings (run by test.sh in a Debian chroot). It
// compiles the committed ios/Sources/ (through the symlinks in Sources/) against the FFI C
// target and links the host-built libwaymark.so; test.sh passes `-L`/`-rpath` for it. App
// developers use ios/Package.swift instead.
import PackageDescription

let package = Package(
    name: "WaymarkLinuxTests",
    targets: [
        // Generated header and module map only; the code is libwaymark.so.
        .target(
            name: "WaymarkFFI",
            path: "Sources/WaymarkFFI",
            linkerSettings: [.linkedLibrary("waymark")]
        ),
        .target(name: "Waymark", dependencies: ["WaymarkFFI"], path: "Sources/Waymark"),
        .testTarget(name: "WaymarkTests", dependencies: ["Waymark"], path: "Tests/WaymarkTests"),
    ]
)
