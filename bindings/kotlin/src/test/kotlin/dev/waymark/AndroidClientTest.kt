package dev.waymark

import dev.waymark.android.AppVisibility
import dev.waymark.android.ClientState
import dev.waymark.android.MotionSensor
import dev.waymark.android.Platform
import dev.waymark.android.ThreadScheduler
import dev.waymark.android.WaymarkLocationCallback
import dev.waymark.android.WaymarkLocationClient
import dev.waymark.android.WaymarkLocationRequest
import dev.waymark.android.WaymarkLocationStatus
import dev.waymark.android.WaymarkPermission
import dev.waymark.android.WaymarkPermissions
import dev.waymark.android.WifiResult
import dev.waymark.android.locationEvents
import dev.waymark.android.locations
import java.io.File
import java.util.concurrent.ConcurrentHashMap
import java.util.concurrent.CopyOnWriteArrayList
import java.util.concurrent.CountDownLatch
import java.util.concurrent.Executor
import java.util.concurrent.Executors
import java.util.concurrent.TimeUnit
import java.util.concurrent.atomic.AtomicInteger
import kotlinx.coroutines.Dispatchers
import kotlinx.coroutines.flow.toList
import kotlinx.coroutines.launch
import kotlinx.coroutines.runBlocking
import kotlinx.coroutines.withTimeout
import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertNotNull
import org.junit.Assert.assertNull
import org.junit.Assert.assertTrue
import org.junit.BeforeClass
import org.junit.Test

/** An engine that records the thread of every call the client makes into it. */
class ThreadRecordingEngine(private val inner: PositioningEngine) : PositioningEngineInterface by inner, AutoCloseable {
    val threads: MutableSet<String> = ConcurrentHashMap.newKeySet()
    val accelerometerSamples = AtomicInteger()
    val scans = AtomicInteger()

    private fun saw() {
        threads += Thread.currentThread().name
    }

    override fun pushAccelerometer(batch: List<MotionSample>): UInt {
        saw()
        accelerometerSamples.addAndGet(batch.size)
        return inner.pushAccelerometer(batch)
    }

    override fun pushGyroscope(batch: List<MotionSample>): UInt = saw().let { inner.pushGyroscope(batch) }
    override fun pushMagnetometer(batch: List<MotionSample>): UInt = saw().let { inner.pushMagnetometer(batch) }
    override fun pushPressure(batch: List<PressureReading>): UInt = saw().let { inner.pushPressure(batch) }
    override fun advance(timestampNs: ULong): PositionEstimate = saw().let { inner.advance(timestampNs) }
    override fun subscribe(listener: PositionListener): Subscription = saw().let { inner.subscribe(listener) }

    override fun pushScan(scan: RadioScan): PositionEstimate {
        saw()
        scans.incrementAndGet()
        return inner.pushScan(scan)
    }

    override fun close() = inner.close()
}

/**
 * The Android client as an app runs it: on its own thread, with the app's lifecycle, Android
 * 8-14's permissions, a Flow that completes, Eddystone identities, Java callers and survey
 * mode.
 */
class AndroidClientTest {
    companion object {
        private lateinit var siteJson: String
        private lateinit var walk: List<Epoch>
        private const val S = 1_000_000_000L
        private const val WORKER = "waymark-location"

        @BeforeClass
        @JvmStatic
        fun load() {
            siteJson = File(System.getProperty("waymark.site")).readText()
            walk = Walk.load(System.getProperty("waymark.walk"))
        }

        val direct = Executor { it.run() }
    }

    /** The client on a thread of its own ([ThreadScheduler]), on the real monotonic clock; the
     *  fake radios and sensors are driven from the test's other threads, as Android's binder
     *  and sensor threads drive them. */
    private class ThreadedPhone {
        val clock = dev.waymark.android.Clock { System.nanoTime() }
        val scheduler = ThreadScheduler(WORKER)
        private val fakeClock = FakeClock()
        val sensors = FakeSensors()
        val wifi = FakeWifi(fakeClock)
        val ble = FakeBle()
        val availability = FakeAvailability()
        val platform = Platform(clock, scheduler, sensors, wifi, ble, availability)

