package dev.waymark.android

import dev.waymark.BeaconReading
import dev.waymark.ErrorCode
import dev.waymark.ErrorReport
import dev.waymark.MotionSample
import dev.waymark.PositionEstimate
import dev.waymark.PositionListener
import dev.waymark.PositioningEngineInterface
import dev.waymark.PositioningException
import dev.waymark.PressureReading
import dev.waymark.RadioScan
import dev.waymark.StatusUpdate
import dev.waymark.Subscription
import dev.waymark.WifiReading
import java.util.EnumMap
import java.util.EnumSet
import java.util.concurrent.CopyOnWriteArrayList
import java.util.concurrent.Executor
import java.util.concurrent.atomic.AtomicLong

/**
 * Positions from the phone's sensors and radios, as Android's fused location provider gives
 * them: [requestLocationUpdates] with a [LocationRequest] and a [LocationCallback] called on
 * the caller's executor, or the `locations(request)` Flow. The client runs the motion sensors,
 * the barometer where the phone has one, WiFi scans within Android's budget ([WifiScanBudget]),
 * BLE scans and a timer that keeps epochs coming between scans, and reports every problem as a
 * coded [LocationStatus].
 *
 * On Android: `WaymarkLocationClient(context, engine)` (AndroidPlatform.kt). Here the platform
 * comes as [Platform] ports, so this class runs on the JVM against fakes. One client per app:
 * Android's scan budget is the app's, and the client keeps it. Thread-safe; the engine stays
 * the app's to close, after [close].
 */
