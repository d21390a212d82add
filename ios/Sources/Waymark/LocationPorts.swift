// The platform ports of `WaymarkLocationManager`: what it needs from CoreMotion, CoreLocation,
// the clock and a timer, as protocols. AppleAdapter.swift implements the first two with the
// Apple frameworks; the clock and the timer are plain Foundation and Dispatch, here. Tests on
// Linux implement every port with fakes, so the manager's logic is covered without a phone.

import Foundation

/// An inertial sensor the manager reads.
public enum WaymarkMotionSensor: String, CaseIterable, Sendable {
    /// `CMAccelerometerData`: steps and the phone's attitude.
    case accelerometer
    /// `CMGyroData`: turns.
    case gyroscope
    /// `CMMagnetometerData`: the heading.
    case magnetometer
}

/// One CoreMotion reading, in CoreMotion's units: `timestamp` is `CMLogItem.timestamp`
/// (seconds on the uptime clock); x, y, z are in g (accelerometer), rad/s (gyroscope) or µT
/// (magnetometer). The manager converts it with `AppleSensorConversion`.
public struct WaymarkMotionReading: Sendable, Equatable {
    /// Which sensor read it.
    public var sensor: WaymarkMotionSensor
    /// Seconds since boot, as `CMLogItem.timestamp` and `ProcessInfo.systemUptime`.
    public var timestamp: TimeInterval
    /// The x axis (to the right of the screen).
    public var x: Double
    /// The y axis (to the top of the screen).
    public var y: Double
    /// The z axis (out of the screen).
    public var z: Double

    /// A reading of `sensor` at `timestamp`.
    public init(sensor: WaymarkMotionSensor, timestamp: TimeInterval, x: Double, y: Double, z: Double) {
        self.sensor = sensor
        self.timestamp = timestamp
        self.x = x
        self.y = y
        self.z = z
    }
}

/// The inertial sensors (`CoreMotionSource` on iOS).
public protocol WaymarkMotionSource: AnyObject {
    /// Whether the device has `sensor` (`CMMotionManager.isAccelerometerAvailable`, ...).
    func isAvailable(_ sensor: WaymarkMotionSensor) -> Bool
    /// Starts `sensors`, one reading every `interval` seconds each, and calls `handler` with
    /// every reading on `queue` (a serial queue), in time order per sensor.
    func start(
        _ sensors: [WaymarkMotionSensor], interval: TimeInterval, queue: DispatchQueue,
        handler: @escaping (WaymarkMotionReading) -> Void)
    /// Stops every sensor; no reading is delivered after it returns.
    func stop()
}

/// One barometer reading, in CoreMotion's units: `CMAltitudeData.timestamp` (seconds on the
/// uptime clock) and `CMAltitudeData.pressure` (kPa). The manager converts it with
/// `AppleSensorConversion.pressure`.
public struct WaymarkPressureReading: Sendable, Equatable {
    /// Seconds since boot, as `CMLogItem.timestamp`.
    public var timestamp: TimeInterval
    /// Air pressure, kPa.
    public var kilopascals: Double

    /// A reading at `timestamp`.
    public init(timestamp: TimeInterval, kilopascals: Double) {
        self.timestamp = timestamp
        self.kilopascals = kilopascals
    }
}

/// The barometer (`CoreMotionAltimeter` on iOS, over `CMAltimeter`). Many devices have one;
/// one without loses only the floor changes it gives (docs/ios.md#the-barometer).
public protocol WaymarkAltimeter: AnyObject {
    /// Whether the device has one and the app may read it
    /// (`CMAltimeter.isRelativeAltitudeAvailable()`, authorization not denied or restricted).
    var isAvailable: Bool { get }
    /// Starts updates (about one a second on iOS) and calls `handler` with each reading on
    /// `queue` (a serial queue), in time order.
    func start(queue: DispatchQueue, handler: @escaping (WaymarkPressureReading) -> Void)
    /// Stops updates; no reading is delivered after it returns.
    func stop()
}

/// The app's location authorization, as `CLAuthorizationStatus` (same raw values).
public enum WaymarkAuthorization: Int32, Sendable {
    /// The user has not been asked yet.
    case notDetermined = 0
    /// Parental controls or a device profile forbid location; the user cannot change it.
    case restricted = 1
    /// The user said no, or turned Location Services off.
    case denied = 2
    /// Allowed at any time.
    case authorizedAlways = 3
    /// Allowed while the app is in use. Ranging stops when the app is suspended.
    case authorizedWhenInUse = 4

    /// Whether beacons may be ranged.
    public var allowsRanging: Bool { self == .authorizedAlways || self == .authorizedWhenInUse }
}

/// One beacon of a ranging result, as `CLBeacon` gives it: `rssi` 0 means Core Location could
/// not measure it this time.
public struct WaymarkRangedBeacon: Sendable, Equatable {
    /// `CLBeacon.uuid`.
    public var uuid: UUID
    /// `CLBeacon.major.intValue`.
    public var major: Int
    /// `CLBeacon.minor.intValue`.
    public var minor: Int
    /// `CLBeacon.rssi`, dBm; 0 when unknown.
    public var rssi: Int
    /// `CLBeacon.timestamp`: when it was last heard.
    public var timestamp: Date?

    /// A ranged beacon.
    public init(uuid: UUID, major: Int, minor: Int, rssi: Int, timestamp: Date? = nil) {
        self.uuid = uuid
        self.major = major
        self.minor = minor
        self.rssi = rssi
        self.timestamp = timestamp
    }
}

