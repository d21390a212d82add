// The Swift bindings on Linux, against the host-built libwaymark.so: the scenarios of
// tests/ffi.rs from Swift, on the walk `waymark sim-export` writes (test.sh exports it, with a
// copy of the site hashed by `waymark site hash` and its salt, and passes the folder in
// WAYMARK_SIM_DIR), plus the plain-Swift sensor conversions.

import Foundation
import XCTest

@testable import Waymark

/// Records what the engine publishes; called on whichever thread pushed the input.
final class Recorder: PositionListener, @unchecked Sendable {
    private let lock = NSLock()
    private var _positions: [PositionEstimate] = []
    private var _statuses: [StatusUpdate] = []
    private var _errors: [String] = []

    var positions: [PositionEstimate] { lock.lock(); defer { lock.unlock() }; return _positions }
    var statuses: [StatusUpdate] { lock.lock(); defer { lock.unlock() }; return _statuses }
    var errors: [String] { lock.lock(); defer { lock.unlock() }; return _errors }

    func onPosition(position: PositionEstimate) {
        lock.lock(); defer { lock.unlock() }
        _positions.append(position)
    }

    func onStatus(status: StatusUpdate) {
        lock.lock(); defer { lock.unlock() }
        _statuses.append(status)
    }

    func onError(error: ErrorReport) {
        lock.lock(); defer { lock.unlock() }
        _errors.append(error.message)
    }
}

/// A listener that ignores everything. Listener methods cannot throw in Swift; the Kotlin and
/// Rust tests cover one that throws or panics.
final class Throwing: PositionListener, @unchecked Sendable {
    func onPosition(position: PositionEstimate) {}
    func onStatus(status: StatusUpdate) {}
    func onError(error: ErrorReport) {}
}

/// `walk.json` of `waymark sim-export`.
struct Walk: Decodable {
    struct Wifi: Decodable {
        let bssid: String
        let rssiDbm: Double
    }
    struct Epoch: Decodable {
        let timestampNs: UInt64
        let truth: [Double]
        let accelerometer: [[Double]]
        let gyroscope: [[Double]]
        let magnetometer: [[Double]]
        let wifi: [Wifi]

        var scan: RadioScan {
            RadioScan(
                timestampNs: timestampNs,
                wifi: wifi.map { WifiReading(bssid: $0.bssid, rssiDbm: $0.rssiDbm) },
                beacons: [])
        }
    }
    let epochs: [Epoch]
    /// A survey walk's taps, `[timestamp_ns, x, y]`: the states the surveyor passed.
    let waypoints: [[Double]]?
}

/// A salt file's hex digits as bytes, as an app would hold its venue's salt.
func saltFromHex(_ text: String) -> Data {
    let digits = Array(text.trimmingCharacters(in: .whitespacesAndNewlines).utf8)
    return Data(stride(from: 0, to: digits.count - 1, by: 2).compactMap {
        UInt8(String(decoding: digits[$0..<$0 + 2], as: UTF8.self), radix: 16)
    })
}

/// Rows `[timestamp_ns, x, y, z]` as samples.
func samples(_ rows: [[Double]]) -> [MotionSample] {
    rows.map { MotionSample(timestampNs: UInt64($0[0]), x: $0[1], y: $0[2], z: $0[3]) }
}

/// Pushes an epoch's IMU batches to each engine.
func pushIMU(_ epoch: Walk.Epoch, to engines: [PositioningEngine]) throws {
    for engine in engines {
        _ = try engine.pushAccelerometer(batch: samples(epoch.accelerometer))
        _ = try engine.pushGyroscope(batch: samples(epoch.gyroscope))
        _ = try engine.pushMagnetometer(batch: samples(epoch.magnetometer))
    }
}

