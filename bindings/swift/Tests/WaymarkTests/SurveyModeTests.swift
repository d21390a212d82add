// Survey mode: WaymarkLocationManager drives a SurveyRecorder with what it reads and the
// surveyor's taps, so a survey app is the client plus a tap button. The office's survey walks
// go through fake CoreMotion and fake ranging (their WiFi as iBeacons, as in
// LocationClientTests), `waymark survey` builds a site from the files, and the client
// positions the office's test walk on it.

import Foundation
import XCTest

@testable import Waymark

/// A recorder whose storage refuses scans while `failing`.
final class FailingRecorder: SurveyRecorder, @unchecked Sendable {
    private let lock = NSLock()
    private var _failing = true
    private var _scanCalls = 0

    var failing: Bool {
        get { lock.lock(); defer { lock.unlock() }; return _failing }
        set { lock.lock(); _failing = newValue; lock.unlock() }
    }

    var scanCalls: Int { lock.lock(); defer { lock.unlock() }; return _scanCalls }

    override func pushScan(scan: RadioScan) throws {
        lock.lock(); _scanCalls += 1; lock.unlock()
        if failing { throw SurveyError.Io(reason: "no space left on device") }
        try super.pushScan(scan: scan)
    }

    override func resume() throws {
        if failing { throw SurveyError.Io(reason: "still no space") }
    }
}

final class SurveyModeTests: XCTestCase {
    /// Replays `walk` through a manager on `siteJson` (ranging its WiFi as beacons) and
    /// returns the mean error of its positions.
    func meanError(siteJson: String, walk: Walk) throws -> Double {
        let h = try Harness(siteJson: siteJson)
        h.manager.start()
        for epoch in walk.epochs {
            h.deliver(epoch)
            h.scheduler.fire()
        }
        h.settle()
        h.manager.stop()
        let truth = Dictionary(uniqueKeysWithValues: walk.epochs.map { ($0.timestampNs, $0.truth) })
        let errors = h.delegate.positions.compactMap { p in truth[p.timestampNs].map { hypot(p.x - $0[0], p.y - $0[1]) } }
        XCTAssertGreaterThan(errors.count, walk.epochs.count * 9 / 10)
        return errors.reduce(0, +) / Double(errors.count)
    }

    /// Records `walk` through `h.manager` in survey mode, tapping each of its waypoints at its
    /// time between the sensor readings and the ranging results, as a surveyor would; returns
    /// how many motion readings and beacon scans went in.
    @discardableResult
    func survey(_ walk: Walk, through h: Harness, floor: String = "F1") throws -> (readings: Int, scans: Int) {
        let taps = try XCTUnwrap(walk.waypoints)
        var tap = 0
        var readings = 0
        var scans = 0
        for epoch in walk.epochs {
            let epochReadings = Harness.readings(epoch)
            readings += epochReadings.count
            h.motion.emit(epochReadings)
            while tap < taps.count && UInt64(taps[tap][0]) <= epoch.timestampNs {
                h.clock.set(UInt64(taps[tap][0]))
                try h.manager.markWaypoint(x: taps[tap][1], y: taps[tap][2], floor: floor)
                tap += 1
            }
            h.clock.set(epoch.timestampNs)
            let beacons = Harness.beacons(epoch)
            if !beacons.isEmpty { scans += 1 }
            h.ranger.send(.ranged(beacons, uuid: beaconUUID))
        }
        for t in taps[tap...] {
            h.clock.set(UInt64(t[0]))
            try h.manager.markWaypoint(x: t[1], y: t[2], floor: floor)
        }
        return (readings, scans)
    }

