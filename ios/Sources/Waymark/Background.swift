// What the location manager does when the app leaves the foreground: the decision, as a pure
// function of the request, the authorization, the app's state, what its Info.plist declares
// and whether the user is at the site. Plain Swift, so the Linux tests cover every case; the
// Core Location calls that carry the decision out are AppleAdapter.swift's
// (`CoreLocationBeaconRanger` as a `WaymarkBackgroundLocation`). Guide: docs/ios.md#background.

import Foundation

/// How the manager behaves when the app goes to the background.
public enum WaymarkBackgroundMode: Int, Sendable {
    /// Positions only while the app is in the foreground: the sensors, ranging and the
    /// `advance` timer pause when the app enters the background (iOS would suspend it
    /// anyway) and resume when it returns. No background mode or "always" needed.
    case off
    /// Positions go on in the background: Core Location keeps the app running
    /// (`allowsBackgroundLocationUpdates`, standard location updates, never paused
    /// automatically), with the background location indicator. Needs `location` in the app's
    /// `UIBackgroundModes`; with "while using" authorization the manager must be running
    /// when the app leaves the foreground.
    case continuous
    /// `continuous`, and iOS wakes or relaunches the app when the user arrives at the site:
    /// the site's beacon UUIDs are monitored as regions. In the background the inputs run
    /// only inside a region, so the app sleeps while the user is away. Needs "always"
    /// authorization (the manager asks for the upgrade when the app's Info.plist has the
    /// usage string) and at least one beacon UUID.
    case wakeOnArrival
}

/// Whether the app is in the foreground.
public enum WaymarkAppState: Sendable, Equatable {
    /// Active or inactive: on screen.
    case foreground
    /// In the background: iOS suspends it unless Core Location keeps it running.
    case background
}

/// What the app allows Core Location to do in the background: its Info.plist, and whether the
/// device can monitor beacon regions.
public struct WaymarkBackgroundCapabilities: Sendable, Equatable {
    /// `UIBackgroundModes` lists `location`. Without it, setting
    /// `allowsBackgroundLocationUpdates` raises an exception, so the manager never does.
    public var declaresLocationBackgroundMode: Bool
    /// `NSLocationAlwaysAndWhenInUseUsageDescription` is set: without it iOS never shows the
    /// "always" prompt.
    public var declaresAlwaysUsage: Bool
    /// `CLLocationManager.isMonitoringAvailable(for: CLBeaconRegion.self)`.
    public var canMonitorBeaconRegions: Bool

    /// Capabilities as given.
    public init(declaresLocationBackgroundMode: Bool, declaresAlwaysUsage: Bool, canMonitorBeaconRegions: Bool) {
        self.declaresLocationBackgroundMode = declaresLocationBackgroundMode
        self.declaresAlwaysUsage = declaresAlwaysUsage
        self.canMonitorBeaconRegions = canMonitorBeaconRegions
    }

    /// The capabilities an Info.plist (`Bundle.main.infoDictionary`) declares.
    public init(infoDictionary: [String: Any]?, canMonitorBeaconRegions: Bool) {
        let modes = infoDictionary?["UIBackgroundModes"] as? [String] ?? []
        let always = infoDictionary?["NSLocationAlwaysAndWhenInUseUsageDescription"] as? String ?? ""
        self.init(
            declaresLocationBackgroundMode: modes.contains("location"),
            declaresAlwaysUsage: !always.trimmingCharacters(in: .whitespacesAndNewlines).isEmpty,
            canMonitorBeaconRegions: canMonitorBeaconRegions)
    }
}

/// The Core Location settings of one moment, as `WaymarkBackgroundLocation.apply` sets them.
public struct WaymarkBackgroundSettings: Sendable, Equatable {
    /// `CLLocationManager.allowsBackgroundLocationUpdates`.
    public var allowsBackgroundLocationUpdates: Bool
    /// `CLLocationManager.showsBackgroundLocationIndicator`.
    public var showsBackgroundLocationIndicator: Bool
    /// `CLLocationManager.pausesLocationUpdatesAutomatically`: false whenever updates run.
    /// Core Location pauses when it believes the user stationary, and an app paused in the
    /// background cannot restart its updates: indoors, standing at a shelf would end tracking.
    public var pausesLocationUpdatesAutomatically: Bool
    /// Standard location updates (`startUpdatingLocation`, at the coarsest accuracy: the
    /// positions are Waymark's): what keeps a backgrounded app running. Started while the
    /// app is in the foreground, so that "while using" authorization carries them into the
    /// background.
    public var updatesLocation: Bool
    /// The proximity UUIDs monitored as beacon regions (`startMonitoring(for:)`), each a
    /// wake-up when the user arrives.
    public var monitoredRegions: [UUID]

