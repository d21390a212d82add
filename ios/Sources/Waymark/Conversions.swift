// Conversions from Apple's sensor APIs to Waymark's inputs.
//
// Plain Swift on purpose: no CoreMotion, CoreLocation or CoreBluetooth import, so this file
// compiles on Linux and bindings/swift/test.sh covers it. The app's adapter stays a thin
// shell: it reads the framework objects (CMAccelerometerData, CLBeacon, ...) and passes their
// numbers here; every unit, sign and clock conversion lives in this file.
//
// Waymark's conventions (src/ffi/uniffi.rs, `MotionSample`): phone frame (x right, y to the
// top of the screen, z out of the screen, as both iOS and Android define it); acceleration in
// m/s² *including* gravity and pointing up at rest (Android's convention: +9.81 on z lying
// face up); rotation rate in rad/s, counter-clockwise positive; magnetic field in µT; every
// timestamp in nanoseconds on one monotonic clock.

import Foundation

/// Unit, sign and clock conversions from CoreMotion and CoreLocation to Waymark's inputs.
public enum AppleSensorConversion {
    /// Standard gravity, m/s² per g. CoreMotion reports acceleration in g.
    public static let standardGravity = 9.80665

    /// Seconds (`CMLogItem.timestamp`, `ProcessInfo.systemUptime`: the uptime clock) to
    /// nanoseconds, rounded. `nil` for a negative, NaN or out-of-range time.
    public static func nanoseconds(fromSeconds seconds: Double) -> UInt64? {
        guard seconds.isFinite, seconds >= 0 else { return nil }
        let ns = (seconds * 1e9).rounded()
        guard ns < 18_446_744_073_709_551_615.0 else { return nil }
        return UInt64(ns)
    }

    /// `CMAccelerometerData` (`timestamp` s, `acceleration` in g) to a Waymark sample in m/s².
    ///
    /// iOS reports −1 g on z for a phone lying face up; Waymark, like Android, expects +9.81
    /// m/s² (the reaction to gravity, pointing up). Hence the sign flip. For `CMDeviceMotion`
    /// pass `gravity + userAcceleration` per axis: that sum is what the accelerometer read.
    public static func accelerometer(timestamp: Double, x: Double, y: Double, z: Double) -> MotionSample? {
        guard let ns = nanoseconds(fromSeconds: timestamp) else { return nil }
        let k = -standardGravity
        return MotionSample(timestampNs: ns, x: x * k, y: y * k, z: z * k)
    }

    /// `CMGyroData.rotationRate` / `CMDeviceMotion.rotationRate` (rad/s, right-handed, as
    /// Android): only the timestamp changes.
    public static func gyroscope(timestamp: Double, x: Double, y: Double, z: Double) -> MotionSample? {
        guard let ns = nanoseconds(fromSeconds: timestamp) else { return nil }
        return MotionSample(timestampNs: ns, x: x, y: y, z: z)
    }

    /// `CMMagnetometerData.magneticField` (raw, µT) or `CMDeviceMotion.magneticField.field`
    /// (calibrated, µT; prefer it when its accuracy is not `.uncalibrated`): only the timestamp
    /// changes.
    public static func magnetometer(timestamp: Double, x: Double, y: Double, z: Double) -> MotionSample? {
        guard let ns = nanoseconds(fromSeconds: timestamp) else { return nil }
        return MotionSample(timestampNs: ns, x: x, y: y, z: z)
    }

    /// `CMAltitudeData` (`timestamp` s on the uptime clock, `pressure` in kPa) to a Waymark
    /// barometer reading in hPa. `nil` for a bad timestamp; a pressure that is no pressure
    /// goes to the engine, which drops and counts it (`InputStats.pressureDropped`).
    public static func pressure(timestamp: Double, kilopascals: Double) -> PressureReading? {
        guard let ns = nanoseconds(fromSeconds: timestamp) else { return nil }
        return PressureReading(timestampNs: ns, hpa: kilopascals * 10)
    }

