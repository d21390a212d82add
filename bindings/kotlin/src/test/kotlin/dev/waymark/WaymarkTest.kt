package dev.waymark

import java.io.File
import java.util.Collections
import java.util.concurrent.CountDownLatch
import java.util.concurrent.Executors
import java.util.concurrent.TimeUnit
import java.util.concurrent.atomic.AtomicInteger
import kotlin.math.hypot
import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertNotNull
import org.junit.Assert.assertTrue
import org.junit.Assert.fail
import org.junit.BeforeClass
import org.junit.Test

/**
 * The Kotlin surface of Waymark on the JVM, against the bindings uniffi generates: the simulated
 * walk of `waymark sim-export` pushed through a Kotlin listener, typed errors, a throwing
 * listener, eight threads at once, and cancellation; the same site with hashed transmitter ids
 * (`waymark site hash`) with and without its salt. Paths come from the system properties
 * `waymark.site` / `waymark.walk` / `waymark.hashedSite` / `waymark.salt` (or the environment
 * variables `WAYMARK_SITE` / `WAYMARK_WALK` / `WAYMARK_HASHED_SITE` / `WAYMARK_SALT_FILE`).
 */
class WaymarkTest {
    /** Counts what it hears; remembers the last position. */
    class Counter : PositionListener {
        val positions = AtomicInteger()
        val statuses = AtomicInteger()
        val errors = AtomicInteger()
        @Volatile var last: PositionEstimate? = null

        override fun onPosition(position: PositionEstimate) {
            positions.incrementAndGet()
            last = position
        }

        override fun onStatus(status: StatusUpdate) {
            statuses.incrementAndGet()
        }

        override fun onError(error: ErrorReport) {
            errors.incrementAndGet()
        }
    }

    /** Throws from every call, as a buggy app's listener might: the typed error and an unexpected one. */
    class Throwing : PositionListener {
        val positions = AtomicInteger()
        val statuses = AtomicInteger()

        override fun onPosition(position: PositionEstimate) {
            positions.incrementAndGet()
            throw PositioningException.Internal("app bug in onPosition")
        }

        override fun onStatus(status: StatusUpdate) {
            statuses.incrementAndGet()
            throw IllegalStateException("app bug in onStatus")
        }

        override fun onError(error: ErrorReport) {
            throw IllegalStateException("app bug in onError")
        }
    }

    /**
     * Throws a kotlin.Error (`TODO()`), which uniffi's generated callback code does not catch
     * (it catches Exception): JNA's callback dispatcher reports it and the call returns as if
     * it succeeded.
     */
    class ThrowingError : PositionListener {
        val calls = AtomicInteger()

        override fun onPosition(position: PositionEstimate) {
            calls.incrementAndGet()
            TODO("app never finished onPosition")
        }

        override fun onStatus(status: StatusUpdate) {
            calls.incrementAndGet()
            throw StackOverflowError("app bug in onStatus")
        }

        override fun onError(error: ErrorReport) {
            calls.incrementAndGet()
        }
    }

    companion object {
        private lateinit var sitePath: String
        private lateinit var siteJson: String
        private lateinit var walk: List<Epoch>

        private fun setting(property: String, env: String): String =
            System.getProperty(property) ?: System.getenv(env)
                ?: throw IllegalStateException("set -D$property=... or $env")

        @BeforeClass
        @JvmStatic
        fun loadWalk() {
            sitePath = setting("waymark.site", "WAYMARK_SITE")
            siteJson = File(sitePath).readText()
            walk = Walk.load(setting("waymark.walk", "WAYMARK_WALK"))
            assertTrue("the walk has epochs", walk.size > 10)
        }

        /** Pushes one epoch's IMU batches then its scan; the position, or null if rejected. */
        fun pushEpoch(engine: PositioningEngine, epoch: Epoch): PositionEstimate? {
            assertEquals(epoch.accelerometer.size.toUInt(), engine.pushAccelerometer(epoch.accelerometer))
            assertEquals(epoch.gyroscope.size.toUInt(), engine.pushGyroscope(epoch.gyroscope))
            assertEquals(epoch.magnetometer.size.toUInt(), engine.pushMagnetometer(epoch.magnetometer))
            return try {
                engine.pushScan(epoch.scan())
            } catch (e: PositioningException.InputRejected) {
                null
            }
        }

        fun newEngine(): PositioningEngine = PositioningEngine(siteJson, EngineOptions())

        /** A salt file's hex digits as bytes, as an app would hold its venue's salt. */
        fun saltFromHex(text: String): ByteArray =
            text.trim().chunked(2).map { it.toInt(16).toByte() }.toByteArray()

        fun sample(t: Long, x: Double) = MotionSample(t.toULong(), x, 0.0, 9.81)
    }

