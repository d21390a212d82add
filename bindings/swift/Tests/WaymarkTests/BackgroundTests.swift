// The background plan (Background.swift) case by case, then WaymarkLocationManager carrying
// it out through a fake Core Location background port and a fake app lifecycle.

import Foundation
import XCTest

@testable import Waymark

final class FakeBackgroundLocation: WaymarkBackgroundLocation {
    var capabilities: WaymarkBackgroundCapabilities
    private(set) var applied: [WaymarkBackgroundSettings] = []
    private(set) var alwaysRequests = 0

    init(capabilities: WaymarkBackgroundCapabilities = .init(
        declaresLocationBackgroundMode: true, declaresAlwaysUsage: true, canMonitorBeaconRegions: true)) {
        self.capabilities = capabilities
    }

    /// What Core Location is set to now.
    var current: WaymarkBackgroundSettings { applied.last ?? .off }

    func apply(_ settings: WaymarkBackgroundSettings) { applied.append(settings) }
    func requestAlwaysAuthorization() { alwaysRequests += 1 }
}

final class FakeLifecycle: WaymarkAppLifecycle {
    private(set) var state: WaymarkAppState
    private var queue: DispatchQueue?
    private var handler: ((WaymarkAppState) -> Void)?

    init(_ state: WaymarkAppState = .foreground) { self.state = state }

    func setHandler(queue: DispatchQueue, handler: @escaping (WaymarkAppState) -> Void) {
        self.queue = queue
        self.handler = handler
    }

    /// The app moves, as UIKit's notification would say, delivered on the manager's queue.
    func move(to new: WaymarkAppState) {
        state = new
        guard let queue, let handler else { return XCTFail("no lifecycle handler") }
        queue.sync { handler(new) }
    }
}

final class BackgroundPlanTests: XCTestCase {
    let all = WaymarkBackgroundCapabilities(declaresLocationBackgroundMode: true, declaresAlwaysUsage: true,
                                            canMonitorBeaconRegions: true)

    func plan(_ mode: WaymarkBackgroundMode, _ authorization: WaymarkAuthorization, _ appState: WaymarkAppState,
              capabilities: WaymarkBackgroundCapabilities? = nil, keptRunning: Bool = false, inside: Bool? = nil,
              showsIndicator: Bool = true, requestsAuthorization: Bool = true) -> WaymarkBackgroundPlan {
        WaymarkBackgroundPlan.make(
            mode: mode, beaconUUIDs: [beaconUUID], showsIndicator: showsIndicator,
            requestsAuthorization: requestsAuthorization, authorization: authorization, appState: appState,
            capabilities: capabilities ?? all, keptRunning: keptRunning, insideSite: inside)
    }

    func testOffRunsInTheForegroundOnly() {
        for authorization in [WaymarkAuthorization.authorizedAlways, .authorizedWhenInUse, .denied, .notDetermined] {
            let front = plan(.off, authorization, .foreground)
            XCTAssertEqual(front, WaymarkBackgroundPlan(settings: .off, runsInputs: true, requestsAlwaysAuthorization: false,
                                                        problem: nil))
            let back = plan(.off, authorization, .background, keptRunning: true)
            XCTAssertEqual(back.settings, .off)
            XCTAssertFalse(back.runsInputs)
            XCTAssertNil(back.problem)
        }
        XCTAssertEqual(WaymarkBackgroundSettings.off.pausesLocationUpdatesAutomatically, true, "Core Location's default")
    }

    func testWithoutTheBackgroundModeNothingIsSetAndTheAppIsTold() {
        let none = WaymarkBackgroundCapabilities(declaresLocationBackgroundMode: false, declaresAlwaysUsage: true,
                                                 canMonitorBeaconRegions: true)
        for mode in [WaymarkBackgroundMode.continuous, .wakeOnArrival] {
            for state in [WaymarkAppState.foreground, .background] {
                let p = plan(mode, .authorizedAlways, state, capabilities: none, keptRunning: true, inside: true)
                XCTAssertEqual(p.settings, .off, "allowsBackgroundLocationUpdates would raise without the mode")
                XCTAssertEqual(p.runsInputs, state == .foreground)
                XCTAssertEqual(p.problem, .backgroundModeMissing)
                XCTAssertFalse(p.requestsAlwaysAuthorization)
            }
        }
    }

