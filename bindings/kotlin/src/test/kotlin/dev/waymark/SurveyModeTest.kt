package dev.waymark

import dev.waymark.android.ClientState
import dev.waymark.android.MotionSensor
import dev.waymark.android.WaymarkLocationClient
import dev.waymark.android.WaymarkLocationRequest
import dev.waymark.android.WaymarkLocationStatus
import dev.waymark.android.WifiResult
import java.io.File
import java.util.concurrent.ExecutionException
import java.util.concurrent.Executor
import kotlin.math.roundToInt
import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertNotNull
import org.junit.Assert.assertNull
import org.junit.Assert.assertTrue
import org.junit.Assert.fail
import org.junit.Test

/**
 * Survey mode: the location client drives a SurveyRecorder with the motion and scans it takes
 * from the (fake) phone, and the surveyor's taps from the app's UI. The demo office's survey
 * walks go through it; `waymark survey` builds a site from the files, and an engine on that
 * site positions the office's test walk like the engine on the office's own site.
 */
class SurveyModeTest {
    private val surveyWalks = File(System.getProperty("waymark.surveyWalks"))
    private val siteJson = File(System.getProperty("waymark.site")).readText()
    private val direct = Executor { it.run() }

    /**
     * Walks [survey] through [phone]: its motion from the sensors, each epoch's WiFi results
     * broadcast 300 ms after the scan (another app's scans, or the client's own), and the
     * surveyor's taps on the UI's button at their times.
     */
    private fun walkSurvey(phone: FakePhone, survey: SurveyWalk, tap: (Tap) -> Unit) {
        var next = 0
        fun tapsUntil(tNs: Long) {
            while (next < survey.taps.size && survey.taps[next].timestampNs.toLong() <= tNs) {
                val t = survey.taps[next++]
                phone.scheduler.runUntil(t.timestampNs.toLong())
                tap(t)
            }
        }
        for (epoch in survey.epochs) {
            val samples = epoch.accelerometer.map { MotionSensor.ACCELEROMETER to it } +
                epoch.gyroscope.map { MotionSensor.GYROSCOPE to it } +
                epoch.magnetometer.map { MotionSensor.MAGNETOMETER to it }
            for ((sensor, s) in samples.sortedBy { it.second.timestampNs }) {
                tapsUntil(s.timestampNs.toLong())
                phone.scheduler.runUntil(s.timestampNs.toLong())
                phone.sensors.emit(sensor, s)
            }
            val t = epoch.timestampNs.toLong()
            tapsUntil(t)
            phone.scheduler.runUntil(t)
            val results = epoch.wifi.map { WifiResult(it.bssid, it.rssiDbm.roundToInt(), t / 1_000L) }
            phone.scheduler.at(t + 300_000_000L) { phone.wifi.broadcast(results) }
        }
        val end = survey.epochs.last().timestampNs.toLong() + 1_000_000_000L
        tapsUntil(Long.MAX_VALUE)
        phone.scheduler.runUntil(end)
    }

    @Test
    fun aSurveyAppIsTheClientPlusATapButton() {
        SurveyRoundTrip.inTempDir("waymark-survey-mode") { dir ->
            val walks = SurveyRoundTrip.walkFiles(surveyWalks)
            assertEquals(12, walks.size)
            for (file in walks) {
                val survey = Walk.loadSurvey(file)
                val phone = FakePhone()
                // No site yet, so no engine: the client records.
                val client = WaymarkLocationClient.forSurvey(phone.platform)
                val recorder = SurveyRecorder(dir.path, SurveyOptions(survey.name, "office", "JVM fake phone"))
                val heard = RecordingCallback()
                val session = client.startSurvey(recorder, direct, heard, WaymarkLocationRequest(ble = false))
                assertEquals(ClientState.RUNNING, client.state)
                val tapTimes = ArrayList<Long>()
                walkSurvey(phone, survey) { t -> tapTimes += session.markWaypoint(t.x, t.y, "F1").get() }
                val summary = session.finish().get()
                // Every scan and tap went in, each tap at the time it was made.
                assertEquals(survey.taps.map { it.timestampNs.toLong() }, tapTimes)
                assertEquals(survey.taps.size.toULong(), summary.waypoints)
                assertEquals(survey.epochs.size.toULong(), summary.scans)
                assertEquals(0uL, summary.samplesDropped)
                assertEquals(survey.epochs.sumOf { it.accelerometer.size + it.gyroscope.size + it.magnetometer.size }.toULong(), summary.samples)
                assertTrue(summary.files.single(), summary.files.single().endsWith("F1/path_data_files/${survey.name}-1.txt"))
                assertEquals(0L, client.stats().surveyScansRejected)
                assertTrue("finishing stopped the phone's sensors and radios", phone.idle)
                assertTrue(heard.statuses.toString(), heard.statuses.isEmpty())
                assertTrue(heard.positions.isEmpty())
                client.close()
                recorder.close()
            }
            SurveyRoundTrip.check(dir, "survey mode")
        }
    }

