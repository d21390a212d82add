// WaymarkLocationManager: the iOS location client. It reads the inertial sensors and ranges
// beacons through its ports (LocationPorts.swift), feeds the engine, keeps positions coming
// between ranging results with `advance`, and reports authorization, availability and engine
// failures as coded statuses. Plain Foundation and Dispatch, so the Linux tests cover all of
// it; AppleAdapter.swift only adapts CoreMotion and CoreLocation to the ports.
// Guide: docs/ios.md.

import Foundation

/// What the manager reads and how often.
public struct WaymarkLocationRequest: Sendable, Equatable {
    /// The proximity UUIDs of the site's beacons; empty: no ranging, motion only, and no
    /// location authorization needed.
    public var beaconUUIDs: [UUID]
    /// Seconds between two readings of each inertial sensor: 0.01 (100 Hz), CoreMotion's
    /// fastest rate (the step detector is tuned from 20 to 200 Hz, docs/tuning.md#step-detector).
    public var motionInterval: TimeInterval
    /// Readings per sensor sent in one engine call: 50 (half a second at 100 Hz). Pending
    /// readings are also sent before every epoch.
    public var motionBatchSize: Int
    /// Seconds without an epoch after which the manager calls `advance`: 2, one unthrottled
    /// scan interval, as the evaluation's replay timer (docs/tuning.md#replay-timer).
    public var advanceInterval: TimeInterval
    /// Whether `start` shows the "while using the app" prompt when the user was never asked:
    /// true. Set it to false to ask at a moment of the app's choosing.
    public var requestsAuthorization: Bool
    /// Whether the barometer is read, where the device has one, for floor changes: true
    /// (docs/ios.md#the-barometer).
    public var usesBarometer: Bool
    /// What happens when the app goes to the background: `.off`, the inputs pause until it
    /// returns (docs/ios.md#background).
    public var background: WaymarkBackgroundMode
    /// Whether iOS shows its background location indicator while the app positions in the
    /// background with "always" authorization: true. ("While using" apps always show it.)
    public var showsBackgroundLocationIndicator: Bool

    /// A request with the documented defaults.
    public init(
        beaconUUIDs: [UUID] = [], motionInterval: TimeInterval = 0.01, motionBatchSize: Int = 50,
        advanceInterval: TimeInterval = 2, requestsAuthorization: Bool = true, usesBarometer: Bool = true,
        background: WaymarkBackgroundMode = .off, showsBackgroundLocationIndicator: Bool = true
    ) {
        self.usesBarometer = usesBarometer
        self.background = background
        self.showsBackgroundLocationIndicator = showsBackgroundLocationIndicator
        self.beaconUUIDs = beaconUUIDs
        self.motionInterval = motionInterval
        self.motionBatchSize = motionBatchSize
        self.advanceInterval = advanceInterval
        self.requestsAuthorization = requestsAuthorization
    }

    /// Why the request cannot be run, or nil.
    func problem() -> String? {
        if !(motionInterval.isFinite && motionInterval > 0) { return "motionInterval must be > 0 s, got \(motionInterval)" }
        if motionBatchSize < 1 { return "motionBatchSize must be >= 1, got \(motionBatchSize)" }
        if !(advanceInterval.isFinite && advanceInterval > 0) { return "advanceInterval must be > 0 s, got \(advanceInterval)" }
        if background == .wakeOnArrival && beaconUUIDs.isEmpty {
            return "background .wakeOnArrival monitors the site's beacon regions: give beaconUUIDs"
        }
        return nil
    }
}

/// Where the manager is.
public enum WaymarkLocationState: Int, Sendable {
    /// Made, never started.
    case idle
    /// Every input the request asks for is running.
    case running
    /// Running on fewer inputs than the request asks for: ranging is not authorized, not
    /// available or failed, or a motion sensor is missing. Positions continue from what is
    /// left (`advance` epochs from the motion); statuses say why.
    case degraded
    /// Stopped by `stop()` or by the end of the last `locations()` stream.
    case stopped
    /// Started, with its inputs paused: the app is in the background and the request's
    /// `background` mode does not run there (or the user is away from every monitored beacon
    /// region). It resumes by itself.
    case paused
}

