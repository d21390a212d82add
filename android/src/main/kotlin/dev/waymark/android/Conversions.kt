package dev.waymark.android

import dev.waymark.MotionSample
import dev.waymark.PositionEstimate
import dev.waymark.PressureReading
import dev.waymark.WifiReading

/**
 * Plain-Kotlin conversions from Android's sensor and WiFi types to Waymark's records. They use
 * no Android classes, so the JVM test covers them; [WaymarkLocationClient] uses them.
 */
object Conversions {
    /** A `SensorEvent` (timestamp in ns since boot, values in SI units) as a Waymark sample. */
    fun sample(timestampNs: Long, values: FloatArray): MotionSample {
        require(values.size >= 3) { "a three-axis sensor event has at least 3 values" }
        return MotionSample(
            timestampNs = timestampNs.toULong(),
            x = values[0].toDouble(),
            y = values[1].toDouble(),
            z = values[2].toDouble(),
        )
    }

    /** A `TYPE_PRESSURE` `SensorEvent` (timestamp in ns since boot, `values[0]` in hPa). */
    fun pressure(timestampNs: Long, hpa: Float): PressureReading =
        PressureReading(timestampNs = timestampNs.toULong(), hpa = hpa.toDouble())

    /**
     * A `ScanResult`: its `timestamp` is µs since boot, the scan's own time is `scanTimeNs`
     * (the newest result's timestamp, in ns), so the reading's age is their difference.
     */
    fun wifi(bssid: String, level: Int, resultTimestampUs: Long, scanTimeNs: Long): WifiReading {
        val ageNs = (scanTimeNs - resultTimestampUs * 1_000L).coerceAtLeast(0L)
        return WifiReading(bssid = bssid, rssiDbm = level.toDouble(), ageMs = (ageNs / 1_000_000L).toULong())
    }

    /** The time of a scan: the newest result's timestamp, µs since boot, in ns. */
    fun scanTimeNs(resultTimestampsUs: List<Long>): Long = (resultTimestampsUs.maxOrNull() ?: 0L) * 1_000L

    /**
     * The wall clock at one instant of the monotonic clock every input and position uses
     * (`SystemClock.elapsedRealtimeNanos()`): `System.currentTimeMillis()` read with it. A
     * position's time, ns since boot, maps to the wall clock through it; the two clocks then
     * agree as long as nobody sets the wall clock, so an anchor is read afresh for each
     * conversion (`toAndroidLocation` does).
     */
    data class WallClockAnchor(val wallTimeMs: Long, val elapsedRealtimeNs: Long) {
        /** The wall time, ms since the Unix epoch, of [elapsedNs] on the monotonic clock. */
        fun wallTimeMs(elapsedNs: Long): Long = wallTimeMs + Math.floorDiv(elapsedNs - elapsedRealtimeNs, 1_000_000L)
    }

    /**
     * What an Android `Location` takes from a position: its time (`elapsedRealtimeNanos` the
     * position's own timestamp, `time` that instant on the wall clock, through [WallClockAnchor]),
     * latitude/longitude (WGS84, computed in Rust from the site file's anchor), `accuracy` the
     * 68% radius (as Android defines it), the true bearing and its one-σ accuracy when the
     * heading is known, and the floor's logical level when the site file gives one.
     */
    data class LocationFields(
        val timeMs: Long,
        val elapsedRealtimeNs: Long,
        val latitudeDeg: Double,
        val longitudeDeg: Double,
        val accuracyM: Double,
        val bearingDeg: Double?,
        val bearingAccuracyDeg: Double?,
        val floorLevel: Int?,
    )

    /** The `Location` fields of a position, its time on the wall clock through [clock]; `null`
     *  when the site is not geo-referenced. */
    fun locationFields(position: PositionEstimate, clock: WallClockAnchor): LocationFields? {
        val lat = position.latitudeDeg ?: return null
        val lon = position.longitudeDeg ?: return null
        val elapsedNs = position.timestampNs.toLong()
        return LocationFields(
            timeMs = clock.wallTimeMs(elapsedNs),
            elapsedRealtimeNs = elapsedNs,
            latitudeDeg = lat,
            longitudeDeg = lon,
            accuracyM = position.accuracyM,
            bearingDeg = position.bearingDeg,
            bearingAccuracyDeg = position.bearingDeg?.let { position.headingAccuracyDeg },
            floorLevel = position.floorLevel,
        )
    }
}