    @Test
    fun aWalkThroughTheBindingsWithAListener() {
        PositioningEngine.fromPath(sitePath, EngineOptions()).use { engine ->
            val counter = Counter()
            val subscription = engine.subscribe(counter)
            val errors = ArrayList<Double>()
            for (epoch in walk) {
                val p = pushEpoch(engine, epoch) ?: continue
                errors.add(hypot(p.x - epoch.truthX, p.y - epoch.truthY))
                assertEquals("office", p.floorName)
                assertTrue(p.accuracyM > 0.0)
                assertTrue(p.accuracy95M >= p.accuracyM)
                assertTrue(p.beyondRadioM >= 0.0 && p.accuracyM >= p.beyondRadioM)
            }
            assertTrue("most scans are accepted", errors.size > walk.size / 2)
            assertEquals("one position per accepted scan", errors.size, counter.positions.get())
            val mean = errors.average()
            println("walk: ${walk.size} epochs, ${errors.size} accepted, mean error %.3f m".format(mean))
            assertTrue("mean error $mean m", mean < 1.5)
            assertEquals(counter.last, engine.position())
            assertFalse(engine.track().isEmpty())
            assertNotNull(engine.fixedLagPosition())
            subscription.cancel()
            subscription.close()
        }
    }

    @Test
    fun withoutTheTrackThePositionsAreTheSame() {
        val kept = PositioningEngine(siteJson, EngineOptions())
        val none = PositioningEngine(siteJson, EngineOptions(track = false))
        assertTrue("the track is kept by default", EngineOptions().track)
        var positions = 0
        for (epoch in walk) {
            val expected = pushEpoch(kept, epoch)
            assertEquals(expected, pushEpoch(none, epoch))
            assertEquals(kept.fixedLagPosition(), none.fixedLagPosition())
            if (expected != null) positions++
        }
        assertTrue("positions: $positions", positions > walk.size / 2)
        assertFalse(kept.track().isEmpty())
        assertTrue(none.track().isEmpty())
        kept.close()
        none.close()
    }

    @Test
    fun aHashedSitePositionsAsTheRawOneWithItsSaltAndFailsWithout() {
        val hashedPath = setting("waymark.hashedSite", "WAYMARK_HASHED_SITE")
        val hashedJson = File(hashedPath).readText()
        assertFalse("no BSSID in the hashed file", hashedJson.contains("\"bssid\""))
        val salt = saltFromHex(File(setting("waymark.salt", "WAYMARK_SALT_FILE")).readText())
        assertEquals(32, salt.size)
        val raw = newEngine()
        val hashed = PositioningEngine.fromPath(hashedPath, EngineOptions(siteSalt = salt))
        for (epoch in walk) {
            assertEquals(pushEpoch(raw, epoch), pushEpoch(hashed, epoch))
        }
        assertNotNull(hashed.position())
        raw.close()
        hashed.close()

        val wrong = salt.copyOf().also { it[0] = (it[0].toInt() xor 1).toByte() }
        for ((what, options) in listOf("no salt" to EngineOptions(), "a wrong salt" to EngineOptions(siteSalt = wrong))) {
            try {
                PositioningEngine(hashedJson, options).close()
                fail("a hashed site with $what was accepted")
            } catch (e: PositioningException.SaltMismatch) {
                assertTrue(e.reason.contains("salt"))
            }
        }
        try {
            PositioningEngine(hashedJson, EngineOptions(siteSalt = ByteArray(8))).close()
            fail("an 8-byte salt was accepted")
        } catch (e: PositioningException.InvalidConfig) {
        }
    }