/// A coded status: what changed about the manager's inputs and what failed. `code` is stable
/// across releases (docs/ios.md#statuses lists what to do for each).
public enum WaymarkLocationStatus: Sendable, Equatable, CustomStringConvertible {
    /// 100: the user was never asked for location; ranging waits for an answer.
    case authorizationNotDetermined
    /// 101: the user refused location: no ranging, motion-only positions.
    case authorizationDenied
    /// 102: location is forbidden on this device (parental controls, a profile).
    case authorizationRestricted
    /// 103: location allowed while the app is in use.
    case authorizedWhenInUse
    /// 104: location allowed at any time.
    case authorizedAlways
    /// 200: this device cannot range beacons (`CLLocationManager.isRangingAvailable()`).
    case rangingUnavailable
    /// 201: ranging the beacons of `uuid` failed with Core Location's error `code`
    /// (`CLError.Code`) and `message`; ranging stays off until authorization changes or the
    /// manager is started again.
    case rangingFailed(uuid: UUID, code: Int, message: String)
    /// 300, 301, 302: the device has no accelerometer, gyroscope or magnetometer.
    case motionUnavailable(WaymarkMotionSensor)
    /// 400: an engine call failed with something other than a rejected scan, or the engine's
    /// listener reported a failure (`onError`).
    case engineError(code: ErrorCode, message: String)
    /// 401: the engine refused a beacon scan (none of its beacons is in the site file: the
    /// phone is probably outside the site); `total` counts this session's refusals.
    case scanRejected(reason: String, total: UInt64)
    /// 500: the request asks for background positioning, but the app's Info.plist has no
    /// `location` in `UIBackgroundModes`: the inputs pause in the background.
    case backgroundModeMissing
    /// 501: `.wakeOnArrival` with "while using" authorization: positions continue in the
    /// background, but iOS will not wake the app on arrival until the user allows "always".
    case wakeOnArrivalNeedsAlways
    /// 502: in the background with "while using" authorization, and the inputs were not
    /// running when the app left the foreground: iOS allows no new location session there,
    /// so they wait for the foreground.
    case backgroundNeedsForegroundStart
    /// 503: this device cannot monitor beacon regions, or monitoring one failed: no wake-up
    /// on arrival.
    case regionMonitoringUnavailable
    /// 600: the survey recorder failed to write (`SurveyError.Io`); the survey takes no input
    /// until `resumeSurvey()` succeeds.
    case surveyFailed(reason: String)

    /// The stable code.
    public var code: Int {
        switch self {
        case .authorizationNotDetermined: return 100
        case .authorizationDenied: return 101
        case .authorizationRestricted: return 102
        case .authorizedWhenInUse: return 103
        case .authorizedAlways: return 104
        case .rangingUnavailable: return 200
        case .rangingFailed: return 201
        case .motionUnavailable(.accelerometer): return 300
        case .motionUnavailable(.gyroscope): return 301
        case .motionUnavailable(.magnetometer): return 302
        case .engineError: return 400
        case .scanRejected: return 401
        case .backgroundModeMissing: return 500
        case .wakeOnArrivalNeedsAlways: return 501
        case .backgroundNeedsForegroundStart: return 502
        case .regionMonitoringUnavailable: return 503
        case .surveyFailed: return 600
        }
    }

    /// The status of an authorization.
    public init(_ authorization: WaymarkAuthorization) {
        switch authorization {
        case .notDetermined: self = .authorizationNotDetermined
        case .denied: self = .authorizationDenied
        case .restricted: self = .authorizationRestricted
        case .authorizedWhenInUse: self = .authorizedWhenInUse
        case .authorizedAlways: self = .authorizedAlways
        }
    }

    /// The code and what happened, for logs.
    public var description: String {
        let text: String
        switch self {
        case .authorizationNotDetermined: text = "location authorization not determined"
        case .authorizationDenied: text = "location authorization denied"
        case .authorizationRestricted: text = "location authorization restricted"
        case .authorizedWhenInUse: text = "location authorized when in use"
        case .authorizedAlways: text = "location authorized always"
        case .rangingUnavailable: text = "beacon ranging unavailable"
        case .rangingFailed(let uuid, let code, let message): text = "ranging \(uuid) failed (\(code)): \(message)"
        case .motionUnavailable(let sensor): text = "no \(sensor.rawValue)"
        case .engineError(let code, let message): text = "engine error \(code): \(message)"
        case .scanRejected(let reason, let total): text = "scan rejected (\(total) so far): \(reason)"
        case .backgroundModeMissing: text = "no location in UIBackgroundModes: paused in the background"
        case .wakeOnArrivalNeedsAlways: text = "wake-up on arrival needs always authorization"
        case .backgroundNeedsForegroundStart: text = "background positioning must start in the foreground"
        case .regionMonitoringUnavailable: text = "beacon region monitoring unavailable"
        case .surveyFailed(let reason): text = "survey recording failed: \(reason)"
        }
        return "\(code) \(text)"
    }
}

/// Receives what a `WaymarkLocationManager` produces, on its `delegateQueue`. Every method
/// has an empty default.
public protocol WaymarkLocationManagerDelegate: AnyObject {
    /// A new position (`position.toCLLocation()` on a geo-referenced site).
    func locationManager(_ manager: WaymarkLocationManager, didUpdate position: PositionEstimate)
    /// A coded status.
    func locationManager(_ manager: WaymarkLocationManager, didReport status: WaymarkLocationStatus)
    /// The manager's state changed.
    func locationManager(_ manager: WaymarkLocationManager, didChange state: WaymarkLocationState)
    /// The engine's own events: motion state, zones and geofences entered and left.
    func locationManager(_ manager: WaymarkLocationManager, didReceive update: StatusUpdate)
}

