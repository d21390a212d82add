package dev.waymark.android

import dev.waymark.SurveyRecorderInterface
import dev.waymark.SurveySummary
import java.util.concurrent.CompletableFuture

/**
 * A survey walk recorded by a [WaymarkLocationClient] ([WaymarkLocationClient.startSurvey]):
 * the client writes every motion batch and scan it takes into the recorder, on its own thread,
 * and the app adds the surveyor's taps. A survey app is the client, this session and a tap
 * button:
 *
 * ```
 * val session = client.startSurvey(SurveyRecorder(dir.path, SurveyOptions("lobby")), mainExecutor, callback)
 * tapButton.setOnClickListener { session.markWaypoint(x, y, "F1") }
 * doneButton.setOnClickListener { session.finish().thenAccept { summary -> ... } }
 * ```
 *
 * Both methods return at once: the recorder writes files, which the main thread must not
 * wait for. Their futures complete on the client's thread.
 */
class WaymarkSurveySession internal constructor(
    private val client: WaymarkLocationClient,
    internal val recorder: SurveyRecorderInterface,
    internal val callback: WaymarkLocationCallback,
) {
    // Guarded by the client's lock.
    internal var result: Result<SurveySummary>? = null
    internal var storageFailure: WaymarkLocationStatus? = null

    /**
     * The surveyor stands at ([x], [y]) m on the plan of [floor] ("F1") now: the tap is stamped
     * with the time of this call, on the clock of every input, and written after the motion
     * batches up to it. The future gives the tap's time (ns) or fails with the recorder's
     * `SurveyException` (`InputRejected` for a NaN coordinate, a floor name it cannot use) or
     * `IllegalStateException` once the session or the client ended.
     */
    fun markWaypoint(x: Double, y: Double, floor: String): CompletableFuture<Long> {
        val done = CompletableFuture<Long>()
        client.markWaypoint(this, x, y, floor, done)
        return done
    }

    /**
     * Ends the recording: the batches held go into the recorder, the session's request is
     * removed (the sensors and radios stop unless another caller wants them), and the recorder
     * is finished. The future gives its summary (the files for `waymark survey`) or fails with
     * its `SurveyException` (`NoWaypoints` before any tap). Closing the client finishes its
     * surveys too; `finish` then gives that result.
     */
    fun finish(): CompletableFuture<SurveySummary> {
        val done = CompletableFuture<SurveySummary>()
        client.finishSurvey(this, done)
        return done
    }
}
