@file:JvmName("WaymarkLocations")

package dev.waymark.android

import android.location.Location
import android.os.Build
import android.os.Bundle
import android.os.SystemClock
import dev.waymark.PositionEstimate

/**
 * A Waymark position as an Android [Location] (provider "waymark"), or `null` when the site
 * file is not geo-referenced (has no anchor): latitude/longitude from the position itself,
 * `accuracy` the 68% radius (as Android defines it), `bearing` and (API 26+)
 * `bearingAccuracyDegrees` when the heading is known, and the site frame's x, y, floor index,
 * floor name and floor level (`waymark.floorLevel`, when the site gives one, with
 * `waymark.levelUnmapped` true for a level the site has no floor for) in the extras.
 * `elapsedRealtimeNanos` is the position's timestamp (the clock of every input), and `time` the
 * same instant on the wall clock: the wall clock now, less the time elapsed since the
 * position ([Conversions.WallClockAnchor]). Every value comes from [Conversions.locationFields],
 * which the JVM test covers.
 */
fun PositionEstimate.toAndroidLocation(): Location? {
    val anchor = Conversions.WallClockAnchor(System.currentTimeMillis(), SystemClock.elapsedRealtimeNanos())
    val fields = Conversions.locationFields(this, anchor) ?: return null
    return Location("waymark").apply {
        latitude = fields.latitudeDeg
        longitude = fields.longitudeDeg
        accuracy = fields.accuracyM.toFloat()
        fields.bearingDeg?.let { bearing = it.toFloat() }
        if (Build.VERSION.SDK_INT >= Build.VERSION_CODES.O) {
            fields.bearingAccuracyDeg?.let { bearingAccuracyDegrees = it.toFloat() }
        }
        elapsedRealtimeNanos = fields.elapsedRealtimeNs
        time = fields.timeMs
        extras = Bundle().apply {
            putDouble("waymark.x", x)
            putDouble("waymark.y", y)
            putInt("waymark.floor", floor.toInt())
            putString("waymark.floorName", floorName)
            fields.floorLevel?.let { putInt("waymark.floorLevel", it) }
            putBoolean("waymark.levelUnmapped", levelUnmapped)
        }
    }
}