public extension WaymarkLocationManagerDelegate {
    func locationManager(_ manager: WaymarkLocationManager, didUpdate position: PositionEstimate) {}
    func locationManager(_ manager: WaymarkLocationManager, didReport status: WaymarkLocationStatus) {}
    func locationManager(_ manager: WaymarkLocationManager, didChange state: WaymarkLocationState) {}
    func locationManager(_ manager: WaymarkLocationManager, didReceive update: StatusUpdate) {}
}

/// Positions for one engine from the phone's sensors, as `CLLocationManager` gives locations:
/// `start()`/`stop()` with a delegate called on `delegateQueue`, or `for await` over
/// `locations()`. On iOS make it on the main thread with `init(engine:request:delegateQueue:)`
/// (AppleAdapter.swift); the designated initialiser takes the platform ports.
///
/// Each inertial sensor is read at `request.motionInterval` and sent in batches, as is the
/// barometer where there is one (a device without one is not degraded). Each ranging
/// result with at least one measured beacon becomes one scan, timed on the motion's clock,
/// after the motion up to its time. When no epoch was made for `request.advanceInterval`
/// (beacons out of range, or ranging off), the manager calls `advance` so the position keeps
/// moving. Every epoch's time is after the one before. Every failure is a status; nothing is
/// dropped silently. In the background it follows `request.background` (Background.swift).
///
/// Survey mode: with a `SurveyRecorder` attached (`startSurvey`), every sensor batch and
/// scan the manager reads also goes to the recorder, and `markWaypoint` records the
/// surveyor's tap at the current time; a manager made with no engine only records.
public final class WaymarkLocationManager: @unchecked Sendable {
    /// The engine fed; nil for a manager that only records surveys.
    public let engine: PositioningEngine?
    /// What is read and how often.
    public let request: WaymarkLocationRequest
    /// Where the delegate is called.
    public let delegateQueue: DispatchQueue

    private let motion: WaymarkMotionSource
    private let ranger: WaymarkBeaconRanger
    private let altimeter: WaymarkAltimeter?
    private let backgroundLocation: WaymarkBackgroundLocation?
    private let lifecycle: WaymarkAppLifecycle?
    private let clock: WaymarkClock
    private let scheduler: WaymarkScheduler

    // Everything below is read and written on `queue` only, except what `lock` guards.
    private let queue = DispatchQueue(label: "dev.waymark.location-manager")
    private let onQueueKey = DispatchSpecificKey<Bool>()
    /// Started (by `start()` or a `locations()` stream), until stopped.
    private var active = false
    /// The sensors, ranging and the timer run: `active` and not paused by the background plan.
    private var inputsOn = false
    private var startedExplicitly = false
    private var subscription: Subscription?
    private var pending: [WaymarkMotionSensor: [MotionSample]] = [:]
    private var pendingPressure: [PressureReading] = []
    private var barometerOn = false
    private var unavailableSensors: [WaymarkMotionSensor] = []
    private var reportedSensors = false
    private var authorization: WaymarkAuthorization = .notDetermined
    private var askedAuthorization = false
    private var askedAlways = false
    private var ranging = false
    private var rangingFailed = false
    private var reportedRangingUnavailable = false
    private var appState: WaymarkAppState
    /// The inputs ran, with location updates, when the app left the foreground.
    private var keptRunning = false
    /// Inside each monitored beacon region, as Core Location last said.
    private var regionInside: [UUID: Bool] = [:]
    private var regionMonitoringFailed = false
    private var appliedSettings = WaymarkBackgroundSettings.off
    private var backgroundProblem: WaymarkLocationStatus?
    /// The latest epoch time handed to the engine (accepted or not): the next one is after it.
    private var lastEpochTimeNs: UInt64?
    /// The latest accepted epoch, or the session's start: `advance` is due an interval later.
    private var advanceFromNs: UInt64 = 0
    private var advanceTimer: WaymarkTimer?
    /// Inside one of the manager's own engine calls: its failure is reported from the throw,
    /// so the listener's echo of it (`onError`) is not reported twice.
    private var inEngineCall = false
    private var locationStreams: [UUID: AsyncStream<PositionEstimate>.Continuation] = [:]
    private var survey: SurveyRecorder?
    /// The survey recorder threw `Io`: it takes nothing until `resumeSurvey()`.
    private var surveyFailing = false

    private let lock = NSLock()
    private weak var _delegate: WaymarkLocationManagerDelegate?
    private var _state: WaymarkLocationState = .idle
    private var _rejectedScans: UInt64 = 0
    private var _usesBarometer = false
    private var _surveying = false
    private var statusStreams: [UUID: AsyncStream<WaymarkLocationStatus>.Continuation] = [:]

