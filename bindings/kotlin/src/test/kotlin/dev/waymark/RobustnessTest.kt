package dev.waymark

import java.io.File
import org.junit.Assert.assertEquals
import org.junit.Assert.assertNotNull
import org.junit.Assert.assertTrue
import org.junit.Assert.fail
import org.junit.BeforeClass
import org.junit.Test

/**
 * Bad input through every method of the Kotlin API (issue 7): NaN, infinities, empty, huge and
 * malformed values. Nothing may crash the JVM: each call returns, drops and counts, or throws a
 * [PositioningException]; and the engine keeps working afterwards.
 */
class RobustnessTest {
    companion object {
        private lateinit var sitePath: String
        private lateinit var siteJson: String
        private lateinit var walk: List<Epoch>
        private val weird = listOf(
            Double.NaN, Double.POSITIVE_INFINITY, Double.NEGATIVE_INFINITY,
            Double.MAX_VALUE, -Double.MAX_VALUE, Double.MIN_VALUE, -0.0, 1e300,
        )
        private val badStrings = listOf(
            "", " ", "\u0000", "💥💥💥", "not a mac", "zz:zz:zz:zz:zz:zz",
            "02:00:00:00:00:00:00", "02:00:00:00:00", "x".repeat(100_000),
        )

        @BeforeClass
        @JvmStatic
        fun load() {
            sitePath = System.getProperty("waymark.site") ?: System.getenv("WAYMARK_SITE")
            siteJson = File(sitePath).readText()
            walk = Walk.load(System.getProperty("waymark.walk") ?: System.getenv("WAYMARK_WALK"))
        }

        fun finite(p: PositionEstimate) =
            listOf(p.x, p.y, p.floorProbability, p.accuracyM, p.accuracy95M, p.beyondRadioM).all { it.isFinite() } &&
                p.accuracyM > 0.0 && p.beyondRadioM >= 0.0 && p.accuracyM >= p.beyondRadioM &&
                (p.headingDeg?.isFinite() ?: true)

        /** The walk's first `n` epochs, as an app pushes them: every accepted position finite. */
        fun replay(engine: PositioningEngine, epochs: List<Epoch>): Int {
            var accepted = 0
            for (e in epochs) {
                engine.pushAccelerometer(e.accelerometer)
                engine.pushGyroscope(e.gyroscope)
                engine.pushMagnetometer(e.magnetometer)
                try {
                    assertTrue(finite(engine.pushScan(e.scan())))
                    accepted++
                } catch (x: PositioningException.InputRejected) {
                }
            }
            return accepted
        }
    }

    /** Runs `call`; it must return or throw a PositioningException (which one is not asked). */
    private fun <T> survives(what: String, call: () -> T): T? = try {
        call()
    } catch (e: PositioningException) {
        null
    } catch (e: Throwable) {
        throw AssertionError("$what threw ${e.javaClass.name}: ${e.message}", e)
    }

    /**
     * A string with a lone surrogate is not valid UTF-16: uniffi's generated code for a `String`
     * argument throws CharacterCodingException before the call reaches Rust (documented on
     * `PositioningEngine` for the constructors; transmitter ids are converted instead, see
     * [loneSurrogatesInIdsAreInputRejected]). True if `call` did that.
     */
    private fun notSent(call: () -> Unit): Boolean = try {
        call()
        false
    } catch (e: java.nio.charset.CharacterCodingException) {
        true
    }

    @Test
    fun malformedSitesAreInvalidSite() {
        val cuts = listOf(0, 1, 10, siteJson.length / 3, siteJson.length / 2, siteJson.length - 1)
        val bad = badStrings + listOf("{", "null", "[]", "{}", "{\"format_version\": 1", "[".repeat(100_000)) +
            cuts.map { siteJson.substring(0, it) } +
            siteJson.replace("\"states\"", "\"stat\u0000es\"") +
            siteJson.replace(Regex("-?[0-9]+\\.[0-9]+"), "NaN")
        assertTrue(notSent { PositioningEngine("\uD800", EngineOptions()) })
        assertTrue(notSent { PositioningEngine.fromPath("\uDC00", EngineOptions()) })
        for (json in bad) {
            try {
                PositioningEngine(json, EngineOptions()).close()
                fail("a malformed site of ${json.length} chars was accepted")
            } catch (e: PositioningException.InvalidSite) {
                assertTrue(e.reason.isNotEmpty())
            }
        }
        for (path in badStrings + listOf("/", "/nonexistent/site.json", "/dev/null", "/proc", sitePath + "\u0000")) {
            try {
                PositioningEngine.fromPath(path, EngineOptions()).close()
                fail("the site at '${path.take(40)}' was accepted")
            } catch (e: PositioningException.InvalidSite) {
            }
        }
    }