final class WaymarkTests: XCTestCase {
    static let simDir: URL = {
        if let dir = ProcessInfo.processInfo.environment["WAYMARK_SIM_DIR"] {
            return URL(fileURLWithPath: dir)
        }
        // bindings/swift/Tests/WaymarkTests/ -> <repo>/target/sim-export
        return URL(fileURLWithPath: #filePath).deletingLastPathComponent()
            .appendingPathComponent("../../../../target/sim-export").standardized
    }()

    /// The simulated office's exported survey walks (`survey/*.json`) by name: each file and
    /// the walk's name, the file's stem.
    static func surveyWalks() throws -> [(file: URL, name: String)] {
        let dir = simDir.appendingPathComponent("survey")
        return try FileManager.default.contentsOfDirectory(atPath: dir.path).filter { $0.hasSuffix(".json") }.sorted()
            .map { (dir.appendingPathComponent($0), String($0.dropLast(".json".count))) }
    }

    func siteJson() throws -> String {
        try String(contentsOf: Self.simDir.appendingPathComponent("site.json"), encoding: .utf8)
    }

    func walk() throws -> Walk {
        let data = try Data(contentsOf: Self.simDir.appendingPathComponent("walk.json"))
        let decoder = JSONDecoder()
        decoder.keyDecodingStrategy = .convertFromSnakeCase
        return try decoder.decode(Walk.self, from: data)
    }

    // (a) The exported walk, raw IMU batches and scans epoch by epoch, through a listener.
    func testWalkThroughTheBindingsWithAListener() throws {
        let engine = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        let recorder = Recorder()
        let subscription = engine.subscribe(listener: recorder)
        let walk = try walk()
        XCTAssertGreaterThan(walk.epochs.count, 10)

        var errors: [Double] = []
        var taken: UInt32 = 0
        for epoch in walk.epochs {
            taken += try engine.pushAccelerometer(batch: samples(epoch.accelerometer))
            taken += try engine.pushGyroscope(batch: samples(epoch.gyroscope))
            taken += try engine.pushMagnetometer(batch: samples(epoch.magnetometer))
            do {
                let p = try engine.pushScan(scan: epoch.scan)
                XCTAssertEqual(p.timestampNs, epoch.timestampNs)
                XCTAssertEqual(p.floorName, "office")
                XCTAssertGreaterThan(p.accuracyM, 0)
                XCTAssertGreaterThanOrEqual(p.accuracy95M, p.accuracyM)
                XCTAssertGreaterThanOrEqual(p.beyondRadioM, 0)
                XCTAssertGreaterThanOrEqual(p.accuracyM, p.beyondRadioM)
                errors.append(hypot(p.x - epoch.truth[0], p.y - epoch.truth[1]))
            } catch PositioningError.InputRejected {
                // A scan with no known transmitter: the engine goes on.
            }
        }
        let rows = walk.epochs.reduce(0) { $0 + $1.accelerometer.count + $1.gyroscope.count + $1.magnetometer.count }
        XCTAssertEqual(Int(taken), rows, "every simulated IMU sample is valid")
        XCTAssertGreaterThan(errors.count, walk.epochs.count * 9 / 10)
        let mean = errors.reduce(0, +) / Double(errors.count)
        XCTAssertLessThan(mean, 1.5, "mean error \(mean) m over \(errors.count) epochs")

        // One position per accepted scan, the last one the engine's.
        XCTAssertEqual(recorder.positions.count, errors.count)
        XCTAssertEqual(recorder.positions.last, try engine.position())
        XCTAssertFalse(recorder.statuses.isEmpty, "walking starts: a motion-state change")
        XCTAssertFalse(try engine.track().isEmpty)
        XCTAssertNotNil(try engine.fixedLagPosition())

        // A cancelled subscription hears nothing more.
        subscription.cancel()
        let before = recorder.positions.count
        _ = try engine.advance(timestampNs: walk.epochs.last!.timestampNs + 1_500_000_000)
        XCTAssertEqual(recorder.positions.count, before)
    }

    // (b) Typed errors.
    func testErrorsAreTyped() throws {
        XCTAssertThrowsError(try PositioningEngine(siteJson: "{\"format_version\": 1", options: EngineOptions())) {
            guard case PositioningError.InvalidSite(let reason) = $0 else {
                return XCTFail("expected invalidSite, got \($0)")
            }
            XCTAssertFalse(reason.isEmpty)
        }
        XCTAssertThrowsError(try PositioningEngine.fromPath(path: "/nonexistent.json", options: EngineOptions())) {
            guard case PositioningError.InvalidSite = $0 else { return XCTFail("expected invalidSite, got \($0)") }
        }
        XCTAssertThrowsError(
            try PositioningEngine(siteJson: try siteJson(), options: EngineOptions(fixedLagEpochs: 1000))
        ) {
            guard case PositioningError.InvalidConfig = $0 else { return XCTFail("expected invalidConfig, got \($0)") }
        }

        let engine = try PositioningEngine.fromPath(
            path: Self.simDir.appendingPathComponent("site.json").path, options: EngineOptions())
        let first = try walk().epochs[0].scan
        _ = try engine.pushScan(scan: first)
        var older = first
        older.timestampNs -= 1
        for rejected in [
            first,  // same time again
            older,  // out of order
            RadioScan(timestampNs: first.timestampNs + 1, wifi: [], beacons: []),
            RadioScan(timestampNs: first.timestampNs + 2, wifi: [WifiReading(bssid: "not a bssid", rssiDbm: -60)], beacons: []),
        ] {
            XCTAssertThrowsError(try engine.pushScan(scan: rejected)) {
                guard case PositioningError.InputRejected = $0 else {
                    return XCTFail("expected inputRejected, got \($0)")
                }
            }
        }
        // NaN and backwards samples are dropped, not fatal.
        let s = { (t: UInt64, x: Double) in MotionSample(timestampNs: first.timestampNs + t, x: x, y: 0, z: 9.81) }
        XCTAssertEqual(try engine.pushAccelerometer(batch: [s(15, 0), s(14, 0), s(16, .nan), s(17, 0.1)]), 2)
        // Barometer readings: NaN, out of range and backwards are dropped and counted.
        let hpa = { (t: UInt64, p: Double) in PressureReading(timestampNs: first.timestampNs + t, hpa: p) }
        XCTAssertEqual(try engine.pushPressure(batch: [hpa(15, 1000), hpa(16, .nan), hpa(17, 20), hpa(14, 1000)]), 1)
        XCTAssertEqual(try engine.inputStats().pressureDropped, 3)
        XCTAssertNotNil(try engine.position())
    }

    // Zones (the office's rooms, aisle and stair hall), user feedback and a position fix.
    func testZonesFeedbackAndPositionFixes() throws {
        let engine = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        let zones = try engine.zonePosterior()
        XCTAssertEqual(zones.count, 12)
        XCTAssertEqual(zones[0].name, "aisle")
        XCTAssertEqual(zones[0].kind, .corridor)
        let first = try engine.pushScan(scan: try walk().epochs[0].scan)
        XCTAssertTrue(first.zone == nil || zones.contains { $0.name == first.zone })
        // "I am in room 3", about the position just shown.
        let pinned = try engine.confirmZone(timestampNs: first.timestampNs, zone: "room 3")
        XCTAssertEqual(pinned.zone, "room 3")
        XCTAssertEqual(pinned.zoneProbability, 1, accuracy: 1e-9)
        XCTAssertThrowsError(try engine.confirmZone(timestampNs: first.timestampNs + 1, zone: "cellar")) {
            guard case PositioningError.InputRejected = $0 else { return XCTFail("expected inputRejected, got \($0)") }
        }
        // "Within 2 m of the aisle's first state", later.
        let tapped = try engine.confirmPosition(
            timestampNs: first.timestampNs + 5_000_000_000, x: 1.7, y: 11.5, floor: 0, radiusM: 2)
        XCTAssertEqual(tapped.zone, "aisle")
        // A precise fix 40 s later (time to walk there) at the stair hall's middle state.
        let fixed = try engine.pushFix(
            fix: PositionFix(timestampNs: first.timestampNs + 45_000_000_000, x: 35.5, y: 11.5, accuracyM: 0.5))
        XCTAssertEqual(fixed.zone, "stair hall")
        XCTAssertLessThan(hypot(fixed.x - 35.5, fixed.y - 11.5), 1)
        XCTAssertThrowsError(
            try engine.pushFix(
                fix: PositionFix(timestampNs: first.timestampNs + 46_000_000_000, x: .nan, y: 11.5, floor: nil, accuracyM: 3))
        ) {
            guard case PositioningError.InputRejected = $0 else { return XCTFail("expected inputRejected, got \($0)") }
        }
        XCTAssertEqual(try engine.position(), fixed)
    }

    // Zone and geofence entries and exits reach the listener as status updates, exits first.
    func testZoneAndGeofenceEvents() throws {
        let engine = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        let recorder = Recorder()
        let subscription = engine.subscribe(listener: recorder)
        try engine.addGeofence(geofence: Geofence(id: "entrance", floor: 0, shape: .circle(x: 1.7, y: 11.5, radiusM: 3)))
        let square = [SitePoint(x: 33, y: 9), SitePoint(x: 38, y: 9), SitePoint(x: 38, y: 14), SitePoint(x: 33, y: 14)]
        try engine.addGeofence(geofence: Geofence(id: "stairs", floor: 0, shape: .polygon(vertices: square)))
        XCTAssertThrowsError(
            try engine.addGeofence(geofence: Geofence(id: "stairs", floor: 0, shape: .circle(x: 1.7, y: 11.5, radiusM: 3)))
        ) {
            guard case PositioningError.InputRejected = $0 else { return XCTFail("expected inputRejected, got \($0)") }
        }
        let first = try engine.pushScan(scan: try walk().epochs[0].scan)
        _ = try engine.confirmPosition(timestampNs: first.timestampNs, x: 1.7, y: 11.5, floor: 0, radiusM: 1)
        _ = try engine.confirmPosition(
            timestampNs: first.timestampNs + 40_000_000_000, x: 35.5, y: 11.5, floor: 0, radiusM: 1)
        let names: [String] = recorder.statuses.compactMap {
            switch $0 {
            case .zoneEntered(_, let zone, _): return "+" + zone
            case .zoneExited(_, let zone, _): return "-" + zone
            case .geofenceEntered(_, let id, _): return "+" + id
            case .geofenceExited(_, let id, _): return "-" + id
            default: return nil
            }
        }
        XCTAssertEqual(Array(names.suffix(4)), ["-aisle", "-entrance", "+stair hall", "+stairs"], "\(names)")
        XCTAssertTrue(names.contains("+entrance") && names.contains("+aisle"), "\(names)")
        XCTAssertTrue(try engine.removeGeofence(id: "stairs"))
        XCTAssertFalse(try engine.removeGeofence(id: "stairs"))
        XCTAssertNil(try engine.geofenceProbability(id: "stairs"))
        subscription.cancel()
    }

    // Routes through the bindings (docs/routes.md): legs with turns, a tracker that notices a
    // detour and reroutes, typed errors.
    func testRoutes() throws {
        let site = try Site.fromPath(path: Self.simDir.appendingPathComponent("site.json").path)
        // From room 1's far corner to room 10, across the aisle.
        let route = try site.route(from: FloorPoint(floor: 0, x: 4.9, y: 2), destination: .zone(name: "room 10"))
        XCTAssertGreaterThanOrEqual(route.legs.count, 3)
        XCTAssertEqual(route.lengthM, route.legs.reduce(0) { $0 + $1.distanceM }, accuracy: 1e-9)
        XCTAssertGreaterThanOrEqual(route.lengthM, hypot(route.end.x - route.start.x, route.end.y - route.start.y))
        XCTAssertNil(route.legs[0].turn)
        XCTAssertTrue(route.legs.dropFirst().allSatisfy { $0.turn != nil })
        XCTAssertEqual(route.legs.last?.points.last, route.end)

        let tracker = try RouteTracker(
            site: site, from: FloorPoint(floor: 0, x: 1.9, y: 9), destination: .zone(name: "stair hall"))
        let planned = tracker.route()
        let first = try tracker.updatePoint(point: planned.start, accuracyM: 2)
        XCTAssertFalse(first.offRoute)
        XCTAssertEqual(first.remainingM, planned.lengthM, accuracy: 1e-9)
        // Deep in room 2, off the aisle: off the route; a reroute leads on from there.
        XCTAssertTrue(try tracker.updatePoint(point: FloorPoint(floor: 0, x: 10, y: 3), accuracyM: 2).offRoute)
        let again = try tracker.reroute()
        XCTAssertEqual(again.end, planned.end)
        XCTAssertTrue(try tracker.updatePoint(point: again.end, accuracyM: 1).arrived)

        XCTAssertThrowsError(
            try site.route(from: FloorPoint(floor: 0, x: 4.9, y: 2), destination: .zone(name: "kitchen"))
        ) {
            guard case RouteError.UnknownZone = $0 else { return XCTFail("expected UnknownZone, got \($0)") }
        }
        XCTAssertThrowsError(
            try site.route(from: FloorPoint(floor: 7, x: 1, y: 1), destination: .point(point: FloorPoint(floor: 0, x: 4.9, y: 2)))
        ) {
            guard case RouteError.OffGraph = $0 else { return XCTFail("expected OffGraph, got \($0)") }
        }
    }

    // Habits: learned from the walk with position fixes and the user's feedback, exported,
    // imported into a second engine, refused with a typed error when they do not fit, cleared.
    func testHabitsLearnExportImport() throws {
        let engine = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        XCTAssertEqual(try engine.fixBias(), FixBias(biasXM: 0, biasYM: 0, spread: 1))
        var positions = 0, fixes = 0, confirmations = 0
        for epoch in try walk().epochs {
            _ = try engine.pushAccelerometer(batch: samples(epoch.accelerometer))
            _ = try engine.pushGyroscope(batch: samples(epoch.gyroscope))
            _ = try engine.pushMagnetometer(batch: samples(epoch.magnetometer))
            guard (try? engine.pushScan(scan: epoch.scan)) != nil else { continue }
            positions += 1
            let (x, y) = (epoch.truth[0], epoch.truth[1])
            if positions % 7 == 3,
                (try? engine.confirmPosition(timestampNs: epoch.timestampNs, x: x, y: y, floor: 0, radiusM: 1.5)) != nil
            {
                confirmations += 1
            }
            if positions % 3 == 1,
                (try? engine.pushFix(
                    fix: PositionFix(timestampNs: epoch.timestampNs + 1000, x: x + 1.5, y: y + 0.5, floor: 0, accuracyM: 2)))
                    != nil
            {
                fixes += 1
            }
        }
        XCTAssertGreaterThan(fixes, 5)
        XCTAssertGreaterThan(confirmations, 2)

        let report = try engine.learnHabits()
        XCTAssertGreaterThan(report.epochs, 10)
        XCTAssertGreaterThan(report.learnedTransitions, 0)
        XCTAssertEqual(report.totalEpochs, UInt64(report.epochs))
        XCTAssertEqual(version(), "0.1.0")
        XCTAssertEqual(try engine.inputStats().fixesAccepted, UInt64(fixes))
        let learned = try engine.fixBias()
        // 1.5 m east, 0.5 m north, shrunk toward 0 by the prior's 5 pseudo-fixes.
        XCTAssertGreaterThan(learned.biasXM, 0.3)
        XCTAssertGreaterThan(learned.biasYM, 0)
        XCTAssertGreaterThan(learned.biasXM, learned.biasYM)
        XCTAssertEqual(try engine.learnHabits().epochs, 0, "each epoch is learned once")

        let json = try engine.exportHabits()
        let other = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        let empty = try other.exportHabits()
        XCTAssertNotEqual(empty, json)
        try other.importHabits(json: json)
        XCTAssertEqual(try other.exportHabits(), json)
        XCTAssertEqual(try other.fixBias(), learned)

        let newer = json.replacingOccurrences(of: "\"version\":1,", with: "\"version\":99,")
        XCTAssertNotEqual(newer, json)
        for bad in ["", "{", "null", "{\"format\":\"waymark-site\",\"version\":1}", newer,
                    json.replacingOccurrences(of: "\"count\":[", with: "\"count\":[-1,")] {
            XCTAssertThrowsError(try other.importHabits(json: bad)) {
                guard case PositioningError.HabitsRejected(let reason) = $0 else {
                    return XCTFail("expected HabitsRejected, got \($0)")
                }
                XCTAssertFalse(reason.isEmpty)
            }
            XCTAssertEqual(try other.exportHabits(), json, "a refused model changed the habits")
        }
        try other.clearHabits()
        XCTAssertEqual(try other.exportHabits(), empty)
        XCTAssertEqual(try other.fixBias(), FixBias(biasXM: 0, biasYM: 0, spread: 1))
    }

    // A site whose transmitter ids are salted hashes: with its salt the engine positions exactly
    // as on the raw site; without it, or with another, it refuses to start with a typed error.
    func testAHashedSiteNeedsItsSalt() throws {
        let hashedURL = Self.simDir.appendingPathComponent("site-hashed.json")
        let hashedJson = try String(contentsOf: hashedURL, encoding: .utf8)
        XCTAssertFalse(hashedJson.contains("\"bssid\""), "no BSSID in the hashed file")
        let salt = saltFromHex(try String(contentsOf: Self.simDir.appendingPathComponent("salt.hex"), encoding: .utf8))
        XCTAssertEqual(salt.count, 32)
        let raw = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        let hashed = try PositioningEngine.fromPath(path: hashedURL.path, options: EngineOptions(siteSalt: salt))
        for epoch in try walk().epochs {
            try pushIMU(epoch, to: [raw, hashed])
            XCTAssertEqual(try? raw.pushScan(scan: epoch.scan), try? hashed.pushScan(scan: epoch.scan))
        }
        XCTAssertNotNil(try hashed.position())

        var wrong = salt
        wrong[0] ^= 1
        for options in [EngineOptions(), EngineOptions(siteSalt: wrong)] {
            XCTAssertThrowsError(try PositioningEngine(siteJson: hashedJson, options: options)) {
                guard case PositioningError.SaltMismatch(let reason) = $0 else {
                    return XCTFail("expected SaltMismatch, got \($0)")
                }
                XCTAssertTrue(reason.contains("salt"))
            }
        }
        XCTAssertThrowsError(try PositioningEngine(siteJson: hashedJson, options: EngineOptions(siteSalt: Data(count: 8)))) {
            guard case PositioningError.InvalidConfig = $0 else { return XCTFail("expected InvalidConfig, got \($0)") }
        }
    }

    // `track: false`: the same positions and fixed-lag positions, and no track.
    func testWithoutTheTrackThePositionsAreTheSame() throws {
        let kept = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        let none = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions(track: false))
        XCTAssertTrue(EngineOptions().track, "the track is kept by default")
        var positions = 0
        for epoch in try walk().epochs {
            try pushIMU(epoch, to: [kept, none])
            let expected = try? kept.pushScan(scan: epoch.scan)
            XCTAssertEqual(expected, try? none.pushScan(scan: epoch.scan))
            XCTAssertEqual(try kept.fixedLagPosition(), try none.fixedLagPosition())
            positions += expected == nil ? 0 : 1
        }
        XCTAssertGreaterThan(positions, 10)
        XCTAssertFalse(try kept.track().isEmpty)
        XCTAssertTrue(try none.track().isEmpty)
    }

