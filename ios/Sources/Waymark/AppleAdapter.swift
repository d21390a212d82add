// The thin iOS shell: CoreMotion, CoreLocation and UIKit behind the ports of
// LocationPorts.swift, and CLLocation output. WaymarkLocationManager (LocationClient.swift)
// holds every decision, Background.swift the background plan and Conversions.swift every unit
// and clock; this file only passes Apple's callbacks and numbers on, and compiles only for iOS
// (the Linux tests cover the rest against fakes; docs/ios.md#what-is-checked-where).
#if os(iOS)
import CoreLocation
import CoreMotion
import Foundation
import UIKit

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

/// Beacon ranging, location authorization and the background services (background updates,
/// beacon region monitoring) through one `CLLocationManager`. Make it on the main thread:
/// Core Location calls its delegate on the run loop of the thread that made it, and every call
/// here goes to the main queue.
public final class CoreLocationBeaconRanger: NSObject, WaymarkBeaconRanger, WaymarkBackgroundLocation,
    CLLocationManagerDelegate, @unchecked Sendable
{
    /// The prefix of the identifiers of the beacon regions Waymark monitors; other regions of
    /// the app are left alone.
    static let regionPrefix = "dev.waymark.site."

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

    // MARK: WaymarkBackgroundLocation

    public var capabilities: WaymarkBackgroundCapabilities {
        WaymarkBackgroundCapabilities(
            infoDictionary: Bundle.main.infoDictionary,
            canMonitorBeaconRegions: CLLocationManager.isMonitoringAvailable(for: CLBeaconRegion.self))
    }

    public func apply(_ settings: WaymarkBackgroundSettings) {
        let declared = capabilities.declaresLocationBackgroundMode
        DispatchQueue.main.async {
            let m = self.manager
            // Without `location` in UIBackgroundModes this setter raises an exception; the plan
            // never asks for it then, and the check here keeps it so.
            m.allowsBackgroundLocationUpdates = settings.allowsBackgroundLocationUpdates && declared
            m.showsBackgroundLocationIndicator = settings.showsBackgroundLocationIndicator
            m.pausesLocationUpdatesAutomatically = settings.pausesLocationUpdatesAutomatically
            if settings.updatesLocation {
                // The updates keep the app running; the coarsest accuracy spares the GPS.
                m.activityType = .otherNavigation
                m.desiredAccuracy = kCLLocationAccuracyThreeKilometers
                m.distanceFilter = kCLDistanceFilterNone
                m.startUpdatingLocation()
            } else {
                m.stopUpdatingLocation()
            }
            let wanted = Set(settings.monitoredRegions.map { Self.regionPrefix + $0.uuidString })
            for region in m.monitoredRegions where region.identifier.hasPrefix(Self.regionPrefix) {
                if !wanted.contains(region.identifier) { m.stopMonitoring(for: region) }
            }
            let monitored = Set(m.monitoredRegions.map(\.identifier))
            for uuid in settings.monitoredRegions where !monitored.contains(Self.regionPrefix + uuid.uuidString) {
                let region = CLBeaconRegion(uuid: uuid, identifier: Self.regionPrefix + uuid.uuidString)
                region.notifyOnEntry = true
                region.notifyOnExit = true
                region.notifyEntryStateOnDisplay = true
                m.startMonitoring(for: region)
            }
        }
    }

    public func requestAlwaysAuthorization() {
        DispatchQueue.main.async { self.manager.requestAlwaysAuthorization() }
    }

    // MARK: CLLocationManagerDelegate

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

    public func locationManager(_ manager: CLLocationManager, didStartMonitoringFor region: CLRegion) {
        manager.requestState(for: region)
    }

    /// Called when monitoring starts (`requestState`), on every entry and exit, and when the
    /// screen lights up inside a region (`notifyEntryStateOnDisplay`).
    public func locationManager(_ manager: CLLocationManager, didDetermineState state: CLRegionState,
                                for region: CLRegion) {
        guard let uuid = Self.siteUUID(region), state != .unknown else { return }
        send(.regionStateChanged(uuid: uuid, inside: state == .inside))
    }

    public func locationManager(_ manager: CLLocationManager, monitoringDidFailFor region: CLRegion?,
                                withError error: Error) {
        guard let region, let uuid = Self.siteUUID(region) else { return }
        let failure = error as NSError
        send(.regionMonitoringFailed(uuid: uuid, code: failure.code, message: failure.localizedDescription))
    }

    /// The standard updates only keep the app running: Waymark's positions come from the engine.
    public func locationManager(_ manager: CLLocationManager, didUpdateLocations locations: [CLLocation]) {}

    public func locationManager(_ manager: CLLocationManager, didFailWithError error: Error) {}

    private static func siteUUID(_ region: CLRegion) -> UUID? {
        guard let beacon = region as? CLBeaconRegion, region.identifier.hasPrefix(regionPrefix) else { return nil }
        return beacon.uuid
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

/// The app's foreground and background, from UIKit's notifications. Make it on the main
/// thread (it reads `UIApplication.shared.applicationState` once).
public final class UIKitAppLifecycle: WaymarkAppLifecycle, @unchecked Sendable {
    private let lock = NSLock()
    private var current: WaymarkAppState
    private var observers: [NSObjectProtocol] = []

    /// Observes `UIApplication.didEnterBackgroundNotification` and
    /// `willEnterForegroundNotification`.
    public init() {
        current = UIApplication.shared.applicationState == .background ? .background : .foreground
    }

    deinit { observers.forEach { NotificationCenter.default.removeObserver($0) } }

    public var state: WaymarkAppState { lock.lock(); defer { lock.unlock() }; return current }

    public func setHandler(queue: DispatchQueue, handler: @escaping (WaymarkAppState) -> Void) {
        let center = NotificationCenter.default
        for (name, state) in [(UIApplication.didEnterBackgroundNotification, WaymarkAppState.background),
                              (UIApplication.willEnterForegroundNotification, .foreground)] {
            observers.append(center.addObserver(forName: name, object: nil, queue: nil) { [weak self] _ in
                guard let self else { return }
                self.lock.lock()
                self.current = state
                self.lock.unlock()
                queue.async { handler(state) }
            })
        }
    }
}

public extension WaymarkLocationManager {
    /// A manager reading CoreMotion (the barometer too, where the device has one), ranging and
    /// running in the background (as `request.background` says) with Core Location, following
    /// the app's state through UIKit, on the uptime clock, with a `DispatchSourceTimer` for
    /// `advance`. `engine` nil: a manager that only records surveys. Make it on the main thread.
    convenience init(
        engine: PositioningEngine?, request: WaymarkLocationRequest = WaymarkLocationRequest(),
        delegateQueue: DispatchQueue = .main
    ) throws {
        let location = CoreLocationBeaconRanger()
        try self.init(engine: engine, request: request, motion: CoreMotionSource(), ranger: location,
                      altimeter: CoreMotionAltimeter(), backgroundLocation: location, lifecycle: UIKitAppLifecycle(),
                      delegateQueue: delegateQueue)
    }
}

/// A position as Core Location gives one: the `CLLocation` for MapKit and other location
/// APIs, and the floor beside it. `CLLocation.floor` has no setter and `CLFloor` no public
/// initialiser, so the floor travels next to the location rather than inside it (as indoor
/// SDKs do); `clLocation.floor` is nil.
public struct WaymarkLocation {
    /// Latitude and longitude, `horizontalAccuracy` the 68% radius, `course` and
    /// `courseAccuracy` (-1 when the heading is unknown), `timestamp` the position's time.
    public let clLocation: CLLocation
    /// The floor's logical level (0 ground, -1 first basement), as `CLFloor.level`; nil when
    /// the site file gives none.
    public let floorLevel: Int?
    /// The floor's name in the site file ("F1").
    public let floorName: String
    /// The position it was made from.
    public let position: PositionEstimate
}

public extension PositionEstimate {
    /// The position as a `WaymarkLocation`, or nil when the site file is not geo-referenced
    /// (has no anchor). Every value comes from `locationFields`, which the Linux tests cover;
    /// the timestamp is the position's `timestampNs` on the uptime clock, as a `Date`.
    func toWaymarkLocation() -> WaymarkLocation? {
        guard let f = locationFields else { return nil }
        let at = AppleSensorConversion.date(
            ofUptimeNs: timestampNs, uptimeNow: ProcessInfo.processInfo.systemUptime, now: Date())
        let location = CLLocation(
            coordinate: CLLocationCoordinate2D(latitude: f.latitudeDeg, longitude: f.longitudeDeg),
            altitude: 0, horizontalAccuracy: f.horizontalAccuracyM, verticalAccuracy: -1,
            course: f.courseDeg, courseAccuracy: f.courseAccuracyDeg, speed: -1, speedAccuracy: -1, timestamp: at)
        return WaymarkLocation(clLocation: location, floorLevel: f.floorLevel, floorName: floorName, position: self)
    }

    /// `toWaymarkLocation()?.clLocation`: the position for APIs that take a `CLLocation`.
    func toCLLocation() -> CLLocation? { toWaymarkLocation()?.clLocation }
}
#endif
