// The lat/lon layers through the Swift bindings (docs/zones.md#latitude-and-longitude): on the
// simulated office anchored in Helsinki with its frame turned 0.4 rad, points, routes, zone
// outlines and geofences in latitude/longitude come back to the metre ones within a
// centimetre, and bad input is a typed GeoError.

import Foundation
import XCTest

@testable import Waymark

final class GeoTests: XCTestCase {
    let cm = 0.01

    func plainJson() throws -> String {
        try String(contentsOf: WaymarkTests.simDir.appendingPathComponent("site.json"), encoding: .utf8)
    }

    func anchored() throws -> Site {
        let json = try plainJson().replacingOccurrences(
            of: "\"floors\":", with: "\"anchor\":{\"lat_deg\":60.17,\"lon_deg\":24.94,\"azimuth_rad\":0.4},\"floors\":",
            options: [], range: nil)
        return try Site.fromBytes(site: Data(json.utf8))
    }

    func assertNear(_ expected: FloorPoint, _ actual: FloorPoint, file: StaticString = #filePath, line: UInt = #line) {
        XCTAssertEqual(expected.floor, actual.floor, file: file, line: line)
        XCTAssertLessThan(hypot(actual.x - expected.x, actual.y - expected.y), cm, "\(actual) vs \(expected)",
                          file: file, line: line)
    }

    func testPointsAndRoutesGoToLatLonAndBackWithinACentimetre() throws {
        let site = try anchored()
        XCTAssertTrue(site.isGeoReferenced())
        for p in [FloorPoint(floor: 0, x: 0, y: 0), FloorPoint(floor: 0, x: 35.5, y: 11.5),
                  FloorPoint(floor: 0, x: -20, y: 400)] {
            assertNear(p, try site.fromLatLon(floor: 0, at: try site.toLatLon(point: p)))
        }
        let route = try site.route(from: FloorPoint(floor: 0, x: 4.9, y: 2), destination: .zone(name: "room 10"))
        let legs = try site.routeLatLon(route: route)
        XCTAssertEqual(legs.count, route.legs.count)
        for (geo, leg) in zip(legs, route.legs) {
            XCTAssertEqual(geo.count, leg.points.count)
            for (g, p) in zip(geo, leg.points) {
                assertNear(p, try site.fromLatLon(floor: g.floor, at: LatLon(latitudeDeg: g.latitudeDeg, longitudeDeg: g.longitudeDeg)))
            }
        }
        let outlines = try site.zoneOutlines()
        XCTAssertEqual(outlines.map { $0.name }, site.zoneNames())
        XCTAssertTrue(outlines.allSatisfy { $0.outline.count >= 3 })
    }

    func testALatLonGeofenceIsTheMetreOne() throws {
        let site = try anchored()
        let square: [(Double, Double)] = [(30, 8), (40, 8), (40, 15), (30, 15)]
        let ring = try square.map { try site.toLatLon(point: FloorPoint(floor: 0, x: $0.0, y: $0.1)) }
        let fence = try site.geofenceFromLatLon(id: "hall", floor: 0, outline: ring + [ring[0]])
        guard case .polygon(let vertices) = fence.shape else { return XCTFail("not a polygon: \(fence)") }
        XCTAssertEqual(vertices.count, 4)
        for (v, xy) in zip(vertices, square) {
            XCTAssertLessThan(hypot(v.x - xy.0, v.y - xy.1), cm)
        }
        for (g, want) in zip(try site.geofenceLatLon(geofence: fence), ring) {
            assertNear(try site.fromLatLon(floor: 0, at: want), try site.fromLatLon(floor: 0, at: g))
        }
        let engine = try PositioningEngine.withSite(site: site, options: EngineOptions())
        try engine.addGeofence(geofence: fence)
        XCTAssertEqual(try engine.geofences().map { $0.id }, ["hall"])
    }

    func testBadLatLonInputIsATypedError() throws {
        let site = try anchored()
        let at = { (x: Double, y: Double) in try site.toLatLon(point: FloorPoint(floor: 0, x: x, y: y)) }
        let bowtie = [try at(30, 8), try at(40, 15), try at(40, 8), try at(30, 15)]
        XCTAssertThrowsError(try site.geofenceFromLatLon(id: "bowtie", floor: 0, outline: bowtie)) {
            guard case GeoError.InvalidGeofence(let reason) = $0 else {
                return XCTFail("expected InvalidGeofence, got \($0)")
            }
            XCTAssertTrue(reason.contains("self-intersection"), reason)
        }
        XCTAssertThrowsError(try site.fromLatLon(floor: 0, at: LatLon(latitudeDeg: .nan, longitudeDeg: 24.94))) {
            guard case GeoError.InvalidCoordinate = $0 else { return XCTFail("expected InvalidCoordinate, got \($0)") }
        }
        XCTAssertThrowsError(try site.toLatLon(point: FloorPoint(floor: 9, x: 1, y: 1))) {
            guard case GeoError.InvalidCoordinate = $0 else { return XCTFail("expected InvalidCoordinate, got \($0)") }
        }
        let plain = try Site.fromBytes(site: Data(try plainJson().utf8))
        XCTAssertFalse(plain.isGeoReferenced())
        XCTAssertThrowsError(try plain.toLatLon(point: FloorPoint(floor: 0, x: 1, y: 1))) {
            guard case GeoError.NotGeoReferenced = $0 else { return XCTFail("expected NotGeoReferenced, got \($0)") }
        }
    }
}