    // The binary site encoding (`waymark site pack`), what an app ships in its bundle: from
    // bytes it positions exactly as the JSON; a damaged copy is an invalid site.
    func testAPackedSitePositionsAsItsJson() throws {
        let packedURL = Self.simDir.appendingPathComponent("site.wmsite")
        var packed = try Data(contentsOf: packedURL)
        let json = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        let binary = try PositioningEngine.fromSiteBytes(site: packed, options: EngineOptions())
        var positions = 0
        for epoch in try walk().epochs {
            try pushIMU(epoch, to: [json, binary])
            let expected = try? json.pushScan(scan: epoch.scan)
            XCTAssertEqual(expected, try? binary.pushScan(scan: epoch.scan))
            positions += expected == nil ? 0 : 1
        }
        XCTAssertGreaterThan(positions, 10)
        packed[packed.count / 2] ^= 0x40
        XCTAssertThrowsError(try PositioningEngine.fromSiteBytes(site: packed, options: EngineOptions())) {
            guard case PositioningError.InvalidSite(let reason) = $0 else {
                return XCTFail("expected InvalidSite, got \($0)")
            }
            XCTAssertTrue(reason.contains("damaged"), reason)
        }
    }

    // Map evidence from the session, and a refitted site loaded in place: the same site in its
    // binary encoding carries the session on exactly; a hashed site without its salt changes
    // nothing.
    func testTheSessionGivesEvidenceAndTakesARefittedSiteInPlace() throws {
        let engine = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        let reference = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        let refitted = try Site.fromBytes(site: try Data(contentsOf: Self.simDir.appendingPathComponent("site.wmsite")))
        XCTAssertNil(try engine.takeEvidence(), "nothing gathered unless asked")
        try engine.startEvidence()
        let epochs = try walk().epochs
        var accepted = 0
        for (k, epoch) in epochs.enumerated() {
            if k == epochs.count / 2 {
                let before = try XCTUnwrap(try engine.takeEvidence())
                XCTAssertEqual(before.scans, UInt64(accepted))
                XCTAssertEqual(before.scansDropped, 0)
                XCTAssertEqual(String(decoding: before.bytes.prefix(4), as: UTF8.self), "WMEV")
                XCTAssertEqual(try engine.replaceSite(site: refitted)?.scans, 0)
                XCTAssertEqual(try engine.position(), try reference.position())
                accepted = 0
            }
            try pushIMU(epoch, to: [engine, reference])
            let expected = try? reference.pushScan(scan: epoch.scan)
            XCTAssertEqual(try? engine.pushScan(scan: epoch.scan), expected, "epoch \(k)")
            accepted += expected == nil ? 0 : 1
        }
        XCTAssertGreaterThan(accepted, 5)
        XCTAssertEqual(try engine.takeEvidence()?.scans, UInt64(accepted))
        try engine.stopEvidence()
        XCTAssertNil(try engine.takeEvidence())
        let hashed = try Site.fromBytes(site: try Data(contentsOf: Self.simDir.appendingPathComponent("site-hashed.json")))
        XCTAssertThrowsError(try engine.replaceSite(site: hashed)) {
            guard case PositioningError.SaltMismatch = $0 else { return XCTFail("expected SaltMismatch, got \($0)") }
        }
        XCTAssertEqual(try engine.position(), try reference.position())
    }

