// WaymarkLocationManager on Linux: a real engine on the simulated site, fed through fake ports
// (motion, ranging and authorization, clock, timer) that replay the simulated walk.
//
// The simulated site knows only WiFi access points and iOS gives apps no WiFi scans, so the
// beacon walk uses a copy of the site whose 15 access points are declared iBeacons (UUID
// `beaconUUID`, major 1, minor = the BSSID's last byte), and ranging reports each WiFi reading
// of the walk as that beacon: same transmitters, same radio map, same RSSI. Tests on the site
// as exported (no beacons) drive positions with motion and `advance`.

import Foundation
import XCTest

@testable import Waymark

let beaconUUID = UUID(uuidString: "FDA50693-A4E2-4FB1-AFCF-C6EB07647825")!

/// An engine that records every input call, in order, before making it.
final class RecordingEngine: PositioningEngine, @unchecked Sendable {
    enum Call: Equatable {
        case motion(WaymarkMotionSensor, [MotionSample])
        case pressure([PressureReading])
        case scan(RadioScan)
        case advance(UInt64)
    }

    private let lock = NSLock()
    private var recorded: [Call] = []

    var calls: [Call] { lock.lock(); defer { lock.unlock() }; return recorded }

    private func record(_ call: Call) { lock.lock(); recorded.append(call); lock.unlock() }

    override func pushAccelerometer(batch: [MotionSample]) throws -> UInt32 {
        record(.motion(.accelerometer, batch))
        return try super.pushAccelerometer(batch: batch)
    }

    override func pushGyroscope(batch: [MotionSample]) throws -> UInt32 {
        record(.motion(.gyroscope, batch))
        return try super.pushGyroscope(batch: batch)
    }

    override func pushMagnetometer(batch: [MotionSample]) throws -> UInt32 {
        record(.motion(.magnetometer, batch))
        return try super.pushMagnetometer(batch: batch)
    }

    override func pushPressure(batch: [PressureReading]) throws -> UInt32 {
        record(.pressure(batch))
        return try super.pushPressure(batch: batch)
    }

    override func pushScan(scan: RadioScan) throws -> PositionEstimate {
        record(.scan(scan))
        return try super.pushScan(scan: scan)
    }

    override func advance(timestampNs: UInt64) throws -> PositionEstimate {
        record(.advance(timestampNs))
        return try super.advance(timestampNs: timestampNs)
    }

    /// The epochs (scans and advances) asked for, with their times, in call order.
    var epochTimes: [UInt64] {
        calls.compactMap {
            switch $0 {
            case .scan(let s): return s.timestampNs
            case .advance(let t): return t
            case .motion, .pressure: return nil
            }
        }
    }
}

final class FakeClock: WaymarkClock {
    private let lock = NSLock()
    private var ns: UInt64 = 0

    func set(_ value: UInt64) { lock.lock(); ns = value; lock.unlock() }
    func nowNs() -> UInt64 { lock.lock(); defer { lock.unlock() }; return ns }
}

final class FakeTimer: WaymarkTimer {
    let after: TimeInterval
    let queue: DispatchQueue
    let work: () -> Void
    var cancelled = false
    var fired = false

    init(after: TimeInterval, queue: DispatchQueue, work: @escaping () -> Void) {
        self.after = after
        self.queue = queue
        self.work = work
    }

    func cancel() { cancelled = true }
}

/// Timers that fire only when the test says their time has come.
final class FakeScheduler: WaymarkScheduler {
    private let lock = NSLock()
    private var timers: [FakeTimer] = []

    func schedule(after seconds: TimeInterval, on queue: DispatchQueue, _ work: @escaping () -> Void) -> WaymarkTimer {
        let timer = FakeTimer(after: seconds, queue: queue, work: work)
        lock.lock(); timers.append(timer); lock.unlock()
        return timer
    }

    /// The armed timer (not cancelled, not fired), if any.
    var armed: FakeTimer? {
        lock.lock(); defer { lock.unlock() }
        return timers.last { !$0.cancelled && !$0.fired }
    }

    /// Fires the armed timer on its queue; false when none is armed.
    @discardableResult
    func fire() -> Bool {
        guard let timer = armed else { return false }
        timer.fired = true
        timer.queue.sync { timer.work() }
        return true
    }
}

final class FakeMotion: WaymarkMotionSource {
    var available = Set(WaymarkMotionSensor.allCases)
    private(set) var started: [WaymarkMotionSensor] = []
    private(set) var interval: TimeInterval?
    private(set) var starts = 0
    private(set) var stops = 0
    private var queue: DispatchQueue?
    private var handler: ((WaymarkMotionReading) -> Void)?

    var running: Bool { handler != nil }

    func isAvailable(_ sensor: WaymarkMotionSensor) -> Bool { available.contains(sensor) }

    func start(_ sensors: [WaymarkMotionSensor], interval: TimeInterval, queue: DispatchQueue,
               handler: @escaping (WaymarkMotionReading) -> Void) {
        started = sensors
        self.interval = interval
        self.queue = queue
        self.handler = handler
        starts += 1
    }

    func stop() {
        handler = nil
        stops += 1
    }

    /// Delivers readings as CoreMotion would, on the queue given to `start`; nothing when stopped.
    func emit(_ readings: [WaymarkMotionReading]) {
        guard let queue, let handler else { return }
        queue.sync { readings.forEach(handler) }
    }
}

