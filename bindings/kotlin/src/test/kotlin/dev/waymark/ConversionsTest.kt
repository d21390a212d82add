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
