package dev.waymark

import dev.waymark.android.BleAdvertisements
import dev.waymark.android.ClientState
import dev.waymark.android.IBeacon
import dev.waymark.android.WaymarkLocationRequest
import dev.waymark.android.WaymarkLocationStatus
import dev.waymark.android.MotionSensor
import dev.waymark.android.WaymarkPermission
import dev.waymark.android.WaymarkLocationClient
import dev.waymark.android.WifiResult
import dev.waymark.android.WifiScanBudget
import dev.waymark.android.locations
import java.io.File
import java.util.concurrent.Executor
import kotlin.math.hypot
import kotlinx.coroutines.Dispatchers
import kotlinx.coroutines.launch
import kotlinx.coroutines.runBlocking
import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertNotNull
import org.junit.Assert.assertNull
import org.junit.Assert.assertTrue
import org.junit.BeforeClass
import org.junit.Test

/**
 * The Android location client (android/.../WaymarkLocationClient.kt) on the JVM: a real engine
 * on the simulated site, the simulated walk replayed through fake sensors and a fake WiFi radio
 * on a fake clock, and fake permissions and switches.
 */
class LocationClientTest {
    companion object {
        private lateinit var siteJson: String
        private lateinit var walk: List<Epoch>
        private const val S = 1_000_000_000L

        @BeforeClass
        @JvmStatic
        fun load() {
            siteJson = File(System.getProperty("waymark.site") ?: System.getenv("WAYMARK_SITE")).readText()
            walk = Walk.load(System.getProperty("waymark.walk") ?: System.getenv("WAYMARK_WALK"))
        }

        fun engine() = RecordingEngine(PositioningEngine(siteJson, EngineOptions()))

        /** The walk's truth at [tNs], linear between epochs; null outside the walk. */
        fun truthAt(tNs: Long): Pair<Double, Double>? {
            val after = walk.indexOfFirst { it.timestampNs.toLong() >= tNs }
            if (after < 0) return null
            val b = walk[after]
            if (after == 0) return if (b.timestampNs.toLong() == tNs) b.truthX to b.truthY else null
            val a = walk[after - 1]
            val f = (tNs - a.timestampNs.toLong()).toDouble() / (b.timestampNs - a.timestampNs).toDouble()
            return (a.truthX + f * (b.truthX - a.truthX)) to (a.truthY + f * (b.truthY - a.truthY))
        }

        fun meanError(positions: List<PositionEstimate>): Double = positions.mapNotNull { p ->
            truthAt(p.timestampNs.toLong())?.let { (x, y) -> hypot(p.x - x, p.y - y) }
        }.average()

        /** The most scans any [windowNs] window (both ends included, as Android counts) holds. */
        fun mostInWindow(calls: List<Long>, windowNs: Long): Int =
            calls.indices.maxOfOrNull { i -> calls.count { it >= calls[i] && it - calls[i] <= windowNs } } ?: 0

        val direct = Executor { it.run() }
    }

    @Test
    fun positionsOnTheSimulatedWalkAreAsAccurateAsTheEngineOwn() {
        // The engine alone, every scan pushed by hand (WaymarkTest's walk).
        val own = PositioningEngine(siteJson, EngineOptions())
        val ownPositions = walk.mapNotNull { epoch ->
            own.pushAccelerometer(epoch.accelerometer)
            own.pushGyroscope(epoch.gyroscope)
            own.pushMagnetometer(epoch.magnetometer)
            try { own.pushScan(epoch.scan()) } catch (e: PositioningException.InputRejected) { null }
        }
        own.close()
        // The client, another app scanning at the walk's cadence (its results reach every app).
        val phone = FakePhone()
        val engine = engine()
        val client = WaymarkLocationClient(engine, phone.platform)
        val callback = RecordingCallback()
        client.requestLocationUpdates(WaymarkLocationRequest(ble = false), direct, callback)
        phone.replay(walk, passive = { true })
        client.close()
        val mine = meanError(callback.positions)
        val theirs = meanError(ownPositions)
        println("location client: ${callback.positions.size} positions, mean error %.3f m (engine alone %.3f m)".format(mine, theirs))
        assertTrue("a position per scan at least: ${callback.positions.size}", callback.positions.size >= walk.size - 1)
        assertTrue("mean error $mine m", mine < 1.5)
        assertTrue("mean error $mine m against the engine's $theirs m", mine < theirs + 0.3)
        // Every scan went in after the motion up to its time (one 100 Hz sample of slack).
        for ((scan, motion) in engine.scans.zip(engine.motionBeforeScan)) {
            assertTrue("motion up to ${scan.timestampNs} pushed first (had $motion)", motion >= scan.timestampNs.toLong() - 10_000_000L)
        }
        // Batched: one FFI call per half second of samples (plus a flush per epoch), not per sample.
        val samples = walk.sumOf { it.accelerometer.size }
        assertEquals(samples, engine.accelerometerSamples)
        assertTrue("${engine.accelerometerCalls} calls for $samples samples", engine.accelerometerCalls <= samples / 50 + 2 * walk.size)
        assertTrue(phone.sensors.registrations.all { it.second == 10_000 && it.third == 0 })
        assertTrue("stopped when closed", phone.idle)
        assertEquals(ClientState.STOPPED, client.state)
        engine.close()
    }