    func testContinuousWhileInUse() {
        let front = plan(.continuous, .authorizedWhenInUse, .foreground)
        XCTAssertEqual(front.settings, WaymarkBackgroundSettings(
            allowsBackgroundLocationUpdates: true, showsBackgroundLocationIndicator: true,
            pausesLocationUpdatesAutomatically: false, updatesLocation: true, monitoredRegions: []))
        XCTAssertTrue(front.runsInputs)
        XCTAssertNil(front.problem)
        // Running when the app left the foreground: iOS lets it go on.
        let kept = plan(.continuous, .authorizedWhenInUse, .background, keptRunning: true)
        XCTAssertEqual(kept.settings, front.settings)
        XCTAssertTrue(kept.runsInputs)
        XCTAssertNil(kept.problem)
        // Not running then (started or authorized in the background): wait for the foreground.
        let late = plan(.continuous, .authorizedWhenInUse, .background, keptRunning: false)
        XCTAssertFalse(late.runsInputs)
        XCTAssertFalse(late.settings.updatesLocation)
        XCTAssertEqual(late.problem, .backgroundNeedsForegroundStart)
        // "Always" may start in the background.
        let always = plan(.continuous, .authorizedAlways, .background, keptRunning: false)
        XCTAssertTrue(always.runsInputs)
        XCTAssertTrue(always.settings.updatesLocation)
        XCTAssertNil(always.problem)
        XCTAssertEqual(always.settings.monitoredRegions, [], "continuous monitors no region")
        XCTAssertFalse(plan(.continuous, .authorizedAlways, .background, showsIndicator: false)
            .settings.showsBackgroundLocationIndicator)
    }

    func testContinuousWithoutAuthorization() {
        for authorization in [WaymarkAuthorization.denied, .restricted, .notDetermined] {
            let front = plan(.continuous, authorization, .foreground)
            XCTAssertTrue(front.runsInputs, "motion-only positions in the foreground")
            XCTAssertFalse(front.settings.allowsBackgroundLocationUpdates)
            XCTAssertFalse(front.settings.updatesLocation)
            XCTAssertNil(front.problem, "the authorization status says it")
            let back = plan(.continuous, authorization, .background, keptRunning: true)
            XCTAssertFalse(back.runsInputs, "without location iOS suspends the app")
            XCTAssertNil(back.problem)
        }
    }

    func testWakeOnArrivalWithAlways() {
        let front = plan(.wakeOnArrival, .authorizedAlways, .foreground)
        XCTAssertEqual(front.settings.monitoredRegions, [beaconUUID])
        XCTAssertTrue(front.runsInputs)
        XCTAssertNil(front.problem)
        // In the background: sleep away from the site, run inside it or while not yet known.
        let away = plan(.wakeOnArrival, .authorizedAlways, .background, keptRunning: true, inside: false)
        XCTAssertFalse(away.runsInputs)
        XCTAssertFalse(away.settings.updatesLocation, "no updates keep the app awake away from the site")
        XCTAssertEqual(away.settings.monitoredRegions, [beaconUUID], "the region stays monitored: it wakes the app")
        XCTAssertTrue(away.settings.allowsBackgroundLocationUpdates)
        XCTAssertTrue(plan(.wakeOnArrival, .authorizedAlways, .background, inside: true).runsInputs)
        XCTAssertTrue(plan(.wakeOnArrival, .authorizedAlways, .background, inside: nil).runsInputs)
        // In the foreground the app positions wherever the user is.
        XCTAssertTrue(plan(.wakeOnArrival, .authorizedAlways, .foreground, inside: false).runsInputs)
        // A device that cannot monitor regions: continuous, and the app is told.
        let cannot = WaymarkBackgroundCapabilities(declaresLocationBackgroundMode: true, declaresAlwaysUsage: true,
                                                   canMonitorBeaconRegions: false)
        let noRegions = plan(.wakeOnArrival, .authorizedAlways, .background, capabilities: cannot, inside: false)
        XCTAssertEqual(noRegions.problem, .regionMonitoringUnavailable)
        XCTAssertEqual(noRegions.settings.monitoredRegions, [])
        XCTAssertTrue(noRegions.runsInputs, "no region state: as continuous")
    }

