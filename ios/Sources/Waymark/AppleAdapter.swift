// The thin iOS shell: CoreMotion device motion and magnetometer, CoreLocation beacon ranging,
// and CLLocation output. Every conversion is in Conversions.swift (plain Swift, tested on
// Linux); this file only wires Apple's callbacks to them and compiles only on Apple platforms.
#if canImport(CoreMotion) && canImport(CoreLocation)
import CoreLocation
import CoreMotion
import Foundation

/// Feeds an engine from CoreMotion at ~100 Hz, batching samples per FFI call.
public final class MotionAdapter: @unchecked Sendable {
    private let engine: PositioningEngine
    private let manager = CMMotionManager()
    private let queue = OperationQueue()
    private let batchSize: Int
    private var accel: [MotionSample] = []
    private var gyro: [MotionSample] = []
    private var mag: [MotionSample] = []

    public init(engine: PositioningEngine, batchSize: Int = 50) {
        self.engine = engine
        self.batchSize = batchSize
        queue.maxConcurrentOperationCount = 1
    }

    /// Starts the raw accelerometer (in g, converted to m/s²), gyroscope and magnetometer.
    public func start() {
        manager.accelerometerUpdateInterval = 0.01
        manager.gyroUpdateInterval = 0.01
        manager.magnetometerUpdateInterval = 0.01
        manager.startAccelerometerUpdates(to: queue) { [weak self] data, _ in
            guard let self, let d = data,
                  let s = AppleSensorConversion.accelerometer(timestamp: d.timestamp, x: d.acceleration.x,
                                                             y: d.acceleration.y, z: d.acceleration.z) else { return }
            self.accel.append(s)
            if self.accel.count >= self.batchSize { _ = try? self.engine.pushAccelerometer(batch: self.accel); self.accel.removeAll() }
        }
        manager.startGyroUpdates(to: queue) { [weak self] data, _ in
            guard let self, let d = data,
                  let s = AppleSensorConversion.gyroscope(timestamp: d.timestamp, x: d.rotationRate.x,
                                                         y: d.rotationRate.y, z: d.rotationRate.z) else { return }
            self.gyro.append(s)
            if self.gyro.count >= self.batchSize { _ = try? self.engine.pushGyroscope(batch: self.gyro); self.gyro.removeAll() }
        }
        manager.startMagnetometerUpdates(to: queue) { [weak self] data, _ in
            guard let self, let d = data,
                  let s = AppleSensorConversion.magnetometer(timestamp: d.timestamp, x: d.magneticField.x,
                                                            y: d.magneticField.y, z: d.magneticField.z) else { return }
            self.mag.append(s)
            if self.mag.count >= self.batchSize { _ = try? self.engine.pushMagnetometer(batch: self.mag); self.mag.removeAll() }
        }
    }

    /// Stops the sensors.
    public func stop() {
        manager.stopAccelerometerUpdates()
        manager.stopGyroUpdates()
        manager.stopMagnetometerUpdates()
    }
}

/// Ranges iBeacons with CoreLocation and pushes one scan per ranging callback.
public final class BeaconAdapter: NSObject, CLLocationManagerDelegate, @unchecked Sendable {
    private let engine: PositioningEngine
    private let manager = CLLocationManager()
    private let constraints: [CLBeaconIdentityConstraint]

    /// Ranges the beacons of the given proximity UUIDs (the site's beacons).
    public init(engine: PositioningEngine, uuids: [UUID]) {
        self.engine = engine
        self.constraints = uuids.map { CLBeaconIdentityConstraint(uuid: $0) }
        super.init()
        manager.delegate = self
    }

    /// Asks for permission and starts ranging.
    public func start() {
        manager.requestWhenInUseAuthorization()
        constraints.forEach { manager.startRangingBeacons(satisfying: $0) }
    }

    /// Stops ranging.
    public func stop() {
        constraints.forEach { manager.stopRangingBeacons(satisfying: $0) }
    }

    public func locationManager(_ manager: CLLocationManager, didRange beacons: [CLBeacon],
                                satisfying constraint: CLBeaconIdentityConstraint) {
        let readings = beacons.compactMap {
            AppleSensorConversion.beacon(uuid: $0.uuid, major: $0.major.intValue, minor: $0.minor.intValue,
                                         rssi: $0.rssi, measuredAt: $0.timestamp)
        }
        guard !readings.isEmpty,
              let scan = AppleSensorConversion.scan(uptime: ProcessInfo.processInfo.systemUptime, beacons: readings)
        else { return }
        _ = try? engine.pushScan(scan: scan)
    }
}

/// A `CLFloor` with the level Waymark gives (Core Location offers no initialiser for one).
final class WaymarkFloor: CLFloor {
    private let logicalLevel: Int

    init(level: Int) {
        logicalLevel = level
        super.init()
    }

    required init?(coder: NSCoder) {
        logicalLevel = coder.decodeInteger(forKey: "waymarkLevel")
        super.init(coder: coder)
    }

    override func encode(with coder: NSCoder) {
        super.encode(with: coder)
        coder.encode(logicalLevel, forKey: "waymarkLevel")
    }

    override class var supportsSecureCoding: Bool { true }

    override var level: Int { logicalLevel }
}

/// A `CLLocation` that carries the floor (`CLLocation.floor` has no setter).
final class WaymarkLocation: CLLocation {
    private let waymarkFloor: CLFloor?

    init(fields f: AppleLocationFields, timestamp: Date) {
        waymarkFloor = f.floorLevel.map { WaymarkFloor(level: $0) }
        super.init(
            coordinate: CLLocationCoordinate2D(latitude: f.latitudeDeg, longitude: f.longitudeDeg),
            altitude: 0, horizontalAccuracy: f.horizontalAccuracyM, verticalAccuracy: -1,
            course: f.courseDeg, courseAccuracy: f.courseAccuracyDeg, speed: -1, speedAccuracy: -1,
            timestamp: timestamp)
    }

    required init?(coder: NSCoder) {
        waymarkFloor = coder.decodeObject(of: CLFloor.self, forKey: "waymarkFloor")
        super.init(coder: coder)
    }

    override func encode(with coder: NSCoder) {
        super.encode(with: coder)
        coder.encode(waymarkFloor, forKey: "waymarkFloor")
    }

    override class var supportsSecureCoding: Bool { true }

    override var floor: CLFloor? { waymarkFloor }
}

public extension PositionEstimate {
    /// The position as a CLLocation, or nil when the site file is not geo-referenced (has no
    /// anchor): coordinates from the position itself, `horizontalAccuracy` the 68% radius (as
    /// iOS defines it), course and course accuracy when the heading is known, and `floor`
    /// with the floor's logical level when the site file gives one. Every value comes from
    /// `locationFields`, which the Linux test covers.
    func toCLLocation() -> CLLocation? {
        guard let fields = locationFields else { return nil }
        return WaymarkLocation(fields: fields, timestamp: Date())
    }
}
#endif