final class FakeAltimeter: WaymarkAltimeter {
    var isAvailable = true
    private(set) var starts = 0
    private(set) var stops = 0
    private var queue: DispatchQueue?
    private var handler: ((WaymarkPressureReading) -> Void)?

    var running: Bool { handler != nil }

    func start(queue: DispatchQueue, handler: @escaping (WaymarkPressureReading) -> Void) {
        self.queue = queue
        self.handler = handler
        starts += 1
    }

    func stop() {
        handler = nil
        stops += 1
    }

    /// Delivers readings as CoreMotion would, on the queue given to `start`; nothing when stopped.
    func emit(_ readings: [WaymarkPressureReading]) {
        guard let queue, let handler else { return }
        queue.sync { readings.forEach(handler) }
    }
}

final class FakeRanger: WaymarkBeaconRanger {
    var authorization: WaymarkAuthorization
    var isRangingAvailable: Bool
    private(set) var ranging: [UUID]?
    private(set) var rangingStarts = 0
    private(set) var rangingStops = 0
    private(set) var authorizationRequests = 0
    private(set) var queue: DispatchQueue?
    private var handler: ((WaymarkRangingEvent) -> Void)?

    init(authorization: WaymarkAuthorization, isRangingAvailable: Bool = true) {
        self.authorization = authorization
        self.isRangingAvailable = isRangingAvailable
    }

    func setEventHandler(queue: DispatchQueue, handler: @escaping (WaymarkRangingEvent) -> Void) {
        self.queue = queue
        self.handler = handler
    }

    func requestWhenInUseAuthorization() { authorizationRequests += 1 }

    func startRanging(uuids: [UUID]) {
        ranging = uuids
        rangingStarts += 1
    }

    func stopRanging() {
        ranging = nil
        rangingStops += 1
    }

    /// Delivers an event as the CLLocationManager delegate would, on the handler's queue.
    func send(_ event: WaymarkRangingEvent) {
        guard let queue, let handler else { return XCTFail("no event handler") }
        queue.sync { handler(event) }
    }

    func change(to new: WaymarkAuthorization) {
        authorization = new
        send(.authorizationChanged(new))
    }
}

/// Records the delegate calls, and whether each ran on the queue tagged with `key`.
final class DelegateRecorder: WaymarkLocationManagerDelegate {
    static let key = DispatchSpecificKey<String>()
    private let lock = NSLock()
    private var _positions: [PositionEstimate] = []
    private var _statuses: [WaymarkLocationStatus] = []
    private var _states: [WaymarkLocationState] = []
    private var _updates: [StatusUpdate] = []
    private var _queues: Set<String> = []

    var positions: [PositionEstimate] { lock.lock(); defer { lock.unlock() }; return _positions }
    var statuses: [WaymarkLocationStatus] { lock.lock(); defer { lock.unlock() }; return _statuses }
    var states: [WaymarkLocationState] { lock.lock(); defer { lock.unlock() }; return _states }
    var updates: [StatusUpdate] { lock.lock(); defer { lock.unlock() }; return _updates }
    /// The tags of the queues the calls ran on ("none" for an untagged one).
    var queues: Set<String> { lock.lock(); defer { lock.unlock() }; return _queues }

    private func record(_ body: () -> Void) {
        lock.lock(); defer { lock.unlock() }
        _queues.insert(DispatchQueue.getSpecific(key: Self.key) ?? "none")
        body()
    }

    func locationManager(_ manager: WaymarkLocationManager, didUpdate position: PositionEstimate) {
        record { _positions.append(position) }
    }

    func locationManager(_ manager: WaymarkLocationManager, didReport status: WaymarkLocationStatus) {
        record { _statuses.append(status) }
    }

    func locationManager(_ manager: WaymarkLocationManager, didChange state: WaymarkLocationState) {
        record { _states.append(state) }
    }

    func locationManager(_ manager: WaymarkLocationManager, didReceive update: StatusUpdate) {
        record { _updates.append(update) }
    }
}

/// A manager on a real engine with fake ports, its delegate on a tagged queue.
final class Harness {
    let engine: RecordingEngine
    let motion = FakeMotion()
    let altimeter = FakeAltimeter()
    let ranger: FakeRanger
    let clock = FakeClock()
    let scheduler = FakeScheduler()
    let delegateQueue = DispatchQueue(label: "test.delegate")
    let delegate = DelegateRecorder()
    let background: FakeBackgroundLocation?
    let lifecycle: FakeLifecycle?
    let manager: WaymarkLocationManager

    /// `withEngine` false: a manager that only records surveys (`engine` is then unused).
    init(siteJson: String, request: WaymarkLocationRequest = WaymarkLocationRequest(beaconUUIDs: [beaconUUID]),
         authorization: WaymarkAuthorization = .authorizedWhenInUse, rangingAvailable: Bool = true,
         clockStart: UInt64 = 0, barometer: Bool = true, background: FakeBackgroundLocation? = nil,
         lifecycle: FakeLifecycle? = nil, withEngine: Bool = true) throws {
        engine = try RecordingEngine(siteJson: siteJson, options: EngineOptions())
        ranger = FakeRanger(authorization: authorization, isRangingAvailable: rangingAvailable)
        self.background = background
        self.lifecycle = lifecycle
        clock.set(clockStart)
        delegateQueue.setSpecific(key: DelegateRecorder.key, value: "delegate")
        manager = try WaymarkLocationManager(
            engine: withEngine ? engine : nil, request: request, motion: motion, ranger: ranger,
            altimeter: barometer ? altimeter : nil, backgroundLocation: background, lifecycle: lifecycle,
            clock: clock, scheduler: scheduler, delegateQueue: delegateQueue)
        manager.delegate = delegate
    }