    func testWakeOnArrivalWhileInUseAsksForAlways() {
        let p = plan(.wakeOnArrival, .authorizedWhenInUse, .foreground)
        XCTAssertEqual(p.problem, .wakeOnArrivalNeedsAlways)
        XCTAssertTrue(p.requestsAlwaysAuthorization)
        XCTAssertEqual(p.settings.monitoredRegions, [])
        XCTAssertTrue(p.settings.updatesLocation, "continuous meanwhile")
        XCTAssertFalse(plan(.wakeOnArrival, .authorizedWhenInUse, .foreground, requestsAuthorization: false)
            .requestsAlwaysAuthorization)
        let noString = WaymarkBackgroundCapabilities(declaresLocationBackgroundMode: true, declaresAlwaysUsage: false,
                                                     canMonitorBeaconRegions: true)
        XCTAssertFalse(plan(.wakeOnArrival, .authorizedWhenInUse, .foreground, capabilities: noString)
            .requestsAlwaysAuthorization, "iOS shows no prompt without the usage string")
        let back = plan(.wakeOnArrival, .authorizedWhenInUse, .background, keptRunning: true)
        XCTAssertTrue(back.runsInputs)
        XCTAssertEqual(back.problem, .wakeOnArrivalNeedsAlways)
    }

    func testCapabilitiesFromInfoPlist() {
        let full = WaymarkBackgroundCapabilities(infoDictionary: [
            "UIBackgroundModes": ["audio", "location"],
            "NSLocationAlwaysAndWhenInUseUsageDescription": "Finds you in the building, even when the app is closed",
        ], canMonitorBeaconRegions: true)
        XCTAssertEqual(full, all)
        let bare = WaymarkBackgroundCapabilities(infoDictionary: [
            "UIBackgroundModes": ["audio"], "NSLocationAlwaysAndWhenInUseUsageDescription": "  ",
        ], canMonitorBeaconRegions: false)
        XCTAssertEqual(bare, WaymarkBackgroundCapabilities(declaresLocationBackgroundMode: false, declaresAlwaysUsage: false,
                                                           canMonitorBeaconRegions: false))
        XCTAssertFalse(WaymarkBackgroundCapabilities(infoDictionary: nil, canMonitorBeaconRegions: true)
            .declaresLocationBackgroundMode)
    }
}

final class BackgroundManagerTests: XCTestCase {
    func siteJson() throws -> String { try makeBeaconSiteJson() }

    func walk() throws -> Walk { try loadWalk() }

    // .off: the inputs pause in the background and resume in the foreground; Core Location's
    // background services are never touched.
    func testOffPausesInTheBackground() throws {
        let background = FakeBackgroundLocation()
        let lifecycle = FakeLifecycle()
        let h = try Harness(siteJson: try siteJson(), background: background, lifecycle: lifecycle)
        h.manager.start()
        XCTAssertTrue(h.motion.running)
        XCTAssertEqual(h.ranger.ranging, [beaconUUID])
        lifecycle.move(to: .background)
        XCTAssertFalse(h.motion.running)
        XCTAssertFalse(h.altimeter.running)
        XCTAssertNil(h.ranger.ranging)
        XCTAssertNil(h.scheduler.armed)
        XCTAssertEqual(h.manager.state, .paused)
        // A result Core Location had queued is no scan while paused.
        let walk = try walk()
        h.clock.set(walk.epochs[0].timestampNs)
        h.ranger.send(.ranged(Harness.beacons(walk.epochs[0]), uuid: beaconUUID))
        XCTAssertEqual(h.engine.epochTimes, [])
        lifecycle.move(to: .foreground)
        XCTAssertTrue(h.motion.running)
        XCTAssertEqual(h.ranger.ranging, [beaconUUID])
        XCTAssertNotNil(h.scheduler.armed)
        h.ranger.send(.ranged(Harness.beacons(walk.epochs[0]), uuid: beaconUUID))
        XCTAssertEqual(h.engine.epochTimes, [walk.epochs[0].timestampNs])
        h.settle()
        XCTAssertEqual(h.delegate.states, [.running, .paused, .running])
        XCTAssertEqual(background.applied, [], "nothing set for .off")
        XCTAssertEqual(h.delegate.statuses, [.authorizedWhenInUse], "sensors reported once, no background status")
        // An app without a lifecycle port says it itself.
        h.manager.appStateDidChange(to: .background)
        XCTAssertEqual(h.manager.state, .paused)
    }

