package dev.waymark.android

import dev.waymark.PositionEstimate
import java.util.concurrent.Executor
import kotlinx.coroutines.channels.BufferOverflow
import kotlinx.coroutines.channels.awaitClose
import kotlinx.coroutines.flow.Flow
import kotlinx.coroutines.flow.buffer
import kotlinx.coroutines.flow.callbackFlow

/** A position or a status, in the order the client reported them. */
sealed class LocationEvent {
    data class Location(val position: PositionEstimate) : LocationEvent()
    data class Status(val status: LocationStatus) : LocationEvent()
}

/**
 * The positions of [request] as a cold Flow: collecting it requests updates, cancelling the
 * collection removes them, which stops the sensors and radios when no other caller is left.
 * A collector slower than the positions gets the newest 64 (older ones are dropped).
 */
fun WaymarkLocationClient.locations(request: LocationRequest = LocationRequest()): Flow<PositionEstimate> =
    callbackFlow {
        val callback = object : LocationCallback {
            override fun onLocation(position: PositionEstimate) {
                trySend(position)
            }
        }
        requestLocationUpdates(request, DIRECT, callback)
        awaitClose { removeLocationUpdates(callback) }
    }.buffer(64, BufferOverflow.DROP_OLDEST)

/** Positions and statuses of [request] as a Flow, as [locations]. */
fun WaymarkLocationClient.locationEvents(request: LocationRequest = LocationRequest()): Flow<LocationEvent> =
    callbackFlow {
        val callback = object : LocationCallback {
            override fun onLocation(position: PositionEstimate) {
                trySend(LocationEvent.Location(position))
            }

            override fun onStatus(status: LocationStatus) {
                trySend(LocationEvent.Status(status))
            }
        }
        requestLocationUpdates(request, DIRECT, callback)
        awaitClose { removeLocationUpdates(callback) }
    }.buffer(64, BufferOverflow.DROP_OLDEST)

/** The channel takes the value at once (it never blocks): no thread hop is needed. */
private val DIRECT = Executor { it.run() }
