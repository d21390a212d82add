// swift-tools-version:5.9
// The Linux test package of the Swift bindings (run by test.sh in a Debian chroot). It tests
// the repository's root package itself, by path: the Waymark target apps get, built from
// ios/Sources/Waymark with its resources, over the root package's Linux WaymarkFFI (the
// generated header linked to the host-built libwaymark.so; test.sh passes `-L`/`-rpath`).
import PackageDescription

let package = Package(
    name: "WaymarkLinuxTests",
    dependencies: [.package(name: "Waymark", path: "../..")],
    targets: [
        .testTarget(
            name: "WaymarkTests",
            dependencies: [.product(name: "Waymark", package: "Waymark")],
            path: "Tests/WaymarkTests"
        ),
    ]
)