    @Test
    fun zonesFeedbackAndPositionFixes() {
        PositioningEngine.fromPath(sitePath, EngineOptions()).use { engine ->
            val zones = engine.zonePosterior()
            assertEquals(12, zones.size)
            assertEquals("aisle", zones[0].name)
            assertEquals(ZoneKind.CORRIDOR, zones[0].kind)
            assertEquals(ZoneKind.HALL, zones[11].kind)
            val first = pushEpoch(engine, walk[0]) ?: pushEpoch(engine, walk[1])!!
            assertTrue(first.zone == null || zones.any { it.name == first.zone })
            assertTrue(first.zoneProbability in 0.0..1.0 + 1e-9)
            // "I am in room 3", about the position just shown.
            val pinned = engine.confirmZone(first.timestampNs, "room 3")
            assertEquals("room 3", pinned.zone)
            assertEquals(1.0, pinned.zoneProbability, 1e-9)
            assertEquals(1.0, engine.zonePosterior().first { it.name == "room 3" }.probability, 1e-9)
            try {
                engine.confirmZone(first.timestampNs + 1UL, "cellar")
                fail("an unknown zone was accepted")
            } catch (e: PositioningException.InputRejected) {
                assertTrue(e.reason.contains("cellar"))
            }
            // "Within 2 m of the aisle's first state", later.
            val tapped = engine.confirmPosition(first.timestampNs + 5_000_000_000UL, 1.7, 11.5, 0U, 2.0)
            assertEquals("aisle", tapped.zone)
            // A precise fix 40 s later (time to walk there) at the stair hall's middle state.
            val fixed = engine.pushFix(PositionFix(first.timestampNs + 45_000_000_000UL, 35.5, 11.5, accuracyM = 0.5))
            assertEquals("stair hall", fixed.zone)
            assertTrue(hypot(fixed.x - 35.5, fixed.y - 11.5) < 1.0)
            try {
                engine.pushFix(PositionFix(first.timestampNs + 46_000_000_000UL, Double.NaN, 11.5, null, 3.0))
                fail("a NaN fix was accepted")
            } catch (e: PositioningException.InputRejected) {
            }
            assertEquals(fixed, engine.position())
        }
    }

    @Test
    fun zoneAndGeofenceEventsReachTheListener() {
        PositioningEngine.fromPath(sitePath, EngineOptions()).use { engine ->
            val heard = Collections.synchronizedList(ArrayList<StatusUpdate>())
            val subscription = engine.subscribe(object : PositionListener {
                override fun onPosition(position: PositionEstimate) {}
                override fun onStatus(status: StatusUpdate) { heard.add(status) }
                override fun onError(error: ErrorReport) {}
            })
            // Around the aisle's first state, and a square over the stair hall's middle.
            engine.addGeofence(Geofence("entrance", 0U, GeofenceShape.Circle(1.7, 11.5, 3.0)))
            val square = listOf(SitePoint(33.0, 9.0), SitePoint(38.0, 9.0), SitePoint(38.0, 14.0), SitePoint(33.0, 14.0))
            engine.addGeofence(Geofence("stairs", 0U, GeofenceShape.Polygon(square)))
            assertEquals(listOf("entrance", "stairs"), engine.geofences().map { it.id })
            try {
                engine.addGeofence(Geofence("stairs", 0U, GeofenceShape.Circle(1.7, 11.5, 3.0)))
                fail("a taken id was accepted")
            } catch (e: PositioningException.InputRejected) {
                assertTrue(e.reason, e.reason.contains("stairs"))
            }
            val first = pushEpoch(engine, walk[0]) ?: pushEpoch(engine, walk[1])!!
            heard.clear()
            engine.confirmPosition(first.timestampNs, 1.7, 11.5, 0U, 1.0)
            assertTrue(heard.toString(), heard.any { it is StatusUpdate.GeofenceEntered && it.id == "entrance" })
            assertTrue(heard.toString(), heard.any { it is StatusUpdate.ZoneEntered && it.zone == "aisle" })
            assertTrue(engine.geofenceProbability("entrance")!! >= 0.68)
            heard.clear()
            engine.confirmPosition(first.timestampNs + 40_000_000_000UL, 35.5, 11.5, 0U, 1.0)
            val names = heard.mapNotNull {
                when (it) {
                    is StatusUpdate.GeofenceExited -> "-${it.id}"
                    is StatusUpdate.GeofenceEntered -> "+${it.id}"
                    is StatusUpdate.ZoneExited -> "-${it.zone}"
                    is StatusUpdate.ZoneEntered -> "+${it.zone}"
                    else -> null
                }
            }
            assertEquals(listOf("-aisle", "-entrance", "+stair hall", "+stairs"), names)
            assertTrue(engine.removeGeofence("stairs"))
            assertFalse(engine.removeGeofence("stairs"))
            assertEquals(null, engine.geofenceProbability("stairs"))
            subscription.cancel()
        }
    }

