// The thin iOS shell: CoreMotion and CoreLocation behind the ports of LocationPorts.swift, and
// CLLocation output. WaymarkLocationManager (LocationClient.swift) holds every decision and
// Conversions.swift every unit and clock; this file only passes Apple's callbacks and numbers
// on, and compiles only on Apple platforms (the Linux tests cover the rest against fakes).
#if canImport(CoreMotion) && canImport(CoreLocation)
import CoreLocation
import CoreMotion
import Foundation

/// The inertial sensors through one `CMMotionManager` (Apple: one per app). Readings are
/// delivered on the manager's queue through an `OperationQueue` over it.
public final class CoreMotionSource: WaymarkMotionSource {
    private let manager: CMMotionManager
    private let operations = OperationQueue()

    /// Reads `manager` (the app's own, if it has one).
    public init(manager: CMMotionManager = CMMotionManager()) {
        self.manager = manager
        operations.maxConcurrentOperationCount = 1
    }

    public func isAvailable(_ sensor: WaymarkMotionSensor) -> Bool {
        switch sensor {
        case .accelerometer: return manager.isAccelerometerAvailable
        case .gyroscope: return manager.isGyroAvailable
        case .magnetometer: return manager.isMagnetometerAvailable
        }
    }

    public func start(
        _ sensors: [WaymarkMotionSensor], interval: TimeInterval, queue: DispatchQueue,
        handler: @escaping (WaymarkMotionReading) -> Void
    ) {
        operations.underlyingQueue = queue
        for sensor in sensors {
            switch sensor {
            case .accelerometer:
                manager.accelerometerUpdateInterval = interval
                manager.startAccelerometerUpdates(to: operations) { data, _ in
                    guard let d = data else { return }
                    handler(WaymarkMotionReading(sensor: .accelerometer, timestamp: d.timestamp,
                                                 x: d.acceleration.x, y: d.acceleration.y, z: d.acceleration.z))
                }
            case .gyroscope:
                manager.gyroUpdateInterval = interval
                manager.startGyroUpdates(to: operations) { data, _ in
                    guard let d = data else { return }
                    handler(WaymarkMotionReading(sensor: .gyroscope, timestamp: d.timestamp,
                                                 x: d.rotationRate.x, y: d.rotationRate.y, z: d.rotationRate.z))
                }
            case .magnetometer:
                manager.magnetometerUpdateInterval = interval
                manager.startMagnetometerUpdates(to: operations) { data, _ in
                    guard let d = data else { return }
                    handler(WaymarkMotionReading(sensor: .magnetometer, timestamp: d.timestamp,
                                                 x: d.magneticField.x, y: d.magneticField.y, z: d.magneticField.z))
                }
            }
        }
    }

    public func stop() {
        manager.stopAccelerometerUpdates()
        manager.stopGyroUpdates()
        manager.stopMagnetometerUpdates()
        operations.cancelAllOperations()
    }
}

/// The barometer through a `CMAltimeter`: its relative-altitude updates carry the pressure.
/// Reading it needs the app's motion authorization (`NSMotionUsageDescription`); iOS asks the
/// user on the first start.
public final class CoreMotionAltimeter: WaymarkAltimeter {
    private let altimeter = CMAltimeter()
    private let operations = OperationQueue()

    /// An altimeter of its own.
    public init() {
        operations.maxConcurrentOperationCount = 1
    }

    public var isAvailable: Bool {
        let status = CMAltimeter.authorizationStatus()
        return CMAltimeter.isRelativeAltitudeAvailable() && status != .denied && status != .restricted
    }

    public func start(queue: DispatchQueue, handler: @escaping (WaymarkPressureReading) -> Void) {
        operations.underlyingQueue = queue
        altimeter.startRelativeAltitudeUpdates(to: operations) { data, _ in
            guard let d = data else { return }
            handler(WaymarkPressureReading(timestamp: d.timestamp, kilopascals: d.pressure.doubleValue))
        }
    }

    public func stop() {
        altimeter.stopRelativeAltitudeUpdates()
        operations.cancelAllOperations()
    }
}