    /// Waits for what the manager queued, then for what it queued for the delegate.
    func settle() {
        ranger.queue?.sync {}
        delegateQueue.sync {}
    }

    /// One epoch of the walk as the phone gives it: its inertial samples, the clock at the
    /// epoch, then its scan as ranged beacons.
    func deliver(_ epoch: Walk.Epoch) {
        motion.emit(Harness.readings(epoch))
        clock.set(epoch.timestampNs)
        ranger.send(.ranged(Harness.beacons(epoch), uuid: beaconUUID))
    }

    /// The walk's inertial rows of one epoch as CoreMotion readings (g, rad/s, µT; seconds),
    /// in time order.
    static func readings(_ epoch: Walk.Epoch) -> [WaymarkMotionReading] {
        func rows(_ rows: [[Double]], _ sensor: WaymarkMotionSensor, _ k: Double) -> [WaymarkMotionReading] {
            rows.map { WaymarkMotionReading(sensor: sensor, timestamp: $0[0] / 1e9, x: $0[1] * k, y: $0[2] * k, z: $0[3] * k) }
        }
        let g = -1 / AppleSensorConversion.standardGravity
        return (rows(epoch.accelerometer, .accelerometer, g) + rows(epoch.gyroscope, .gyroscope, 1)
            + rows(epoch.magnetometer, .magnetometer, 1)).sorted { $0.timestamp < $1.timestamp }
    }

    /// The walk's WiFi readings of one epoch as ranged iBeacons (see the file's comment).
    static func beacons(_ epoch: Walk.Epoch) -> [WaymarkRangedBeacon] {
        epoch.wifi.map {
            WaymarkRangedBeacon(uuid: beaconUUID, major: 1, minor: Int($0.bssid.suffix(2), radix: 16)!,
                                rssi: Int($0.rssiDbm))
        }
    }
}

/// The simulated site, as exported.
func simSiteJson() throws -> String {
    try String(contentsOf: WaymarkTests.simDir.appendingPathComponent("site.json"), encoding: .utf8)
}