    @Test
    fun theBarometerReachesTheEngineBeforeEachScan() {
        val phone = FakePhone(hasBarometer = true)
        val engine = engine()
        val client = WaymarkLocationClient(engine, phone.platform)
        val callback = RecordingCallback()
        client.requestLocationUpdates(WaymarkLocationRequest(ble = false, sensorMaxLatencyMs = 200), direct, callback)
        assertTrue(client.usesBarometer)
        // 10 Hz, reports held up to the request's 200 ms, as the motion sensors are.
        assertEquals(listOf(100_000 to 200_000), phone.barometer.registrations)
        // A level walk at 1000 hPa, with a few hundredths of noise and one reading that is no pressure.
        val start = walk.first().timestampNs.toLong()
        var emitted = 0
        phone.replay(walk, passive = { true }, pressureHpa = { t ->
            emitted++
            if (emitted == 25) Float.NaN else 1000f + 0.03f * ((t - start) / 100_000_000L % 3).toFloat()
        })
        val stats = client.stats()
        client.close()
        assertTrue("readings: $emitted", emitted > 400)
        // Every reading went in, in batches, and the engine dropped the one that was no pressure.
        assertEquals(emitted, engine.pressureReadings)
        assertEquals(1UL, engine.inputStats().pressureDropped)
        assertTrue("${stats.pressureBatches} batches", stats.pressureBatches in 1L..(emitted / 10).toLong())
        // Every scan went in after the barometer up to its time (one 10 Hz reading of slack).
        for ((scan, pressure) in engine.scans.zip(engine.pressureBeforeScan)) {
            assertTrue("pressure up to ${scan.timestampNs} pushed first (had $pressure)", pressure >= scan.timestampNs.toLong() - 100_000_000L)
        }
        assertTrue("positions: ${callback.positions.size}", callback.positions.size >= walk.size - 1)
        assertTrue("stopped when closed", phone.idle && !client.usesBarometer)
        engine.close()
    }

    @Test
    fun aPhoneWithoutABarometerOrARequestForItRunsWithoutOne() {
        for ((hasBarometer, request) in listOf(false to WaymarkLocationRequest(ble = false), true to WaymarkLocationRequest(ble = false, barometer = false))) {
            val phone = FakePhone(hasBarometer = hasBarometer)
            val engine = engine()
            val client = WaymarkLocationClient(engine, phone.platform)
            val callback = RecordingCallback()
            client.requestLocationUpdates(request, direct, callback)
            phone.replay(walk.take(10), passive = { true }, pressureHpa = { 1000f })
            // Not a condition: the client runs, and says so with no status.
            assertEquals(ClientState.RUNNING, client.state)
            assertTrue(callback.statuses.toString(), callback.statuses.isEmpty())
            assertFalse(client.usesBarometer)
            assertTrue(phone.barometer.registrations.isEmpty())
            assertEquals(0, engine.pressureReadings)
            assertTrue(callback.positions.size >= 9)
            client.close()
            engine.close()
        }
        // Refused by Android: off, and not asked again on every tick.
        val phone = FakePhone(hasBarometer = true)
        phone.barometer.refuse = true
        val engine = engine()
        val client = WaymarkLocationClient(engine, phone.platform)
        client.requestLocationUpdates(WaymarkLocationRequest(ble = false), direct, RecordingCallback())
        phone.scheduler.runUntil(60 * S)
        assertFalse(client.usesBarometer)
        assertEquals(ClientState.RUNNING, client.state)
        client.close()
        engine.close()
    }