    // .continuous, "while using": location updates from the start, so the inputs keep running
    // in the background and positions keep coming.
    func testContinuousKeepsPositioningInTheBackground() throws {
        let background = FakeBackgroundLocation()
        let lifecycle = FakeLifecycle()
        let h = try Harness(siteJson: try siteJson(),
                            request: WaymarkLocationRequest(beaconUUIDs: [beaconUUID], background: .continuous),
                            background: background, lifecycle: lifecycle)
        h.manager.start()
        XCTAssertEqual(background.current, WaymarkBackgroundSettings(
            allowsBackgroundLocationUpdates: true, showsBackgroundLocationIndicator: true,
            pausesLocationUpdatesAutomatically: false, updatesLocation: true, monitoredRegions: []))
        let walk = try walk()
        for (i, epoch) in walk.epochs.prefix(6).enumerated() {
            if i == 3 { lifecycle.move(to: .background) }
            h.deliver(epoch)
        }
        h.settle()
        XCTAssertEqual(h.engine.epochTimes, walk.epochs.prefix(6).map(\.timestampNs), "scans in the background too")
        XCTAssertEqual(h.delegate.positions.count, 6 - Int(h.manager.rejectedScanCount))
        XCTAssertGreaterThanOrEqual(h.delegate.positions.count, 4)
        XCTAssertEqual(h.delegate.states, [.running])
        XCTAssertEqual(background.applied.count, 1, "nothing changes on entering the background")
        h.manager.stop()
        XCTAssertEqual(background.current, .off, "stop() ends the background services")
        XCTAssertEqual(h.manager.state, .stopped)
    }

    // Started in the background with "while using": paused (502) until the foreground.
    func testContinuousStartedInTheBackgroundWaitsForTheForeground() throws {
        let background = FakeBackgroundLocation()
        let lifecycle = FakeLifecycle(.background)
        let h = try Harness(siteJson: try siteJson(),
                            request: WaymarkLocationRequest(beaconUUIDs: [beaconUUID], background: .continuous),
                            background: background, lifecycle: lifecycle)
        h.manager.start()
        XCTAssertFalse(h.motion.running)
        XCTAssertFalse(background.current.updatesLocation)
        XCTAssertEqual(h.manager.state, .paused)
        lifecycle.move(to: .foreground)
        XCTAssertTrue(h.motion.running)
        XCTAssertTrue(background.current.updatesLocation)
        lifecycle.move(to: .background)
        XCTAssertTrue(h.motion.running, "running when it left the foreground: it goes on")
        h.settle()
        XCTAssertEqual(h.delegate.statuses, [.authorizedWhenInUse, .backgroundNeedsForegroundStart])
        XCTAssertEqual(h.delegate.states, [.paused, .running])
    }

    // The Info.plist lacks the background mode: told once (500), paused in the background,
    // allowsBackgroundLocationUpdates never set.
    func testAMissingBackgroundModeIsAStatus() throws {
        let background = FakeBackgroundLocation(capabilities: .init(
            declaresLocationBackgroundMode: false, declaresAlwaysUsage: true, canMonitorBeaconRegions: true))
        let lifecycle = FakeLifecycle()
        let h = try Harness(siteJson: try siteJson(),
                            request: WaymarkLocationRequest(beaconUUIDs: [beaconUUID], background: .continuous),
                            background: background, lifecycle: lifecycle)
        h.manager.start()
        lifecycle.move(to: .background)
        lifecycle.move(to: .foreground)
        h.settle()
        XCTAssertEqual(h.delegate.statuses.map(\.code), [103, 500])
        XCTAssertEqual(h.delegate.states, [.running, .paused, .running])
        XCTAssertFalse(background.applied.contains { $0.allowsBackgroundLocationUpdates })
    }