        /** 100 Hz of each motion sensor for [seconds], from the calling thread. */
        fun emitMotion(seconds: Double, sample: Int = 0) {
            val n = (seconds * 100).toInt()
            for (i in 0 until n) {
                val t = System.nanoTime()
                for (sensor in MotionSensor.values()) {
                    val z = if (sensor == MotionSensor.ACCELEROMETER) 9.81 + 0.3 * Math.sin((sample + i) / 8.0) else 0.01
                    sensors.running[sensor]?.onSample(sensor, t, floatArrayOf(0.1f, 0.2f, z.toFloat()))
                }
                Thread.sleep(10)
            }
        }

        /** The walk's epoch [k] heard now. */
        fun broadcastScan(k: Int) {
            val t = System.nanoTime()
            wifi.results = walk[k % walk.size].wifi.map { WifiResult(it.bssid, it.rssiDbm.toInt(), t / 1_000L) }
            wifi.sink?.onScanResults(true)
        }
    }

    private fun thread(name: String, failures: MutableCollection<Throwable>, body: () -> Unit) =
        Thread({ try { body() } catch (t: Throwable) { failures += t } }, name).apply { start() }

    @Test
    fun noEpochSensorBatchOrScanRunsOnTheThreadThatRequestedUpdates() {
        val phone = ThreadedPhone()
        val engine = ThreadRecordingEngine(PositioningEngine(siteJson, EngineOptions()))
        val client = WaymarkLocationClient(engine, phone.platform)
        val app = Executors.newSingleThreadExecutor { Thread(it, "app-main") }
        val callbackThreads = ConcurrentHashMap.newKeySet<String>()
        val positions = AtomicInteger()
        val callback = object : WaymarkLocationCallback {
            override fun onLocation(position: PositionEstimate) {
                callbackThreads += Thread.currentThread().name
                positions.incrementAndGet()
            }

            override fun onStatus(status: WaymarkLocationStatus) {
                callbackThreads += Thread.currentThread().name
            }
        }
        val requester = Thread.currentThread().name
        // Every input the client takes, from the threads Android would deliver it on.
        phone.availability.granted -= WaymarkPermission.BLUETOOTH_CONNECT
        phone.ble.enabled = false // a status too: PermissionMissing(BLUETOOTH_CONNECT), BluetoothOff
        client.requestLocationUpdates(WaymarkLocationRequest(advanceIntervalMs = 500), app, callback)
        val failures = CopyOnWriteArrayList<Throwable>()
        val deadline = System.nanoTime() + 10 * S
        while (phone.sensors.running.size < 3 && System.nanoTime() < deadline) Thread.sleep(5)
        val sensorThread = thread("sensor-hub", failures) { phone.emitMotion(3.0) }
        val binder = thread("binder", failures) {
            for (k in 0 until 5) {
                Thread.sleep(500)
                phone.broadcastScan(k)
            }
        }
        // Meanwhile the requesting thread changes the request (the sensors re-register, their
        // batches flush), re-checks permissions and asks again.
        Thread.sleep(700)
        client.requestLocationUpdates(WaymarkLocationRequest(sensorRateHz = 50, advanceIntervalMs = 500), app, callback)
        client.refreshAvailability()
        phone.availability.granted -= WaymarkPermission.NEARBY_WIFI_DEVICES
        client.refreshAvailability()
        phone.availability.granted += WaymarkPermission.NEARBY_WIFI_DEVICES
        client.refreshAvailability()
        sensorThread.join()
        binder.join()
        client.close() // flushes the last batches: on the client's thread too
        assertTrue("the client's thread ended", phone.scheduler.awaitTermination(5_000))
        app.shutdown()
        assertTrue(app.awaitTermination(5, TimeUnit.SECONDS))
        assertTrue("no thread threw: $failures", failures.isEmpty())
        println("engine calls on ${engine.threads}, callbacks on $callbackThreads, ${positions.get()} positions")
        assertEquals("every engine call on the client's thread", setOf(WORKER), engine.threads.toSet())
        assertFalse(requester in engine.threads)
        assertEquals("every callback on the app's executor", setOf("app-main"), callbackThreads.toSet())
        // The scan handling (results read, scans started) and the sensors' registrations too.
        assertEquals(setOf(WORKER), phone.wifi.threads.toSet())
        assertEquals(setOf(WORKER), phone.sensors.threads.toSet())
        // Epochs from scans and from the advance timer (a scan older than an advance the timer
        // made meanwhile is late, and counted: LocationClientStats.wifiScansLate). One broadcast
        // may fall in the moment WiFi is off for the revoked NEARBY_WIFI_DEVICES.
        val stats = client.stats()
        assertTrue("$stats", stats.wifiScansPushed + stats.wifiScansLate >= 4)
        assertTrue("scans pushed: ${engine.scans.get()}", engine.scans.get() >= 2)
        assertTrue("positions: ${positions.get()}", positions.get() >= 4)
        assertTrue("samples: ${engine.accelerometerSamples.get()}", engine.accelerometerSamples.get() >= 250)
        assertEquals(ClientState.STOPPED, client.state)
        engine.close()
    }

