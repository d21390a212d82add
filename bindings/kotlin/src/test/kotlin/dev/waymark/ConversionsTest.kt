package dev.waymark

import dev.waymark.android.Conversions
import org.junit.Assert.assertEquals
import org.junit.Assert.assertThrows
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

class GeoConversionsTest {
    private fun position(x: Double, y: Double, heading: Double?) = PositionEstimate(
        timestampNs = 1UL, x = x, y = y, floor = 0U, floorName = "G", floorProbability = 1.0, accuracyM = 2.5, accuracy95M = 5.0,
        headingDeg = heading, headingAccuracyDeg = heading?.let { 5.0 }, motionState = MotionState.WALKING,
        scenario = MotionScenario.DISTANCE_HEADING, steps = 2U,
    )

    @Test
    fun siteMetresBecomeLatitudeAndLongitude() {
        val origin = Conversions.GeoOrigin(60.0, 24.0, 0.0)
        // 111.2 m north is 0.001°; at 60°N, 55.6 m east is 0.001° of longitude.
        val north = Conversions.geo(position(0.0, 111.195, 10.0), origin)
        org.junit.Assert.assertEquals(60.001, north.latitudeDeg, 1e-6)
        org.junit.Assert.assertEquals(24.0, north.longitudeDeg, 1e-9)
        org.junit.Assert.assertEquals(10.0, north.bearingDeg!!, 1e-9)
        org.junit.Assert.assertEquals(2.5, north.accuracyM, 0.0)
        val east = Conversions.geo(position(55.597, 0.0, null), origin)
        org.junit.Assert.assertEquals(24.001, east.longitudeDeg, 1e-6)
        org.junit.Assert.assertNull(east.bearingDeg)
        // A site whose +y points east: +y metres go east, headings turn by 90°.
        val rotated = Conversions.geo(position(0.0, 55.597, 300.0), Conversions.GeoOrigin(60.0, 24.0, 90.0))
        org.junit.Assert.assertEquals(24.001, rotated.longitudeDeg, 1e-6)
        org.junit.Assert.assertEquals(60.0, rotated.latitudeDeg, 1e-9)
        org.junit.Assert.assertEquals(30.0, rotated.bearingDeg!!, 1e-9)
    }
}
