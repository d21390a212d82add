package dev.waymark.android

import dev.waymark.MotionSample
import dev.waymark.WifiReading

/**
 * Plain-Kotlin conversions from Android's sensor and WiFi types to Waymark's records. They use
 * no Android classes, so the JVM test covers them; [SensorAdapter] is the thin platform shell.
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
}