    /// A manager over the given ports (`altimeter` nil: a device without a barometer;
    /// `backgroundLocation` and `lifecycle` nil: no background handling, the app counts as in
    /// the foreground). `engine` nil makes a manager that only records surveys. Throws
    /// `PositioningError.InvalidConfig` for a request with an interval not > 0, a batch size
    /// below 1, `.wakeOnArrival` without beacon UUIDs, or a background mode without a
    /// `backgroundLocation` port.
    public init(
        engine: PositioningEngine?, request: WaymarkLocationRequest = WaymarkLocationRequest(),
        motion: WaymarkMotionSource, ranger: WaymarkBeaconRanger, altimeter: WaymarkAltimeter? = nil,
        backgroundLocation: WaymarkBackgroundLocation? = nil, lifecycle: WaymarkAppLifecycle? = nil,
        clock: WaymarkClock = UptimeClock(), scheduler: WaymarkScheduler = DispatchTimerScheduler(),
        delegateQueue: DispatchQueue = .main
    ) throws {
        if let problem = request.problem() { throw PositioningError.InvalidConfig(reason: problem) }
        if request.background != .off && backgroundLocation == nil {
            throw PositioningError.InvalidConfig(reason: "background \(request.background) needs a backgroundLocation port")
        }
        self.engine = engine
        self.request = request
        self.motion = motion
        self.ranger = ranger
        self.altimeter = altimeter
        self.backgroundLocation = backgroundLocation
        self.lifecycle = lifecycle
        self.clock = clock
        self.scheduler = scheduler
        self.delegateQueue = delegateQueue
        appState = lifecycle?.state ?? .foreground
        queue.setSpecific(key: onQueueKey, value: true)
        ranger.setEventHandler(queue: queue) { [weak self] event in self?.handle(event) }
        lifecycle?.setHandler(queue: queue) { [weak self] state in self?.appStateChanged(state) }
    }

    deinit {
        subscription?.cancel()
        advanceTimer?.cancel()
        if inputsOn {
            motion.stop()
            if barometerOn { altimeter?.stop() }
            if ranging { ranger.stopRanging() }
        }
        if appliedSettings != .off { backgroundLocation?.apply(.off) }
        locationStreams.values.forEach { $0.finish() }
        statusStreams.values.forEach { $0.finish() }
    }

    /// Called on `delegateQueue`; held weakly.
    public var delegate: WaymarkLocationManagerDelegate? {
        get { lock.lock(); defer { lock.unlock() }; return _delegate }
        set { lock.lock(); defer { lock.unlock() }; _delegate = newValue }
    }

    /// Where the manager is now.
    public var state: WaymarkLocationState { lock.lock(); defer { lock.unlock() }; return _state }

    /// Whether the barometer is read: the device has one, the app may read it, and the request
    /// asks for it. A device without one positions as well, less its floor changes.
    public var usesBarometer: Bool { lock.lock(); defer { lock.unlock() }; return _usesBarometer }

    /// Beacon scans the engine refused since the manager was made.
    public var rejectedScanCount: UInt64 { lock.lock(); defer { lock.unlock() }; return _rejectedScans }

    /// Whether a survey recorder is attached (`startSurvey` until `finishSurvey` returns).
    public var isSurveying: Bool { lock.lock(); defer { lock.unlock() }; return _surveying }

    /// Starts the sensors, ranging (when the request names beacon UUIDs and location is
    /// authorized; it asks when the user was never asked) and the `advance` timer, as the
    /// app's state and `request.background` allow. Does nothing when started. Call it from
    /// any thread but the manager's own.
    public func start() {
        dispatchPrecondition(condition: .notOnQueue(queue))
        queue.sync {
            startedExplicitly = true
            startSession()
        }
    }

    /// Stops the sensors, ranging, the timer and every background location service, cancels
    /// the engine subscription and ends every `locations()` stream. `start()` resumes on the
    /// same engine. An attached survey stays attached (with the motion read so far).
    public func stop() {
        dispatchPrecondition(condition: .notOnQueue(queue))
        queue.sync { stopSession() }
    }

    /// The app entered the background or returned: for an app that drives the manager
    /// itself, without a `lifecycle` port (the iOS initialiser observes UIKit's notifications).
    public func appStateDidChange(to state: WaymarkAppState) {
        dispatchPrecondition(condition: .notOnQueue(queue))
        queue.sync { appStateChanged(state) }
    }

    /// Positions as they come. Starts the manager if it is not running; when the last stream
    /// ends (its task is cancelled or the loop left) and `start()` was not called, the
    /// manager stops. A slow consumer gets the newest `bufferingNewest` positions.
    public func locations(bufferingNewest: Int = 64) -> AsyncStream<PositionEstimate> {
        let (stream, continuation) = AsyncStream.makeStream(
            of: PositionEstimate.self, bufferingPolicy: .bufferingNewest(bufferingNewest))
        let id = UUID()
        continuation.onTermination = { [weak self] _ in
            guard let manager = self else { return }
            manager.queue.async { manager.locationStreamEnded(id) }
        }
        dispatchPrecondition(condition: .notOnQueue(queue))
        queue.sync {
            locationStreams[id] = continuation
            startSession()
        }
        return stream
    }

