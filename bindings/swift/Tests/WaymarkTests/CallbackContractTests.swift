// The callback contract of docs/errors.md#callbacks from Swift: a `LogSink` that calls the engine
// on the thread that logged (it deadlocked when records were delivered under the engine's lock),
// and a listener that drops the last reference to its engine.

import Foundation
import XCTest

@testable import Waymark

/// Calls its engine from every record it receives.
final class CallingSink: LogSink, @unchecked Sendable {
    private let lock = NSLock()
    private var _reads = 0
    weak var engine: PositioningEngine?

    var reads: Int { lock.lock(); defer { lock.unlock() }; return _reads }

    func log(level: LogLevel, target: String, message: String) {
        guard let engine else { return }
        _ = try? engine.position()
        lock.lock(); defer { lock.unlock() }
        _reads += 1
    }
}

/// Holds the only reference to an engine and drops it at the engine's first position.
final class Dropping: PositionListener, @unchecked Sendable {
    var engine: PositioningEngine?
    private(set) var positions = 0

    func onPosition(position: PositionEstimate) {
        positions += 1
        engine = nil
    }
    func onStatus(status: StatusUpdate) {}
    func onError(error: ErrorReport) {}
}

final class CallbackContractTests: XCTestCase {
    func siteJson() throws -> String {
        try String(contentsOf: WaymarkTests.simDir.appendingPathComponent("site.json"), encoding: .utf8)
    }

    func testALogSinkMayCallTheEngine() throws {
        let engine = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        let sink = CallingSink()
        sink.engine = engine
        initLogging(sink: sink, level: .debug)
        defer { initLogging(sink: nil, level: .error) }
        // A rejected scan logs "scan rejected" at DEBUG inside the engine's lock.
        let unknown = [WifiReading(bssid: "0a:0b:0c:0d:0e:0f", rssiDbm: -60, ageMs: 0)]
        XCTAssertThrowsError(try engine.pushScan(scan: RadioScan(timestampNs: 1_000_000_000, wifi: unknown, beacons: [])))
        XCTAssertGreaterThan(sink.reads, 0)
    }

    func testAListenerMayDropTheLastReferenceToItsEngine() throws {
        let dropping = Dropping()
        var subscription: Subscription?
        do {
            let engine = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
            dropping.engine = engine
            subscription = engine.subscribe(listener: dropping)
        }
        let wifi = [WifiReading(bssid: "02:00:00:00:00:00", rssiDbm: -60, ageMs: 0)]
        // The call holds the engine until it returns, though the listener let it go.
        let position = try dropping.engine!.pushScan(scan: RadioScan(timestampNs: 10, wifi: wifi, beacons: []))
        XCTAssertEqual(position.timestampNs, 10)
        XCTAssertEqual(dropping.positions, 1)
        XCTAssertNil(dropping.engine)
        subscription?.cancel()
    }
}