    @Test
    fun theBarometerStopsWhilePausedAndResumes() {
        val phone = FakePhone(hasBarometer = true)
        val engine = engine()
        val client = WaymarkLocationClient(engine, phone.platform)
        val mine = RecordingCallback()
        client.requestLocationUpdates(WaymarkLocationRequest(ble = false), direct, mine)
        assertTrue(client.usesBarometer)
        phone.barometer.emit(1_000_000L, 1000f)
        // Location permission revoked: nothing runs, the held reading went to the engine first.
        phone.availability.granted -= WaymarkPermission.ACCESS_FINE_LOCATION
        client.refreshAvailability()
        assertEquals(ClientState.PAUSED, client.state)
        assertFalse(client.usesBarometer)
        assertNull(phone.barometer.sink)
        assertEquals(1, engine.pressureReadings)
        // Granted again: registered again.
        phone.availability.granted += WaymarkPermission.ACCESS_FINE_LOCATION
        client.refreshAvailability()
        assertTrue(client.usesBarometer)
        assertEquals(2, phone.barometer.registrations.size)
        // Another caller that asks for no barometer keeps it on; removing the one that did stops it.
        val other = RecordingCallback()
        client.requestLocationUpdates(WaymarkLocationRequest(ble = false, barometer = false), direct, other)
        assertTrue(client.usesBarometer)
        client.removeLocationUpdates(mine)
        assertFalse(client.usesBarometer)
        assertNull(phone.barometer.sink)
        assertNotNull("the motion sensors run on", phone.sensors.running[MotionSensor.ACCELEROMETER])
        client.close()
        assertTrue(phone.idle)
        engine.close()
    }

    @Test
    fun theScanBudgetHoldsOverHoursInTheForegroundAndInTheBackground() {
        val phone = FakePhone()
        val engine = engine()
        val client = WaymarkLocationClient(engine, phone.platform)
        val callback = RecordingCallback()
        // Each scan the client starts ends 2 s later, results stamped with the scan's time.
        val answer = Runnable {
            val t = phone.clock.now
            phone.scheduler.at(t + 2 * S) { phone.wifi.broadcast(listOf(WifiResult("02:00:00:00:00:00", -60, t / 1_000L))) }
        }
        var answered = 0
        fun run(untilNs: Long) {
            while (phone.clock.now < untilNs) {
                phone.scheduler.runUntil(phone.clock.now + S)
                while (answered < phone.wifi.startCalls.size) {
                    answered++
                    answer.run()
                }
            }
        }
        // A caller that asks for a scan every second gets what Android allows, no more.
        val greedy = WaymarkLocationRequest(ble = false, wifiScanIntervalMs = 1_000, advanceIntervalMs = 60_000)
        client.requestLocationUpdates(greedy, direct, callback)
        run(3 * 3_600 * S)
        val foreground = phone.wifi.startCalls.toList()
        assertTrue("at most 4 in any 2 minutes", mostInWindow(foreground, 120 * S) <= 4)
        // The budget is spent, and spread: one scan about every 30 s.
        assertTrue("${foreground.size} scans in 3 h", foreground.size >= 3 * 3_600 / 31)
        assertTrue(foreground.zipWithNext().all { (a, b) -> b - a >= 30 * S })
        // The app goes to the background: the same callback re-requests.
        val switched = phone.clock.now
        client.requestLocationUpdates(greedy.copy(background = true), direct, callback)
        run(switched + 3 * 3_600 * S)
        val background = phone.wifi.startCalls.filter { it >= switched }
        val sinceLast = listOf(foreground.last()) + background
        assertTrue("one scan per 30 minutes", sinceLast.zipWithNext().all { (a, b) -> b - a > 30 * 60 * S })
        assertTrue("${background.size} scans in 3 h", background.size >= 5)
        assertEquals(0L, client.stats().wifiScansRefused)
        assertTrue(client.stats().wifiScansPushed >= foreground.size + background.size - 1)
        client.close()
        engine.close()
    }