    @Test
    fun anInjectedPanicIsAnExceptionAndTheEngineGoesOn() {
        val engine = PositioningEngine.fromPath(sitePath, EngineOptions())
        val counter = Counter()
        val subscription = engine.subscribe(counter)
        val wifi = listOf(WifiReading("02:00:00:00:00:00", -60.0, 0UL))
        try {
            // This test build panics inside Rust on this timestamp (feature fault-injection).
            engine.pushScan(RadioScan(ULong.MAX_VALUE - 7UL, wifi, emptyList()))
            fail("the injected panic did not surface")
        } catch (e: PositioningException.Internal) {
            assertTrue(e.reason.isNotEmpty())
        }
        assertEquals(1, counter.errors.get())
        val position = engine.pushScan(RadioScan(10UL, wifi, emptyList()))
        assertEquals(1, counter.positions.get())
        // A panic half-way through an epoch (this build, at Long.MAX_VALUE - 8, after the filter has
        // stepped and the listeners' position was made) is undone: the same position, no
        // position heard, the error heard; a scan and an advance alike.
        for (call in listOf<() -> Unit>(
            { engine.pushScan(RadioScan(Long.MAX_VALUE.toULong() - 8UL, wifi, emptyList())) },
            { engine.advance(Long.MAX_VALUE.toULong() - 8UL) },
        )) {
            try {
                call()
                fail("the injected panic did not surface")
            } catch (e: PositioningException.Internal) {
            }
        }
        assertEquals(position, engine.position())
        assertEquals(1, counter.positions.get())
        assertEquals(3, counter.errors.get())
        engine.pushScan(RadioScan(20UL, wifi, emptyList()))
        assertEquals(2, counter.positions.get())
        subscription.cancel()
    }

    @Test
    fun errorsAreTyped() {
        try {
            PositioningEngine("{\"format_version\": 1", EngineOptions())
            fail("bad JSON was accepted")
        } catch (e: PositioningException.InvalidSite) {
            assertTrue(e.reason.isNotEmpty())
        }
        try {
            PositioningEngine.fromPath("/nonexistent/site.json", EngineOptions())
            fail("a missing file was accepted")
        } catch (e: PositioningException.InvalidSite) {
        }
        try {
            PositioningEngine(siteJson, EngineOptions(fixedLagEpochs = 1000u))
            fail("fixed_lag_epochs = 1000 was accepted")
        } catch (e: PositioningException.InvalidConfig) {
        }

        newEngine().use { engine ->
            val bssid = walk.first().wifi.first().bssid
            fun scan(t: Long, b: String = bssid, rssi: Double = -60.0) =
                RadioScan(t.toULong(), listOf(WifiReading(b, rssi, 0uL)), emptyList())

            engine.pushScan(scan(1_000))
            val rejected = mapOf(
                "out of order" to scan(500),
                "same time" to scan(1_000),
                "invalid BSSID" to scan(2_000, b = "not a bssid"),
                "NaN RSSI" to scan(2_000, rssi = Double.NaN),
                "empty" to RadioScan(2_000uL, emptyList(), emptyList()),
            )
            for ((what, bad) in rejected) {
                try {
                    engine.pushScan(bad)
                    fail("$what scan was accepted")
                } catch (e: PositioningException.InputRejected) {
                    assertTrue(e.reason.isNotEmpty())
                }
            }
            // The engine is unchanged by the rejections and goes on.
            assertEquals(1_000uL, engine.position()!!.timestampNs)
            engine.pushScan(scan(2_000))

            // NaN and backwards samples are dropped and not counted, not thrown.
            val batch = listOf(sample(2_005, 0.0), sample(2_004, 0.0), sample(2_006, Double.NaN), sample(2_007, 0.1))
            assertEquals(2u, engine.pushAccelerometer(batch))
            assertEquals(0u, engine.pushGyroscope(listOf(MotionSample(2_010uL, Double.NaN, 0.0, 0.0))))
            assertEquals(0u, engine.pushMagnetometer(emptyList()))
        }
    }