    @Test
    fun aBlockingCallbackDoesNotHoldUpTheSensorsOrTheEpochs() {
        val phone = ThreadedPhone()
        val engine = ThreadRecordingEngine(PositioningEngine(siteJson, EngineOptions()))
        val client = WaymarkLocationClient(engine, phone.platform)
        val app = Executors.newSingleThreadExecutor { Thread(it, "app-main") }
        val release = CountDownLatch(1)
        val blocked = CountDownLatch(1)
        val heard = AtomicInteger()
        val callback = object : WaymarkLocationCallback {
            override fun onLocation(position: PositionEstimate) {
                heard.incrementAndGet()
                blocked.countDown()
                release.await() // the app's main thread busy, for as long as the test says
            }
        }
        // Epochs from the scans alone (no advance would come between two scans 0.5 s apart).
        client.requestLocationUpdates(WaymarkLocationRequest(ble = false, advanceIntervalMs = 5_000), app, callback)
        val failures = CopyOnWriteArrayList<Throwable>()
        val deadline = System.nanoTime() + 10 * S
        while (phone.sensors.running.size < 3 && System.nanoTime() < deadline) Thread.sleep(5)
        phone.emitMotion(0.3)
        phone.broadcastScan(0)
        assertTrue("the first position reached the callback", blocked.await(10, TimeUnit.SECONDS))
        // The callback blocks. The sensors and radios go on into the engine regardless.
        val samplesBefore = engine.accelerometerSamples.get()
        val scansBefore = engine.scans.get()
        val sensorThread = thread("sensor-hub", failures) { phone.emitMotion(2.0, sample = 30) }
        val binder = thread("binder", failures) {
            for (k in 1..3) {
                Thread.sleep(500)
                phone.broadcastScan(k)
            }
        }
        sensorThread.join()
        binder.join()
        Thread.sleep(300)
        val samplesWhileBlocked = engine.accelerometerSamples.get() - samplesBefore
        val scansWhileBlocked = engine.scans.get() - scansBefore
        assertEquals("the callback is still blocked", 1, heard.get())
        // 200 samples emitted; all but those held in a batch (fewer than 50) went in.
        assertTrue("samples went in while the callback blocked: $samplesWhileBlocked", samplesWhileBlocked >= 150)
        assertTrue("scans went in while the callback blocked: $scansWhileBlocked", scansWhileBlocked >= 3)
        release.countDown()
        client.close()
        app.shutdown()
        assertTrue(app.awaitTermination(5, TimeUnit.SECONDS))
        // The positions made meanwhile were queued on the app's executor, none lost.
        assertTrue("positions heard after the release: ${heard.get()}", heard.get() >= 1 + scansWhileBlocked)
        assertTrue("no thread threw: $failures", failures.isEmpty())
        engine.close()
    }