    @Test
    fun budgetsFollowTheAndroidVersionAndTheDeveloperOption() {
        assertEquals(WifiScanBudget.FOREGROUND, WifiScanBudget.of(false, 28, true))
        assertEquals(WifiScanBudget.UNTHROTTLED, WifiScanBudget.of(false, 27, true))
        assertEquals(WifiScanBudget.BACKGROUND, WifiScanBudget.of(true, 26, true))
        assertEquals(WifiScanBudget.UNTHROTTLED, WifiScanBudget.of(true, 34, false))
        // 4 scans in a window: the fifth waits until the first is more than 2 minutes old.
        val history = listOf(0L, 30 * S, 60 * S, 90 * S)
        assertTrue(WifiScanBudget.FOREGROUND.nextAllowedNs(history) > 120 * S)
        assertEquals(Long.MIN_VALUE, WifiScanBudget.FOREGROUND.nextAllowedNs(emptyList()))
    }

    @Test
    fun passiveResultsArePushedOnceAndStaleEntriesCarryTheirAge() {
        val phone = FakePhone()
        val engine = engine()
        val client = WaymarkLocationClient(engine, phone.platform)
        val callback = RecordingCallback()
        // 70 Hz: batches of 35 samples, which end between the walk's scans (1.5 s apart).
        client.requestLocationUpdates(WaymarkLocationRequest(ble = false, sensorRateHz = 70), direct, callback)
        // Another app scans every epoch; every fourth result set is broadcast a second time (a
        // third app's receiver, the same cached list), and one scan fails (not updated).
        phone.replay(walk.take(20), passive = { true }) { k ->
            val t = walk[k].timestampNs.toLong()
            if (k % 4 == 1) phone.scheduler.at(t + 600_000_000L) { phone.wifi.broadcast(phone.wifi.results) }
            if (k == 10) phone.scheduler.at(t + 700_000_000L) { phone.wifi.broadcast(emptyList(), updated = false) }
        }
        val stats = client.stats()
        val times = engine.scans.map { it.timestampNs }
        assertEquals("no scan pushed twice", times.toSet().size, times.size)
        assertTrue("every epoch's scan pushed: ${times.size}", times.size >= 19)
        assertTrue("passive results: ${stats.wifiScansPassive}", stats.wifiScansPassive >= 18)
        assertTrue("duplicates counted: ${stats.wifiScansDuplicate}", stats.wifiScansDuplicate >= 4)
        // The batches were flushed before each scan: the motion up to its time went in first.
        for ((k, scan) in engine.scans.withIndex()) {
            val newest = walk.flatMap { it.accelerometer }.last { it.timestampNs <= scan.timestampNs }.timestampNs.toLong()
            assertTrue("scan $k: motion up to $newest pushed first", engine.motionBeforeScan[k] >= newest)
        }
        // A cached list: the newest entry makes the scan's time, the older ones their age.
        val t = phone.clock.now + S
        phone.wifi.broadcast(
            listOf(WifiResult("02:00:00:00:00:00", -60, t / 1_000L), WifiResult("02:00:00:00:00:01", -70, (t - 3 * S) / 1_000L)),
        )
        val last = engine.scans.last()
        assertEquals(t.toULong(), last.timestampNs)
        assertEquals(listOf(0UL, 3_000UL), last.wifi.map { it.ageMs })
        client.close()
        engine.close()
    }

    @Test
    fun theAdvanceTimerKeepsPositionsComingWhileScansAreThrottled() {
        val phone = FakePhone()
        val engine = engine()
        val client = WaymarkLocationClient(engine, phone.platform)
        val callback = RecordingCallback()
        client.requestLocationUpdates(WaymarkLocationRequest(ble = false, advanceIntervalMs = 2_000), direct, callback)
        // The first scan goes through; Android refuses every later one.
        phone.replay(walk, afterEpoch = { phone.wifi.accept = false })
        val stats = client.stats()
        assertEquals(1, engine.scans.size)
        assertTrue(stats.wifiScansRefused >= 1)
        assertTrue(callback.statuses.any { it == WaymarkLocationStatus.WifiScanThrottled && it.code == 200 })
        // 49 s of walk, an epoch every 2 s after the one scan.
        assertTrue("advances: ${stats.advances}", stats.advances >= 20)
        assertEquals(0L, stats.advancesRejected)
        assertEquals(0UL, engine.inputStats().advancesRejected)
        val times = callback.positions.map { it.timestampNs.toLong() }
        assertTrue("positions in time order", times.zipWithNext().all { (a, b) -> b > a })
        assertTrue("no gap over 2.5 s", times.zipWithNext().all { (a, b) -> b - a <= 2_500_000_000L })
        // Motion alone from one fix: worse than with every scan, still on the walk.
        val mean = meanError(callback.positions)
        println("location client, one scan then motion alone: ${times.size} positions, mean error %.3f m".format(mean))
        assertTrue("mean error $mean m", mean < 3.0)
        client.close()
        engine.close()
    }