    @Test
    fun optionsOutOfRangeAreInvalidConfigOrHarmless() {
        val options = weird.map { EngineOptions(stepLengthM = it) } +
            listOf(0.0, -0.7).map { EngineOptions(stepLengthM = it) } +
            weird.map { EngineOptions(declinationDeg = it) } +
            weird.map { EngineOptions(siteRotationDeg = it) } +
            listOf(UInt.MAX_VALUE, 1000u, 0u).map { EngineOptions(fixedLagEpochs = it) } +
            TransitionKind.values().map { EngineOptions(transition = it) }
        for (o in options) {
            val engine = try {
                PositioningEngine(siteJson, o)
            } catch (e: PositioningException.InvalidConfig) {
                continue
            }
            // Accepted: then it must position finitely.
            engine.use { assertTrue("$o", replay(it, walk.take(6)) > 0) }
        }
    }

    @Test
    fun badSamplesAreDroppedAndCounted() {
        PositioningEngine(siteJson, EngineOptions()).use { engine ->
            val pushes = listOf<(List<MotionSample>) -> UInt>(
                engine::pushAccelerometer, engine::pushGyroscope, engine::pushMagnetometer,
            )
            for (push in pushes) {
                assertEquals(0u, push(emptyList()))
                val bad = weird.flatMap { v ->
                    listOf(MotionSample(5uL, v, 0.0, 9.8), MotionSample(5uL, 0.0, v, 9.8), MotionSample(5uL, 0.0, 0.0, v))
                }
                assertTrue(push(bad) <= 1u) // -0.0 and MIN_VALUE are fine values, but one timestamp
                // Backwards, duplicate, and the clock's ends.
                val times = listOf(10uL, 9uL, 10uL, 0uL, ULong.MAX_VALUE - 1uL, 11uL)
                push(times.map { MotionSample(it, 0.0, 0.0, 9.8) })
            }
            // A batch of 300 000 samples: taken (a bounded backlog keeps the newest).
            val huge = (1..300_000).map { MotionSample(20_000_000_000uL + it.toULong() * 1_000_000uL, 0.0, 0.0, 9.81) }
            assertNotNull(survives("a huge batch") { engine.pushGyroscope(huge) })
        }
        // Barometer readings: every weird value and one outside 300-1100 hPa dropped and counted.
        PositioningEngine(siteJson, EngineOptions()).use { engine ->
            val readings = weird.mapIndexed { i, v -> PressureReading(10uL + i.toULong(), v) } +
                PressureReading(100uL, 1000.0) + PressureReading(99uL, 1000.0) + PressureReading(101uL, 5.0)
            assertEquals(1u, engine.pushPressure(readings))
            assertEquals(readings.size.toULong() - 1uL, engine.inputStats().pressureDropped)
            assertTrue(replay(engine, walk.take(10)) > 5)
        }
        // Still usable: a fresh engine's walk after the same abuse positions finitely.
        PositioningEngine(siteJson, EngineOptions()).use { engine ->
            engine.pushAccelerometer(weird.map { MotionSample(1uL, it, it, it) })
            assertTrue(replay(engine, walk.take(10)) > 5)
        }
    }

    @Test
    fun badScansAreRejectedAndTheEngineGoesOn() {
        PositioningEngine(siteJson, EngineOptions()).use { engine ->
            val errors = WaymarkTest.Counter()
            val subscription = engine.subscribe(errors)
            val known = walk.first().wifi.first().bssid
            var t = 1_000uL
            var rejections = 0
            fun push(wifi: List<WifiReading>, beacons: List<BeaconReading> = emptyList(), at: ULong = ++t) {
                val p = survives("pushScan") { engine.pushScan(RadioScan(at, wifi, beacons)) }
                if (p == null) rejections++ else assertTrue("$p", finite(p))
            }
            push(emptyList())
            for (v in weird) push(listOf(WifiReading(known, v, 0uL)))
            for (s in badStrings) push(listOf(WifiReading(s, -60.0, 0uL)))
            for (s in badStrings) {
                push(emptyList(), listOf(BeaconReading(uuid = s, major = 1u, minor = 2u, rssiDbm = -60.0)))
                push(emptyList(), listOf(BeaconReading(rssiDbm = -60.0, address = s)))
            }
            push(listOf(WifiReading("\uD800", -60.0, 0uL)))
            push(emptyList(), listOf(BeaconReading(rssiDbm = -60.0, address = "a\uDFFF")))
            push(listOf(WifiReading(known, -60.0, ULong.MAX_VALUE)))
            push(List(10_000) { WifiReading(known, -60.0 - it % 30, it.toULong()) }) // duplicates
            push(List(10_000) { WifiReading("0a:00:00:00:%02x:%02x".format(it / 256, it % 256), -70.0, 0uL) })
            push(listOf(WifiReading(known, -60.0, 0uL)), at = 0uL) // before the last epoch
            // The injected panic (a test build, feature fault-injection) is Internal.
            try {
                engine.pushScan(RadioScan(ULong.MAX_VALUE - 7uL, listOf(WifiReading(known, -60.0, 0uL)), emptyList()))
                fail("the injected panic did not surface")
            } catch (e: PositioningException.Internal) {
                rejections++
            }
            assertTrue(rejections > 30)
            assertEquals("every rejection reached onError", rejections, errors.errors.get())
            // Reads, advance, and a walk after it all.
            engine.position()?.let { assertTrue(finite(it)) }
            assertTrue(engine.track().all { it.x.isFinite() && it.y.isFinite() })
            engine.fixedLagPosition()
            survives("advance(0)") { engine.advance(0uL) }
            val shifted = walk.take(10).map { e ->
                val d = 100_000_000_000uL
                Epoch(e.timestampNs + d, e.truthX, e.truthY,
                    e.accelerometer.map { it.copy(timestampNs = it.timestampNs + d) },
                    e.gyroscope.map { it.copy(timestampNs = it.timestampNs + d) },
                    e.magnetometer.map { it.copy(timestampNs = it.timestampNs + d) }, e.wifi)
            }
            assertTrue(replay(engine, shifted) > 5)
            // Past any phone's clock (a negative Long as ULong): refused, not adopted.
            try {
                engine.advance(ULong.MAX_VALUE)
                fail("an epoch past the end of the clock was accepted")
            } catch (e: PositioningException.InputRejected) {
            }
            // The end of the clock: accepted once, then everything is out of order.
            val end = Long.MAX_VALUE.toULong()
            assertTrue(finite(engine.advance(end)))
            try {
                engine.advance(end)
                fail("a second epoch at the end of the clock was accepted")
            } catch (e: PositioningException.InputRejected) {
            }
            assertEquals(end, engine.position()!!.timestampNs)
            subscription.close()
            subscription.close() // twice: nothing
        }
    }