    @Test
    fun theFlowCompletesWhenTheClientCloses() {
        val phone = FakePhone()
        val engine = ThreadRecordingEngine(PositioningEngine(siteJson, EngineOptions()))
        val client = WaymarkLocationClient(engine, phone.platform)
        runBlocking {
            val positions = ArrayList<PositionEstimate>()
            var events = 0
            val job = launch(Dispatchers.Unconfined) { client.locations().collect { positions += it } }
            val statusJob = launch(Dispatchers.Unconfined) { client.locationEvents().collect { events++ } }
            phone.replay(walk.take(6), passive = { true })
            client.close()
            // Both collections end by themselves: close completes the Flows, nobody cancels them.
            withTimeout(5_000) {
                job.join()
                statusJob.join()
            }
            assertFalse(job.isCancelled)
            assertFalse(statusJob.isCancelled)
            assertTrue("${positions.size} positions", positions.size >= 4)
            assertTrue(events >= positions.size)
            // A Flow of a closed client completes at once, empty.
            assertEquals(emptyList<PositionEstimate>(), withTimeout(5_000) { client.locations().toList() })
        }
        assertTrue(phone.idle)
        engine.close()
    }

    @Test
    fun everyPermissionCombinationOfAndroid8To14IsACodedStatus() {
        val all = WaymarkPermission.values().toList()
        // Every permission its own code, 100 to 106; approximate location 107.
        assertEquals((100..106).toList(), all.map { it.code })
        assertEquals(107, WaymarkLocationStatus.ApproximateLocationOnly.code)
        var cases = 0
        for (sdk in 26..34) for (mask in 0 until (1 shl all.size)) for (visible in listOf(true, false))
            for (serviceWanted in listOf(false, true)) for (bluetoothOn in listOf(true, false)) {
                val granted = all.filterIndexed { i, _ -> mask and (1 shl i) != 0 }.toSet()
                val has = { p: WaymarkPermission -> p in granted }
                val phone = FakePhone()
                phone.availability.sdk = sdk
                phone.availability.granted.clear()
                phone.availability.granted += granted
                phone.ble.enabled = bluetoothOn
                if (!visible) {
                    phone.lifecycle.activityStarted()
                    phone.lifecycle.activityStopped()
                    phone.scheduler.runUntil(S)
                }
                if (serviceWanted && phone.lifecycle.foregroundServiceStarting(sdk, has) == null) phone.lifecycle.foregroundServiceStarted()
                val client = WaymarkLocationClient.forSurvey(phone.platform)
                client.requestLocationUpdates(WaymarkLocationRequest(), direct, RecordingCallback())

                // What Android 8 to 14 allow, rule by rule (docs/android.md#permissions).
                // Scan results need FINE from Android 10 on; COARSE was enough before.
                val anyLocation = has(WaymarkPermission.ACCESS_FINE_LOCATION) || has(WaymarkPermission.ACCESS_COARSE_LOCATION)
                val fine = has(WaymarkPermission.ACCESS_FINE_LOCATION) || (sdk < 29 && anyLocation)
                val serviceRuns = serviceWanted && (sdk < 34 || (has(WaymarkPermission.FOREGROUND_SERVICE_LOCATION) && anyLocation))
                val inForeground = visible || serviceRuns
                val backgroundOk = inForeground || sdk < 29 || has(WaymarkPermission.ACCESS_BACKGROUND_LOCATION)
                val expected = HashSet<WaymarkLocationStatus>()
                fun missing(p: WaymarkPermission) = WaymarkLocationStatus.PermissionMissing(p)
                when {
                    fine -> if (!backgroundOk) expected += missing(WaymarkPermission.ACCESS_BACKGROUND_LOCATION)
                    anyLocation -> expected += WaymarkLocationStatus.ApproximateLocationOnly
                    else -> expected += missing(WaymarkPermission.ACCESS_FINE_LOCATION)
                }
                if (sdk >= 33 && !has(WaymarkPermission.NEARBY_WIFI_DEVICES)) expected += missing(WaymarkPermission.NEARBY_WIFI_DEVICES)
                if (sdk >= 31 && !has(WaymarkPermission.BLUETOOTH_SCAN)) expected += missing(WaymarkPermission.BLUETOOTH_SCAN)
                if (sdk >= 31 && !bluetoothOn && !has(WaymarkPermission.BLUETOOTH_CONNECT)) expected += missing(WaymarkPermission.BLUETOOTH_CONNECT)
                if (serviceWanted && !serviceRuns) {
                    expected += if (!has(WaymarkPermission.FOREGROUND_SERVICE_LOCATION)) {
                        missing(WaymarkPermission.FOREGROUND_SERVICE_LOCATION)
                    } else {
                        missing(WaymarkPermission.ACCESS_FINE_LOCATION)
                    }
                }
                if (!bluetoothOn) expected += WaymarkLocationStatus.BluetoothOff
                val positioning = fine && backgroundOk
                val wifiRuns = positioning && (sdk < 33 || has(WaymarkPermission.NEARBY_WIFI_DEVICES))
                val bleRuns = positioning && bluetoothOn && (sdk < 31 || has(WaymarkPermission.BLUETOOTH_SCAN))

                val case = "API $sdk, granted $granted, visible $visible, service wanted $serviceWanted, Bluetooth $bluetoothOn"
                assertEquals(case, expected, client.conditions)
                assertEquals(case, if (positioning) (if (expected.isEmpty()) ClientState.RUNNING else ClientState.DEGRADED) else ClientState.PAUSED, client.state)
                assertEquals(case, positioning, phone.sensors.running.isNotEmpty())
                assertEquals(case, wifiRuns, phone.wifi.sink != null)
                assertEquals(case, bleRuns, phone.ble.sink != null)
                if (bleRuns) assertEquals(case, !visible, phone.ble.lowPower)
                client.close()
                cases++
            }
        assertEquals(9 * 128 * 8, cases)
        // What to request: FINE with COARSE always; the radios' permissions from their version on.
        val names = { sdk: Int -> WaymarkPermissions.manifestNames(WaymarkPermissions.foreground(sdk)).map { it.substringAfterLast('.') } }
        assertEquals(listOf("ACCESS_FINE_LOCATION", "ACCESS_COARSE_LOCATION"), names(30))
        assertEquals(listOf("ACCESS_FINE_LOCATION", "ACCESS_COARSE_LOCATION", "BLUETOOTH_SCAN", "BLUETOOTH_CONNECT"), names(31))
        assertEquals(
            listOf("ACCESS_FINE_LOCATION", "ACCESS_COARSE_LOCATION", "NEARBY_WIFI_DEVICES", "BLUETOOTH_SCAN", "BLUETOOTH_CONNECT"), names(33),
        )
        assertEquals(listOf(WaymarkPermission.ACCESS_FINE_LOCATION, WaymarkPermission.ACCESS_COARSE_LOCATION),
            WaymarkPermissions.foreground(34, WaymarkLocationRequest(ble = false, wifi = true)).filter { it.code < 102 })
        assertEquals(emptyList<WaymarkPermission>(), WaymarkPermissions.background(28))
        assertEquals(listOf(WaymarkPermission.ACCESS_BACKGROUND_LOCATION), WaymarkPermissions.background(29))
    }