    /// Milliseconds between a reading's wall-clock time (`CLBeacon.timestamp`) and the scan
    /// (`now`); 0 if the reading is fresh or from the future, `nil`-safe.
    public static func ageMs(measuredAt: Date?, now: Date) -> UInt64 {
        guard let measuredAt else { return 0 }
        let ms = (now.timeIntervalSince(measuredAt) * 1000).rounded()
        guard ms.isFinite, ms > 0 else { return 0 }
        return ms < 18_446_744_073_709_551_615.0 ? UInt64(ms) : UInt64.max
    }

    /// A ranged `CLBeacon` (`uuid`, `major.intValue`, `minor.intValue`, `rssi`, `timestamp`)
    /// to a `BeaconReading`. `nil` when CoreLocation could not measure the signal (`rssi` 0)
    /// or major/minor are outside 0...65535.
    public static func beacon(
        uuid: UUID, major: Int, minor: Int, rssi: Int, measuredAt: Date? = nil, now: Date = Date()
    ) -> BeaconReading? {
        guard rssi < 0, let major = UInt16(exactly: major), let minor = UInt16(exactly: minor) else {
            return nil
        }
        return BeaconReading(
            uuid: uuid.uuidString, major: major, minor: minor, rssiDbm: Double(rssi),
            ageMs: ageMs(measuredAt: measuredAt, now: now))
    }

    /// The wall-clock time of `timestampNs` (a position's time, on the uptime clock), given
    /// the uptime and the wall clock read together now: `Date` for `CLLocation.timestamp`.
    public static func date(ofUptimeNs timestampNs: UInt64, uptimeNow: Double, now: Date) -> Date {
        now.addingTimeInterval(Double(timestampNs) / 1e9 - uptimeNow)
    }

    /// One positioning epoch from what `locationManager(_:didRange:satisfying:)` delivered.
    /// `uptime` is `ProcessInfo.processInfo.systemUptime` at delivery: the same clock as
    /// CoreMotion's timestamps, so scans and motion samples order correctly. Unmeasured
    /// beacons are dropped; `nil` if the time is invalid.
    public static func scan(
        uptime: Double, beacons: [BeaconReading], wifi: [WifiReading] = []
    ) -> RadioScan? {
        guard let ns = nanoseconds(fromSeconds: uptime) else { return nil }
        return RadioScan(timestampNs: ns, wifi: wifi, beacons: beacons)
    }
}

/// What a `CLLocation` takes from a position: latitude/longitude (WGS84, computed in Rust from
/// the site file's anchor), `horizontalAccuracy` the 68% radius (as iOS defines it), course
/// and course accuracy (-1 when the heading is unknown, as Core Location marks invalid values),
/// and the floor's logical level when the site file gives one. Plain Swift, so the Linux test
/// covers it; `toCLLocation` wraps it.
public struct AppleLocationFields: Sendable, Equatable {
    /// Degrees north.
    public let latitudeDeg: Double
    /// Degrees east.
    public let longitudeDeg: Double
    /// The 68% radius, m.
    public let horizontalAccuracyM: Double
    /// Degrees clockwise from true north; -1 when unknown.
    public let courseDeg: Double
    /// One standard deviation of the course, degrees; -1 when unknown.
    public let courseAccuracyDeg: Double
    /// The floor's logical level (`CLFloor.level`); nil when the site file gives none.
    public let floorLevel: Int?
}

public extension PositionEstimate {
    /// The `CLLocation` fields of this position; nil when the site is not geo-referenced.
    var locationFields: AppleLocationFields? {
        guard let lat = latitudeDeg, let lon = longitudeDeg else { return nil }
        let course = bearingDeg
        return AppleLocationFields(
            latitudeDeg: lat, longitudeDeg: lon, horizontalAccuracyM: accuracyM,
            courseDeg: course ?? -1, courseAccuracyDeg: course.flatMap { _ in headingAccuracyDeg } ?? -1,
            floorLevel: floorLevel.map(Int.init))
    }
}
