package dev.waymark.android

import android.location.Location
import android.os.Bundle
import dev.waymark.PositionEstimate

/**
 * A Waymark position as an Android [Location] (provider "waymark"): latitude/longitude from
 * the site's [Conversions.GeoOrigin], `accuracy` the 68% radius (as Android defines it),
 * `bearing` when the heading is known, and the site frame's x, y, floor in the extras.
 */
fun PositionEstimate.toAndroidLocation(origin: Conversions.GeoOrigin): Location {
    val geo = Conversions.geo(this, origin)
    return Location("waymark").apply {
        latitude = geo.latitudeDeg
        longitude = geo.longitudeDeg
        accuracy = geo.accuracyM.toFloat()
        geo.bearingDeg?.let { bearing = it.toFloat() }
        elapsedRealtimeNanos = timestampNs.toLong()
        time = System.currentTimeMillis()
        extras = Bundle().apply {
            putDouble("waymark.x", x)
            putDouble("waymark.y", y)
            putInt("waymark.floor", floor.toInt())
            putString("waymark.floorName", floorName)
        }
    }
}