    /**
     * A BLE beacon known by its advertiser address only (Eddystone, or an iBeacon left at
     * major = minor = 0), as an Android app reads it from `ScanResult.getDevice().getAddress()`.
     * The site is the simulated one with its first access point turned into such a beacon.
     */
    @Test
    fun beaconsKnownByAddressOnly() {
        val wifi = "{\"wifi\":{\"bssid\":\"02:00:00:00:00:00\"}}"
        assertTrue("the simulator's first access point moved", siteJson.contains(wifi))
        val site = siteJson.replace(wifi, "{\"ble_address\":{\"mac\":\"02:00:00:00:00:00\"}}")
        val uuid = "fda50693-a4e2-4fb1-afcf-c6eb07647825"
        PositioningEngine(site, EngineOptions()).use { engine ->
            fun scan(t: Long, beacon: BeaconReading) = RadioScan(t.toULong(), emptyList(), listOf(beacon))
            // UUID, major and minor default to "", 0 and 0: the address alone identifies it.
            assertEquals(10uL, engine.pushScan(scan(10, BeaconReading(rssiDbm = -60.0, address = "02-00-00-00-00-00"))).timestampNs)
            engine.pushScan(scan(20, BeaconReading(uuid = uuid, rssiDbm = -60.0, address = "02:00:00:00:00:00")))
            val rejected = mapOf(
                "an iBeacon with a major/minor (another, unknown beacon)" to
                    BeaconReading(uuid = uuid, major = 1u, minor = 2u, rssiDbm = -60.0, address = "02:00:00:00:00:00"),
                "neither UUID nor address" to BeaconReading(rssiDbm = -60.0),
                "an empty address" to BeaconReading(rssiDbm = -60.0, address = ""),
                "a short address" to BeaconReading(rssiDbm = -60.0, address = "02:00:00:00:00"),
                "not an address" to BeaconReading(rssiDbm = -60.0, address = "not a mac address"),
            )
            for ((what, beacon) in rejected) {
                try {
                    engine.pushScan(scan(30, beacon))
                    fail("$what was accepted")
                } catch (e: PositioningException.InputRejected) {
                    assertTrue(e.reason.isNotEmpty())
                }
            }
            assertEquals(30uL, engine.pushScan(scan(30, BeaconReading(rssiDbm = -60.0, address = "02:00:00:00:00:00"))).timestampNs)
        }
    }

    @Test
    fun aThrowingListenerBreaksNothing() {
        // Count (and silence) what JNA's callback dispatcher reports: the kotlin.Errors.
        val reported = AtomicInteger()
        val jnaHandler = com.sun.jna.Native.getCallbackExceptionHandler()
        com.sun.jna.Native.setCallbackExceptionHandler { _, _ -> reported.incrementAndGet() }
        try {
            throwingListeners(reported)
        } finally {
            com.sun.jna.Native.setCallbackExceptionHandler(jnaHandler)
        }
    }

    private fun throwingListeners(reported: AtomicInteger) {
        newEngine().use { engine ->
            val throwing = Throwing()
            val throwingError = ThrowingError()
            val before = Counter()
            val after = Counter()
            val s1 = engine.subscribe(throwing)
            val s0 = engine.subscribe(throwingError)
            val s2 = engine.subscribe(before) // runs after the throwing ones
            var accepted = 0
            for (epoch in walk.take(10)) {
                if (pushEpoch(engine, epoch) != null) accepted++
            }
            assertTrue(accepted > 0)
            assertEquals("the throwing listener was called", accepted, throwing.positions.get())
            assertTrue("the throwing listener heard a status", throwing.statuses.get() > 0)
            assertEquals(accepted + throwing.statuses.get(), throwingError.calls.get())
            assertEquals(throwingError.calls.get(), reported.get())
            assertEquals(accepted, before.positions.get())
            // The next push still works and a listener subscribed now hears it.
            val s3 = engine.subscribe(after)
            val next = walk[10]
            assertNotNull(pushEpoch(engine, next))
            assertEquals(accepted + 1, before.positions.get())
            assertEquals(1, after.positions.get())
            engine.advance(next.timestampNs + 1_000_000_000uL)
            assertEquals(2, after.positions.get())
            listOf(s0, s1, s2, s3).forEach { it.close() }
        }
    }

