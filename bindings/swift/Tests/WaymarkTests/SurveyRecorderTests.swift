import Foundation
import XCTest

@testable import Waymark

/// Record → survey → position through the Swift bindings: the demo office's survey walks (from
/// `waymark sim-export`) are pushed to a `SurveyRecorder` as an app would push them, with a tap
/// at each state passed; `waymark survey` builds a site from the files; an engine on that site
/// positions the office's test walk, never surveyed, like the engine on the office's own site.
final class SurveyRecorderTests: XCTestCase {
    private func load(_ url: URL) throws -> Walk {
        let decoder = JSONDecoder()
        decoder.keyDecodingStrategy = .convertFromSnakeCase
        return try decoder.decode(Walk.self, from: Data(contentsOf: url))
    }

    private func meanError(_ engine: PositioningEngine, _ walk: Walk) throws -> Double {
        var errors: [Double] = []
        for epoch in walk.epochs {
            _ = try engine.pushAccelerometer(batch: samples(epoch.accelerometer))
            _ = try engine.pushGyroscope(batch: samples(epoch.gyroscope))
            _ = try engine.pushMagnetometer(batch: samples(epoch.magnetometer))
            if let p = try? engine.pushScan(scan: epoch.scan) {
                errors.append(hypot(p.x - epoch.truth[0], p.y - epoch.truth[1]))
            }
        }
        XCTAssertGreaterThan(errors.count, 20)
        return errors.reduce(0, +) / Double(errors.count)
    }

    func testARecordedSurveyPositionsTheTestWalkLikeTheDemo() throws {
        let cli = try XCTUnwrap(ProcessInfo.processInfo.environment["WAYMARK_CLI"], "test.sh sets WAYMARK_CLI")
        let dir = FileManager.default.temporaryDirectory.appendingPathComponent("waymark-survey-\(UUID().uuidString)")
        defer { try? FileManager.default.removeItem(at: dir) }
        let walks = try WaymarkTests.surveyWalks()
        XCTAssertEqual(walks.count, 12)
        for (file, name) in walks {
            let survey = try load(file)
            let taps = try XCTUnwrap(survey.waypoints)
            let recorder = try SurveyRecorder(
                directory: dir.path, options: SurveyOptions(walkName: name, siteId: "office", device: "Swift Test"))
            var tap = 0
            for epoch in survey.epochs {
                // The surveyor taps each state as they pass it, between the scans.
                while tap < taps.count && UInt64(taps[tap][0]) <= epoch.timestampNs {
                    try recorder.markWaypoint(timestampNs: UInt64(taps[tap][0]), x: taps[tap][1], y: taps[tap][2], floor: "F1")
                    tap += 1
                }
                _ = try recorder.pushAccelerometer(batch: samples(epoch.accelerometer))
                _ = try recorder.pushGyroscope(batch: samples(epoch.gyroscope))
                _ = try recorder.pushMagnetometer(batch: samples(epoch.magnetometer))
                try recorder.pushScan(scan: epoch.scan)
            }
            for t in taps[tap...] {
                try recorder.markWaypoint(timestampNs: UInt64(t[0]), x: t[1], y: t[2], floor: "F1")
            }
            let summary = try recorder.finish()
            XCTAssertEqual(summary.files.count, 1)
            XCTAssertEqual(summary.samplesDropped, 0)
            XCTAssertEqual(summary.scans, UInt64(survey.epochs.count))
            XCTAssertEqual(summary.waypoints, UInt64(taps.count))
            XCTAssertTrue(summary.files[0].hasSuffix("F1/path_data_files/\(name)-1.txt"), summary.files[0])
        }

        let site = try surveySite(cli: cli, walksIn: dir)

        let walk = try load(WaymarkTests.simDir.appendingPathComponent("walk.json"))
        let surveyed = try meanError(
            try PositioningEngine(siteJson: try String(contentsOf: site, encoding: .utf8), options: EngineOptions()), walk)
        let demo = try meanError(
            try PositioningEngine(
                siteJson: try String(contentsOf: WaymarkTests.simDir.appendingPathComponent("site.json"), encoding: .utf8),
                options: EngineOptions()), walk)
        print(String(format: "recorded survey: mean error %.2f m on its site, %.2f m on the office's", surveyed, demo))
        XCTAssertLessThanOrEqual(surveyed, 1.5 * demo)
    }

    func testBadInputIsRefusedWithTypedErrors() throws {
        let dir = FileManager.default.temporaryDirectory.appendingPathComponent("waymark-survey-\(UUID().uuidString)")
        defer { try? FileManager.default.removeItem(at: dir) }
        XCTAssertThrowsError(try SurveyRecorder(directory: dir.path, options: SurveyOptions(walkName: ".."))) {
            guard case SurveyError.InputRejected = $0 else { return XCTFail("\($0)") }
        }
        let recorder = try SurveyRecorder(directory: dir.path, options: SurveyOptions(walkName: "walk"))
        let accepted = try recorder.pushGyroscope(batch: [
            MotionSample(timestampNs: 10, x: 0, y: 0, z: 0), MotionSample(timestampNs: 10, x: 1, y: 0, z: 0),
            MotionSample(timestampNs: 20, x: .infinity, y: 0, z: 0),
        ])
        XCTAssertEqual(accepted, 1)
        let beacon = BeaconReading(uuid: "fda50693-a4e2-4fb1-afcf-c6eb07647825", major: 1, minor: 7, rssiDbm: -71)
        try recorder.pushScan(scan: RadioScan(timestampNs: 1_000, wifi: [], beacons: [beacon]))
        XCTAssertThrowsError(try recorder.pushScan(scan: RadioScan(timestampNs: 999, wifi: [], beacons: [beacon]))) {
            guard case SurveyError.InputRejected = $0 else { return XCTFail("\($0)") }
        }
        XCTAssertThrowsError(try recorder.markWaypoint(timestampNs: 5, x: .nan, y: 0, floor: "F1"))
        try recorder.markWaypoint(timestampNs: 5, x: 0.5, y: 4, floor: "F1")
        let summary = try recorder.finish()
        XCTAssertEqual([summary.samples, summary.samplesDropped, summary.scans, summary.scansRejected, summary.waypoints],
                       [1, 2, 1, 1, 1])
        let text = try String(contentsOfFile: summary.files[0], encoding: .utf8)
        XCTAssertTrue(text.contains("1000\tTYPE_BEACON\tfda50693-a4e2-4fb1-afcf-c6eb07647825\t1\t7\t0\t-71\t0\t\t1000\n"), text)
        XCTAssertThrowsError(try recorder.finish()) {
            guard case SurveyError.Finished = $0 else { return XCTFail("\($0)") }
        }
        let empty = try SurveyRecorder(directory: dir.path, options: SurveyOptions(walkName: "empty"))
        XCTAssertThrowsError(try empty.finish()) {
            guard case SurveyError.NoWaypoints = $0 else { return XCTFail("\($0)") }
        }
    }
}

/// `waymark survey` (the binary at `cli`) on the walks recorded under `dir/F1`: the site file it
/// wrote, `dir/site.json`. Shared by the tests that record a survey and position on it.
func surveySite(cli: String, walksIn dir: URL) throws -> URL {
    let site = dir.appendingPathComponent("site.json")
    let process = Process()
    process.executableURL = URL(fileURLWithPath: cli)
    process.arguments = ["survey", dir.appendingPathComponent("F1").path, "--out", site.path, "--name", "office"]
    try process.run()
    process.waitUntilExit()
    XCTAssertEqual(process.terminationStatus, 0, "waymark survey")
    return site
}