/// Beacon ranging and location authorization through a `CLLocationManager`. Make it on the
/// main thread: Core Location calls its delegate on the run loop of the thread that made it,
/// and every call here goes to the main queue.
public final class CoreLocationBeaconRanger: NSObject, WaymarkBeaconRanger, CLLocationManagerDelegate, @unchecked Sendable {
    private let manager: CLLocationManager
    private let lock = NSLock()
    private var current: WaymarkAuthorization
    private var target: (queue: DispatchQueue, handler: (WaymarkRangingEvent) -> Void)?
    private var constraints: [CLBeaconIdentityConstraint] = []

    /// A ranger with its own `CLLocationManager`.
    override public init() {
        let manager = CLLocationManager()
        self.manager = manager
        current = CoreLocationBeaconRanger.authorization(manager.authorizationStatus)
        super.init()
        manager.delegate = self
    }

    public var authorization: WaymarkAuthorization { lock.lock(); defer { lock.unlock() }; return current }

    public var isRangingAvailable: Bool { CLLocationManager.isRangingAvailable() }

    public func setEventHandler(queue: DispatchQueue, handler: @escaping (WaymarkRangingEvent) -> Void) {
        lock.lock(); defer { lock.unlock() }
        target = (queue, handler)
    }

    public func requestWhenInUseAuthorization() {
        DispatchQueue.main.async { self.manager.requestWhenInUseAuthorization() }
    }

    public func startRanging(uuids: [UUID]) {
        DispatchQueue.main.async {
            self.constraints = uuids.map { CLBeaconIdentityConstraint(uuid: $0) }
            self.constraints.forEach { self.manager.startRangingBeacons(satisfying: $0) }
        }
    }

    public func stopRanging() {
        DispatchQueue.main.async {
            self.constraints.forEach { self.manager.stopRangingBeacons(satisfying: $0) }
            self.constraints = []
        }
    }

    public func locationManager(_ manager: CLLocationManager, didRange beacons: [CLBeacon],
                                satisfying constraint: CLBeaconIdentityConstraint) {
        let ranged = beacons.map {
            WaymarkRangedBeacon(uuid: $0.uuid, major: $0.major.intValue, minor: $0.minor.intValue,
                                rssi: $0.rssi, timestamp: $0.timestamp)
        }
        send(.ranged(ranged, uuid: constraint.uuid))
    }

    public func locationManager(_ manager: CLLocationManager, didFailRangingFor constraint: CLBeaconIdentityConstraint,
                                error: Error) {
        let failure = error as NSError
        send(.failed(uuid: constraint.uuid, code: failure.code, message: failure.localizedDescription))
    }

    public func locationManagerDidChangeAuthorization(_ manager: CLLocationManager) {
        let new = CoreLocationBeaconRanger.authorization(manager.authorizationStatus)
        lock.lock()
        current = new
        lock.unlock()
        send(.authorizationChanged(new))
    }

    private func send(_ event: WaymarkRangingEvent) {
        lock.lock()
        let target = self.target
        lock.unlock()
        guard let target else { return }
        target.queue.async { target.handler(event) }
    }

    private static func authorization(_ status: CLAuthorizationStatus) -> WaymarkAuthorization {
        WaymarkAuthorization(rawValue: status.rawValue) ?? .notDetermined
    }
}

public extension WaymarkLocationManager {
    /// A manager reading CoreMotion (the barometer too, where the device has one) and ranging
    /// with CoreLocation, on the uptime clock, with a `DispatchSourceTimer` for `advance`.
    /// Make it on the main thread.
    convenience init(
        engine: PositioningEngine, request: WaymarkLocationRequest = WaymarkLocationRequest(),
        delegateQueue: DispatchQueue = .main
    ) throws {
        try self.init(engine: engine, request: request, motion: CoreMotionSource(),
                      ranger: CoreLocationBeaconRanger(), altimeter: CoreMotionAltimeter(),
                      delegateQueue: delegateQueue)
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
    /// `locationFields`, which the Linux test covers. `timestamp` is when the position was
    /// (its `timestampNs` on the uptime clock, as a `Date`).
    func toCLLocation() -> CLLocation? {
        guard let fields = locationFields else { return nil }
        let at = AppleSensorConversion.date(
            ofUptimeNs: timestampNs, uptimeNow: ProcessInfo.processInfo.systemUptime, now: Date())
        return WaymarkLocation(fields: fields, timestamp: at)
    }
}
#endif
