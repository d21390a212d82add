@file:JvmName("WaymarkJava")

package dev.waymark.android

import dev.waymark.BeaconReading
import dev.waymark.MotionSample
import dev.waymark.PositionEstimate
import dev.waymark.PositioningEngineInterface
import dev.waymark.RadioScan
import dev.waymark.SurveyRecorderInterface
import dev.waymark.SurveySummary
import dev.waymark.WifiReading

/*
 * Java-friendly accessors and factories for the generated records whose fields are Kotlin's
 * unsigned types (`ULong`, `UInt`, `UShort`). Java cannot call those getters or constructors:
 * Kotlin mangles their names. From Java: `WaymarkJava.timestampNs(position)`,
 * `WaymarkJava.motionSample(t, x, y, z)`; values above `Long.MAX_VALUE` never occur (times are
 * ns since boot).
 */

/** [PositionEstimate.timestampNs] as a `long`: ns on the clock of every input. */
fun PositionEstimate.timestampNanos(): Long = timestampNs.toLong()

/** [PositionEstimate.floor] as an `int`: the floor's index in the site file. */
fun PositionEstimate.floorIndex(): Int = floor.toInt()

/** [PositionEstimate.steps] as a `long`: steps detected so far. */
fun PositionEstimate.stepCount(): Long = steps.toLong()

/** A motion sample: ns on the clock of every input, SI units. */
fun motionSample(timestampNs: Long, x: Double, y: Double, z: Double): MotionSample =
    MotionSample(timestampNs.toULong(), x, y, z)

/** A WiFi reading [ageMs] old at its scan's time. */
@JvmOverloads
fun wifiReading(bssid: String, rssiDbm: Double, ageMs: Long = 0): WifiReading =
    WifiReading(bssid, rssiDbm, ageMs.coerceAtLeast(0).toULong())

/** A beacon reading: an iBeacon by [uuid], [major] and [minor] (0 to 65535), or one by [address]. */
@JvmOverloads
fun beaconReading(uuid: String, major: Int, minor: Int, rssiDbm: Double, ageMs: Long = 0, address: String? = null): BeaconReading {
    require(major in 0..65_535 && minor in 0..65_535) { "major and minor are 0 to 65535" }
    return BeaconReading(uuid, major.toUShort(), minor.toUShort(), rssiDbm, ageMs.coerceAtLeast(0).toULong(), address)
}

/** A scan at [timestampNs]. */
fun radioScan(timestampNs: Long, wifi: List<WifiReading>, beacons: List<BeaconReading>): RadioScan =
    RadioScan(timestampNs.toULong(), wifi, beacons)

/** `engine.advance(timestampNs)`: an epoch from motion alone. */
fun advance(engine: PositioningEngineInterface, timestampNs: Long): PositionEstimate = engine.advance(timestampNs.toULong())

/** `recorder.markWaypoint(timestampNs, x, y, floor)`. */
fun markWaypoint(recorder: SurveyRecorderInterface, timestampNs: Long, x: Double, y: Double, floor: String) =
    recorder.markWaypoint(timestampNs.toULong(), x, y, floor)

/** [SurveySummary.samples] as a `long`. */
fun SurveySummary.sampleCount(): Long = samples.toLong()

/** [SurveySummary.scans] as a `long`. */
fun SurveySummary.scanCount(): Long = scans.toLong()

/** [SurveySummary.waypoints] as a `long`. */
fun SurveySummary.waypointCount(): Long = waypoints.toLong()