    /// Every coded status from now on, until the stream's task is cancelled or the manager is
    /// released. Does not start anything.
    public func statuses(bufferingNewest: Int = 64) -> AsyncStream<WaymarkLocationStatus> {
        let (stream, continuation) = AsyncStream.makeStream(
            of: WaymarkLocationStatus.self, bufferingPolicy: .bufferingNewest(bufferingNewest))
        let id = UUID()
        continuation.onTermination = { [weak self] _ in
            guard let self else { return }
            self.lock.lock(); defer { self.lock.unlock() }
            self.statusStreams[id] = nil
        }
        lock.lock(); defer { lock.unlock() }
        statusStreams[id] = continuation
        return stream
    }

    // MARK: - Survey mode

    /// Attaches `recorder`: from now on every sensor batch and beacon scan the manager reads
    /// goes to it too, as to the engine (the barometer excepted: survey files carry none).
    /// It does not start the manager. Throws `SurveyError.InputRejected` when a survey is
    /// attached already.
    public func startSurvey(_ recorder: SurveyRecorder) throws {
        dispatchPrecondition(condition: .notOnQueue(queue))
        try queue.sync {
            guard survey == nil else {
                throw SurveyError.InputRejected(reason: "a survey is being recorded: finish it first")
            }
            // Motion read before the survey goes to the engine alone.
            flush(upTo: UInt64.max)
            survey = recorder
            surveyFailing = false
            setSurveying(true)
        }
    }

    /// The surveyor's tap: they stand at (`x`, `y`) m on the plan of `floor` (its name, "F1")
    /// now, on the clock every input is timed on. The motion read up to now goes to the
    /// recorder first. Throws `SurveyError.InputRejected` with no survey attached or for a
    /// coordinate that is not finite, `Io` when the storage refuses.
    public func markWaypoint(x: Double, y: Double, floor: String) throws {
        dispatchPrecondition(condition: .notOnQueue(queue))
        try queue.sync {
            guard let survey else { throw SurveyError.InputRejected(reason: "no survey is being recorded") }
            let t = clock.nowNs()
            flush(upTo: t)
            try survey.markWaypoint(timestampNs: t, x: x, y: y, floor: floor)
        }
    }

    /// Sends the motion read so far, closes the recording (`SurveyRecorder.finish`) and
    /// detaches it. On a throw (`NoWaypoints`: tap first; `Io`) it stays attached.
    public func finishSurvey() throws -> SurveySummary {
        dispatchPrecondition(condition: .notOnQueue(queue))
        return try queue.sync {
            guard let survey else { throw SurveyError.InputRejected(reason: "no survey is being recorded") }
            flush(upTo: UInt64.max)
            let summary = try survey.finish()
            self.survey = nil
            surveyFailing = false
            setSurveying(false)
            return summary
        }
    }

    /// After a `surveyFailed` status (600): `SurveyRecorder.resume`, then the survey takes
    /// input again. Throws `Io` while the storage still refuses.
    public func resumeSurvey() throws {
        dispatchPrecondition(condition: .notOnQueue(queue))
        try queue.sync {
            guard let survey else { throw SurveyError.InputRejected(reason: "no survey is being recorded") }
            try survey.resume()
            surveyFailing = false
        }
    }

    private func setSurveying(_ on: Bool) {
        lock.lock(); defer { lock.unlock() }
        _surveying = on
    }

    /// One call on the attached recorder. A refused input is counted by the recorder itself
    /// (`SurveySummary.scansRejected`); a failed write is a status, once, until resumed.
    private func record(_ call: (SurveyRecorder) throws -> Void) {
        guard let survey, !surveyFailing else { return }
        do {
            try call(survey)
        } catch SurveyError.InputRejected {
        } catch {
            surveyFailing = true
            report(.surveyFailed(reason: String(describing: error)))
        }
    }

    // MARK: - Session (on `queue`)

    /// Whether the request needs location authorization: to range, or to run in the background.
    private var needsLocation: Bool { !request.beaconUUIDs.isEmpty || request.background != .off }

    private func startSession() {
        dispatchPrecondition(condition: .onQueue(queue))
        guard !active else { return }
        active = true
        rangingFailed = false
        reportedRangingUnavailable = false
        reportedSensors = false
        regionMonitoringFailed = false
        regionInside = [:]
        keptRunning = false
        backgroundProblem = nil
        if let engine { subscription = engine.subscribe(listener: EngineListener(self)) }
        if needsLocation {
            authorization = ranger.authorization
            report(WaymarkLocationStatus(authorization))
        }
        update()
    }

    private func stopSession() {
        dispatchPrecondition(condition: .onQueue(queue))
        startedExplicitly = false
        guard active else { return }
        active = false
        stopInputs()
        apply(.off)
        subscription?.cancel()
        subscription = nil
        let streams = locationStreams
        locationStreams = [:]
        streams.values.forEach { $0.finish() }
        setState(.stopped)
    }

    private func locationStreamEnded(_ id: UUID) {
        guard locationStreams.removeValue(forKey: id) != nil else { return }
        if locationStreams.isEmpty && !startedExplicitly { stopSession() }
    }

