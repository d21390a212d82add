package dev.waymark.android

import android.location.Location
import android.os.Build
import android.os.Bundle
import dev.waymark.PositionEstimate

/**
 * A Waymark position as an Android [Location] (provider "waymark"), or `null` when the site
 * file is not geo-referenced (has no anchor): latitude/longitude from the position itself,
 * `accuracy` the 68% radius (as Android defines it), `bearing` and (API 26+)
 * `bearingAccuracyDegrees` when the heading is known, and the site frame's x, y, floor index,
 * floor name and floor level (`waymark.floorLevel`, when the site gives one) in the extras.
 * Every value comes from [Conversions.locationFields], which the JVM test covers.
 */
fun PositionEstimate.toAndroidLocation(): Location? {
    val fields = Conversions.locationFields(this) ?: return null
    return Location("waymark").apply {
        latitude = fields.latitudeDeg
        longitude = fields.longitudeDeg
        accuracy = fields.accuracyM.toFloat()
        fields.bearingDeg?.let { bearing = it.toFloat() }
        if (Build.VERSION.SDK_INT >= Build.VERSION_CODES.O) {
            fields.bearingAccuracyDeg?.let { bearingAccuracyDegrees = it.toFloat() }
        }
        elapsedRealtimeNanos = timestampNs.toLong()
        time = System.currentTimeMillis()
        extras = Bundle().apply {
            putDouble("waymark.x", x)
            putDouble("waymark.y", y)
            putInt("waymark.floor", floor.toInt())
            putString("waymark.floorName", floorName)
            fields.floorLevel?.let { putInt("waymark.floorLevel", it) }
        }
    }
}