    @Test
    fun approximateLocationPausesWithItsOwnStatusAndPreciseResumes() {
        val phone = FakePhone()
        phone.availability.sdk = 31
        phone.availability.granted -= WaymarkPermission.ACCESS_FINE_LOCATION // "Approximate" in the dialog
        val client = WaymarkLocationClient.forSurvey(phone.platform)
        val callback = RecordingCallback()
        client.requestLocationUpdates(WaymarkLocationRequest(), direct, callback)
        assertEquals(listOf<WaymarkLocationStatus>(WaymarkLocationStatus.ApproximateLocationOnly), callback.statuses)
        assertEquals(ClientState.PAUSED, client.state)
        assertTrue(phone.idle)
        phone.availability.granted += WaymarkPermission.ACCESS_FINE_LOCATION // the upgrade to precise
        client.refreshAvailability()
        assertEquals(WaymarkLocationStatus.Restored(WaymarkLocationStatus.ApproximateLocationOnly), callback.statuses.last())
        assertEquals(ClientState.RUNNING, client.state)
        client.close()
    }

    @Test
    fun theClientFollowsTheAppToTheBackgroundAndBackWithoutANewRequest() {
        val phone = FakePhone()
        phone.availability.granted -= WaymarkPermission.ACCESS_BACKGROUND_LOCATION
        val engine = ThreadRecordingEngine(PositioningEngine(siteJson, EngineOptions()))
        val client = WaymarkLocationClient(engine, phone.platform)
        val callback = RecordingCallback()
        phone.lifecycle.activityStarted()
        client.requestLocationUpdates(WaymarkLocationRequest(wifiScanIntervalMs = 0, advanceIntervalMs = 60_000), direct, callback)
        assertFalse(client.inBackground)
        assertFalse(phone.ble.lowPower)
        // A rotation: the activity stops and a new one starts within 700 ms; nothing switches.
        phone.lifecycle.activityStopped()
        phone.scheduler.runUntil(phone.clock.now + 300_000_000L)
        phone.lifecycle.activityStarted()
        phone.scheduler.runUntil(phone.clock.now + 2 * S)
        assertFalse(client.inBackground)
        assertEquals(1, phone.ble.starts)
        assertTrue(callback.statuses.isEmpty())
        // Home: 700 ms later the client is in the background. Without background location or a
        // foreground service, Android gives it no scan results: paused, with the status.
        phone.lifecycle.activityStopped()
        phone.scheduler.runUntil(phone.clock.now + 600_000_000L)
        assertFalse(client.inBackground)
        phone.scheduler.runUntil(phone.clock.now + 200_000_000L)
        assertTrue(client.inBackground)
        assertEquals(WaymarkLocationStatus.PermissionMissing(WaymarkPermission.ACCESS_BACKGROUND_LOCATION), callback.statuses.last())
        assertEquals(105, callback.statuses.last().code)
        assertEquals(ClientState.PAUSED, client.state)
        assertTrue(phone.idle)
        // The app starts its foreground service (WaymarkForegroundService): the client runs,
        // BLE in low power, WiFi on the foreground budget (Android counts a foreground service
        // as foreground for scans): about one scan per 30 s.
        assertNull(phone.lifecycle.foregroundServiceStarting(34) { it in phone.availability.granted })
        phone.lifecycle.foregroundServiceStarted()
        assertEquals(WaymarkLocationStatus.Restored(WaymarkLocationStatus.PermissionMissing(WaymarkPermission.ACCESS_BACKGROUND_LOCATION)), callback.statuses.last())
        assertEquals(ClientState.RUNNING, client.state)
        assertTrue(phone.ble.lowPower)
        val from = phone.clock.now
        val answered = AtomicInteger()
        while (phone.clock.now < from + 10 * 60 * S) {
            phone.scheduler.runUntil(phone.clock.now + S)
            while (answered.get() < phone.wifi.startCalls.size) {
                answered.incrementAndGet()
                val t = phone.clock.now
                phone.wifi.broadcast(listOf(WifiResult(walk[0].wifi[0].bssid, -60, t / 1_000L)))
            }
        }
        val scans = phone.wifi.startCalls.count { it >= from }
        assertTrue("$scans scans in 10 minutes with the service", scans in 18..21)
        // The service stops: without background location, paused again; the app comes back:
        // running, BLE at full rate, and no request was made since the first.
        phone.lifecycle.foregroundServiceStopped()
        assertEquals(ClientState.PAUSED, client.state)
        phone.lifecycle.activityStarted()
        assertFalse(client.inBackground)
        assertEquals(ClientState.RUNNING, client.state)
        assertFalse(phone.ble.lowPower)
        // Android 14 without FOREGROUND_SERVICE_LOCATION in the app's manifest: the service is
        // refused, and says why until it is stopped.
        phone.availability.granted -= WaymarkPermission.FOREGROUND_SERVICE_LOCATION
        val refusal = phone.lifecycle.foregroundServiceStarting(34) { it in phone.availability.granted }
        assertEquals(WaymarkLocationStatus.PermissionMissing(WaymarkPermission.FOREGROUND_SERVICE_LOCATION), refusal)
        assertEquals(refusal, callback.statuses.last())
        assertEquals(106, refusal!!.code)
        // Android refused the start itself (from the background, say): its reason replaces the refusal.
        phone.lifecycle.foregroundServiceFailed("ForegroundServiceStartNotAllowedException")
        val failed = WaymarkLocationStatus.ForegroundServiceFailed("ForegroundServiceStartNotAllowedException")
        assertEquals(150, failed.code)
        assertEquals(setOf<WaymarkLocationStatus>(failed), client.conditions)
        assertEquals(listOf(failed, WaymarkLocationStatus.Restored(refusal)), callback.statuses.takeLast(2))
        phone.lifecycle.foregroundServiceStopped()
        assertTrue(client.conditions.isEmpty())
        client.close()
        engine.close()
    }

