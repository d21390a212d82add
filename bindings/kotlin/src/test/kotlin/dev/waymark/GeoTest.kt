package dev.waymark

import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertTrue
import org.junit.Assert.fail
import org.junit.Test

/**
 * The lat/lon layers through the bindings (docs/zones.md#latitude-and-longitude): on the
 * simulated office anchored in Helsinki with its frame turned 0.4 rad, points, routes, zone
 * outlines and geofences in latitude/longitude come back to the metre ones within a centimetre,
 * and bad input is a typed `GeoException`.
 */
class GeoTest {
    private fun plainJson(): String =
        java.io.File(System.getProperty("waymark.site") ?: throw IllegalStateException("set -Dwaymark.site=...")).readText()

    private fun anchored(): Site = Site.fromBytes(
        plainJson()
            .replaceFirst("\"floors\":", "\"anchor\":{\"lat_deg\":60.17,\"lon_deg\":24.94,\"azimuth_rad\":0.4},\"floors\":")
            .toByteArray(),
    )

    private val cm = 0.01

    private fun assertNear(expected: FloorPoint, actual: FloorPoint) {
        assertEquals(expected.floor, actual.floor)
        assertTrue("$actual is not within 1 cm of $expected", Math.hypot(actual.x - expected.x, actual.y - expected.y) < cm)
    }

    @Test
    fun pointsAndRoutesGoToLatLonAndBackWithinACentimetre() {
        anchored().use { site ->
            assertTrue(site.isGeoReferenced())
            for (p in listOf(FloorPoint(0u, 0.0, 0.0), FloorPoint(0u, 35.5, 11.5), FloorPoint(0u, -20.0, 400.0))) {
                assertNear(p, site.fromLatLon(0u, site.toLatLon(p)))
            }
            val route = site.route(FloorPoint(0u, 4.9, 2.0), Destination.Zone("room 10"))
            val legs = site.routeLatLon(route)
            assertEquals(route.legs.size, legs.size)
            for ((geo, leg) in legs.zip(route.legs)) {
                assertEquals(leg.points.size, geo.size)
                for ((g, p) in geo.zip(leg.points)) {
                    assertNear(p, site.fromLatLon(g.floor, LatLon(g.latitudeDeg, g.longitudeDeg)))
                }
            }
            val outlines = site.zoneOutlines()
            assertEquals(site.zoneNames(), outlines.map { it.name })
            assertTrue(outlines.all { it.outline.size >= 3 })
        }
    }

    @Test
    fun aLatLonGeofenceIsTheMetreOne() {
        anchored().use { site ->
            val square = listOf(30.0 to 8.0, 40.0 to 8.0, 40.0 to 15.0, 30.0 to 15.0)
            val ring = square.map { (x, y) -> site.toLatLon(FloorPoint(0u, x, y)) }
            val fence = site.geofenceFromLatLon("hall", 0u, ring + ring[0])
            val vertices = (fence.shape as GeofenceShape.Polygon).vertices
            assertEquals(4, vertices.size)
            for ((v, xy) in vertices.zip(square)) {
                assertTrue("$v vs $xy", Math.hypot(v.x - xy.first, v.y - xy.second) < cm)
            }
            for ((g, want) in site.geofenceLatLon(fence).zip(ring)) {
                assertNear(site.fromLatLon(0u, want), site.fromLatLon(0u, g))
            }
            PositioningEngine.withSite(site, EngineOptions()).use { engine ->
                engine.addGeofence(fence)
                assertEquals(listOf("hall"), engine.geofences().map { it.id })
            }
        }
    }

    @Test
    fun badLatLonInputIsATypedError() {
        anchored().use { site ->
            val at = { x: Double, y: Double -> site.toLatLon(FloorPoint(0u, x, y)) }
            try {
                site.geofenceFromLatLon("bowtie", 0u, listOf(at(30.0, 8.0), at(40.0, 15.0), at(40.0, 8.0), at(30.0, 15.0)))
                fail("a bow tie was taken")
            } catch (e: GeoException.InvalidGeofence) {
                assertTrue(e.reason, e.reason.contains("self-intersection"))
            }
            try {
                site.fromLatLon(0u, LatLon(Double.NaN, 24.94))
                fail("NaN was taken")
            } catch (e: GeoException.InvalidCoordinate) {
                assertTrue(e.reason.isNotEmpty())
            }
            try {
                site.toLatLon(FloorPoint(9u, 1.0, 1.0))
                fail("floor 9 was taken")
            } catch (e: GeoException.InvalidCoordinate) {
                assertTrue(e.reason.isNotEmpty())
            }
        }
        Site.fromBytes(plainJson().toByteArray()).use { plain ->
            assertFalse(plain.isGeoReferenced())
            try {
                plain.toLatLon(FloorPoint(0u, 1.0, 1.0))
                fail("a site without an anchor gave lat/lon")
            } catch (e: GeoException.NotGeoReferenced) {
                // expected
            }
        }
    }
}