    /// Nothing in the background: Core Location's defaults, no updates, no regions.
    public static let off = WaymarkBackgroundSettings(
        allowsBackgroundLocationUpdates: false, showsBackgroundLocationIndicator: false,
        pausesLocationUpdatesAutomatically: true, updatesLocation: false, monitoredRegions: [])

    /// Settings as given.
    public init(
        allowsBackgroundLocationUpdates: Bool, showsBackgroundLocationIndicator: Bool,
        pausesLocationUpdatesAutomatically: Bool, updatesLocation: Bool, monitoredRegions: [UUID]
    ) {
        self.allowsBackgroundLocationUpdates = allowsBackgroundLocationUpdates
        self.showsBackgroundLocationIndicator = showsBackgroundLocationIndicator
        self.pausesLocationUpdatesAutomatically = pausesLocationUpdatesAutomatically
        self.updatesLocation = updatesLocation
        self.monitoredRegions = monitoredRegions
    }
}

/// What the manager does now: the Core Location settings, whether the sensors, ranging and
/// the timer run, whether to ask for "always", and what to tell the app.
public struct WaymarkBackgroundPlan: Sendable, Equatable {
    /// What Core Location is set to.
    public var settings: WaymarkBackgroundSettings
    /// Whether the sensors, ranging and the `advance` timer run.
    public var runsInputs: Bool
    /// Whether to ask for the upgrade to "always" (`requestAlwaysAuthorization`).
    public var requestsAlwaysAuthorization: Bool
    /// Why the request's background mode is not carried out in full, or nil.
    public var problem: WaymarkLocationStatus?

    /// The plan for one moment.
    ///
    /// - `keptRunning`: the inputs were running, with location updates, when the app left the
    ///   foreground. With "while using" authorization, iOS lets location run in the background
    ///   only then.
    /// - `insideSite`: whether the user is inside a monitored beacon region (nil: not known
    ///   yet, or no region monitored).
    public static func make(
        mode: WaymarkBackgroundMode, beaconUUIDs: [UUID], showsIndicator: Bool, requestsAuthorization: Bool,
        authorization: WaymarkAuthorization, appState: WaymarkAppState, capabilities: WaymarkBackgroundCapabilities,
        keptRunning: Bool, insideSite: Bool?
    ) -> WaymarkBackgroundPlan {
        let foreground = appState == .foreground
        if mode == .off {
            return WaymarkBackgroundPlan(settings: .off, runsInputs: foreground, requestsAlwaysAuthorization: false, problem: nil)
        }
        guard capabilities.declaresLocationBackgroundMode else {
            return WaymarkBackgroundPlan(
                settings: .off, runsInputs: foreground, requestsAlwaysAuthorization: false, problem: .backgroundModeMissing)
        }
        let authorized = authorization.allowsRanging
        let always = authorization == .authorizedAlways
        var problem: WaymarkLocationStatus?
        var regions: [UUID] = []
        var askAlways = false
        if mode == .wakeOnArrival && authorized {
            if !always {
                problem = .wakeOnArrivalNeedsAlways
                askAlways = requestsAuthorization && capabilities.declaresAlwaysUsage
            } else if !capabilities.canMonitorBeaconRegions {
                problem = .regionMonitoringUnavailable
            } else {
                regions = beaconUUIDs
            }
        }
        // Away from every monitored region, the app may sleep: arriving wakes it.
        let away = !regions.isEmpty && insideSite == false
        let mayRunInBackground = authorized && (always || keptRunning)
        if !foreground && authorized && !mayRunInBackground && problem == nil {
            problem = .backgroundNeedsForegroundStart
        }
        let runs = foreground || (mayRunInBackground && !away)
        let settings = WaymarkBackgroundSettings(
            allowsBackgroundLocationUpdates: authorized, showsBackgroundLocationIndicator: authorized && showsIndicator,
            pausesLocationUpdatesAutomatically: false, updatesLocation: authorized && runs, monitoredRegions: regions)
        return WaymarkBackgroundPlan(settings: settings, runsInputs: runs, requestsAlwaysAuthorization: askAlways, problem: problem)
    }
}