/// The simulated site with its access points declared as iBeacons (see the file's comment).
func makeBeaconSiteJson(_ site: String? = nil) throws -> String {
    var json = try site ?? simSiteJson()
    for minor in 0..<15 {
        let byte = (minor < 16 ? "0" : "") + String(minor, radix: 16)
        let wifi = #"{"wifi":{"bssid":"02:00:00:00:00:\#(byte)"}}"#
        XCTAssertTrue(json.contains(wifi), "the simulator's access points changed: \(wifi)")
        json = json.replacingOccurrences(
            of: wifi, with: #"{"ble":{"uuid":"\#(beaconUUID.uuidString.lowercased())","major":1,"minor":\#(minor)}}"#)
    }
    XCTAssertFalse(json.contains(#""wifi":"#))
    return json
}

/// A walk file of the simulated office (`walk.json`, or one of `survey/`).
func loadWalk(_ url: URL = WaymarkTests.simDir.appendingPathComponent("walk.json")) throws -> Walk {
    let decoder = JSONDecoder()
    decoder.keyDecodingStrategy = .convertFromSnakeCase
    return try decoder.decode(Walk.self, from: Data(contentsOf: url))
}

final class LocationClientTests: XCTestCase {
    func siteJson() throws -> String { try simSiteJson() }

    func beaconSiteJson() throws -> String { try makeBeaconSiteJson() }

    func walk() throws -> Walk { try loadWalk() }

    /// Fails unless every motion sample up to each epoch's time was sent before it, and none
    /// after it; returns how many motion calls were made.
    @discardableResult
    func assertMotionFlushedBeforeEachEpoch(_ calls: [RecordingEngine.Call], emitted: [UInt64],
                                            file: StaticString = #filePath, line: UInt = #line) -> Int {
        var sent: [UInt64] = []
        var motionCalls = 0
        for call in calls {
            let t: UInt64
            switch call {
            case .motion(_, let batch):
                sent += batch.map(\.timestampNs)
                motionCalls += 1
                continue
            case .pressure: continue
            case .scan(let scan): t = scan.timestampNs
            case .advance(let at): t = at
            }
            let due = emitted.filter { $0 <= t }.count
            XCTAssertEqual(sent.filter { $0 <= t }.count, due, "motion up to \(t) sent before its epoch", file: file, line: line)
            XCTAssertFalse(sent.contains { $0 > t }, "motion after \(t) sent before its epoch", file: file, line: line)
        }
        return motionCalls
    }

    // The walk through ranging: one scan per ranging result with the motion before it, the
    // delegate on its queue, unmeasured beacons dropped, no advance while beacons come.
    func testABeaconWalkThroughTheManager() throws {
        let walk = try walk()
        let h = try Harness(siteJson: try beaconSiteJson())
        h.manager.start()
        h.settle()
        XCTAssertEqual(h.ranger.ranging, [beaconUUID])
        XCTAssertEqual(h.motion.started, WaymarkMotionSensor.allCases)
        XCTAssertEqual(h.motion.interval, 0.01)
        XCTAssertEqual(h.manager.state, .running)
        XCTAssertEqual(h.delegate.statuses, [.authorizedWhenInUse])

        var emitted: [UInt64] = []
        for epoch in walk.epochs {
            let readings = Harness.readings(epoch)
            emitted += readings.map { AppleSensorConversion.nanoseconds(fromSeconds: $0.timestamp)! }
            h.motion.emit(readings)
            h.clock.set(epoch.timestampNs)
            // A beacon Core Location could not measure (rssi 0) rides along; it is dropped.
            let unmeasured = WaymarkRangedBeacon(uuid: beaconUUID, major: 1, minor: 3, rssi: 0)
            h.ranger.send(.ranged(Harness.beacons(epoch) + [unmeasured], uuid: beaconUUID))
            // The timer comes due 2 s after the start or the last scan: scans 1.5 s apart
            // keep re-arming it for the rest, and no advance is made.
            XCTAssertNotNil(h.scheduler.armed)
            h.scheduler.fire()
        }
        h.settle()

        let calls = h.engine.calls
        let scans = calls.compactMap { if case .scan(let s) = $0 { return s } else { return nil } }
        XCTAssertEqual(scans.map(\.timestampNs), walk.epochs.map(\.timestampNs), "one scan per ranging result, at its time")
        for (scan, epoch) in zip(scans, walk.epochs) {
            XCTAssertEqual(scan.wifi, [])
            XCTAssertEqual(scan.beacons.count, epoch.wifi.count, "the rssi-0 beacon is dropped")
            XCTAssertFalse(scan.beacons.contains { $0.rssiDbm == 0 })
            XCTAssertEqual(scan.beacons.first?.uuid, beaconUUID.uuidString)
        }
        XCTAssertFalse(calls.contains { if case .advance = $0 { return true } else { return false } })
        let motionCalls = assertMotionFlushedBeforeEachEpoch(calls, emitted: emitted)
        // Batched: 50 samples a call, plus one flush per sensor and scan at most.
        XCTAssertLessThanOrEqual(motionCalls, emitted.count / 50 + 3 * walk.epochs.count)
        // In m/s², pointing up at rest: the walk's own values back through the conversion.
        let firstAccel = try XCTUnwrap(calls.lazy.compactMap {
            if case .motion(.accelerometer, let b) = $0 { return b.first } else { return nil }
        }.first)
        XCTAssertEqual(firstAccel.z, walk.epochs[0].accelerometer[0][3], accuracy: 1e-9)

        // Positions on the delegate queue, as good as the WiFi walk's (WaymarkTests).
        let positions = h.delegate.positions
        XCTAssertEqual(positions.count, scans.count - Int(h.manager.rejectedScanCount))
        XCTAssertGreaterThan(positions.count, walk.epochs.count * 9 / 10)
        let truth = Dictionary(uniqueKeysWithValues: walk.epochs.map { ($0.timestampNs, $0.truth) })
        let errors = positions.compactMap { p in truth[p.timestampNs].map { hypot(p.x - $0[0], p.y - $0[1]) } }
        XCTAssertEqual(errors.count, positions.count, "every position at a scan's time")
        let mean = errors.reduce(0, +) / Double(errors.count)
        XCTAssertLessThan(mean, 1.5, "mean error \(mean) m over \(errors.count) epochs")
        XCTAssertEqual(h.delegate.queues, ["delegate"])
        XCTAssertFalse(h.delegate.updates.isEmpty, "the engine's own events (walking starts) reach the delegate")
        XCTAssertEqual(try h.engine.inputStats().scansAccepted, UInt64(positions.count))

        h.manager.stop()
        h.settle()
        XCTAssertNil(h.ranger.ranging)
        XCTAssertFalse(h.motion.running)
        XCTAssertNil(h.scheduler.armed)
        XCTAssertEqual(h.delegate.states, [.running, .stopped])
    }

    // No beacon in range (the site has none): ranging results are empty or refused, and the
    // timer's advance epochs keep the position moving, each after the one before.
    func testAdvanceEpochsWhileNoRangingResultMakesOne() throws {
        let walk = try walk()
        let h = try Harness(siteJson: try siteJson())
        h.manager.start()
        XCTAssertEqual(h.scheduler.armed?.after, 2, "the documented default interval")
        var emitted: [UInt64] = []
        for epoch in walk.epochs.prefix(20) {
            let readings = Harness.readings(epoch)
            emitted += readings.map { AppleSensorConversion.nanoseconds(fromSeconds: $0.timestamp)! }
            h.motion.emit(readings)
            h.clock.set(epoch.timestampNs)
            h.ranger.send(.ranged([], uuid: beaconUUID))  // nothing in range: no scan
            // Heard but not measured (rssi 0): no scan either.
            h.ranger.send(.ranged([WaymarkRangedBeacon(uuid: beaconUUID, major: 1, minor: 2, rssi: 0)], uuid: beaconUUID))
            h.scheduler.fire()
        }
        // Two ranging results at the same instant with a beacon the site does not know: two
        // scans, refused and counted, at different times.
        let last = walk.epochs[19].timestampNs
        h.clock.set(last + 500_000_000)
        h.ranger.send(.ranged([WaymarkRangedBeacon(uuid: beaconUUID, major: 9, minor: 9, rssi: -70)], uuid: beaconUUID))
        h.ranger.send(.ranged([WaymarkRangedBeacon(uuid: beaconUUID, major: 9, minor: 9, rssi: -71)], uuid: beaconUUID))
        // A refused scan is no epoch: the advance comes as due, 2 s after the last one.
        h.clock.set(last + 2_000_000_000)
        h.scheduler.fire()
        h.settle()

        let calls = h.engine.calls
        let advances = calls.compactMap { if case .advance(let t) = $0 { return t } else { return nil } }
        let times = h.engine.epochTimes
        XCTAssertEqual(times.count, advances.count + 2)
        XCTAssertEqual(times, times.sorted())
        XCTAssertEqual(Set(times).count, times.count, "no two epochs at one time")
        let refused = calls.compactMap { if case .scan(let s) = $0 { return s.timestampNs } else { return nil } }
        XCTAssertEqual(refused, [last + 500_000_000, last + 500_000_001])
        // Epochs 1.5 s apart and a 2 s interval: an advance every other epoch (3 s apart).
        XCTAssertEqual(advances.first, walk.epochs[1].timestampNs)
        XCTAssertEqual(advances.last, last + 2_000_000_000)
        for (a, b) in zip(advances, advances.dropFirst()) {
            XCTAssertGreaterThanOrEqual(b - a, 2_000_000_000, "advances at least the interval apart")
        }
        XCTAssertGreaterThanOrEqual(advances.count, 9)
        assertMotionFlushedBeforeEachEpoch(calls, emitted: emitted)

        XCTAssertEqual(h.delegate.positions.map(\.timestampNs), advances)
        XCTAssertEqual(try h.engine.inputStats().motionEpochs, UInt64(advances.count))
        XCTAssertEqual(h.manager.rejectedScanCount, 2)
        let rejections = h.delegate.statuses.filter { $0.code == 401 }
        XCTAssertEqual(rejections.count, 2)
        if case .scanRejected(_, let total) = rejections.last { XCTAssertEqual(total, 2) } else { XCTFail("\(rejections)") }
        // The engine's echo of a refused scan (onError) is not a second status.
        XCTAssertFalse(h.delegate.statuses.contains { $0.code == 400 }, "\(h.delegate.statuses)")
        XCTAssertEqual(h.manager.state, .running)
    }

    // An epoch the app makes itself (a GNSS fix) counts: the next advance is after it.
    func testAnAppEpochPushesTheNextAdvanceAfterIt() throws {
        let h = try Harness(siteJson: try siteJson(), request: WaymarkLocationRequest(), clockStart: 1_000_000_000)
        h.manager.start()
        _ = try h.engine.pushFix(fix: PositionFix(timestampNs: 10_000_000_000, x: 35.5, y: 11.5, accuracyM: 1))
        h.settle()
        h.clock.set(11_000_000_000)
        h.scheduler.fire()
        XCTAssertEqual(h.engine.epochTimes, [], "not due: 1 s after the fix")
        h.clock.set(12_000_000_000)
        h.scheduler.fire()
        XCTAssertEqual(h.engine.epochTimes, [12_000_000_000])
        h.settle()
        XCTAssertEqual(h.delegate.positions.map(\.timestampNs), [10_000_000_000, 12_000_000_000])
        // No beacon UUIDs: no authorization asked, no ranging, nothing missing.
        XCTAssertEqual(h.ranger.authorizationRequests, 0)
        XCTAssertNil(h.ranger.ranging)
        XCTAssertEqual(h.delegate.statuses, [])
        XCTAssertEqual(h.manager.state, .running)
    }

    // Denied at start: the coded status, no ranging, and motion-only positions go on.
    func testDeniedAtStartRangesNothingAndMotionGoesOn() throws {
        let walk = try walk()
        let h = try Harness(siteJson: try siteJson(), authorization: .denied)
        h.manager.start()
        h.ranger.send(.ranged([WaymarkRangedBeacon(uuid: beaconUUID, major: 1, minor: 1, rssi: -60)], uuid: beaconUUID))
        for epoch in walk.epochs.prefix(6) {
            h.motion.emit(Harness.readings(epoch))
            h.clock.set(epoch.timestampNs)
            h.scheduler.fire()
        }
        h.settle()
        XCTAssertEqual(h.delegate.statuses, [.authorizationDenied])
        XCTAssertEqual(h.delegate.statuses.map(\.code), [101])
        XCTAssertEqual(h.ranger.rangingStarts, 0)
        XCTAssertEqual(h.ranger.authorizationRequests, 0, "a denied user is not asked again")
        XCTAssertEqual(h.manager.state, .degraded)
        XCTAssertFalse(h.engine.calls.contains { if case .scan = $0 { return true } else { return false } })
        XCTAssertGreaterThanOrEqual(h.delegate.positions.count, 2, "motion-only positions")

        let restricted = try Harness(siteJson: try siteJson(), authorization: .restricted)
        restricted.manager.start()
        restricted.settle()
        XCTAssertEqual(restricted.delegate.statuses.map(\.code), [102])
        XCTAssertEqual(restricted.ranger.rangingStarts, 0)
    }

    // Never asked: the prompt once, degraded until the answer; the answer starts ranging.
    func testNotDeterminedAsksOnceAndTheAnswerStartsRanging() throws {
        let h = try Harness(siteJson: try siteJson(), authorization: .notDetermined)
        h.manager.start()
        // Core Location repeats the current status when its manager is made: nothing changes.
        h.ranger.send(.authorizationChanged(.notDetermined))
        h.settle()
        XCTAssertEqual(h.ranger.authorizationRequests, 1)
        XCTAssertEqual(h.delegate.statuses, [.authorizationNotDetermined])
        XCTAssertEqual(h.manager.state, .degraded)
        XCTAssertNil(h.ranger.ranging)

        h.ranger.change(to: .authorizedAlways)
        h.settle()
        XCTAssertEqual(h.ranger.ranging, [beaconUUID])
        XCTAssertEqual(h.delegate.statuses.map(\.code), [100, 104])
        XCTAssertEqual(h.delegate.states, [.degraded, .running])

        let quiet = try Harness(siteJson: try siteJson(),
                                request: WaymarkLocationRequest(beaconUUIDs: [beaconUUID], requestsAuthorization: false),
                                authorization: .notDetermined)
        quiet.manager.start()
        XCTAssertEqual(quiet.ranger.authorizationRequests, 0, "the app asks when it chooses")
    }

    // Revoked while running: ranging stops, the status says why, advance goes on; granted
    // again: ranging resumes.
    func testAuthorizationRevokedAndRestoredWhileRunning() throws {
        let h = try Harness(siteJson: try beaconSiteJson())
        let walk = try walk()
        h.manager.start()
        XCTAssertEqual(h.ranger.rangingStarts, 1)

        h.ranger.change(to: .denied)
        XCTAssertNil(h.ranger.ranging)
        XCTAssertEqual(h.ranger.rangingStops, 1)
        XCTAssertEqual(h.manager.state, .degraded)
        // A result Core Location had queued before the change is not a scan.
        h.clock.set(walk.epochs[0].timestampNs)
        h.ranger.send(.ranged(Harness.beacons(walk.epochs[0]), uuid: beaconUUID))
        XCTAssertEqual(h.engine.epochTimes, [])
        h.motion.emit(Harness.readings(walk.epochs[1]))
        h.clock.set(walk.epochs[1].timestampNs)
        h.scheduler.fire()
        XCTAssertEqual(h.engine.epochTimes, [walk.epochs[1].timestampNs], "motion-only advance while denied")

        h.ranger.change(to: .authorizedWhenInUse)
        XCTAssertEqual(h.ranger.ranging, [beaconUUID])
        XCTAssertEqual(h.ranger.rangingStarts, 2)
        h.clock.set(walk.epochs[2].timestampNs)
        h.ranger.send(.ranged(Harness.beacons(walk.epochs[2]), uuid: beaconUUID))
        h.settle()
        XCTAssertEqual(h.engine.epochTimes, [walk.epochs[1].timestampNs, walk.epochs[2].timestampNs])
        XCTAssertEqual(h.delegate.statuses.map(\.code), [103, 101, 103])
        XCTAssertEqual(h.delegate.states, [.running, .degraded, .running])
        XCTAssertEqual(h.delegate.positions.count, 2)
    }

    // Ranging unavailable or failing: coded statuses, degraded, motion goes on.
    func testRangingUnavailableAndRangingFailure() throws {
        let unavailable = try Harness(siteJson: try siteJson(), rangingAvailable: false)
        unavailable.manager.start()
        unavailable.settle()
        XCTAssertEqual(unavailable.delegate.statuses, [.authorizedWhenInUse, .rangingUnavailable])
        XCTAssertEqual(unavailable.ranger.rangingStarts, 0)
        XCTAssertEqual(unavailable.manager.state, .degraded)

        let h = try Harness(siteJson: try siteJson())
        h.manager.start()
        h.ranger.send(.failed(uuid: beaconUUID, code: 17, message: "kCLErrorDomain error 17"))
        h.settle()
        XCTAssertEqual(h.delegate.statuses.last, .rangingFailed(uuid: beaconUUID, code: 17, message: "kCLErrorDomain error 17"))
        XCTAssertEqual(h.delegate.statuses.last?.code, 201)
        XCTAssertNil(h.ranger.ranging)
        XCTAssertEqual(h.manager.state, .degraded)
        // A new authorization retries.
        h.ranger.change(to: .authorizedAlways)
        XCTAssertEqual(h.ranger.ranging, [beaconUUID])
        XCTAssertEqual(h.manager.state, .running)
        // So does starting again.
        h.ranger.send(.failed(uuid: beaconUUID, code: 17, message: "again"))
        h.manager.stop()
        h.manager.start()
        XCTAssertEqual(h.ranger.ranging, [beaconUUID])
        XCTAssertEqual(h.ranger.rangingStarts, 3)
    }

    // Missing sensors: one coded status each, the others started, degraded.
    // The barometer's readings (kPa, about 1 Hz) reach the engine in hPa, each before the
    // first epoch after it and none after, and stop with the manager.
    func testTheBarometerReachesTheEngineBeforeEachEpoch() throws {
        let walk = try walk()
        let h = try Harness(siteJson: try beaconSiteJson())
        h.manager.start()
        h.settle()
        XCTAssertTrue(h.manager.usesBarometer)
        XCTAssertEqual(h.altimeter.starts, 1)
        XCTAssertEqual(h.manager.state, .running)
        var emitted: [UInt64] = []
        var next = walk.epochs[0].timestampNs
        for epoch in walk.epochs {
            var readings: [WaymarkPressureReading] = []
            while next <= epoch.timestampNs {
                readings.append(WaymarkPressureReading(timestamp: Double(next) / 1e9, kilopascals: 100.0))
                emitted.append(next)
                next += 1_000_000_000
            }
            h.altimeter.emit(readings)
            h.deliver(epoch)
            h.scheduler.fire()
        }
        h.settle()
        let calls = h.engine.calls
        var sent: [PressureReading] = []
        for call in calls {
            switch call {
            case .pressure(let batch): sent += batch
            case .scan(let scan):
                let t = scan.timestampNs
                XCTAssertEqual(sent.filter { $0.timestampNs <= t }.count, emitted.filter { $0 <= t }.count,
                               "pressure up to \(t) sent before its epoch")
                XCTAssertFalse(sent.contains { $0.timestampNs > t }, "pressure after \(t) sent before its epoch")
            default: continue
            }
        }
        XCTAssertGreaterThan(emitted.count, 20)
        XCTAssertEqual(Set(sent.map(\.hpa)), [1000.0], "kPa × 10")
        XCTAssertEqual(try h.engine.inputStats().pressureDropped, 0)
        h.manager.stop()
        h.settle()
        XCTAssertFalse(h.altimeter.running)
        XCTAssertFalse(h.manager.usesBarometer)
        // A reading after stop is not delivered (the fake drops it, as CoreMotion does) nor sent.
        h.altimeter.emit([WaymarkPressureReading(timestamp: Double(next) / 1e9, kilopascals: 100.0)])
        XCTAssertEqual(h.engine.calls.count, calls.count)
    }

    // No barometer, one the app may not read, or a request without it: nothing is degraded.
    func testWithoutABarometerNothingIsDegraded() throws {
        for (present, available, wanted) in [(false, true, true), (true, false, true), (true, true, false)] {
            let h = try Harness(siteJson: try siteJson(), request: WaymarkLocationRequest(usesBarometer: wanted),
                                barometer: present)
            h.altimeter.isAvailable = available
            h.manager.start()
            h.settle()
            XCTAssertFalse(h.manager.usesBarometer)
            XCTAssertEqual(h.altimeter.starts, 0)
            XCTAssertEqual(h.manager.state, .running)
            XCTAssertEqual(h.delegate.statuses, [])
            h.manager.stop()
        }
    }

    func testMissingMotionSensors() throws {
        let h = try Harness(siteJson: try siteJson(), request: WaymarkLocationRequest())
        h.motion.available = [.accelerometer]
        h.manager.start()
        h.settle()
        XCTAssertEqual(h.motion.started, [.accelerometer])
        XCTAssertEqual(h.delegate.statuses, [.motionUnavailable(.gyroscope), .motionUnavailable(.magnetometer)])
        XCTAssertEqual(h.delegate.statuses.map(\.code), [301, 302])
        XCTAssertEqual(h.manager.state, .degraded)
    }

    // An engine failure is a status, once; a failure of the app's own call is reported too.
    func testEngineErrorsAreReportedNotSwallowed() throws {
        // The test library panics on a scan at this time (feature fault-injection).
        let h = try Harness(siteJson: try beaconSiteJson(), clockStart: UInt64.max - 7)
        let walk = try walk()
        h.manager.start()
        h.ranger.send(.ranged(Harness.beacons(walk.epochs[0]), uuid: beaconUUID))
        h.settle()
        let errors = h.delegate.statuses.filter { $0.code == 400 }
        XCTAssertEqual(errors.count, 1, "\(h.delegate.statuses)")
        guard case .engineError(let code, let message)? = errors.first else { return XCTFail("\(errors)") }
        XCTAssertEqual(code, .internal)
        XCTAssertFalse(message.isEmpty)
        XCTAssertEqual(h.manager.rejectedScanCount, 0, "a panic is no refusal")

        // The app's own call on the engine, refused: the listener's onError is the report.
        XCTAssertThrowsError(try h.engine.pushScan(scan: RadioScan(timestampNs: 5, wifi: [], beacons: [])))
        h.settle()
        let reported = h.delegate.statuses.filter { $0.code == 400 }
        XCTAssertEqual(reported.count, 2, "\(h.delegate.statuses)")
        guard case .engineError(.inputRejected, let reason)? = reported.last else { return XCTFail("\(reported)") }
        XCTAssertFalse(reason.isEmpty)
    }

    // The stream starts the manager, yields positions, and its end stops every source.
    func testTheLocationStreamYieldsPositionsAndItsEndStopsTheSources() throws {
        let walk = try walk()
        let h = try Harness(siteJson: try beaconSiteJson())
        let received = expectation(description: "three positions")
        let got = Box<[UInt64]>([])
        let task = Task {
            for await position in h.manager.locations() {
                got.update { $0.append(position.timestampNs) }
                if got.value.count == 3 { break }
            }
            received.fulfill()
        }
        XCTAssertTrue(waitUntil { h.manager.state == .running }, "the stream started the manager")
        XCTAssertEqual(h.ranger.ranging, [beaconUUID])
        XCTAssertTrue(h.motion.running)
        for epoch in walk.epochs.prefix(3) {
            h.deliver(epoch)
        }
        wait(for: [received], timeout: 10)
        XCTAssertEqual(got.value, walk.epochs.prefix(3).map(\.timestampNs))
        // Leaving the loop ends the stream: sensors, ranging and the timer stop.
        XCTAssertTrue(waitUntil { h.manager.state == .stopped })
        h.settle()
        XCTAssertFalse(h.motion.running)
        XCTAssertEqual(h.motion.stops, 1)
        XCTAssertNil(h.ranger.ranging)
        XCTAssertNil(h.scheduler.armed)
        task.cancel()

        // Started explicitly, the manager outlives a stream; stop() ends the others.
        h.manager.start()
        let first = h.manager.locations()
        let left = expectation(description: "the cancelled stream ends")
        let cancelled = Task {
            for await _ in first {}
            left.fulfill()
        }
        cancelled.cancel()
        wait(for: [left], timeout: 10)
        Thread.sleep(forTimeInterval: 0.05)
        h.settle()
        XCTAssertEqual(h.manager.state, .running)
        XCTAssertTrue(h.motion.running)
        let ended = expectation(description: "stop() ends the stream")
        let second = h.manager.locations()
        Task {
            for await _ in second {}
            ended.fulfill()
        }
        h.manager.stop()
        wait(for: [ended], timeout: 10)
        XCTAssertEqual(h.manager.state, .stopped)
    }

    // The status stream hears every coded status.
    func testTheStatusStream() throws {
        let h = try Harness(siteJson: try siteJson(), authorization: .denied)
        let statuses = h.manager.statuses()
        let heard = expectation(description: "two statuses")
        let got = Box<[Int]>([])
        Task {
            for await status in statuses {
                got.update { $0.append(status.code) }
                if got.value.count == 2 { break }
            }
            heard.fulfill()
        }
        h.manager.start()
        h.ranger.change(to: .authorizedWhenInUse)
        wait(for: [heard], timeout: 10)
        XCTAssertEqual(got.value, [101, 103])
    }

    func testInvalidRequestsAreRefused() throws {
        let engine = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        for request in [
            WaymarkLocationRequest(motionInterval: 0),
            WaymarkLocationRequest(motionInterval: .nan),
            WaymarkLocationRequest(motionBatchSize: 0),
            WaymarkLocationRequest(advanceInterval: -1),
            WaymarkLocationRequest(advanceInterval: .infinity),
        ] {
            XCTAssertThrowsError(try WaymarkLocationManager(
                engine: engine, request: request, motion: FakeMotion(), ranger: FakeRanger(authorization: .denied))) {
                guard case PositioningError.InvalidConfig = $0 else { return XCTFail("expected InvalidConfig, got \($0)") }
            }
        }
    }

    // The real timer: fires once on its queue after its time; a cancelled one never does.
    func testDispatchTimerScheduler() throws {
        let key = DispatchSpecificKey<Int>()
        let queue = DispatchQueue(label: "test.timer")
        queue.setSpecific(key: key, value: 7)
        let scheduler = DispatchTimerScheduler()
        let fired = expectation(description: "fired")
        let start = Date()
        let onQueue = Box<Int?>(nil)
        let timer = scheduler.schedule(after: 0.05, on: queue) {
            onQueue.update { $0 = DispatchQueue.getSpecific(key: key) }
            fired.fulfill()
        }
        let cancelled = scheduler.schedule(after: 0.05, on: queue) { XCTFail("a cancelled timer fired") }
        cancelled.cancel()
        wait(for: [fired], timeout: 5)
        XCTAssertGreaterThanOrEqual(Date().timeIntervalSince(start), 0.05)
        XCTAssertEqual(onQueue.value, 7)
        Thread.sleep(forTimeInterval: 0.1)  // the cancelled timer's time passes
        timer.cancel()
    }

    func testStatusCodesAndDescriptions() {
        let all: [WaymarkLocationStatus] = [
            .authorizationNotDetermined, .authorizationDenied, .authorizationRestricted, .authorizedWhenInUse,
            .authorizedAlways, .rangingUnavailable, .rangingFailed(uuid: beaconUUID, code: 17, message: "m"),
            .motionUnavailable(.accelerometer), .motionUnavailable(.gyroscope), .motionUnavailable(.magnetometer),
            .engineError(code: .internal, message: "m"), .scanRejected(reason: "r", total: 3),
        ]
        XCTAssertEqual(all.map(\.code), [100, 101, 102, 103, 104, 200, 201, 300, 301, 302, 400, 401])
        for status in all { XCTAssertTrue(status.description.hasPrefix("\(status.code) "), status.description) }
        XCTAssertEqual(WaymarkLocationStatus.scanRejected(reason: "no known transmitter", total: 3).description,
                       "401 scan rejected (3 so far): no known transmitter")
        XCTAssertEqual(WaymarkLocationStatus(.denied), .authorizationDenied)
    }

    func testUptimeToDate() {
        let now = Date(timeIntervalSince1970: 1_700_000_000)
        let at = AppleSensorConversion.date(ofUptimeNs: 98_500_000_000, uptimeNow: 100, now: now)
        XCTAssertEqual(at.timeIntervalSince(now), -1.5, accuracy: 1e-9)
    }

    /// Polls `condition` for up to 5 s; whether it held.
    func waitUntil(_ condition: () -> Bool) -> Bool {
        let deadline = Date().addingTimeInterval(5)
        while Date() < deadline {
            if condition() { return true }
            Thread.sleep(forTimeInterval: 0.005)
        }
        return condition()
    }
}

/// A value shared with a task.
final class Box<T>: @unchecked Sendable {
    private let lock = NSLock()
    private var _value: T

    init(_ value: T) { _value = value }

    var value: T { lock.lock(); defer { lock.unlock() }; return _value }

    func update(_ change: (inout T) -> Void) { lock.lock(); change(&_value); lock.unlock() }
}