    @Test(timeout = 300_000)
    fun eightThreadsAtOnce() {
        newEngine().use { engine ->
            val threads = 8
            val accepted = AtomicInteger()
            val heard = AtomicInteger()
            val failures = Collections.synchronizedList(ArrayList<Throwable>())
            val start = CountDownLatch(1)
            val pool = Executors.newFixedThreadPool(threads) { r -> Thread(r).apply { isDaemon = true } }
            try {
                val futures = (0 until threads).map { thread ->
                    pool.submit {
                        try {
                            start.await()
                            // A listener that calls back into the engine: listeners run with no lock held.
                            val reentrant = object : PositionListener {
                                override fun onPosition(position: PositionEstimate) {
                                    heard.incrementAndGet()
                                    engine.position()
                                }

                                override fun onStatus(status: StatusUpdate) {}

                                override fun onError(error: ErrorReport) {}
                            }
                            for ((k, epoch) in walk.withIndex().filter { it.index % threads == thread }.map { it.value }.withIndex()) {
                                val subscription = engine.subscribe(if (k % 2 == 0) reentrant else Counter())
                                val t = epoch.timestampNs.toLong()
                                engine.pushAccelerometer(listOf(sample(t - 1, 0.0)))
                                engine.pushGyroscope(epoch.gyroscope)
                                try {
                                    engine.pushScan(epoch.scan())
                                    accepted.incrementAndGet()
                                } catch (e: PositioningException.InputRejected) {
                                    // Scans from other threads may arrive out of order.
                                }
                                engine.position()
                                engine.track()
                                engine.fixedLagPosition()
                                subscription.cancel()
                                subscription.close()
                            }
                        } catch (t: Throwable) {
                            failures.add(t)
                        }
                    }
                }
                start.countDown()
                for (f in futures) f.get(240, TimeUnit.SECONDS) // a deadlock fails here
            } finally {
                pool.shutdownNow()
            }
            if (failures.isNotEmpty()) throw AssertionError("a thread failed", failures.first())
            assertTrue(accepted.get() > 0)
            assertTrue(heard.get() > 0)
            assertNotNull(engine.position())
            // Still usable afterwards.
            val counter = Counter()
            engine.subscribe(counter).use {
                engine.advance(walk.last().timestampNs + 5_000_000_000uL)
                assertEquals(1, counter.positions.get())
            }
        }
    }

    @Test
    fun cancelCloseAndDestroyStopDelivery() {
        newEngine().use { engine ->
            val cancelled = Counter()
            val closed = Counter()
            val destroyed = Counter()
            val kept = Counter()
            val s1 = engine.subscribe(cancelled)
            val s2 = engine.subscribe(closed)
            val s3 = engine.subscribe(destroyed)
            val s4 = engine.subscribe(kept)
            var t = walk.first().timestampNs
            fun epoch() {
                t += 1_000_000_000uL
                engine.advance(t)
            }
            epoch()
            listOf(cancelled, closed, destroyed, kept).forEach { assertEquals(1, it.positions.get()) }

            s1.cancel()
            s1.cancel() // idempotent
            epoch()
            assertEquals(1, cancelled.positions.get())
            assertEquals(2, kept.positions.get())

            s2.close()
            epoch()
            assertEquals(2, closed.positions.get())

            s3.destroy()
            epoch()
            assertEquals(3, destroyed.positions.get())

            assertEquals(4, kept.positions.get())
            s1.close()
            s4.close()
            epoch()
            assertEquals(4, kept.positions.get())
        }
    }
}