    private func startInputs() {
        guard !inputsOn else { return }
        inputsOn = true
        pending = [:]
        unavailableSensors = WaymarkMotionSensor.allCases.filter { !motion.isAvailable($0) }
        if !reportedSensors {
            reportedSensors = true
            unavailableSensors.forEach { report(.motionUnavailable($0)) }
        }
        let sensors = WaymarkMotionSensor.allCases.filter { !unavailableSensors.contains($0) }
        if !sensors.isEmpty {
            motion.start(sensors, interval: request.motionInterval, queue: queue) { [weak self] reading in
                self?.receive(reading)
            }
        }
        if request.usesBarometer, let altimeter, altimeter.isAvailable {
            pendingPressure = []
            barometerOn = true
            altimeter.start(queue: queue) { [weak self] reading in self?.receive(reading) }
        }
        setUsesBarometer(barometerOn)
        if engine != nil {
            advanceFromNs = clock.nowNs()
            armAdvance(after: request.advanceInterval)
        }
    }

    /// Stops the sensors, ranging and the timer. Motion read after the last epoch is
    /// dropped, as the engine has no epoch for it, except that an attached survey gets it.
    private func stopInputs() {
        guard inputsOn else { return }
        for sensor in WaymarkMotionSensor.allCases {
            if let batch = pending[sensor], !batch.isEmpty { recordMotion(batch, of: sensor) }
        }
        inputsOn = false
        motion.stop()
        if barometerOn {
            altimeter?.stop()
            barometerOn = false
            setUsesBarometer(false)
        }
        pendingPressure = []
        pending = [:]
        if ranging {
            ranger.stopRanging()
            ranging = false
        }
        advanceTimer?.cancel()
        advanceTimer = nil
    }

    private func apply(_ settings: WaymarkBackgroundSettings) {
        guard settings != appliedSettings else { return }
        appliedSettings = settings
        backgroundLocation?.apply(settings)
    }

    private func appStateChanged(_ new: WaymarkAppState) {
        dispatchPrecondition(condition: .onQueue(queue))
        guard new != appState else { return }
        keptRunning = new == .background && inputsOn && appliedSettings.updatesLocation
        appState = new
        update()
    }

    /// Whether the user is inside a monitored beacon region: true inside any, false when
    /// outside all of them, nil while one is not known.
    private var insideSite: Bool? {
        let monitored = appliedSettings.monitoredRegions
        guard !monitored.isEmpty, !regionMonitoringFailed else { return nil }
        let known = monitored.compactMap { regionInside[$0] }
        if known.contains(true) { return true }
        return known.count == monitored.count ? false : nil
    }

    /// Carries out the background plan, starts or stops ranging as authorization,
    /// availability and failures allow, asks for authorization once, and sets the state.
    private func update() {
        guard active else { return }
        var capabilities = backgroundLocation?.capabilities
            ?? WaymarkBackgroundCapabilities(declaresLocationBackgroundMode: false, declaresAlwaysUsage: false,
                                             canMonitorBeaconRegions: false)
        if regionMonitoringFailed { capabilities.canMonitorBeaconRegions = false }
        let plan = WaymarkBackgroundPlan.make(
            mode: request.background, beaconUUIDs: request.beaconUUIDs,
            showsIndicator: request.showsBackgroundLocationIndicator, requestsAuthorization: request.requestsAuthorization,
            authorization: authorization, appState: appState, capabilities: capabilities,
            keptRunning: keptRunning, insideSite: insideSite)
        if plan.problem != backgroundProblem {
            backgroundProblem = plan.problem
            if let problem = plan.problem { report(problem) }
        }
        if plan.requestsAlwaysAuthorization && !askedAlways && appState == .foreground {
            askedAlways = true
            backgroundLocation?.requestAlwaysAuthorization()
        }
        apply(plan.settings)
        if plan.runsInputs { startInputs() } else { stopInputs() }

        if !request.beaconUUIDs.isEmpty && inputsOn {
            let available = ranger.isRangingAvailable
            if authorization.allowsRanging && !available && !reportedRangingUnavailable {
                reportedRangingUnavailable = true
                report(.rangingUnavailable)
            }
        }
        if needsLocation && authorization == .notDetermined && request.requestsAuthorization && !askedAuthorization
            && appState == .foreground {
            askedAuthorization = true
            ranger.requestWhenInUseAuthorization()
        }
        let allowed = inputsOn && !request.beaconUUIDs.isEmpty && authorization.allowsRanging
            && ranger.isRangingAvailable && !rangingFailed
        if allowed && !ranging {
            ranger.startRanging(uuids: request.beaconUUIDs)
            ranging = true
        } else if !allowed && ranging {
            ranger.stopRanging()
            ranging = false
        }
        let missing = (!request.beaconUUIDs.isEmpty && !ranging) || !unavailableSensors.isEmpty
        setState(!inputsOn ? .paused : missing ? .degraded : .running)
    }

    // MARK: - Inputs (on `queue`)