    @Test
    fun withoutLocationPermissionNothingStartsAndGrantingResumes() {
        val phone = FakePhone()
        phone.availability.granted -= WaymarkPermission.ACCESS_FINE_LOCATION
        phone.availability.granted -= WaymarkPermission.ACCESS_COARSE_LOCATION
        val engine = engine()
        val client = WaymarkLocationClient(engine, phone.platform)
        val callback = RecordingCallback()
        client.requestLocationUpdates(WaymarkLocationRequest(), direct, callback)
        phone.scheduler.runUntil(60 * S)
        assertEquals(listOf<WaymarkLocationStatus>(WaymarkLocationStatus.PermissionMissing(WaymarkPermission.ACCESS_FINE_LOCATION)), callback.statuses)
        assertEquals(100, callback.statuses[0].code)
        assertEquals(ClientState.PAUSED, client.state)
        assertTrue("no sensor, radio or scan", phone.idle && phone.wifi.startCalls.isEmpty() && phone.ble.starts == 0)
        assertTrue(callback.positions.isEmpty())
        // The user grants it: the client's own check finds it within 5 s.
        phone.availability.granted += WaymarkPermission.ACCESS_FINE_LOCATION
        phone.availability.granted += WaymarkPermission.ACCESS_COARSE_LOCATION
        phone.scheduler.runUntil(66 * S)
        assertEquals(WaymarkLocationStatus.Restored(WaymarkLocationStatus.PermissionMissing(WaymarkPermission.ACCESS_FINE_LOCATION)), callback.statuses.last())
        assertEquals(ClientState.RUNNING, client.state)
        assertEquals(3, phone.sensors.running.size)
        assertNotNull(phone.wifi.sink)
        assertNotNull(phone.ble.sink)
        assertEquals(1, phone.wifi.startCalls.size)
        client.close()
        engine.close()
    }

    @Test
    fun revokingAndRestoringAtRunTimeStopsAndResumesTheRadio() {
        val phone = FakePhone()
        val engine = engine()
        val client = WaymarkLocationClient(engine, phone.platform)
        val callback = RecordingCallback()
        client.requestLocationUpdates(WaymarkLocationRequest(), direct, callback)
        phone.scheduler.runUntil(S)
        assertEquals(ClientState.RUNNING, client.state)
        assertTrue(callback.statuses.isEmpty())
        // BLUETOOTH_SCAN revoked: BLE stops, WiFi and the sensors go on.
        phone.availability.granted -= WaymarkPermission.BLUETOOTH_SCAN
        client.refreshAvailability()
        assertEquals(WaymarkLocationStatus.PermissionMissing(WaymarkPermission.BLUETOOTH_SCAN), callback.statuses.last())
        assertEquals(ClientState.DEGRADED, client.state)
        assertNull(phone.ble.sink)
        assertNotNull(phone.wifi.sink)
        assertEquals(3, phone.sensors.running.size)
        phone.availability.granted += WaymarkPermission.BLUETOOTH_SCAN
        phone.scheduler.runUntil(7 * S) // found by the client's own check
        assertEquals(WaymarkLocationStatus.Restored(WaymarkLocationStatus.PermissionMissing(WaymarkPermission.BLUETOOTH_SCAN)), callback.statuses.last())
        assertNotNull(phone.ble.sink)
        assertEquals(2, phone.ble.starts)
        assertEquals(ClientState.RUNNING, client.state)
        // Location services off (a broadcast): everything stops; back on: everything resumes.
        phone.availability.locationOn = false
        phone.availability.watcher!!.run()
        assertEquals(WaymarkLocationStatus.LocationServicesOff, callback.statuses.last())
        assertEquals(ClientState.PAUSED, client.state)
        assertTrue(phone.idle)
        phone.availability.locationOn = true
        phone.availability.watcher!!.run()
        assertEquals(ClientState.RUNNING, client.state)
        assertFalse(phone.idle)
        // WiFi switched off: only WiFi stops.
        phone.wifi.available = false
        client.refreshAvailability()
        assertEquals(WaymarkLocationStatus.WifiOff, callback.statuses.last())
        assertNull(phone.wifi.sink)
        assertNotNull(phone.ble.sink)
        // A second caller hears the conditions that hold.
        val late = RecordingCallback()
        client.requestLocationUpdates(WaymarkLocationRequest(), direct, late)
        assertEquals(listOf<WaymarkLocationStatus>(WaymarkLocationStatus.WifiOff), late.statuses)
        client.removeLocationUpdates(late)
        client.removeLocationUpdates(callback)
        assertEquals(ClientState.IDLE, client.state)
        assertTrue(phone.idle)
        assertEquals("no timer left", 0, phone.scheduler.pending)
        client.close()
        engine.close()
    }