    func testASurveyRecordedThroughTheClientPositionsLikeTheDemo() throws {
        let cli = try XCTUnwrap(ProcessInfo.processInfo.environment["WAYMARK_CLI"], "test.sh sets WAYMARK_CLI")
        let dir = FileManager.default.temporaryDirectory.appendingPathComponent("waymark-survey-mode-\(UUID().uuidString)")
        defer { try? FileManager.default.removeItem(at: dir) }
        let walks = try WaymarkTests.surveyWalks()
        XCTAssertEqual(walks.count, 12)
        for (file, name) in walks {
            let walk = try loadWalk(file)
            // A survey app: the client with no site yet (no engine), and a recorder.
            let h = try Harness(siteJson: try simSiteJson(), withEngine: false)
            try h.manager.startSurvey(
                SurveyRecorder(directory: dir.path, options: SurveyOptions(walkName: name, siteId: "office", device: "iPhone")))
            XCTAssertTrue(h.manager.isSurveying)
            h.manager.start()
            XCTAssertNil(h.scheduler.armed, "no engine: no advance timer")
            let (readings, scans) = try survey(walk, through: h)
            let summary = try h.manager.finishSurvey()
            XCTAssertFalse(h.manager.isSurveying)
            h.manager.stop()
            XCTAssertEqual(summary.samples, UInt64(readings), "every reading recorded, the last ones at finish")
            XCTAssertEqual(summary.samplesDropped, 0)
            XCTAssertEqual(summary.scans, UInt64(scans))
            XCTAssertGreaterThan(scans, walk.epochs.count / 2)
            XCTAssertEqual(summary.scansRejected, 0)
            XCTAssertEqual(summary.waypoints, UInt64(try XCTUnwrap(walk.waypoints).count))
            XCTAssertEqual(summary.files.count, 1)
            XCTAssertTrue(summary.files[0].hasSuffix("F1/path_data_files/\(name)-1.txt"), summary.files[0])
            XCTAssertEqual(h.engine.calls, [], "the engine was never given to the manager")
        }

        let site = try surveySite(cli: cli, walksIn: dir)

        let surveyedJson = try String(contentsOf: site, encoding: .utf8)
        XCTAssertTrue(surveyedJson.contains(#""ble""#), "the surveyed site knows the beacons")
        let walk = try loadWalk()
        let surveyed = try meanError(siteJson: surveyedJson, walk: walk)
        let demo = try meanError(siteJson: try makeBeaconSiteJson(), walk: walk)
        print(String(format: "survey mode: mean error %.2f m on the surveyed site, %.2f m on the office's", surveyed, demo))
        XCTAssertLessThanOrEqual(surveyed, 1.5 * demo)
    }

    // Surveying while positioning: the engine and the recorder get the same scans, at the
    // same times; positions go on.
    func testSurveyingAlongsidePositioning() throws {
        let dir = FileManager.default.temporaryDirectory.appendingPathComponent("waymark-survey-mode-\(UUID().uuidString)")
        defer { try? FileManager.default.removeItem(at: dir) }
        let h = try Harness(siteJson: try makeBeaconSiteJson())
        h.manager.start()
        try h.manager.startSurvey(SurveyRecorder(directory: dir.path, options: SurveyOptions(walkName: "check")))
        var walk = try loadWalk()
        walk = Walk(epochs: Array(walk.epochs.prefix(12)),
                    waypoints: walk.epochs.prefix(12).map { [Double($0.timestampNs) - 1e6, $0.truth[0], $0.truth[1]] })
        let (readings, scans) = try survey(walk, through: h)
        h.settle()
        let summary = try h.manager.finishSurvey()
        XCTAssertEqual(summary.samples, UInt64(readings))
        XCTAssertEqual(summary.waypoints, 12)
        let engineScans = h.engine.calls.compactMap { if case .scan(let s) = $0 { return s.timestampNs } else { return nil } }
        XCTAssertEqual(engineScans.count, scans)
        XCTAssertEqual(UInt64(engineScans.count), summary.scans)
        XCTAssertEqual(h.delegate.positions.count, scans - Int(h.manager.rejectedScanCount))
        let text = try String(contentsOfFile: summary.files[0], encoding: .utf8)
        let beaconTimes = Set(text.split(separator: "\n").filter { $0.contains("\tTYPE_BEACON\t") }
            .compactMap { UInt64($0.split(separator: "\t")[0]) })
        XCTAssertEqual(beaconTimes, Set(engineScans), "the file's scans are the engine's, at the same times")
        let accelerometer = text.split(separator: "\n").filter { $0.contains("\tTYPE_ACCELEROMETER\t") }
        let engineAccelerometer = h.engine.calls.reduce(0) {
            if case .motion(.accelerometer, let b) = $1 { return $0 + b.count } else { return $0 }
        }
        XCTAssertEqual(accelerometer.count, engineAccelerometer, "the same samples as the engine")
        XCTAssertEqual(h.manager.state, .running, "finishing the survey leaves positioning running")
    }

    func testSurveyCallsAreChecked() throws {
        let dir = FileManager.default.temporaryDirectory.appendingPathComponent("waymark-survey-mode-\(UUID().uuidString)")
        defer { try? FileManager.default.removeItem(at: dir) }
        let h = try Harness(siteJson: try simSiteJson(), withEngine: false)
        func rejected(_ call: () throws -> Void, file: StaticString = #filePath, line: UInt = #line) {
            XCTAssertThrowsError(try call(), file: file, line: line) {
                guard case SurveyError.InputRejected = $0 else { return XCTFail("\($0)", file: file, line: line) }
            }
        }
        rejected { try h.manager.markWaypoint(x: 1, y: 2, floor: "F1") }
        rejected { _ = try h.manager.finishSurvey() }
        try h.manager.startSurvey(SurveyRecorder(directory: dir.path, options: SurveyOptions(walkName: "w")))
        rejected { try h.manager.startSurvey(SurveyRecorder(directory: dir.path, options: SurveyOptions(walkName: "v"))) }
        rejected { try h.manager.markWaypoint(x: .nan, y: 2, floor: "F1") }
        XCTAssertThrowsError(try h.manager.finishSurvey()) {
            guard case SurveyError.NoWaypoints = $0 else { return XCTFail("\($0)") }
        }
        XCTAssertTrue(h.manager.isSurveying, "a failed finish keeps the survey")
        h.clock.set(5_000)
        try h.manager.markWaypoint(x: 1, y: 2, floor: "F1")
        let summary = try h.manager.finishSurvey()
        XCTAssertEqual(summary.waypoints, 1)
        let text = try String(contentsOfFile: summary.files[0], encoding: .utf8)
        XCTAssertTrue(text.contains("5000\tTYPE_WAYPOINT\t1\t2\n"), "the tap at the clock's time: \(text)")
        XCTAssertFalse(h.manager.isSurveying)
    }

    // Readings still in the manager's batches reach the survey at finishSurvey(), and at
    // stop() (the engine gets no epoch for them, the survey does not need one).
    func testTheLastReadingsReachTheSurvey() throws {
        let dir = FileManager.default.temporaryDirectory.appendingPathComponent("waymark-survey-mode-\(UUID().uuidString)")
        defer { try? FileManager.default.removeItem(at: dir) }
        let h = try Harness(siteJson: try simSiteJson(), withEngine: false)
        let walk = try loadWalk()
        for (name, epoch) in [("finished", 1), ("stopped", 2)] {
            try h.manager.startSurvey(SurveyRecorder(directory: dir.path, options: SurveyOptions(walkName: name)))
            h.manager.start()
            h.clock.set(walk.epochs[epoch - 1].timestampNs)
            try h.manager.markWaypoint(x: 1, y: 1, floor: "F1")
            // Fewer than a batch per sensor: all of them wait in the manager.
            let readings = Array(Harness.readings(walk.epochs[epoch]).prefix(100))
            h.motion.emit(readings)
            if name == "stopped" { h.manager.stop() }
            let summary = try h.manager.finishSurvey()
            XCTAssertEqual(summary.samples, UInt64(readings.count), name)
        }
    }

    // A failing storage is one status (600) until resumed; nothing is pushed meanwhile.
    func testAFailingRecorderIsAStatusUntilResumed() throws {
        let dir = FileManager.default.temporaryDirectory.appendingPathComponent("waymark-survey-mode-\(UUID().uuidString)")
        defer { try? FileManager.default.removeItem(at: dir) }
        let h = try Harness(siteJson: try makeBeaconSiteJson())
        let recorder = try FailingRecorder(directory: dir.path, options: SurveyOptions(walkName: "full"))
        try h.manager.startSurvey(recorder)
        h.manager.start()
        let walk = try loadWalk()
        for epoch in walk.epochs.prefix(3) {
            h.clock.set(epoch.timestampNs)
            h.ranger.send(.ranged(Harness.beacons(epoch), uuid: beaconUUID))
        }
        h.settle()
        XCTAssertEqual(recorder.scanCalls, 1, "nothing pushed after the failure")
        XCTAssertEqual(h.delegate.statuses.filter { $0.code == 600 },
                       [.surveyFailed(reason: String(describing: SurveyError.Io(reason: "no space left on device")))])
        XCTAssertEqual(h.delegate.positions.count, 3 - Int(h.manager.rejectedScanCount), "positioning goes on")
        XCTAssertGreaterThanOrEqual(h.delegate.positions.count, 2)
        XCTAssertThrowsError(try h.manager.resumeSurvey())
        recorder.failing = false
        try h.manager.resumeSurvey()
        h.clock.set(walk.epochs[3].timestampNs)
        h.ranger.send(.ranged(Harness.beacons(walk.epochs[3]), uuid: beaconUUID))
        XCTAssertEqual(recorder.scanCalls, 2)
        h.settle()
        XCTAssertEqual(h.delegate.statuses.filter { $0.code == 600 }.count, 1)
    }
}