    private func receive(_ reading: WaymarkMotionReading) {
        dispatchPrecondition(condition: .onQueue(queue))
        guard inputsOn else { return }
        let sample: MotionSample?
        switch reading.sensor {
        case .accelerometer:
            sample = AppleSensorConversion.accelerometer(timestamp: reading.timestamp, x: reading.x, y: reading.y, z: reading.z)
        case .gyroscope:
            sample = AppleSensorConversion.gyroscope(timestamp: reading.timestamp, x: reading.x, y: reading.y, z: reading.z)
        case .magnetometer:
            sample = AppleSensorConversion.magnetometer(timestamp: reading.timestamp, x: reading.x, y: reading.y, z: reading.z)
        }
        guard let sample else { return }
        pending[reading.sensor, default: []].append(sample)
        if let batch = pending[reading.sensor], batch.count >= request.motionBatchSize {
            pending[reading.sensor] = nil
            push(batch, of: reading.sensor)
        }
    }

    private func receive(_ reading: WaymarkPressureReading) {
        dispatchPrecondition(condition: .onQueue(queue))
        guard inputsOn, barometerOn else { return }
        guard let pressure = AppleSensorConversion.pressure(timestamp: reading.timestamp, kilopascals: reading.kilopascals)
        else { return }
        pendingPressure.append(pressure)
        if pendingPressure.count >= request.motionBatchSize {
            pushPressure(pendingPressure)
            pendingPressure = []
        }
    }

    private func pushPressure(_ batch: [PressureReading]) {
        guard let engine else { return }
        do {
            _ = try engineCall { try engine.pushPressure(batch: batch) }
        } catch {
            reportEngineError(error)
        }
    }

    private func setUsesBarometer(_ on: Bool) {
        lock.lock(); defer { lock.unlock() }
        _usesBarometer = on
    }

    /// Sends every pending sample and barometer reading up to `t`, so the epoch at `t` has
    /// the motion and the height before it.
    private func flush(upTo t: UInt64) {
        let split = pendingPressure.firstIndex { $0.timestampNs > t } ?? pendingPressure.count
        if split > 0 {
            let batch = Array(pendingPressure[..<split])
            pendingPressure.removeFirst(split)
            pushPressure(batch)
        }
        for sensor in WaymarkMotionSensor.allCases {
            guard let batch = pending[sensor], !batch.isEmpty else { continue }
            let split = batch.firstIndex { $0.timestampNs > t } ?? batch.count
            pending[sensor] = split < batch.count ? Array(batch[split...]) : nil
            if split > 0 { push(Array(batch[..<split]), of: sensor) }
        }
    }

    /// One batch to the engine and to the survey, the same samples.
    private func push(_ batch: [MotionSample], of sensor: WaymarkMotionSensor) {
        if let engine {
            do {
                _ = try engineCall {
                    switch sensor {
                    case .accelerometer: return try engine.pushAccelerometer(batch: batch)
                    case .gyroscope: return try engine.pushGyroscope(batch: batch)
                    case .magnetometer: return try engine.pushMagnetometer(batch: batch)
                    }
                }
            } catch {
                reportEngineError(error)
            }
        }
        recordMotion(batch, of: sensor)
    }

    private func recordMotion(_ batch: [MotionSample], of sensor: WaymarkMotionSensor) {
        record { survey in
            switch sensor {
            case .accelerometer: _ = try survey.pushAccelerometer(batch: batch)
            case .gyroscope: _ = try survey.pushGyroscope(batch: batch)
            case .magnetometer: _ = try survey.pushMagnetometer(batch: batch)
            }
        }
    }

    private func handle(_ event: WaymarkRangingEvent) {
        dispatchPrecondition(condition: .onQueue(queue))
        switch event {
        case .authorizationChanged(let new):
            guard new != authorization else { return }
            authorization = new
            if new.allowsRanging { rangingFailed = false }
            guard active, needsLocation else { return }
            report(WaymarkLocationStatus(new))
            update()
        case .regionStateChanged(let uuid, let inside):
            regionInside[uuid] = inside
            update()
        case .regionMonitoringFailed:
            guard active, !regionMonitoringFailed else { return }
            regionMonitoringFailed = true
            update()
        case .failed(let uuid, let code, let message):
            guard active, ranging else { return }
            rangingFailed = true
            report(.rangingFailed(uuid: uuid, code: code, message: message))
            update()
        case .ranged(let beacons, _):
            guard inputsOn, ranging else { return }
            let now = Date()
            let readings = beacons.compactMap {
                AppleSensorConversion.beacon(
                    uuid: $0.uuid, major: $0.major, minor: $0.minor, rssi: $0.rssi, measuredAt: $0.timestamp, now: now)
            }
            guard !readings.isEmpty else { return }
            let t = nextEpochTime()
            flush(upTo: t)
            let scan = RadioScan(timestampNs: t, wifi: [], beacons: readings)
            if let engine {
                do {
                    _ = try engineCall { try engine.pushScan(scan: scan) }
                    advanceFromNs = t
                } catch PositioningError.InputRejected(let reason) {
                    lock.lock()
                    _rejectedScans += 1
                    let total = _rejectedScans
                    lock.unlock()
                    report(.scanRejected(reason: reason, total: total))
                } catch {
                    reportEngineError(error)
                }
            }
            record { try $0.pushScan(scan: scan) }
        }
    }