    @Test
    fun aBleScanFailureIsACodedStatusAndRetried() {
        val phone = FakePhone()
        phone.ble.failNextStartWith = 2 // SCAN_FAILED_APPLICATION_REGISTRATION_FAILED
        val engine = engine()
        val client = WaymarkLocationClient(engine, phone.platform)
        val callback = RecordingCallback()
        client.requestLocationUpdates(WaymarkLocationRequest(), direct, callback)
        val failed = callback.statuses.single() as WaymarkLocationStatus.BleScanFailed
        assertEquals(2, failed.errorCode)
        assertEquals(140, failed.code)
        assertEquals(ClientState.DEGRADED, client.state)
        assertNull(phone.ble.sink)
        phone.scheduler.runUntil(31 * S)
        assertEquals(WaymarkLocationStatus.Restored(failed), callback.statuses.last())
        assertNotNull(phone.ble.sink)
        assertEquals(ClientState.RUNNING, client.state)
        // 4, feature unsupported: no retry.
        phone.ble.failNextStartWith = 4
        client.requestLocationUpdates(WaymarkLocationRequest(background = true), direct, callback) // BLE restarts in low power
        assertEquals(WaymarkLocationStatus.BleScanFailed(4), callback.statuses.last())
        val starts = phone.ble.starts
        phone.scheduler.runUntil(200 * S)
        assertEquals(starts, phone.ble.starts)
        client.close()
        engine.close()
    }

    @Test
    fun beaconsGoWithTheNextWifiScanOrOnTheirOwn() {
        val uuid = "fda50693-a4e2-4fb1-afcf-c6eb07647825"
        val record = iBeaconRecord(uuid, 1, 7, -59)
        val phone = FakePhone()
        val engine = engine()
        val client = WaymarkLocationClient(engine, phone.platform)
        client.requestLocationUpdates(WaymarkLocationRequest(wifi = false), direct, RecordingCallback())
        // An advertisement every 100 ms at -70 and -72 dBm in turn; a phone's own advertising too.
        for (i in 1..50) {
            phone.scheduler.runUntil(i * 100_000_000L)
            phone.ble.sink!!.onAdvertisement("C0:00:00:00:00:01", if (i % 2 == 0) -70 else -72, phone.clock.now, record)
            phone.ble.sink!!.onAdvertisement("5A:00:00:00:00:02", -50, phone.clock.now, byteArrayOf(2, 1, 6))
        }
        val beaconScans = engine.scans.filter { it.wifi.isEmpty() }
        assertEquals("epochs at 2 s and 4 s", 2, beaconScans.size)
        val b = beaconScans[0].beacons.single()
        assertEquals(uuid, b.uuid)
        assertEquals(1.toUShort(), b.major)
        assertEquals(7.toUShort(), b.minor)
        // The mean of the advertisements heard up to the epoch, not the last one.
        assertEquals(-71.0, b.rssiDbm, 0.1)
        assertTrue(client.stats().bleAdvertisementsIgnored >= 50)
        client.close()

        // With WiFi: beacons heard before a scan ride with its results.
        val phone2 = FakePhone()
        val engine2 = engine()
        val client2 = WaymarkLocationClient(engine2, phone2.platform)
        client2.requestLocationUpdates(WaymarkLocationRequest(), direct, RecordingCallback())
        phone2.scheduler.runUntil(500_000_000L)
        phone2.ble.sink!!.onAdvertisement("C0:00:00:00:00:01", -65, phone2.clock.now, record)
        val t = 1_000_000_000L
        phone2.scheduler.runUntil(t)
        phone2.wifi.broadcast(listOf(WifiResult("02:00:00:00:00:00", -60, t / 1_000L)))
        val scan = engine2.scans.single()
        assertEquals(1, scan.wifi.size)
        assertEquals(uuid, scan.beacons.single().uuid)
        assertEquals(500UL, scan.beacons.single().ageMs)
        client2.close()
        engine.close()
        engine2.close()
    }

