// The root package as apps get it: its privacy manifest ships as a resource of the Waymark
// target and declares every required-reason API the target's Swift calls.

import Foundation
import XCTest

@testable import Waymark

final class PackageTests: XCTestCase {
    /// ios/Sources/Waymark, from this file's place in the checkout.
    static let sources = URL(fileURLWithPath: #filePath)
        .deletingLastPathComponent().deletingLastPathComponent().deletingLastPathComponent()
        .deletingLastPathComponent().deletingLastPathComponent()
        .appendingPathComponent("ios/Sources/Waymark")

    func manifest() throws -> [String: Any] {
        let url = try XCTUnwrap(Bundle.module.url(forResource: "PrivacyInfo", withExtension: "xcprivacy"),
                                "PrivacyInfo.xcprivacy is a resource of the Waymark target")
        let plist = try PropertyListSerialization.propertyList(from: Data(contentsOf: url), format: nil)
        return try XCTUnwrap(plist as? [String: Any])
    }

    func testThePrivacyManifestShipsWithTheDeclarationsAppleExpects() throws {
        let m = try manifest()
        XCTAssertEqual(Set(m.keys), ["NSPrivacyTracking", "NSPrivacyTrackingDomains", "NSPrivacyCollectedDataTypes",
                                     "NSPrivacyAccessedAPITypes"], "only keys App Store Connect accepts")
        XCTAssertEqual(m["NSPrivacyTracking"] as? Bool, false)
        XCTAssertEqual(m["NSPrivacyTrackingDomains"] as? [String], [])
        let collected = try XCTUnwrap(m["NSPrivacyCollectedDataTypes"] as? [[String: Any]])
        XCTAssertEqual(collected.count, 1)
        XCTAssertEqual(collected[0]["NSPrivacyCollectedDataType"] as? String, "NSPrivacyCollectedDataTypePreciseLocation")
        XCTAssertEqual(collected[0]["NSPrivacyCollectedDataTypeLinked"] as? Bool, false)
        XCTAssertEqual(collected[0]["NSPrivacyCollectedDataTypeTracking"] as? Bool, false)
        XCTAssertEqual(collected[0]["NSPrivacyCollectedDataTypePurposes"] as? [String],
                       ["NSPrivacyCollectedDataTypePurposeAppFunctionality"])
        let apis = try XCTUnwrap(m["NSPrivacyAccessedAPITypes"] as? [[String: Any]])
        var reasons: [String: [String]] = [:]
        for api in apis {
            reasons[try XCTUnwrap(api["NSPrivacyAccessedAPIType"] as? String)] = api["NSPrivacyAccessedAPITypeReasons"] as? [String]
        }
        XCTAssertEqual(reasons, [
            "NSPrivacyAccessedAPICategorySystemBootTime": ["35F9.1"],
            "NSPrivacyAccessedAPICategoryFileTimestamp": ["C617.1"],
        ])
    }

    // Apple's required-reason APIs, by category, as they appear in Swift: each one the
    // target's code (not its comments) names must be declared.
    func testEveryRequiredReasonAPIInTheSourcesIsDeclared() throws {
        let categories: [String: [String]] = [
            "NSPrivacyAccessedAPICategorySystemBootTime": ["systemUptime", "mach_absolute_time"],
            "NSPrivacyAccessedAPICategoryFileTimestamp": [
                "creationDate", "modificationDate", "fileModificationDate", "contentModificationDateKey",
                "creationDateKey", "getattrlist", "fstat(", "stat(", "lstat(",
            ],
            "NSPrivacyAccessedAPICategoryDiskSpace": [
                "volumeAvailableCapacity", "systemFreeSize", "systemSize", "statfs", "statvfs",
            ],
            "NSPrivacyAccessedAPICategoryActiveKeyboards": ["activeInputModes"],
            "NSPrivacyAccessedAPICategoryUserDefaults": ["UserDefaults"],
        ]
        let declared = Set(try XCTUnwrap(manifest()["NSPrivacyAccessedAPITypes"] as? [[String: Any]])
            .compactMap { $0["NSPrivacyAccessedAPIType"] as? String })
        let files = try FileManager.default.contentsOfDirectory(atPath: Self.sources.path).filter { $0.hasSuffix(".swift") }
        XCTAssertTrue(files.contains("LocationPorts.swift"), "\(Self.sources.path)")
        var used: [String: String] = [:]
        for file in files {
            let code = try String(contentsOf: Self.sources.appendingPathComponent(file), encoding: .utf8)
                .split(separator: "\n").map { $0.trimmingCharacters(in: .whitespaces) }
                .filter { !$0.hasPrefix("//") && !$0.hasPrefix("*") && !$0.hasPrefix("/*") }
                .joined(separator: "\n")
            for (category, names) in categories {
                for name in names where code.contains(name) { used[category] = "\(file): \(name)" }
            }
        }
        XCTAssertEqual(used["NSPrivacyAccessedAPICategorySystemBootTime"].map { _ in true }, true,
                       "the uptime clock is found: the scan works")
        for (category, place) in used {
            XCTAssertTrue(declared.contains(category), "\(place) needs \(category) in PrivacyInfo.xcprivacy")
        }
    }
}
