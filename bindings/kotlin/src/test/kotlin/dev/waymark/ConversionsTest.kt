package dev.waymark

import dev.waymark.android.Conversions
import org.junit.Assert.assertEquals
import org.junit.Assert.assertThrows
import org.junit.Assert.assertTrue
import org.junit.Test

/** The Android adapter's plain-Kotlin conversions (android/src/main/kotlin/.../Conversions.kt). */
class ConversionsTest {
    @Test
    fun sensorEventsKeepTheirNanosecondClockAndSiUnits() {
        val s = Conversions.sample(123_456_789L, floatArrayOf(0.5f, -1.25f, 9.75f, 0f))
        assertEquals(123_456_789UL, s.timestampNs)
        assertEquals(0.5, s.x, 0.0)
        assertEquals(-1.25, s.y, 0.0)
        assertEquals(9.75, s.z, 0.0)
        assertThrows(IllegalArgumentException::class.java) { Conversions.sample(1L, floatArrayOf(1f)) }
    }

    @Test
    fun scanResultsBecomeReadingsWithTheirAge() {
        // ScanResult.timestamp is µs since boot; the scan is as new as its newest result.
        val scanNs = Conversions.scanTimeNs(listOf(5_000_000L, 7_500_000L))
        assertEquals(7_500_000_000L, scanNs)
        val fresh = Conversions.wifi("AA:BB:CC:DD:EE:FF", -61, 7_500_000L, scanNs)
        assertEquals(0UL, fresh.ageMs)
        assertEquals(-61.0, fresh.rssiDbm, 0.0)
        val cached = Conversions.wifi("AA:BB:CC:DD:EE:FF", -70, 5_000_000L, scanNs)
        assertEquals(2_500UL, cached.ageMs)
        // A result stamped after the scan time (clock jitter) is not negative-aged.
        assertEquals(0UL, Conversions.wifi("AA:BB:CC:DD:EE:FF", -70, 8_000_000L, scanNs).ageMs)
        assertEquals(0L, Conversions.scanTimeNs(emptyList()))
    }
}

/**
 * Positions on a geo-referenced site: latitude/longitude, bearing and floor level come from
 * Rust (the site file's anchor and levels), `pushFix` takes latitude/longitude, and the
 * Android adapter's `Location` fields are read from the position as it is.
 */
class GeoConversionsTest {
    /** The wall clock read at 5 s since boot: 2023-11-14T22:13:20Z. */
    private val clock = Conversions.WallClockAnchor(wallTimeMs = 1_700_000_000_000L, elapsedRealtimeNs = 5_000_000_000L)

    private fun position(lat: Double?, lon: Double?, bearing: Double?, level: Int?, timestampNs: ULong = 3_250_000_000UL) = PositionEstimate(
        timestampNs = timestampNs, x = 3.0, y = 4.0, floor = 0U, floorName = "G", floorLevel = level, floorProbability = 1.0,
        latitudeDeg = lat, longitudeDeg = lon, accuracyM = 2.5, accuracy95M = 5.0,
        headingDeg = bearing?.let { 12.0 }, headingAccuracyDeg = bearing?.let { 5.0 }, bearingDeg = bearing,
        motionState = MotionState.WALKING, scenario = MotionScenario.DISTANCE_HEADING, steps = 2U,
    )

    @Test
    fun locationFieldsComeFromThePositionItself() {
        val fields = Conversions.locationFields(position(60.001, 24.002, 30.0, -1), clock)!!
        // The position's own time: elapsedRealtimeNanos its timestamp, time the same instant on
        // the wall clock (1.75 s before the anchor was read), not the time of the conversion.
        assertEquals(3_250_000_000L, fields.elapsedRealtimeNs)
        assertEquals(1_700_000_000_000L - 1_750L, fields.timeMs)
        // After the anchor, and a part of a millisecond before it rounds down (to the ms it falls in).
        assertEquals(1_700_000_002_000L, Conversions.locationFields(position(1.0, 1.0, null, null, 7_000_999_999UL), clock)!!.timeMs)
        assertEquals(1_699_999_999_999L, Conversions.locationFields(position(1.0, 1.0, null, null, 4_999_999_999UL), clock)!!.timeMs)
        assertEquals(60.001, fields.latitudeDeg, 0.0)
        assertEquals(24.002, fields.longitudeDeg, 0.0)
        assertEquals(2.5, fields.accuracyM, 0.0)
        assertEquals(30.0, fields.bearingDeg!!, 0.0)
        assertEquals(5.0, fields.bearingAccuracyDeg!!, 0.0)
        assertEquals(-1, fields.floorLevel)
        val still = Conversions.locationFields(position(60.0, 24.0, null, null), clock)!!
        org.junit.Assert.assertNull(still.bearingDeg)
        org.junit.Assert.assertNull(still.bearingAccuracyDeg)
        org.junit.Assert.assertNull(still.floorLevel)
        // A site without an anchor has no Location.
        org.junit.Assert.assertNull(Conversions.locationFields(position(null, null, 30.0, 1), clock))
    }