    @Test
    fun iBeaconsAreParsedFromManufacturerData() {
        val uuid = "fda50693-a4e2-4fb1-afcf-c6eb07647825"
        val record = iBeaconRecord(uuid, 513, 65535, -59)
        assertEquals(IBeacon(uuid, 513, 65535, -59), BleAdvertisements.iBeacon(record))
        val payload = record.copyOfRange(7, record.size) // after flags (3), length, type, company id (2)
        assertEquals(IBeacon(uuid, 513, 65535, -59), BleAdvertisements.iBeacon(0x004C, payload))
        // Another company's data, a short payload, another Apple type: none.
        assertNull(BleAdvertisements.iBeacon(0x0059, payload))
        assertNull(BleAdvertisements.iBeacon(0x004C, payload.copyOf(20)))
        assertNull(BleAdvertisements.iBeacon(0x004C, payload.copyOf().also { it[0] = 0x10 }))
        // A truncated record: no iBeacon, no exception.
        assertNull(BleAdvertisements.iBeacon(record.copyOf(20)))
        assertNull(BleAdvertisements.iBeacon(byteArrayOf()))
        // Eddystone URL frame (0x10): Eddystone, but it names no transmitter of the site.
        val eddystoneUrl = byteArrayOf(3, 3, 0xAA.toByte(), 0xFE.toByte(), 5, 0x16, 0xAA.toByte(), 0xFE.toByte(), 0x10, 0)
        assertTrue(BleAdvertisements.isEddystone(eddystoneUrl))
        assertFalse(BleAdvertisements.isEddystone(record))
        assertNull(BleAdvertisements.reading("C0:00:00:00:00:09", eddystoneUrl))
        assertNull(BleAdvertisements.reading("C0:00:00:00:00:09", byteArrayOf(2, 1, 6)))
    }

    @Test
    fun callbacksRunOnTheCallersExecutor() {
        val queued = ArrayList<Runnable>()
        val executor = Executor { queued += it }
        var inExecutor = false
        var outside = 0
        val callback = object : dev.waymark.android.WaymarkLocationCallback {
            val positions = ArrayList<PositionEstimate>()
            override fun onLocation(position: PositionEstimate) {
                if (!inExecutor) outside++
                positions += position
            }

            override fun onStatus(status: WaymarkLocationStatus) {
                if (!inExecutor) outside++
            }
        }
        val phone = FakePhone()
        phone.wifi.available = false // a status too
        val engine = engine()
        val client = WaymarkLocationClient(engine, phone.platform)
        client.requestLocationUpdates(WaymarkLocationRequest(), executor, callback)
        phone.replay(walk.take(8), passive = { true })
        assertTrue("nothing called before the executor ran", callback.positions.isEmpty())
        assertTrue("${queued.size} queued", queued.size >= 8)
        inExecutor = true
        queued.forEach { it.run() }
        assertEquals(0, outside)
        assertTrue(callback.positions.size >= 3) // advances (WiFi off) or scans
        // An executor that refuses (shut down) is counted, and throws into no platform callback.
        val refusing = RecordingCallback()
        client.requestLocationUpdates(WaymarkLocationRequest(), { throw java.util.concurrent.RejectedExecutionException() }, refusing)
        client.removeLocationUpdates(callback)
        phone.scheduler.runUntil(phone.clock.now + 10 * S)
        assertTrue(client.stats().callbackFailures > 0)
        client.close()
        engine.close()
    }

    @Test
    fun theFlowDeliversPositionsAndCancellingItStopsEverything() {
        val phone = FakePhone()
        val engine = engine()
        val client = WaymarkLocationClient(engine, phone.platform)
        val positions = ArrayList<PositionEstimate>()
        runBlocking {
            val job = launch(Dispatchers.Unconfined) { client.locations(WaymarkLocationRequest()).collect { positions += it } }
            assertFalse("collecting started the sensors and radios", phone.idle)
            phone.replay(walk.take(12), passive = { true })
            job.cancel()
            job.join()
        }
        assertTrue("${positions.size} positions", positions.size >= 10)
        assertTrue("cancelling stopped the sensors and radios", phone.idle)
        assertEquals(0, phone.scheduler.pending)
        assertEquals(ClientState.IDLE, client.state)
        client.close()
        engine.close()
    }