    @Test
    fun eddystoneBeaconsAreKnownByNamespaceAndInstanceNotByTheirRotatingAddress() {
        val namespace = "edd1ebeac04e5defa017"
        val instance = "0123456789ab"
        fun uid(ns: String, inst: String, rfu: Boolean): ByteArray {
            val id = (ns + inst).chunked(2).map { it.toInt(16).toByte() }
            val data = listOf<Byte>(0xAA.toByte(), 0xFE.toByte(), 0x00, (-20).toByte()) + id + if (rfu) listOf<Byte>(0, 0) else emptyList()
            return byteArrayOf(2, 1, 6, 3, 3, 0xAA.toByte(), 0xFE.toByte(), (data.size + 1).toByte(), 0x16) + data.toByteArray()
        }
        val parsed = dev.waymark.android.BleAdvertisements.eddystoneUid(uid(namespace, instance, rfu = true))!!
        assertEquals(namespace, parsed.namespace)
        assertEquals(instance, parsed.instance)
        assertEquals(-20, parsed.txPowerDbm)
        assertEquals("edd1ebea-c04e-5def-a017-0123456789ab", parsed.uuid)
        assertEquals(parsed, dev.waymark.android.BleAdvertisements.eddystoneUid(uid(namespace, instance, rfu = false)))
        assertNull(dev.waymark.android.BleAdvertisements.eddystoneUid(uid(namespace, instance, rfu = false).copyOf(20)))
        // One beacon whose address rotates, heard through the client: one reading, by its identity.
        val phone = FakePhone()
        val engine = RecordingEngine(PositioningEngine(siteJson, EngineOptions()))
        val client = WaymarkLocationClient(engine, phone.platform)
        client.requestLocationUpdates(WaymarkLocationRequest(wifi = false), direct, RecordingCallback())
        for (i in 1..19) {
            phone.scheduler.runUntil(i * 100_000_000L)
            val address = "C0:00:00:00:00:%02X".format(i % 4) // a new address every advertisement
            phone.ble.sink!!.onAdvertisement(address, -70, phone.clock.now, uid(namespace, instance, rfu = true))
        }
        phone.scheduler.runUntil(2 * S)
        val beacon = engine.scans.single().beacons.single()
        assertEquals(parsed.uuid, beacon.uuid)
        assertEquals(0.toUShort(), beacon.major)
        assertEquals(0.toUShort(), beacon.minor)
        assertNull(beacon.address)
        client.close()
        engine.close()
        // The engine takes the reading as a well-formed beacon id, beside the site's WiFi (alone,
        // a beacon the site does not know is a scan that hears nothing of the site).
        val other = PositioningEngine(siteJson, EngineOptions())
        val t = walk[0].timestampNs
        other.pushScan(RadioScan(t, walk[0].wifi, listOf(beacon.copy(rssiDbm = -70.0))))
        assertEquals(1UL, other.inputStats().scansAccepted)
        other.close()
    }

    @Test
    fun javaCallersNeedNoUnsignedTypes() {
        val phone = FakePhone()
        val engine = PositioningEngine(siteJson, EngineOptions())
        val java = Class.forName("dev.waymark.JavaCaller")
        val report = java.getMethod("run", PositioningEngineInterface::class.java, Platform::class.java, RadioScan::class.java)
            .invoke(null, engine, phone.platform, walk[0].scan()) as String
        println("Java caller: $report")
        assertTrue(report, report.startsWith("ok"))
        assertTrue(report, report.contains("statuses=[103]"))
        engine.close()
    }
}