class WaymarkLocationClient(
    private val engine: PositioningEngineInterface,
    private val platform: Platform,
) : AutoCloseable {
    private class Registration(val callback: LocationCallback, val request: LocationRequest, val executor: Executor)

    private val lock = Any()

    // Read without the lock by the engine's listener, which may run on an app's thread.
    private val registrations = CopyOnWriteArrayList<Registration>()
    private val engineLastEpochNs = AtomicLong(Long.MIN_VALUE)
    private val callbackFailures = AtomicLong()

    // Everything below is guarded by `lock`.
    private var request: LocationRequest? = null
    private var current = ClientState.IDLE
    private val holding = LinkedHashSet<LocationStatus>()
    private var reconciling = false
    private var reconcileAgain = false
    private var subscription: Subscription? = null
    private var watching = false
    private var ticker: Cancellable? = null

    private val sensorsOn = EnumSet.noneOf(MotionSensor::class.java)
    private val sensorsRefused = EnumSet.noneOf(MotionSensor::class.java)
    private var sensorSettings: Pair<Int, Int>? = null
    private val batches = EnumMap<MotionSensor, ArrayList<MotionSample>>(MotionSensor::class.java)
    private var newestAccelerometerNs = Long.MIN_VALUE
    private var motionStartedNs = Long.MIN_VALUE

    // The report latency the barometer was asked to run with; null: not asked.
    private var barometerLatencyUs: Int? = null
    private var barometerOn = false
    private val pressures = ArrayList<PressureReading>()

    private var wifiOn = false
    private val scanHistory = ArrayList<Long>()
    private var scanInFlightSinceNs: Long? = null
    private var lastWifiScanNs = Long.MIN_VALUE

    private var bleOn = false
    private var bleLowPower = false
    private var bleFailure: LocationStatus.BleScanFailed? = null
    private var bleRetry: Cancellable? = null
    private val beacons = BeaconWindow()

    private var lastEpochNs = Long.MIN_VALUE
    private var stats = LocationClientStats()

    private val motionSink = MotionSink { sensor, timestampNs, values -> onSample(sensor, timestampNs, values) }
    private val pressureSink = PressureSink { timestampNs, hpa -> onPressure(timestampNs, hpa) }
    private val wifiSink = WifiSink { updated -> onWifiResults(updated) }
    private val bleSink = object : BleSink {
        override fun onAdvertisement(address: String, rssiDbm: Int, timestampNs: Long, scanRecord: ByteArray?) =
            onBeacon(address, rssiDbm, timestampNs, scanRecord)

        override fun onScanFailed(errorCode: Int) = onBleFailure(errorCode)
    }
    private val availabilityChanged = Runnable { refreshAvailability() }

    /** The engine's events, to every caller on its executor. Takes no lock of the client. */
    private val listener = object : PositionListener {
        override fun onPosition(position: PositionEstimate) {
            engineLastEpochNs.accumulateAndGet(position.timestampNs.toLong(), ::maxOf)
            dispatch { it.onLocation(position) }
        }

        override fun onStatus(status: StatusUpdate) = dispatch { it.onEngineStatus(status) }

        // A rejected input threw to whoever pushed it too: the client counts its own
        // (LocationClientStats), an app's own calls got the exception.
        override fun onError(error: ErrorReport) {
            if (error.code != ErrorCode.INPUT_REJECTED) dispatch { it.onStatus(LocationStatus.EngineError(error)) }
        }
    }

    /** Where the client is: idle, running, degraded, paused or stopped. */
    val state: ClientState get() = synchronized(lock) { current }

    /** The conditions that hold now (permissions missing, radios off, sensors missing). */
    val conditions: Set<LocationStatus> get() = synchronized(lock) { LinkedHashSet(holding) }

    /** Whether the barometer is read: the phone has one, a request asks for it, and Android
     *  registered it. A phone without one positions as well, less its floor changes. */
    val usesBarometer: Boolean get() = synchronized(lock) { barometerOn }

    /** What the client did and dropped so far. */
    fun stats(): LocationClientStats = synchronized(lock) { stats.copy(callbackFailures = callbackFailures.get()) }

    /**
     * Starts updates for [callback], called on [executor] (`ContextCompat.getMainExecutor`, a
     * background executor, or `Runnable::run`); the same callback again replaces its request.
     * The callback first hears the conditions that already hold.
     */
    fun requestLocationUpdates(request: LocationRequest, executor: Executor, callback: LocationCallback) {
        synchronized(lock) {
            check(current != ClientState.STOPPED) { "the client is closed" }
            registrations.removeAll { it.callback === callback }
            val registration = Registration(callback, request, executor)
            registrations.add(registration)
            for (c in holding) post(registration) { it.onStatus(c) }
            apply()
        }
    }

    /** Stops updates for [callback]; with the last one, everything stops. */
    fun removeLocationUpdates(callback: LocationCallback) {
        synchronized(lock) {
            if (registrations.removeAll { it.callback === callback }) apply()
        }
    }

    /**
     * Re-checks permissions and switches now; call it from `onRequestPermissionsResult`. The
     * client also re-checks on its timer and when location, WiFi or Bluetooth is switched.
     */
    fun refreshAvailability() {
        synchronized(lock) { if (request != null) reconcile() }
    }

    /** Stops everything for good. The engine is the caller's to close afterwards. */
    override fun close() {
        synchronized(lock) {
            if (current == ClientState.STOPPED) return
            registrations.clear()
            apply()
            current = ClientState.STOPPED
        }
    }

    // --- What runs ------------------------------------------------------------------------------

    /** Starts, changes or stops what runs after the callers changed. */
    private fun apply() {
        if (registrations.isEmpty()) {
            request = null
            halt()
            holding.clear()
            current = ClientState.IDLE
            return
        }
        request = LocationRequest.merge(registrations.map { it.request })
        if (subscription == null) subscription = engine.subscribe(listener)
        if (!watching) {
            platform.availability.watch(availabilityChanged)
            watching = true
        }
        reconcile()
    }

    /** Checks permissions and switches, reports what changed, and runs what may run. A radio
     *  that fails while it starts asks for another pass instead of nesting one. */
    private fun reconcile() {
        if (reconciling) {
            reconcileAgain = true
            return
        }
        reconciling = true
        try {
            do {
                reconcileAgain = false
                reconcileOnce()
            } while (reconcileAgain)
        } finally {
            reconciling = false
        }
    }

    private fun reconcileOnce() {
        val request = request ?: return
        val availability = platform.availability
        val sdk = availability.sdkInt()
        val now = LinkedHashSet<LocationStatus>()

        val fine = availability.isGranted(Permission.ACCESS_FINE_LOCATION)
        if (!fine) now += LocationStatus.PermissionMissing(Permission.ACCESS_FINE_LOCATION)
        val located = availability.isLocationEnabled()
        if (!located) now += LocationStatus.LocationServicesOff
        // Waymark's positions are location: without the permission or with location services
        // off, the client derives none, from radios or from motion.
        val positioning = fine && located

        var wifiMayRun = false
        if (request.wifi) {
            val nearby = sdk < 33 || availability.isGranted(Permission.NEARBY_WIFI_DEVICES)
            if (!nearby) now += LocationStatus.PermissionMissing(Permission.NEARBY_WIFI_DEVICES)
            val on = platform.wifi.isScanAvailable()
            if (!on) now += LocationStatus.WifiOff
            wifiMayRun = positioning && nearby && on
        }
        var bleMayRun = false
        if (request.ble) {
            val scan = sdk < 31 || availability.isGranted(Permission.BLUETOOTH_SCAN)
            if (!scan) now += LocationStatus.PermissionMissing(Permission.BLUETOOTH_SCAN)
            val on = platform.ble.isEnabled()
            if (!on) now += LocationStatus.BluetoothOff
            bleFailure?.let { now += it }
            bleMayRun = positioning && scan && on && bleFailure == null
        }
        for (sensor in MotionSensor.values()) {
            if (!platform.sensors.has(sensor) || sensor in sensorsRefused) now += LocationStatus.SensorMissing(sensor)
        }

        for (c in now) if (c !in holding) emit(c)
        for (c in holding) if (c !in now) emit(LocationStatus.Restored(c))
        holding.clear()
        holding += now

        setMotion(positioning, request)
        setBarometer(if (positioning && request.barometer) request.maxLatencyUs else null)
        setWifi(wifiMayRun)
        setBle(bleMayRun, request.background)
        current = when {
            !positioning -> ClientState.PAUSED
            holding.isEmpty() -> ClientState.RUNNING
            else -> ClientState.DEGRADED
        }
        schedule(positioning)
    }

    /** Stops every sensor, radio and timer. */
    private fun halt() {
        setMotion(false, null)
        setBarometer(null)
        setWifi(false)
        setBle(false, false)
        bleRetry?.cancel()
        bleRetry = null
        bleFailure = null
        ticker?.cancel()
        ticker = null
        if (watching) {
            platform.availability.unwatch()
            watching = false
        }
        subscription?.let {
            it.cancel()
            it.close()
        }
        subscription = null
    }

    private fun setMotion(on: Boolean, request: LocationRequest?) {
        val settings = request?.let { it.sensorPeriodUs to it.maxLatencyUs }
        if (on && settings == sensorSettings && sensorsOn.isNotEmpty()) return
        flushMotion()
        for (sensor in sensorsOn) platform.sensors.stop(sensor)
        sensorsOn.clear()
        sensorSettings = null
        if (!on || settings == null) return
        sensorSettings = settings
        motionStartedNs = platform.clock.nowNs()
        for (sensor in MotionSensor.values()) {
            if (!platform.sensors.has(sensor)) continue
            if (platform.sensors.start(sensor, settings.first, settings.second, motionSink)) {
                sensorsOn += sensor
                sensorsRefused -= sensor
            } else if (sensorsRefused.add(sensor)) {
                reconcileAgain = true // reported as missing by the next pass
            }
        }
    }

    /** Runs the barometer with report latency [maxLatencyUs], or stops it (null). One that
     *  Android refuses stays off until the request changes: it is an extra, not a condition. */
    private fun setBarometer(maxLatencyUs: Int?) {
        if (maxLatencyUs == barometerLatencyUs) return
        flushPressure()
        if (barometerOn) platform.barometer.stop()
        barometerOn = false
        barometerLatencyUs = maxLatencyUs
        if (maxLatencyUs != null && platform.barometer.has()) {
            barometerOn = platform.barometer.start(BAROMETER_PERIOD_US, maxLatencyUs, pressureSink)
        }
    }

    private fun setWifi(on: Boolean) {
        if (on == wifiOn) return
        wifiOn = on
        scanInFlightSinceNs = null
        if (on) platform.wifi.listen(wifiSink) else platform.wifi.stopListening()
    }

    private fun setBle(on: Boolean, lowPower: Boolean) {
        if (on == bleOn && lowPower == bleLowPower) return
        if (bleOn) platform.ble.stop()
        bleOn = on
        bleLowPower = lowPower
        if (!on) beacons.clear()
        // A failure may be reported from inside start(): it stops BLE again (onBleFailure).
        if (on) platform.ble.start(lowPower, bleSink)
    }

    // --- The timer ------------------------------------------------------------------------------

    /** Plans the next tick: the next scan, epoch or scan timeout, or an availability check. */
    private fun schedule(positioning: Boolean) {
        ticker?.cancel()
        val request = request ?: return
        val nowNs = platform.clock.nowNs()
        var nextNs = nowNs + AVAILABILITY_CHECK_NS
        if (positioning) {
            val inFlight = scanInFlightSinceNs
            // While a scan is in flight, epochs wait for its results or its timeout.
            nextNs = if (inFlight != null) minOf(nextNs, inFlight + SCAN_TIMEOUT_NS) else minOf(nextNs, epochDueNs(request))
            if (inFlight == null && wifiOn) nextNs = minOf(nextNs, nextScanNs(request))
        }
        // Never sooner than MIN_TICK_MS: an epoch due but waiting for held-back samples polls.
        val delayMs = maxOf(MIN_TICK_MS, ((nextNs - nowNs) + 999_999L) / 1_000_000L)
        ticker = platform.scheduler.schedule(delayMs) { tick() }
    }

    private fun tick() {
        synchronized(lock) {
            val request = request ?: return
            reconcile() // re-checks permissions (no broadcast says one was granted or revoked)
            if (current == ClientState.PAUSED) return
            val nowNs = platform.clock.nowNs()
            val inFlight = scanInFlightSinceNs
            if (inFlight != null && nowNs - inFlight >= SCAN_TIMEOUT_NS) {
                scanInFlightSinceNs = null
                emit(LocationStatus.WifiScanFailed)
            }
            if (wifiOn && scanInFlightSinceNs == null && nowNs >= nextScanNs(request)) startScan(nowNs)
            // An epoch waits for a scan in flight: its results would be older than the epoch.
            if (scanInFlightSinceNs == null && nowNs >= epochDueNs(request)) timerEpoch(nowNs, request)
            schedule(true)
        }
    }

    /** An epoch is due an interval after the last one, or after the sensors started. */
    private fun epochDueNs(request: LocationRequest): Long =
        maxOf(lastEpoch(), motionStartedNs) + request.advanceIntervalMs * 1_000_000L

    private fun nextScanNs(request: LocationRequest): Long {
        val budget = WifiScanBudget.of(request.background, platform.availability.sdkInt(), platform.wifi.isScanThrottleEnabled())
        val byRequest = scanHistory.lastOrNull()?.let { it + request.wifiScanIntervalMs * 1_000_000L } ?: Long.MIN_VALUE
        return maxOf(budget.nextAllowedNs(scanHistory), byRequest)
    }

    /** Starts a WiFi scan. Every call counts against the budget, refused or not: Android's
     *  count of a refused call is not documented, so the client assumes the worst. */
    private fun startScan(nowNs: Long) {
        scanHistory += nowNs
        if (scanHistory.size > 64) scanHistory.subList(0, scanHistory.size - 64).clear()
        if (platform.wifi.startScan()) {
            scanInFlightSinceNs = nowNs
            stats = stats.copy(wifiScansStarted = stats.wifiScansStarted + 1)
        } else {
            stats = stats.copy(wifiScansRefused = stats.wifiScansRefused + 1)
            emit(LocationStatus.WifiScanThrottled)
        }
    }

    /** An epoch on the timer: the beacons heard, or motion alone. Its time is that of the
     *  newest accelerometer sample when batching holds samples back (never in the future of
     *  the motion the engine has). */
    private fun timerEpoch(nowNs: Long, request: LocationRequest) {
        val heldBack = MotionSensor.ACCELEROMETER in sensorsOn && newestAccelerometerNs != Long.MIN_VALUE &&
            nowNs - newestAccelerometerNs < maxOf(2_000_000_000L, 2 * request.sensorMaxLatencyMs * 1_000_000L)
        val atNs = if (heldBack) minOf(nowNs, newestAccelerometerNs) else nowNs
        if (atNs <= lastEpoch()) return
        flushMotion()
        val heard = beacons.drain(atNs, MAX_BEACON_AGE_NS)
        if (heard.isNotEmpty() && push(atNs, emptyList(), heard)) {
            stats = stats.copy(bleScansPushed = stats.bleScansPushed + 1)
            return
        }
        try {
            engine.advance(atNs.toULong())
            lastEpochNs = atNs
            stats = stats.copy(advances = stats.advances + 1)
        } catch (e: PositioningException) {
            stats = stats.copy(advancesRejected = stats.advancesRejected + 1, lastRejection = e.message)
        }
    }

    private fun lastEpoch(): Long = maxOf(lastEpochNs, engineLastEpochNs.get())

    // --- Inputs ---------------------------------------------------------------------------------

    private fun onSample(sensor: MotionSensor, timestampNs: Long, values: FloatArray) {
        synchronized(lock) {
            if (sensor !in sensorsOn || values.size < 3) return
            val batch = batches.getOrPut(sensor) { ArrayList(request?.batchSize ?: 50) }
            batch += Conversions.sample(timestampNs, values)
            if (sensor == MotionSensor.ACCELEROMETER) newestAccelerometerNs = maxOf(newestAccelerometerNs, timestampNs)
            if (batch.size >= (request?.batchSize ?: 50)) flush(sensor)
        }
    }

    private fun onPressure(timestampNs: Long, hpa: Float) {
        synchronized(lock) {
            if (!barometerOn) return
            pressures += Conversions.pressure(timestampNs, hpa)
            if (pressures.size >= (request?.batchSize ?: 50)) flushPressure()
        }
    }

    /** Pushes every sensor's batch: the engine needs the motion (and the height) up to an
     *  epoch before it. */
    private fun flushMotion() {
        for (sensor in MotionSensor.values()) flush(sensor)
        flushPressure()
    }

    /** Pushes the barometer's batch. Readings that are not a pressure, or not after the
     *  previous, are dropped and counted by the engine (`inputStats().pressureDropped`). */
    private fun flushPressure() {
        if (pressures.isEmpty()) return
        val copy = pressures.toList()
        pressures.clear()
        try {
            engine.pushPressure(copy)
            stats = stats.copy(pressureBatches = stats.pressureBatches + 1)
        } catch (e: PositioningException) {
            // As for motion: a throw is an internal error, reported by the listener.
        }
    }

    private fun flush(sensor: MotionSensor) {
        val batch = batches[sensor] ?: return
        if (batch.isEmpty()) return
        val copy = batch.toList()
        batch.clear()
        try {
            when (sensor) {
                MotionSensor.ACCELEROMETER -> engine.pushAccelerometer(copy)
                MotionSensor.GYROSCOPE -> engine.pushGyroscope(copy)
                MotionSensor.MAGNETOMETER -> engine.pushMagnetometer(copy)
            }
            stats = stats.copy(motionBatches = stats.motionBatches + 1)
        } catch (e: PositioningException) {
            // Bad samples are dropped and counted by the engine (inputStats); a throw is an
            // internal error, which the listener reports as EngineError.
        }
    }

    private fun onWifiResults(updated: Boolean) {
        synchronized(lock) {
            if (!wifiOn) return
            val mine = scanInFlightSinceNs != null
            scanInFlightSinceNs = null
            if (!updated) {
                if (mine) emit(LocationStatus.WifiScanFailed)
                return
            }
            val results = platform.wifi.scanResults()
            if (results.isEmpty()) return
            // Conversions: the scan is as new as its newest result; older cached entries carry
            // their age, so the engine weighs them as such.
            val scanNs = Conversions.scanTimeNs(results.map { it.timestampUs })
            when {
                scanNs <= lastWifiScanNs -> stats = stats.copy(wifiScansDuplicate = stats.wifiScansDuplicate + 1)
                scanNs <= lastEpoch() -> {
                    lastWifiScanNs = scanNs
                    stats = stats.copy(wifiScansLate = stats.wifiScansLate + 1)
                }
                else -> {
                    lastWifiScanNs = scanNs
                    val readings = results.map { Conversions.wifi(it.bssid, it.levelDbm, it.timestampUs, scanNs) }
                    stats = stats.copy(
                        wifiScansPushed = stats.wifiScansPushed + 1,
                        wifiScansPassive = stats.wifiScansPassive + if (mine) 0 else 1,
                    )
                    flushMotion()
                    push(scanNs, readings, beacons.drain(scanNs, MAX_BEACON_AGE_NS))
                }
            }
            request?.let { schedule(true) }
        }
    }

    private fun onBeacon(address: String, rssiDbm: Int, timestampNs: Long, scanRecord: ByteArray?) {
        synchronized(lock) {
            if (!bleOn) return
            val key = BleAdvertisements.reading(address, scanRecord)
            if (key == null) {
                stats = stats.copy(bleAdvertisementsIgnored = stats.bleAdvertisementsIgnored + 1)
                return
            }
            beacons.add(key, rssiDbm, timestampNs)
        }
    }

    private fun onBleFailure(errorCode: Int) {
        synchronized(lock) {
            if (!bleOn) return
            platform.ble.stop()
            bleOn = false
            bleFailure = LocationStatus.BleScanFailed(errorCode)
            // SCAN_FAILED_FEATURE_UNSUPPORTED (4) will not change; the others may (Android
            // allows 5 scan starts per 30 s, so retry after that).
            if (errorCode != SCAN_FAILED_FEATURE_UNSUPPORTED) {
                bleRetry?.cancel()
                bleRetry = platform.scheduler.schedule(BLE_RETRY_MS) {
                    synchronized(lock) {
                        bleRetry = null
                        bleFailure = null
                        if (request != null) reconcile()
                    }
                }
            }
            reconcile()
        }
    }

    /** Pushes one scan; false if the engine rejected it (counted with its reason). */
    private fun push(atNs: Long, wifi: List<WifiReading>, heard: List<BeaconReading>): Boolean {
        if (wifi.isEmpty() && heard.isEmpty()) return false
        return try {
            engine.pushScan(RadioScan(atNs.toULong(), wifi, heard))
            lastEpochNs = maxOf(lastEpochNs, atNs)
            true
        } catch (e: PositioningException) {
            stats = stats.copy(scansRejected = stats.scansRejected + 1, lastRejection = e.message)
            false
        }
    }

    // --- Delivery -------------------------------------------------------------------------------

    private fun emit(status: LocationStatus) = dispatch { it.onStatus(status) }

    private fun dispatch(call: (LocationCallback) -> Unit) {
        for (registration in registrations) post(registration, call)
    }

    /** Hands [call] to the caller's executor; an executor that refuses or throws (a direct one
     *  running a throwing callback) is counted, and never throws into Android's callbacks. */
    private fun post(registration: Registration, call: (LocationCallback) -> Unit) {
        try {
            registration.executor.execute { call(registration.callback) }
        } catch (e: RuntimeException) {
            callbackFailures.incrementAndGet()
        }
    }

    private companion object {
        /** The barometer's period, µs: 10 Hz, so the engine's one-second low-pass averages about
         *  ten readings (docs/accuracy.md#barometer); a stair climb takes several seconds. */
        const val BAROMETER_PERIOD_US = 100_000
        const val SCAN_TIMEOUT_NS = 10_000_000_000L
        const val MIN_TICK_MS = 50L
        const val AVAILABILITY_CHECK_NS = 5_000_000_000L
        const val MAX_BEACON_AGE_NS = 10_000_000_000L
        const val BLE_RETRY_MS = 30_000L
        const val SCAN_FAILED_FEATURE_UNSUPPORTED = 4
    }
}