    @Test
    fun aMissingSensorIsReportedAndTheOthersRun() {
        val phone = FakePhone(setOf(MotionSensor.ACCELEROMETER, MotionSensor.MAGNETOMETER))
        val engine = engine()
        val client = WaymarkLocationClient(engine, phone.platform)
        val callback = RecordingCallback()
        client.requestLocationUpdates(WaymarkLocationRequest(ble = false), direct, callback)
        assertEquals(listOf<WaymarkLocationStatus>(WaymarkLocationStatus.SensorMissing(MotionSensor.GYROSCOPE)), callback.statuses)
        assertEquals(ClientState.DEGRADED, client.state)
        assertEquals(setOf(MotionSensor.ACCELEROMETER, MotionSensor.MAGNETOMETER), phone.sensors.running.keys)
        phone.replay(walk.take(10), passive = { true })
        assertTrue(callback.positions.size >= 9)
        client.close()
        // A sensor the phone has but refuses to register is missing too.
        val refusing = FakePhone()
        refusing.sensors.refused += MotionSensor.MAGNETOMETER
        val heard = RecordingCallback()
        val second = WaymarkLocationClient(engine, refusing.platform)
        second.requestLocationUpdates(WaymarkLocationRequest(), direct, heard)
        assertEquals(listOf<WaymarkLocationStatus>(WaymarkLocationStatus.SensorMissing(MotionSensor.MAGNETOMETER)), heard.statuses)
        assertEquals(2, refusing.sensors.running.size)
        second.close()
        engine.close()
    }

    @Test
    fun sensorsRadiosAndTheTimerOnTheirOwnThreadsAtOnce() {
        val phone = FakePhone()
        val engine = engine()
        val client = WaymarkLocationClient(engine, phone.platform)
        val callback = RecordingCallback()
        client.requestLocationUpdates(WaymarkLocationRequest(), direct, callback)
        val part = walk.take(20)
        val failures = java.util.concurrent.ConcurrentLinkedQueue<Throwable>()
        val record = iBeaconRecord("fda50693-a4e2-4fb1-afcf-c6eb07647825", 1, 7, -59)
        fun thread(body: () -> Unit) = Thread { try { body() } catch (t: Throwable) { failures += t } }.apply { start() }
        val sensorsThread = thread {
            for (epoch in part) for (s in epoch.accelerometer) phone.sensors.emit(MotionSensor.ACCELEROMETER, s)
        }
        val gyroThread = thread {
            for (epoch in part) for (s in epoch.gyroscope) phone.sensors.emit(MotionSensor.GYROSCOPE, s)
        }
        val wifiThread = thread {
            for (epoch in part) {
                val t = epoch.timestampNs.toLong()
                phone.wifi.broadcast(epoch.wifi.map { WifiResult(it.bssid, it.rssiDbm.toInt(), t / 1_000L) })
            }
        }
        val bleThread = thread {
            for (i in 0 until 2_000) phone.ble.sink?.onAdvertisement("C0:00:00:00:00:01", -70, phone.clock.now, record)
        }
        // The timer, on this thread, across the walk's time.
        for (epoch in part) phone.scheduler.runUntil(epoch.timestampNs.toLong())
        listOf(sensorsThread, gyroThread, wifiThread, bleThread).forEach { it.join() }
        phone.scheduler.runUntil(part.last().timestampNs.toLong() + 5 * S)
        client.close()
        assertTrue("no thread threw: $failures", failures.isEmpty())
        val times = callback.positions.map { it.timestampNs.toLong() }
        assertTrue("${times.size} positions", times.isNotEmpty())
        assertTrue("positions in time order", times.zipWithNext().all { (a, b) -> b > a })
        // The client only makes epochs after the last one: the engine refused no advance.
        assertEquals(0UL, engine.inputStats().advancesRejected)
        assertEquals(0UL, engine.inputStats().scansOutOfOrder)
        engine.close()
    }

    /** Flags, then Apple manufacturer data with an iBeacon. */
    private fun iBeaconRecord(uuid: String, major: Int, minor: Int, txPower: Int): ByteArray {
        val id = uuid.replace("-", "").chunked(2).map { it.toInt(16).toByte() }
        val data = listOf<Byte>(0x4C, 0x00, 0x02, 0x15) + id +
            listOf(major shr 8, major, minor shr 8, minor, txPower).map { it.toByte() }
        return byteArrayOf(2, 1, 6, (data.size + 1).toByte(), 0xFF.toByte()) + data.toByteArray()
    }
}