    @Test
    fun aGeoReferencedSiteGivesLatitudeLongitudeAndLevelAndTakesLatLonFixes() {
        val plain = java.io.File(System.getProperty("waymark.site") ?: System.getenv("WAYMARK_SITE")).readText()
        // The simulated site, anchored in Helsinki with +y due north, its first floor level 2.
        val geo = plain
            .replaceFirst("\"floors\":", "\"anchor\":{\"lat_deg\":60.17,\"lon_deg\":24.94},\"floors\":")
            .replaceFirst("\"elevation_m\":", "\"level\":2,\"elevation_m\":")
        val t0 = 1_000_000_000UL
        // A precise fix at a place of the simulated office (WaymarkTest's), in metres.
        val engine = PositioningEngine(geo, EngineOptions())
        val inMetres = engine.pushFix(PositionFix(timestampNs = t0, x = 35.5, y = 11.5, accuracyM = 0.5))
        assertEquals(2, inMetres.floorLevel)
        val here = Conversions.locationFields(inMetres, Conversions.WallClockAnchor(0L, 0L))!!
        // At 60°N a degree of latitude is 111 412 m and one of longitude 55 800 m (WGS84).
        assertEquals(60.17 + inMetres.y / 111_412.0, here.latitudeDeg, 1e-6)
        assertEquals(24.94 + inMetres.x / 55_800.0, here.longitudeDeg, 1e-5)
        // A fix at the estimate's latitude/longitude positions exactly as one at its x, y.
        val other = PositioningEngine(geo, EngineOptions())
        val inDegrees = other.pushFix(
            PositionFix(timestampNs = t0, latitudeDeg = here.latitudeDeg, longitudeDeg = here.longitudeDeg, accuracyM = 0.5),
        )
        val third = PositioningEngine(geo, EngineOptions())
        val atEstimate = third.pushFix(PositionFix(timestampNs = t0, x = inMetres.x, y = inMetres.y, accuracyM = 0.5))
        assertEquals(atEstimate.x, inDegrees.x, 1e-6)
        assertEquals(atEstimate.y, inDegrees.y, 1e-6)
        val lat = here.latitudeDeg
        // x and y and latitude/longitude together, or neither: rejected.
        assertThrows(PositioningException.InputRejected::class.java) {
            engine.pushFix(PositionFix(timestampNs = t0 + 1UL, x = 1.0, y = 1.0, latitudeDeg = lat, longitudeDeg = here.longitudeDeg, accuracyM = 1.0))
        }
        assertThrows(PositioningException.InputRejected::class.java) {
            engine.pushFix(PositionFix(timestampNs = t0 + 2UL, accuracyM = 1.0))
        }
        // The same fix on the site without an anchor: a typed error, and no lat/lon in positions.
        val unanchored = PositioningEngine(plain, EngineOptions())
        val e = assertThrows(PositioningException.InputRejected::class.java) {
            unanchored.pushFix(PositionFix(timestampNs = t0, latitudeDeg = lat, longitudeDeg = here.longitudeDeg, accuracyM = 0.5))
        }
        assertTrue(e.message!!, e.message!!.contains("not geo-referenced"))
        val local = unanchored.pushFix(PositionFix(timestampNs = t0, x = 35.5, y = 11.5, accuracyM = 0.5))
        org.junit.Assert.assertNull(local.latitudeDeg)
        org.junit.Assert.assertNull(Conversions.locationFields(local, Conversions.WallClockAnchor(0L, 0L)))
        engine.close()
        other.close()
        third.close()
        unanchored.close()
    }
}