    @Test
    fun surveyModeBesideTrackingTapsThatFailAndCloseFinishing() {
        SurveyRoundTrip.inTempDir("waymark-survey-mode") { dir ->
            val survey = Walk.loadSurvey(SurveyRoundTrip.walkFiles(surveyWalks).first())
            val phone = FakePhone()
            val engine = RecordingEngine(PositioningEngine(siteJson, EngineOptions()))
            val client = WaymarkLocationClient(engine, phone.platform)
            // A blue dot and a recording at once: one set of sensors and radios feeds both.
            val tracking = RecordingCallback()
            client.requestLocationUpdates(WaymarkLocationRequest(ble = false), direct, tracking)
            val recorder = SurveyRecorder(dir.path, SurveyOptions("both", "office"))
            val surveying = RecordingCallback()
            val session = client.startSurvey(recorder, direct, surveying, WaymarkLocationRequest(ble = false))
            // Finishing before any tap: NoWaypoints, and the recording goes on.
            try {
                session.finish().get()
                fail("finished without a tap")
            } catch (e: ExecutionException) {
                assertTrue(e.cause.toString(), e.cause is SurveyException.NoWaypoints)
            }
            // A tap the recorder refuses fails its future; the next one is taken.
            try {
                session.markWaypoint(Double.NaN, 1.0, "F1").get()
                fail("a NaN tap")
            } catch (e: ExecutionException) {
                assertTrue(e.cause.toString(), e.cause is SurveyException.InputRejected)
            }
            walkSurvey(phone, survey) { t -> session.markWaypoint(t.x, t.y, "F1").get() }
            assertTrue("positions while surveying: ${tracking.positions.size}", tracking.positions.size >= survey.epochs.size - 2)
            assertEquals("the survey's callback hears the engine's positions too", tracking.positions.size, surveying.positions.size)
            // Closing the client finishes the survey; finish then gives that summary.
            client.close()
            assertTrue(phone.idle)
            val summary = session.finish().get()
            assertEquals(survey.taps.size.toULong(), summary.waypoints)
            assertEquals(engine.scans.size.toULong(), summary.scans)
            try {
                session.markWaypoint(1.0, 1.0, "F1").get()
                fail("a tap after the end")
            } catch (e: ExecutionException) {
                assertTrue(e.cause is IllegalStateException)
            }
            recorder.close()
            engine.close()
        }
    }

    @Test
    fun aStorageFailureIsAConditionAndTheRecordingResumes() {
        SurveyRoundTrip.inTempDir("waymark-survey-mode") { dir ->
            val phone = FakePhone()
            val client = WaymarkLocationClient.forSurvey(phone.platform)
            // A recorder whose storage fails for three calls, as a full disk would.
            val inner = SurveyRecorder(dir.path, SurveyOptions("flaky"))
            var failing = 0
            val recorder = object : SurveyRecorderInterface by inner {
                override fun pushScan(scan: RadioScan) {
                    if (failing > 0) throw SurveyException.Io("disk full")
                    inner.pushScan(scan)
                }

                override fun resume() {
                    if (failing > 0) {
                        failing--
                        throw SurveyException.Io("disk full")
                    }
                    inner.resume()
                }
            }
            val heard = RecordingCallback()
            val session = client.startSurvey(recorder, direct, heard, WaymarkLocationRequest(ble = false))
            session.markWaypoint(0.0, 0.0, "F1").get()
            fun scan(k: Int) {
                val t = (k + 1) * 2 * 1_000_000_000L
                phone.scheduler.runUntil(t)
                phone.wifi.broadcast(listOf(WifiResult("02:00:00:00:00:0$k", -60, t / 1_000L)))
            }
            scan(0)
            failing = 3
            scan(1)
            val failed = heard.statuses.single()
            assertTrue(failed.toString(), failed is WaymarkLocationStatus.SurveyStorageFailed && failed.reason.contains("disk full"))
            assertEquals(160, failed.code)
            // Each later scan tries resume first; the third try succeeds (scan 5).
            for (k in 2..4) scan(k)
            assertEquals(failed, heard.statuses.last())
            scan(5)
            assertEquals(WaymarkLocationStatus.Restored(failed), heard.statuses.last())
            session.markWaypoint(10.0, 0.0, "F1").get()
            val summary = session.finish().get()
            assertTrue("lost: ${client.stats().surveyInputsLost}", client.stats().surveyInputsLost >= 3)
            assertEquals("scans 0, and 5 after the storage came back", 2uL, summary.scans)
            assertNull(client.stats().lastRejection)
            client.close()
            inner.close()
        }
    }
}
