package dev.waymark

import java.io.File
import org.junit.Assert.assertEquals
import org.junit.Assert.assertTrue
import org.junit.Assert.fail
import org.junit.Test

/**
 * Record → survey → position through the Kotlin bindings: the demo office's survey walks (from
 * `waymark sim-export`) are pushed to a [SurveyRecorder] as an app would push them, with a tap
 * at each state passed; `waymark survey` builds a site from the files; an engine on that site
 * positions the office's test walk, never surveyed, like the engine on the office's own site.
 */
class SurveyRecorderTest {
    private val surveyWalks = File(System.getProperty("waymark.surveyWalks"))

    @Test
    fun aRecordedSurveyPositionsTheTestWalkLikeTheDemo() {
        SurveyRoundTrip.inTempDir("waymark-survey") { dir ->
            val walks = SurveyRoundTrip.walkFiles(surveyWalks)
            assertEquals(12, walks.size)
            for (file in walks) {
                val survey = Walk.loadSurvey(file)
                val recorder = SurveyRecorder(dir.path, SurveyOptions(survey.name, "office", "JVM Test"))
                var tap = 0
                for (epoch in survey.epochs) {
                    // The surveyor taps each state as they pass it, between the scans.
                    while (tap < survey.taps.size && survey.taps[tap].timestampNs <= epoch.timestampNs) {
                        val t = survey.taps[tap++]
                        recorder.markWaypoint(t.timestampNs, t.x, t.y, "F1")
                    }
                    recorder.pushAccelerometer(epoch.accelerometer)
                    recorder.pushGyroscope(epoch.gyroscope)
                    recorder.pushMagnetometer(epoch.magnetometer)
                    recorder.pushScan(epoch.scan())
                }
                survey.taps.drop(tap).forEach { recorder.markWaypoint(it.timestampNs, it.x, it.y, "F1") }
                val summary = recorder.finish()
                assertEquals(1, summary.files.size)
                assertEquals(0uL, summary.samplesDropped)
                assertEquals(survey.epochs.size.toULong(), summary.scans)
                assertEquals(survey.taps.size.toULong(), summary.waypoints)
                assertTrue(summary.files[0], summary.files[0].endsWith("F1/path_data_files/${survey.name}-1.txt"))
                recorder.close()
            }
            SurveyRoundTrip.check(dir, "recorded survey")
        }
    }

    @Test
    fun badInputIsRefusedWithTypedErrorsAndNothingIsLost() {
        SurveyRoundTrip.inTempDir("waymark-survey") { dir ->
            try {
                SurveyRecorder(dir.path, SurveyOptions("no/slashes"))
                fail("a walk name that is not a file name")
            } catch (e: SurveyException.InputRejected) {
            }
            val recorder = SurveyRecorder(dir.path, SurveyOptions("walk"))
            val batch = listOf(MotionSample(10uL, 0.0, 0.0, 9.8), MotionSample(10uL, 0.0, 0.0, 9.8),
                MotionSample(20uL, Double.NaN, 0.0, 9.8))
            assertEquals(1u, recorder.pushAccelerometer(batch))
            val scan = RadioScan(1_000_000_000uL, listOf(WifiReading("aa:bb:cc:dd:ee:01", -70.0, 0uL)), emptyList())
            recorder.pushScan(scan)
            for (bad in listOf(scan, RadioScan(2_000_000_000uL, emptyList(), emptyList()),
                RadioScan(3_000_000_000uL, listOf(WifiReading("not a bssid", -70.0, 0uL)), emptyList()))) {
                try {
                    recorder.pushScan(bad)
                    fail("scan ${bad.timestampNs} should be refused")
                } catch (e: SurveyException.InputRejected) {
                }
            }
            try {
                recorder.markWaypoint(5uL, Double.NaN, 0.0, "F1")
                fail("a NaN waypoint")
            } catch (e: SurveyException.InputRejected) {
            }
            recorder.markWaypoint(5uL, 1.5, -2.25, "F1")
            val summary = recorder.finish()
            assertEquals(listOf(1uL, 2uL, 1uL, 3uL, 1uL),
                listOf(summary.samples, summary.samplesDropped, summary.scans, summary.scansRejected, summary.waypoints))
            val text = File(summary.files.single()).readText()
            assertTrue(text, text.contains("5\tTYPE_WAYPOINT\t1.5\t-2.25\n"))
            assertTrue(text, text.contains("1000000000\tTYPE_WIFI\t\taa:bb:cc:dd:ee:01\t-70\t0\t1000000000\n"))
            try {
                recorder.finish()
                fail("finished twice")
            } catch (e: SurveyException.Finished) {
            }
            recorder.close()

            val empty = SurveyRecorder(dir.path, SurveyOptions("empty"))
            try {
                empty.finish()
                fail("no waypoint")
            } catch (e: SurveyException.NoWaypoints) {
            }
            empty.close()
        }
    }
}