    // A BLE beacon known by its advertiser address only (Eddystone, or an iBeacon left at
    // major = minor = 0). The site is the simulated one with its first access point turned
    // into such a beacon.
    func testBeaconsKnownByAddressOnly() throws {
        let wifi = #"{"wifi":{"bssid":"02:00:00:00:00:00"}}"#
        let json = try siteJson()
        XCTAssertTrue(json.contains(wifi), "the simulator's first access point moved")
        let site = json.replacingOccurrences(of: wifi, with: #"{"ble_address":{"mac":"02:00:00:00:00:00"}}"#)
        let engine = try PositioningEngine(siteJson: site, options: EngineOptions())
        let uuid = "fda50693-a4e2-4fb1-afcf-c6eb07647825"
        let scan = { (t: UInt64, beacon: BeaconReading) in RadioScan(timestampNs: t, wifi: [], beacons: [beacon]) }
        // UUID, major and minor default to "", 0 and 0: the address alone identifies it.
        let first = try engine.pushScan(scan: scan(10, BeaconReading(rssiDbm: -60, address: "02-00-00-00-00-00")))
        XCTAssertEqual(first.timestampNs, 10)
        _ = try engine.pushScan(scan: scan(20, BeaconReading(uuid: uuid, rssiDbm: -60, address: "02:00:00:00:00:00")))
        for rejected in [
            // An iBeacon with a major/minor is another, unknown, beacon.
            BeaconReading(uuid: uuid, major: 1, minor: 2, rssiDbm: -60, address: "02:00:00:00:00:00"),
            BeaconReading(rssiDbm: -60),  // neither UUID nor address
            BeaconReading(rssiDbm: -60, address: ""),
            BeaconReading(rssiDbm: -60, address: "02:00:00:00:00"),
            BeaconReading(rssiDbm: -60, address: "not a mac address"),
        ] {
            XCTAssertThrowsError(try engine.pushScan(scan: scan(30, rejected))) {
                guard case PositioningError.InputRejected(let reason) = $0 else {
                    return XCTFail("expected inputRejected, got \($0)")
                }
                XCTAssertFalse(reason.isEmpty)
            }
        }
        let last = try engine.pushScan(scan: scan(30, BeaconReading(rssiDbm: -60, address: "02:00:00:00:00:00")))
        XCTAssertEqual(last.timestampNs, 30)
    }

    // (c) A throwing listener is reported, never fatal, and does not starve the others.
    func testAThrowingListenerDoesNotBreakTheEngine() throws {
        let engine = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        let throwing = engine.subscribe(listener: Throwing())
        let recorder = Recorder()
        let subscription = engine.subscribe(listener: recorder)
        var accepted = 0
        for epoch in try walk().epochs.prefix(20) {
            _ = try engine.pushAccelerometer(batch: samples(epoch.accelerometer))
            _ = try engine.pushGyroscope(batch: samples(epoch.gyroscope))
            _ = try engine.pushMagnetometer(batch: samples(epoch.magnetometer))
            if (try? engine.pushScan(scan: epoch.scan)) != nil { accepted += 1 }
        }
        XCTAssertGreaterThan(accepted, 0)
        XCTAssertEqual(recorder.positions.count, accepted)
        XCTAssertFalse(recorder.statuses.isEmpty, "status changes reached the listener after the throwing one")
        throwing.cancel()
        subscription.cancel()
    }

    // A panic inside Rust (injected on this timestamp in the test build) is a thrown error,
    // not an abort, and the engine goes on.
    func testAnInjectedPanicIsAnErrorAndTheEngineGoesOn() throws {
        let engine = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        let recorder = Recorder()
        let subscription = engine.subscribe(listener: recorder)
        let wifi = [WifiReading(bssid: "02:00:00:00:00:00", rssiDbm: -60, ageMs: 0)]
        XCTAssertThrowsError(try engine.pushScan(scan: RadioScan(timestampNs: UInt64.max - 7, wifi: wifi, beacons: []))) {
            guard case PositioningError.Internal = $0 else { return XCTFail("expected Internal, got \($0)") }
        }
        XCTAssertEqual(recorder.errors.count, 1)
        _ = try engine.pushScan(scan: RadioScan(timestampNs: 10, wifi: wifi, beacons: []))
        XCTAssertEqual(recorder.positions.count, 1)
        subscription.cancel()
    }

    // (d) Several threads at once: pushes, polls and subscriptions, as sensor queues would.
    func testManyThreadsAtOnce() throws {
        let engine = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        let epochs = try walk().epochs
        let recorder = Recorder()
        let lock = NSLock()
        var accepted = 0
        let threads = 8
        DispatchQueue.concurrentPerform(iterations: threads) { thread in
            let subscription = engine.subscribe(listener: recorder)
            for epoch in epochs.enumerated().filter({ $0.offset % threads == thread }).map(\.element) {
                _ = try? engine.pushAccelerometer(batch: samples(epoch.accelerometer))
                _ = try? engine.pushGyroscope(batch: samples(epoch.gyroscope))
                _ = try? engine.pushMagnetometer(batch: samples(epoch.magnetometer))
                if (try? engine.pushScan(scan: epoch.scan)) != nil {
                    lock.lock(); accepted += 1; lock.unlock()
                }
                _ = try? engine.position()
                _ = try? engine.track()
                _ = try? engine.fixedLagPosition()
            }
            subscription.cancel()
        }
        // Scans from other threads may arrive out of order and be rejected; the engine works.
        XCTAssertGreaterThan(accepted, 0)
        XCTAssertNotNil(try engine.position())
        _ = try engine.advance(timestampNs: epochs.last!.timestampNs + 1_000_000_000)
    }

    // (e) The CoreMotion / CoreLocation conversions of Conversions.swift.
    func testLocationFields() throws {
        func at(_ lat: Double?, _ lon: Double?, bearing: Double?, level: Int32?) -> PositionEstimate {
            PositionEstimate(timestampNs: 1, x: 3, y: 4, floor: 0, floorName: "G", floorLevel: level, floorProbability: 1,
                             latitudeDeg: lat, longitudeDeg: lon, accuracyM: 2.5, accuracy95M: 5.0,
                             headingDeg: bearing.map { _ in 12 }, headingAccuracyDeg: bearing.map { _ in 5 }, bearingDeg: bearing,
                             motionState: .walking, scenario: .distanceHeading, steps: 2)
        }
        let walking = try XCTUnwrap(at(60.001, 24.002, bearing: 30, level: -1).locationFields)
        XCTAssertEqual(walking, AppleLocationFields(latitudeDeg: 60.001, longitudeDeg: 24.002, horizontalAccuracyM: 2.5,
                                                    courseDeg: 30, courseAccuracyDeg: 5, floorLevel: -1))
        // No heading: Core Location's "invalid" course and course accuracy; no level: no floor.
        let still = try XCTUnwrap(at(60, 24, bearing: nil, level: nil).locationFields)
        XCTAssertEqual(still.courseDeg, -1)
        XCTAssertEqual(still.courseAccuracyDeg, -1)
        XCTAssertNil(still.floorLevel)
        // A site without an anchor has no CLLocation.
        XCTAssertNil(at(nil, nil, bearing: 30, level: 1).locationFields)
    }

    // A geo-referenced site: positions carry latitude/longitude and the floor level from Rust,
    // and pushFix takes latitude/longitude; without an anchor that is a typed error.
    func testGeoReferencedSite() throws {
        let plain = try siteJson()
        var geo = plain.replacingOccurrences(
            of: "\"floors\":", with: "\"anchor\":{\"lat_deg\":60.17,\"lon_deg\":24.94},\"floors\":")
        if let r = geo.range(of: "\"elevation_m\":") { geo.replaceSubrange(r, with: "\"level\":2,\"elevation_m\":") }
        let t0: UInt64 = 1_000_000_000
        let engine = try PositioningEngine(siteJson: geo, options: EngineOptions())
        let inMetres = try engine.pushFix(fix: PositionFix(timestampNs: t0, x: 35.5, y: 11.5, accuracyM: 0.5))
        XCTAssertEqual(inMetres.floorLevel, 2)
        let here = try XCTUnwrap(inMetres.locationFields)
        // At 60°N a degree of latitude is 111 412 m and one of longitude 55 800 m (WGS84).
        XCTAssertEqual(here.latitudeDeg, 60.17 + inMetres.y / 111_412, accuracy: 1e-6)
        XCTAssertEqual(here.longitudeDeg, 24.94 + inMetres.x / 55_800, accuracy: 1e-5)
        // A fix at the estimate's latitude/longitude positions exactly as one at its x, y.
        let other = try PositioningEngine(siteJson: geo, options: EngineOptions())
        let inDegrees = try other.pushFix(fix: PositionFix(
            timestampNs: t0, accuracyM: 0.5, latitudeDeg: here.latitudeDeg, longitudeDeg: here.longitudeDeg))
        let third = try PositioningEngine(siteJson: geo, options: EngineOptions())
        let atEstimate = try third.pushFix(fix: PositionFix(timestampNs: t0, x: inMetres.x, y: inMetres.y, accuracyM: 0.5))
        XCTAssertEqual(inDegrees.x, atEstimate.x, accuracy: 1e-6)
        XCTAssertEqual(inDegrees.y, atEstimate.y, accuracy: 1e-6)
        let unanchored = try PositioningEngine(siteJson: plain, options: EngineOptions())
        XCTAssertThrowsError(try unanchored.pushFix(fix: PositionFix(
            timestampNs: t0, accuracyM: 0.5, latitudeDeg: here.latitudeDeg, longitudeDeg: here.longitudeDeg))) { error in
            guard case PositioningError.InputRejected(let reason) = error else { return XCTFail("\(error)") }
            XCTAssertTrue(reason.contains("not geo-referenced"), reason)
        }
        XCTAssertNil(try unanchored.pushFix(fix: PositionFix(timestampNs: t0, x: 35.5, y: 11.5, accuracyM: 0.5)).locationFields)
    }

    func testAppleSensorConversions() throws {
        typealias C = AppleSensorConversion
        XCTAssertEqual(C.nanoseconds(fromSeconds: 0), 0)
        XCTAssertEqual(C.nanoseconds(fromSeconds: 12.5), 12_500_000_000)
        // A day of uptime keeps nanosecond resolution.
        XCTAssertEqual(C.nanoseconds(fromSeconds: 86_400.000_000_123), 86_400_000_000_123)
        XCTAssertNil(C.nanoseconds(fromSeconds: -1))
        XCTAssertNil(C.nanoseconds(fromSeconds: .nan))
        XCTAssertNil(C.nanoseconds(fromSeconds: .infinity))
        XCTAssertNil(C.nanoseconds(fromSeconds: 1e12))

        // Lying face up: iOS reads z = -1 g; Waymark wants +9.80665 m/s² (Android's sign).
        let a = try XCTUnwrap(C.accelerometer(timestamp: 2, x: 0.5, y: 0, z: -1))
        XCTAssertEqual(a.timestampNs, 2_000_000_000)
        XCTAssertEqual(a.x, -4.903325, accuracy: 1e-12)
        XCTAssertEqual(a.y, 0)
        XCTAssertEqual(a.z, 9.80665, accuracy: 1e-12)
        XCTAssertNil(C.accelerometer(timestamp: -0.1, x: 0, y: 0, z: -1))

        XCTAssertEqual(
            C.gyroscope(timestamp: 1.25, x: 0.1, y: -0.2, z: 3.14),
            MotionSample(timestampNs: 1_250_000_000, x: 0.1, y: -0.2, z: 3.14))
        XCTAssertEqual(
            C.magnetometer(timestamp: 3, x: 20, y: -5, z: -42),
            MotionSample(timestampNs: 3_000_000_000, x: 20, y: -5, z: -42))

        let uuid = try XCTUnwrap(UUID(uuidString: "f7826da6-4fa2-4e98-8024-bc5b71e0893e"))
        let now = Date(timeIntervalSince1970: 1_700_000_000)
        XCTAssertEqual(
            C.beacon(uuid: uuid, major: 1, minor: 65_535, rssi: -71, measuredAt: now.addingTimeInterval(-0.25), now: now),
            BeaconReading(uuid: "F7826DA6-4FA2-4E98-8024-BC5B71E0893E", major: 1, minor: 65_535, rssiDbm: -71, ageMs: 250))
        XCTAssertNil(C.beacon(uuid: uuid, major: 1, minor: 2, rssi: 0), "rssi 0: not measured")
        XCTAssertNil(C.beacon(uuid: uuid, major: 70_000, minor: 2, rssi: -60))
        XCTAssertNil(C.beacon(uuid: uuid, major: 1, minor: -1, rssi: -60))
        XCTAssertEqual(C.ageMs(measuredAt: nil, now: now), 0)
        XCTAssertEqual(C.ageMs(measuredAt: now.addingTimeInterval(5), now: now), 0, "clock skew: fresh")

        let scan = try XCTUnwrap(C.scan(uptime: 4.5, beacons: []))
        XCTAssertEqual(scan.timestampNs, 4_500_000_000)
        XCTAssertNil(C.scan(uptime: .nan, beacons: []))

        // A converted beacon scan is a well-formed engine input: rejected only because this
        // site has no beacons ("no known transmitter"), with the typed error.
        let engine = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        let beacon = try XCTUnwrap(C.beacon(uuid: uuid, major: 1, minor: 2, rssi: -60))
        XCTAssertThrowsError(try engine.pushScan(scan: C.scan(uptime: 1, beacons: [beacon])!)) {
            guard case PositioningError.InputRejected = $0 else { return XCTFail("got \($0)") }
        }
        // Converted motion is accepted.
        let batch = (0..<50).compactMap { C.accelerometer(timestamp: 0.5 + Double($0) / 100, x: 0, y: 0, z: -1) }
        XCTAssertEqual(try engine.pushAccelerometer(batch: batch), 50)
    }
}