    private func armAdvance(after seconds: TimeInterval) {
        advanceTimer?.cancel()
        advanceTimer = scheduler.schedule(after: seconds, on: queue) { [weak self] in self?.advanceIfDue() }
    }

    /// The timer: an `advance` epoch when none was made for the interval, else wait for the
    /// rest of it.
    private func advanceIfDue() {
        dispatchPrecondition(condition: .onQueue(queue))
        guard inputsOn, let engine else { return }
        let now = clock.nowNs()
        let interval = AppleSensorConversion.nanoseconds(fromSeconds: request.advanceInterval) ?? UInt64.max
        let (due, overflow) = advanceFromNs.addingReportingOverflow(interval)
        if !overflow && now < due {
            armAdvance(after: Double(due - now) / 1e9)
            return
        }
        let t = nextEpochTime()
        flush(upTo: t)
        do {
            _ = try engineCall { try engine.advance(timestampNs: t) }
        } catch {
            reportEngineError(error)
        }
        advanceFromNs = t
        armAdvance(after: request.advanceInterval)
    }

    /// Now on the motion's clock, or just after the previous epoch if the clock has not moved
    /// past it: epochs never share a time or go back.
    private func nextEpochTime() -> UInt64 {
        let now = clock.nowNs()
        let t = lastEpochTimeNs.map { max(now, $0 &+ 1) } ?? now
        lastEpochTimeNs = t
        return t
    }

    private func engineCall<T>(_ call: () throws -> T) throws -> T {
        inEngineCall = true
        defer { inEngineCall = false }
        return try call()
    }

    // MARK: - Engine events (any thread)

    /// Runs `work` on `queue`: now when already there (the engine calls its listeners on the
    /// thread that called it), else after what is queued.
    private func onQueue(_ work: @escaping @Sendable () -> Void) {
        if DispatchQueue.getSpecific(key: onQueueKey) == true { work() } else { queue.async(execute: work) }
    }

    fileprivate func enginePosition(_ position: PositionEstimate) {
        onQueue { [self] in
            guard active else { return }
            // An epoch the app made itself (pushFix, confirmZone) counts too.
            if position.timestampNs > lastEpochTimeNs ?? 0 { lastEpochTimeNs = position.timestampNs }
            advanceFromNs = max(advanceFromNs, position.timestampNs)
            locationStreams.values.forEach { $0.yield(position) }
            notify { $0.locationManager(self, didUpdate: position) }
        }
    }

    fileprivate func engineStatus(_ update: StatusUpdate) {
        onQueue { [self] in
            guard active else { return }
            notify { $0.locationManager(self, didReceive: update) }
        }
    }

    fileprivate func engineError(_ report: ErrorReport) {
        if DispatchQueue.getSpecific(key: onQueueKey) == true && inEngineCall { return }
        onQueue { [self] in self.report(.engineError(code: report.code, message: report.message)) }
    }

    // MARK: - Delivery

    private func reportEngineError(_ error: Error) {
        let (code, message) = describe(error)
        report(.engineError(code: code, message: message))
    }

    private func report(_ status: WaymarkLocationStatus) {
        lock.lock()
        let streams = Array(statusStreams.values)
        lock.unlock()
        streams.forEach { $0.yield(status) }
        notify { $0.locationManager(self, didReport: status) }
    }

    private func setState(_ new: WaymarkLocationState) {
        lock.lock()
        let changed = _state != new
        _state = new
        lock.unlock()
        if changed { notify { $0.locationManager(self, didChange: new) } }
    }

    private func notify(_ call: @escaping (WaymarkLocationManagerDelegate) -> Void) {
        delegateQueue.async { [weak self] in
            guard let delegate = self?.delegate else { return }
            call(delegate)
        }
    }
}

/// The manager's engine listener; holds it weakly (the engine holds the listener).
private final class EngineListener: PositionListener, @unchecked Sendable {
    private weak var manager: WaymarkLocationManager?

    init(_ manager: WaymarkLocationManager) { self.manager = manager }

    func onPosition(position: PositionEstimate) { manager?.enginePosition(position) }
    func onStatus(status: StatusUpdate) { manager?.engineStatus(status) }
    func onError(error: ErrorReport) { manager?.engineError(error) }
}

/// The code and message of an error an engine call threw.
private func describe(_ error: Error) -> (ErrorCode, String) {
    switch error {
    case PositioningError.InvalidSite(let reason): return (.invalidSite, reason)
    case PositioningError.InvalidConfig(let reason): return (.invalidConfig, reason)
    case PositioningError.InputRejected(let reason): return (.inputRejected, reason)
    case PositioningError.SaltMismatch(let reason): return (.saltMismatch, reason)
    case PositioningError.HabitsRejected(let reason): return (.habitsRejected, reason)
    case PositioningError.Internal(let reason): return (.internal, reason)
    default: return (.internal, String(describing: error))
    }
}