/// What beacon ranging reports (`CLLocationManagerDelegate` on iOS).
public enum WaymarkRangingEvent: Sendable {
    /// `locationManager(_:didRange:satisfying:)`: the beacons of one proximity UUID heard in
    /// the last second (often none).
    case ranged([WaymarkRangedBeacon], uuid: UUID)
    /// `locationManager(_:didFailRangingFor:error:)`: the error's `CLError.Code` raw value
    /// (16 ranging unavailable, 17 ranging failure) and description.
    case failed(uuid: UUID, code: Int, message: String)
    /// `locationManagerDidChangeAuthorization(_:)`, with the new authorization.
    case authorizationChanged(WaymarkAuthorization)
    /// `locationManager(_:didDetermineState:for:)` for the beacon region of `uuid` (also sent
    /// on entry and exit): whether the user is inside it.
    case regionStateChanged(uuid: UUID, inside: Bool)
    /// `locationManager(_:monitoringDidFailFor:withError:)`: monitoring the region of `uuid`
    /// failed (`CLError.Code` raw value and description); no wake-up on arrival.
    case regionMonitoringFailed(uuid: UUID, code: Int, message: String)
}

/// Beacon ranging and location authorization (`CoreLocationBeaconRanger` on iOS).
public protocol WaymarkBeaconRanger: AnyObject {
    /// The current authorization (`CLLocationManager.authorizationStatus`).
    var authorization: WaymarkAuthorization { get }
    /// Whether the device can range beacons (`CLLocationManager.isRangingAvailable()`).
    var isRangingAvailable: Bool { get }
    /// Where events go: `handler` is called on `queue`. Set once, before the other calls.
    func setEventHandler(queue: DispatchQueue, handler: @escaping (WaymarkRangingEvent) -> Void)
    /// Shows the system's "allow while using the app" prompt if the user was never asked.
    func requestWhenInUseAuthorization()
    /// Ranges the beacons of each proximity UUID (one `CLBeaconIdentityConstraint` each).
    func startRanging(uuids: [UUID])
    /// Stops ranging every UUID.
    func stopRanging()
}

/// Core Location's background services (`CoreLocationBeaconRanger` on iOS, on the same
/// `CLLocationManager` as ranging): what the manager's background plan sets
/// (Background.swift). Its events (region states, authorization) come through the ranger's
/// event handler.
public protocol WaymarkBackgroundLocation: AnyObject {
    /// What the app's Info.plist and the device allow.
    var capabilities: WaymarkBackgroundCapabilities { get }
    /// Sets `allowsBackgroundLocationUpdates`, `showsBackgroundLocationIndicator` and
    /// `pausesLocationUpdatesAutomatically`, starts or stops standard location updates and
    /// monitors exactly `settings.monitoredRegions` (asking each one's state when it starts).
    func apply(_ settings: WaymarkBackgroundSettings)
    /// Shows the system's "always" prompt (`requestAlwaysAuthorization`).
    func requestAlwaysAuthorization()
}

/// Whether the app is in the foreground (`UIKitAppLifecycle` on iOS).
public protocol WaymarkAppLifecycle: AnyObject {
    /// The app's state now.
    var state: WaymarkAppState { get }
    /// Where changes go: `handler` is called on `queue`. Set once.
    func setHandler(queue: DispatchQueue, handler: @escaping (WaymarkAppState) -> Void)
}

/// The monotonic clock every input is timed on: CoreMotion's, seconds since boot.
public protocol WaymarkClock: AnyObject {
    /// Now, in nanoseconds since boot.
    func nowNs() -> UInt64
}

/// `ProcessInfo.systemUptime`: the clock of `CMLogItem.timestamp`.
public final class UptimeClock: WaymarkClock {
    /// The uptime clock.
    public init() {}

    public func nowNs() -> UInt64 {
        AppleSensorConversion.nanoseconds(fromSeconds: ProcessInfo.processInfo.systemUptime) ?? 0
    }
}

/// A one-shot timer, cancelled by `cancel()`.
public protocol WaymarkTimer: AnyObject {
    /// Stops the timer; its work does not run after it returns (if called on the timer's queue).
    func cancel()
}

/// Makes one-shot timers (`DispatchTimerScheduler`; a fake in tests).
public protocol WaymarkScheduler: AnyObject {
    /// Runs `work` on `queue` once, `seconds` from now.
    func schedule(after seconds: TimeInterval, on queue: DispatchQueue, _ work: @escaping () -> Void) -> WaymarkTimer
}

/// One-shot timers on a `DispatchSourceTimer`.
public final class DispatchTimerScheduler: WaymarkScheduler {
    /// A scheduler with Dispatch's default leeway.
    public init() {}

    public func schedule(after seconds: TimeInterval, on queue: DispatchQueue, _ work: @escaping () -> Void) -> WaymarkTimer {
        let source = DispatchSource.makeTimerSource(queue: queue)
        source.schedule(deadline: .now() + max(0, seconds))
        source.setEventHandler(handler: work)
        source.resume()
        return DispatchTimer(source: source)
    }

    private final class DispatchTimer: WaymarkTimer {
        let source: DispatchSourceTimer

        init(source: DispatchSourceTimer) { self.source = source }

        func cancel() { source.cancel() }

        deinit { source.cancel() }
    }
}
