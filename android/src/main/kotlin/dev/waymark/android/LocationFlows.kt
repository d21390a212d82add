package dev.waymark.android

import dev.waymark.PositionEstimate
import java.util.concurrent.Executor
import kotlinx.coroutines.channels.BufferOverflow
import kotlinx.coroutines.channels.awaitClose
import kotlinx.coroutines.flow.Flow
import kotlinx.coroutines.flow.buffer
import kotlinx.coroutines.flow.callbackFlow

/** A position or a status, in the order the client reported them. */
sealed class WaymarkLocationEvent {
    data class Location(val position: PositionEstimate) : WaymarkLocationEvent()
    data class Status(val status: WaymarkLocationStatus) : WaymarkLocationEvent()
}

/**
 * The positions of [request] as a cold Flow: collecting it requests updates, cancelling the
 * collection removes them, which stops the sensors and radios when no other caller is left.
 * The Flow completes when the client is closed (at once, for a client closed already). A
 * collector slower than the positions gets the newest 64 (older ones are dropped).
 */
fun WaymarkLocationClient.locations(request: WaymarkLocationRequest = WaymarkLocationRequest()): Flow<PositionEstimate> =
    callbackFlow {
        val callback = object : WaymarkLocationCallback {
            override fun onLocation(position: PositionEstimate) {
                trySend(position)
            }

            override fun onClientClosed() {
                channel.close()
            }
        }
        requestOrComplete(request, callback)
        awaitClose { removeLocationUpdates(callback) }
    }.buffer(64, BufferOverflow.DROP_OLDEST)

/** Positions and statuses of [request] as a Flow, as [locations]. */
fun WaymarkLocationClient.locationEvents(request: WaymarkLocationRequest = WaymarkLocationRequest()): Flow<WaymarkLocationEvent> =
    callbackFlow {
        val callback = object : WaymarkLocationCallback {
            override fun onLocation(position: PositionEstimate) {
                trySend(WaymarkLocationEvent.Location(position))
            }

            override fun onStatus(status: WaymarkLocationStatus) {
                trySend(WaymarkLocationEvent.Status(status))
            }

            override fun onClientClosed() {
                channel.close()
            }
        }
        requestOrComplete(request, callback)
        awaitClose { removeLocationUpdates(callback) }
    }.buffer(64, BufferOverflow.DROP_OLDEST)

/** Requests updates for a Flow's [callback]; on a closed client the Flow completes. */
private fun WaymarkLocationClient.requestOrComplete(request: WaymarkLocationRequest, callback: WaymarkLocationCallback) {
    try {
        requestLocationUpdates(request, DIRECT, callback)
    } catch (e: IllegalStateException) {
        if (!isClosed) throw e
        callback.onClientClosed()
    }
}

/** The channel takes the value at once (it never blocks): no thread hop is needed. */
private val DIRECT = Executor { it.run() }
