package dev.waymark

import java.io.File
import java.util.concurrent.atomic.AtomicInteger
import org.junit.Assert.assertEquals
import org.junit.Assert.assertNotEquals
import org.junit.Assert.assertTrue
import org.junit.Assert.fail
import org.junit.BeforeClass
import org.junit.Test

/**
 * Habits (issue 6) from Kotlin: learned from the simulated walk with position fixes and the
 * user's feedback, exported as JSON, imported into a second engine, refused with the typed
 * [PositioningException.HabitsRejected] when the model does not fit, and cleared.
 */
class HabitsTest {
    companion object {
        private lateinit var siteJson: String
        private lateinit var walk: List<Epoch>

        @BeforeClass
        @JvmStatic
        fun load() {
            siteJson = File(System.getProperty("waymark.site") ?: System.getenv("WAYMARK_SITE")).readText()
            walk = Walk.load(System.getProperty("waymark.walk") ?: System.getenv("WAYMARK_WALK"))
        }

        /**
         * The walk with a fix 1.5 m east and 0.5 m north of the truth just after every third
         * position, and the user confirming where they are after every seventh. Returns the
         * accepted (fixes, confirmations).
         */
        fun replayWithFixes(engine: PositioningEngine): Pair<Int, Int> {
            var positions = 0
            var fixes = 0
            var confirmations = 0
            for (e in walk) {
                engine.pushAccelerometer(e.accelerometer)
                engine.pushGyroscope(e.gyroscope)
                engine.pushMagnetometer(e.magnetometer)
                try {
                    engine.pushScan(e.scan())
                } catch (x: PositioningException.InputRejected) {
                    continue
                }
                positions++
                try {
                    if (positions % 7 == 3) {
                        engine.confirmPosition(e.timestampNs, e.truthX, e.truthY, 0u, 1.5)
                        confirmations++
                    }
                    if (positions % 3 == 1) {
                        engine.pushFix(PositionFix(e.timestampNs + 1000uL, e.truthX + 1.5, e.truthY + 0.5, 0u, 2.0))
                        fixes++
                    }
                } catch (x: PositioningException.InputRejected) {
                }
            }
            return fixes to confirmations
        }
    }

    @Test
    fun learnExportImportRoundTrip() {
        PositioningEngine(siteJson, EngineOptions()).use { engine ->
            assertEquals(FixBias(0.0, 0.0, 1.0), engine.fixBias())
            val (fixes, confirmations) = replayWithFixes(engine)
            assertTrue("$fixes fixes, $confirmations confirmations", fixes > 5 && confirmations > 2)

            val report = engine.learnHabits()
            assertTrue("$report", report.epochs > 10u)
            assertTrue("$report", report.learnedTransitions > 0uL)
            assertEquals(report.epochs.toULong(), report.totalEpochs)
            val learned = engine.fixBias()
            // 1.5 m east, 0.5 m north, shrunk toward 0 by the prior's 5 pseudo-fixes.
            assertTrue("$learned", learned.biasXM > 0.3 && learned.biasYM > 0.0 && learned.biasXM > learned.biasYM)

            // Each epoch once: a second pass learns nothing and changes nothing.
            val json = engine.exportHabits()
            val again = engine.learnHabits()
            assertEquals(0u, again.epochs)
            assertEquals(report.applied, again.applied)
            assertEquals(json, engine.exportHabits())

            PositioningEngine(siteJson, EngineOptions()).use { other ->
                val empty = other.exportHabits()
                assertNotEquals(empty, json)
                other.importHabits(json)
                assertEquals(json, other.exportHabits())
                assertEquals(learned, other.fixBias())
                other.clearHabits()
                assertEquals(empty, other.exportHabits())
                assertEquals(FixBias(0.0, 0.0, 1.0), other.fixBias())
            }
        }
    }

    @Test
    fun refusedModelsThrowHabitsRejectedAndChangeNothing() {
        PositioningEngine(siteJson, EngineOptions()).use { engine ->
            replayWithFixes(engine)
            engine.learnHabits()
            val json = engine.exportHabits()
            val errors = AtomicInteger()
            val listener = object : PositionListener {
                override fun onPosition(position: PositionEstimate) {}
                override fun onStatus(status: StatusUpdate) {}
                override fun onError(error: ErrorReport) {
                    errors.incrementAndGet()
                }
            }
            engine.subscribe(listener).use {
                val refused = listOf(
                    "", "{", "null", "[]", "\u0000", "💥",
                    // A lone surrogate is not text: replaced by '?' on the way, then refused.
                    "\uD800", "{\"format\":\"waymark-habits\",\"version\":1,\"site\":\"\uDC00\"}",
                    json.replace("waymark-habits", "waymark-site"),
                    json.replace(Regex("\"version\":\\d+"), "\"version\":99"),
                    json.replace(Regex("\"digest\":\"[0-9a-f]"), "\"digest\":\"g"),
                    json.replaceFirst("\"count\":[", "\"count\":[-1,"),
                    "[".repeat(100_000),
                )
                for ((k, bad) in refused.withIndex()) {
                    try {
                        engine.importHabits(bad)
                        fail("model $k (${bad.take(60)}) was accepted")
                    } catch (e: PositioningException.HabitsRejected) {
                        assertTrue(e.reason.isNotEmpty())
                    }
                    assertEquals("model $k changed the habits", json, engine.exportHabits())
                    assertEquals(k + 1, errors.get())
                }
                // The version check says what is wrong.
                try {
                    engine.importHabits(json.replace(Regex("\"version\":\\d+"), "\"version\":99"))
                    fail("a newer layout was accepted")
                } catch (e: PositioningException.HabitsRejected) {
                    assertTrue(e.reason, e.reason.contains("99"))
                }
            }
            // The engine goes on: its own model is still accepted.
            engine.importHabits(json)
            assertEquals(json, engine.exportHabits())
        }
    }

    @Test
    fun errorsAreExhaustive() {
        // An app's exhaustive `when` over the errors: the new case is one of them.
        val e: PositioningException = PositioningException.HabitsRejected("x")
        val what = when (e) {
            is PositioningException.InvalidSite -> "site"
            is PositioningException.InvalidConfig -> "config"
            is PositioningException.InputRejected -> "input"
            is PositioningException.SaltMismatch -> "salt"
            is PositioningException.HabitsRejected -> "habits"
            is PositioningException.Internal -> "bug"
        }
        assertEquals("habits", what)
    }
}