    /**
     * A transmitter id holding a lone UTF-16 surrogate is not text. uniffi's own String encoding
     * threw CharacterCodingException for it, before the call reached Rust and after it had
     * cloned the engine's handle, which then leaked: `close()` no longer freed the engine. Ids
     * now go through the custom type TransmitterIdString (uniffi.toml), whose conversion puts
     * `?` for a lone surrogate: the scan reaches the engine and is InputRejected like any
     * malformed id, reported to onError, the engine unchanged and freed on close.
     */
    @Test
    fun loneSurrogatesInIdsAreInputRejected() {
        val engine = PositioningEngine(siteJson, EngineOptions())
        val errors = WaymarkTest.Counter()
        val subscription = engine.subscribe(errors)
        assertTrue(replay(engine, walk.take(4)) > 0)
        val before = engine.position()
        val known = walk.first().wifi.first().bssid
        var t = before!!.timestampNs
        val bad: List<Pair<List<WifiReading>, List<BeaconReading>>> = listOf(
            listOf(WifiReading("\uD800", -60.0, 0uL)) to emptyList(),
            listOf(WifiReading(known.dropLast(1) + "\uDC00", -60.0, 0uL)) to emptyList(),
            listOf(WifiReading(known, -60.0, 0uL), WifiReading("\uDBFF\uDBFF", -70.0, 0uL)) to emptyList(),
            emptyList<WifiReading>() to listOf(BeaconReading(rssiDbm = -60.0, address = "a\uDFFF")),
            emptyList<WifiReading>() to listOf(BeaconReading(uuid = "\uD83D", major = 1u, minor = 2u, rssiDbm = -60.0)),
        )
        for ((wifi, beacons) in bad) {
            try {
                engine.pushScan(RadioScan(++t, wifi, beacons))
                fail("a scan with a lone surrogate in an id was accepted")
            } catch (e: PositioningException.InputRejected) {
                assertTrue(e.reason, e.reason.contains("?"))
            }
        }
        assertEquals(bad.size, errors.errors.get())
        assertEquals(before, engine.position())
        // A valid surrogate pair passes as it is: no BSSID, but Waymark saw what was sent.
        try {
            engine.pushScan(RadioScan(++t, listOf(WifiReading("💥", -60.0, 0uL)), emptyList()))
            fail("an emoji BSSID was accepted")
        } catch (e: PositioningException.InputRejected) {
            assertTrue(e.reason, e.reason.contains("💥"))
        }
        // Nothing leaked: closing the engine frees it, and with it the listener it held.
        // (uniffi's handle map of Kotlin listeners is internal; this test is compiled with the
        // bindings. Another test's engine freed meanwhile can only lower the count further.)
        val listeners = FfiConverterTypePositionListener.handleMap.size
        engine.close()
        assertTrue(FfiConverterTypePositionListener.handleMap.size <= listeners - 1)
        subscription.close()
    }

    @Test
    fun callsAfterCloseThrowInsteadOfCrashing() {
        val engine = PositioningEngine(siteJson, EngineOptions())
        val subscription = engine.subscribe(WaymarkTest.Counter())
        engine.close()
        engine.close() // twice: nothing
        for ((what, call) in listOf<Pair<String, () -> Any?>>(
            "position" to { engine.position() },
            "pushScan" to { engine.pushScan(RadioScan(1uL, emptyList(), emptyList())) },
            "pushAccelerometer" to { engine.pushAccelerometer(emptyList()) },
            "advance" to { engine.advance(1uL) },
            "subscribe" to { engine.subscribe(WaymarkTest.Counter()) },
        )) {
            try {
                call()
                fail("$what after close returned")
            } catch (e: IllegalStateException) {
            }
        }
        // The subscription outlives its engine harmlessly.
        subscription.cancel()
        subscription.close()
    }
}
