package dev.waymark.android

import dev.waymark.MotionSample
import dev.waymark.PositionEstimate
import dev.waymark.WifiReading
import kotlin.math.cos
import kotlin.math.sin

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

    /** Mean Earth radius, m (IUGG). */
    private const val EARTH_RADIUS_M = 6_371_008.8

    /**
     * Where the site frame sits on the Earth: the latitude/longitude of its origin and the
     * true azimuth of its +y axis (the site file's `north.site_rotation_rad`), in degrees.
     */
    data class GeoOrigin(val latitudeDeg: Double, val longitudeDeg: Double, val siteRotationDeg: Double)

    /** Latitude, longitude, bearing and accuracy for an Android `Location`. */
    data class Geo(val latitudeDeg: Double, val longitudeDeg: Double, val bearingDeg: Double?, val accuracyM: Double)

    /**
     * A position in the site frame as latitude/longitude (local tangent plane; metres of error
     * per kilometre from the origin are negligible inside a building).
     */
    fun geo(position: PositionEstimate, origin: GeoOrigin): Geo {
        val theta = Math.toRadians(origin.siteRotationDeg)
        val east = position.x * cos(theta) + position.y * sin(theta)
        val north = -position.x * sin(theta) + position.y * cos(theta)
        val lat = origin.latitudeDeg + Math.toDegrees(north / EARTH_RADIUS_M)
        val lon = origin.longitudeDeg + Math.toDegrees(east / (EARTH_RADIUS_M * cos(Math.toRadians(origin.latitudeDeg))))
        val bearing = position.headingDeg?.let { ((it + origin.siteRotationDeg) % 360.0 + 360.0) % 360.0 }
        return Geo(lat, lon, bearing, position.accuracyM)
    }
}