    // .wakeOnArrival with "always": the site's region monitored; away from it in the background
    // the app sleeps, arriving wakes the inputs and positions come.
    func testWakeOnArrival() throws {
        let background = FakeBackgroundLocation()
        let lifecycle = FakeLifecycle()
        let h = try Harness(siteJson: try siteJson(),
                            request: WaymarkLocationRequest(beaconUUIDs: [beaconUUID], background: .wakeOnArrival),
                            authorization: .authorizedAlways, background: background, lifecycle: lifecycle)
        h.manager.start()
        XCTAssertEqual(background.current.monitoredRegions, [beaconUUID])
        lifecycle.move(to: .background)
        XCTAssertTrue(h.motion.running, "region state not known yet: keep going")
        h.ranger.send(.regionStateChanged(uuid: beaconUUID, inside: false))
        XCTAssertFalse(h.motion.running)
        XCTAssertNil(h.ranger.ranging)
        XCTAssertFalse(background.current.updatesLocation)
        XCTAssertEqual(background.current.monitoredRegions, [beaconUUID])
        XCTAssertEqual(h.manager.state, .paused)
        // The user arrives: iOS wakes the app with the region's state.
        let walk = try walk()
        h.ranger.send(.regionStateChanged(uuid: beaconUUID, inside: true))
        XCTAssertTrue(h.motion.running)
        XCTAssertEqual(h.ranger.ranging, [beaconUUID])
        XCTAssertTrue(background.current.updatesLocation)
        for epoch in walk.epochs.prefix(3) {
            h.deliver(epoch)
        }
        h.settle()
        XCTAssertEqual(h.delegate.positions.count, 3 - Int(h.manager.rejectedScanCount))
        XCTAssertGreaterThanOrEqual(h.delegate.positions.count, 2)
        XCTAssertEqual(h.delegate.states, [.running, .paused, .running])
        // Monitoring fails: no wake-ups (503), positions go on as continuous.
        h.ranger.send(.regionMonitoringFailed(uuid: beaconUUID, code: 4, message: "kCLErrorDomain error 4"))
        h.settle()
        XCTAssertEqual(h.delegate.statuses.last, .regionMonitoringUnavailable)
        XCTAssertEqual(background.current.monitoredRegions, [])
        XCTAssertTrue(h.motion.running)
    }

    // .wakeOnArrival with "while using": asks for "always" once (501), monitors once granted.
    func testWakeOnArrivalAsksForAlways() throws {
        let background = FakeBackgroundLocation()
        let h = try Harness(siteJson: try siteJson(),
                            request: WaymarkLocationRequest(beaconUUIDs: [beaconUUID], background: .wakeOnArrival),
                            background: background, lifecycle: FakeLifecycle())
        h.manager.start()
        XCTAssertEqual(background.alwaysRequests, 1)
        XCTAssertEqual(background.current.monitoredRegions, [])
        h.ranger.change(to: .authorizedAlways)
        XCTAssertEqual(background.current.monitoredRegions, [beaconUUID])
        XCTAssertEqual(background.alwaysRequests, 1)
        h.settle()
        XCTAssertEqual(h.delegate.statuses.map(\.code), [103, 501, 104])
    }

    // A motion-only request that runs in the background needs location: it asks.
    func testBackgroundWithoutBeaconsAsksForLocation() throws {
        let background = FakeBackgroundLocation()
        let h = try Harness(siteJson: try siteJson(), request: WaymarkLocationRequest(background: .continuous),
                            authorization: .notDetermined, background: background, lifecycle: FakeLifecycle())
        h.manager.start()
        XCTAssertEqual(h.ranger.authorizationRequests, 1)
        XCTAssertFalse(background.current.updatesLocation)
        h.ranger.change(to: .authorizedWhenInUse)
        XCTAssertTrue(background.current.updatesLocation)
        XCTAssertNil(h.ranger.ranging, "no beacon to range")
        XCTAssertEqual(h.manager.state, .running)
    }

    func testBackgroundRequestsAreChecked() throws {
        let engine = try PositioningEngine(siteJson: try siteJson(), options: EngineOptions())
        XCTAssertThrowsError(try WaymarkLocationManager(
            engine: engine, request: WaymarkLocationRequest(beaconUUIDs: [beaconUUID], background: .continuous),
            motion: FakeMotion(), ranger: FakeRanger(authorization: .denied))) {
            guard case PositioningError.InvalidConfig = $0 else { return XCTFail("\($0)") }
        }
        XCTAssertThrowsError(try WaymarkLocationManager(
            engine: engine, request: WaymarkLocationRequest(background: .wakeOnArrival), motion: FakeMotion(),
            ranger: FakeRanger(authorization: .denied), backgroundLocation: FakeBackgroundLocation())) {
            guard case PositioningError.InvalidConfig = $0 else { return XCTFail("\($0)") }
        }
    }
}
