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
import dev.waymark.SurveyException
import dev.waymark.SurveyRecorderInterface
import dev.waymark.SurveySummary
import dev.waymark.WifiReading
import java.util.EnumMap
import java.util.EnumSet
import java.util.concurrent.CompletableFuture
import java.util.concurrent.CopyOnWriteArrayList
import java.util.concurrent.CountDownLatch
import java.util.concurrent.Executor
import java.util.concurrent.TimeUnit
import java.util.concurrent.atomic.AtomicLong

/**
 * Positions from the phone's sensors and radios, as Android's fused location provider gives
 * them: [requestLocationUpdates] with a [WaymarkLocationRequest] and a [WaymarkLocationCallback]
 * called on the caller's executor, or the `locations(request)` Flow. The client runs the motion
 * sensors, the barometer where the phone has one, WiFi scans within Android's budget
 * ([WifiScanBudget]), BLE scans and a timer that keeps epochs coming between scans, and reports
 * every problem as a coded [WaymarkLocationStatus].
 *
 * **Threads.** Everything the client does runs on its own thread, [Platform.scheduler] (a
 * `HandlerThread` on Android): sensor events, broadcasts, BLE results, the timer, every engine
 * call and so every epoch. The public methods only enqueue, so the app's main thread never
 * runs an epoch; callbacks are handed to the caller's executor, and a callback that blocks
 * holds up only that executor.
 *
 * **Foreground and background.** The client follows [Platform.lifecycle]: when no activity is
 * visible it switches to the background budget and low-power BLE by itself, and back, with no
 * new request; a location foreground service ([WaymarkForegroundService]) keeps it in the
 * foreground mode.
 *
 * **Survey mode.** [startSurvey] feeds a `SurveyRecorder` the same motion, scans and beacons,
 * with the surveyor's taps from the app's UI ([WaymarkSurveySession.markWaypoint]).
 *
 * On Android: `WaymarkLocationClient(context, engine)` (AndroidPlatform.kt). Here the platform
 * comes as [Platform] ports, so this class runs on the JVM against fakes. One client per app:
 * Android's scan budget is the app's, and the client keeps it. Thread-safe; the engine stays
 * the app's to close, after [close].
 */
class WaymarkLocationClient private constructor(
    private val engine: PositioningEngineInterface?,
    private val platform: Platform,
    @Suppress("UNUSED_PARAMETER") marker: Unit,
) : AutoCloseable {
    /** A client that positions with [engine]. */
    constructor(engine: PositioningEngineInterface, platform: Platform) : this(engine, platform, Unit)

    private class Registration(
        val callback: WaymarkLocationCallback,
        val request: WaymarkLocationRequest,
        val executor: Executor,
        val survey: WaymarkSurveySession? = null,
    ) {
        /** It heard the conditions that held when it came: only then does it hear the rest. */
        @Volatile var greeted = false
    }

    private val lock = Any()

    // Read without the lock by the engine's listener.
    private val registrations = CopyOnWriteArrayList<Registration>()
    private val engineLastEpochNs = AtomicLong(Long.MIN_VALUE)
    private val callbackFailures = AtomicLong()
    @Volatile private var closed = false

    // Everything below is guarded by `lock`, and changed on the client's thread only.
    private var request: WaymarkLocationRequest? = null
    private var current = ClientState.IDLE
    private val holding = LinkedHashSet<WaymarkLocationStatus>()
    private var reconciling = false
    private var reconcileAgain = false
    private var subscription: Subscription? = null
    private var watching: List<Cancellable> = emptyList()
    private var ticker: Cancellable? = null
    private var visibleMode = true
    private var foregroundBudget = true
    private val surveys = ArrayList<WaymarkSurveySession>()

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
    private var bleFailure: WaymarkLocationStatus.BleScanFailed? = null
    private var bleRetry: Cancellable? = null
    private val beacons = BeaconWindow()

    private var lastEpochNs = Long.MIN_VALUE
    private var lastQuietEpochNs = Long.MIN_VALUE
    private var stats = LocationClientStats()

    // The ports may call from any thread (Android delivers BLE results on the main thread):
    // each input moves to the client's thread before it is handled.
    private val motionSink = MotionSink { sensor, timestampNs, values ->
        if (platform.scheduler.isClientThread()) {
            onSample(sensor, timestampNs, values)
        } else {
            val copy = values.copyOf() // Android reuses a SensorEvent's values array
            platform.scheduler.post { onSample(sensor, timestampNs, copy) }
        }
    }
    private val pressureSink = PressureSink { timestampNs, hpa -> onClientThread { onPressure(timestampNs, hpa) } }
    private val wifiSink = WifiSink { updated -> onClientThread { onWifiResults(updated) } }
    private val bleSink = object : BleSink {
        override fun onAdvertisement(address: String, rssiDbm: Int, timestampNs: Long, scanRecord: ByteArray?) =
            onClientThread { onBeacon(address, rssiDbm, timestampNs, scanRecord) }

        override fun onScanFailed(errorCode: Int) = onClientThread { onBleFailure(errorCode) }
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
            if (error.code != ErrorCode.INPUT_REJECTED) dispatch { it.onStatus(WaymarkLocationStatus.EngineError(error)) }
        }
    }

    /** Where the client is: idle, running, degraded, paused or stopped. */
    val state: ClientState get() = synchronized(lock) { current }

    /** The conditions that hold now (permissions missing, radios off, sensors missing). */
    val conditions: Set<WaymarkLocationStatus> get() = synchronized(lock) { LinkedHashSet(holding) }

    /** Whether the barometer is read: the phone has one, a request asks for it, and Android
     *  registered it. A phone without one positions as well, less its floor changes. */
    val usesBarometer: Boolean get() = synchronized(lock) { barometerOn }

    /** Whether the client runs in the background mode now (no activity visible, or every
     *  request says `background`): low-power BLE, and the background WiFi budget unless a
     *  location foreground service runs. */
    val inBackground: Boolean get() = synchronized(lock) { !visibleMode }

    /** Whether [close] was called. */
    val isClosed: Boolean get() = closed

    /** What the client did and dropped so far. */
    fun stats(): LocationClientStats = synchronized(lock) { stats.copy(callbackFailures = callbackFailures.get()) }

    /**
     * Starts updates for [callback], called on [executor] (`ContextCompat.getMainExecutor`, a
     * background executor, or `Runnable::run`, which runs it on the client's thread: keep it
     * short there); the same callback again replaces its request. The callback first hears the
     * conditions that already hold. Returns at once: the sensors and radios start on the
     * client's thread. Throws `IllegalStateException` once the client is closed.
     */
    fun requestLocationUpdates(request: WaymarkLocationRequest, executor: Executor, callback: WaymarkLocationCallback) {
        register(Registration(callback, request, executor))
    }

    /**
     * Survey mode: runs the sensors and radios of [request] as [requestLocationUpdates] does,
     * and writes every motion batch and scan into [recorder], with the taps of the returned
     * session. [callback] hears the statuses (and positions, when the client has an engine),
     * on [executor]. The recorder stays the caller's to close, after the session finished.
     */
    @JvmOverloads
    fun startSurvey(
        recorder: SurveyRecorderInterface,
        executor: Executor,
        callback: WaymarkLocationCallback,
        request: WaymarkLocationRequest = WaymarkLocationRequest(),
    ): WaymarkSurveySession {
        val session = WaymarkSurveySession(this, recorder, callback)
        register(Registration(callback, request, executor, session))
        return session
    }

    private fun register(registration: Registration) {
        synchronized(lock) {
            check(!closed) { "the client is closed" }
            registrations.removeAll { it.callback === registration.callback }
            registrations.add(registration)
        }
        onClientThread {
            synchronized(lock) {
                if (current == ClientState.STOPPED || registration !in registrations) return@onClientThread
                for (c in holding) post(registration) { it.onStatus(c) }
                registration.greeted = true
                registration.survey?.let { if (it !in surveys) surveys += it }
                apply()
            }
        }
    }

    /** Stops updates for [callback]; with the last one, everything stops. A survey's callback
     *  is removed by its session's `finish`. */
    fun removeLocationUpdates(callback: WaymarkLocationCallback) {
        val removed = synchronized(lock) { registrations.removeAll { it.callback === callback && it.survey == null } }
        if (removed) onClientThread { synchronized(lock) { if (current != ClientState.STOPPED) apply() } }
    }

    /**
     * Re-checks permissions and switches; call it from `onRequestPermissionsResult`. The
     * client also re-checks on its timer and when location, WiFi or Bluetooth is switched or
     * the app goes to the background or comes back.
     */
    fun refreshAvailability() {
        onClientThread { synchronized(lock) { if (request != null) reconcile() } }
    }

    /**
     * Stops everything for good: the sensors and radios stop, the batches held go to the engine
     * (and to the surveys, which are finished), every callback hears `onClientClosed`, and the
     * client's thread ends. Waits up to [CLOSE_TIMEOUT_MS] for the client's thread, so the
     * engine may be closed afterwards.
     */
    override fun close() {
        synchronized(lock) {
            if (closed) return
            closed = true
        }
        val done = CountDownLatch(1)
        onClientThread {
            try {
                shutdown()
            } finally {
                done.countDown()
            }
        }
        if (!platform.scheduler.isClientThread()) done.await(CLOSE_TIMEOUT_MS, TimeUnit.MILLISECONDS)
        platform.scheduler.quit()
    }

    private fun shutdown() {
        synchronized(lock) {
            if (current == ClientState.STOPPED) return
            flushMotion()
            for (session in surveys.toList()) finishSurvey(session, ending = true)
            val leaving = registrations.toList()
            registrations.clear()
            apply()
            current = ClientState.STOPPED
            for (r in leaving) post(r) { it.onClientClosed() }
        }
    }

    /** Runs [task] on the client's thread: now if this is it, else after what is queued. */
    internal fun onClientThread(task: () -> Unit) {
        if (platform.scheduler.isClientThread()) task() else platform.scheduler.post { task() }
    }

    // --- Survey mode ----------------------------------------------------------------------------

    internal fun markWaypoint(session: WaymarkSurveySession, x: Double, y: Double, floor: String, done: CompletableFuture<Long>) {
        // The tap's time is when the surveyor tapped, on the clock of every input.
        val atNs = platform.clock.nowNs()
        if (closed && !platform.scheduler.isClientThread()) {
            done.completeExceptionally(IllegalStateException("the client is closed"))
            return
        }
        onClientThread {
            synchronized(lock) {
                if (session.result != null) {
                    done.completeExceptionally(IllegalStateException("the survey is finished"))
                    return@onClientThread
                }
                flushMotion()
                try {
                    session.recorder.markWaypoint(atNs.toULong(), x, y, floor)
                    done.complete(atNs)
                } catch (e: SurveyException) {
                    done.completeExceptionally(e)
                }
            }
        }
    }

    internal fun finishSurvey(session: WaymarkSurveySession, done: CompletableFuture<SurveySummary>) {
        val run = {
            val result = synchronized(lock) { finishSurvey(session, ending = false) }
            result.fold(done::complete, done::completeExceptionally)
            Unit
        }
        // Once closed, the client's thread may be gone; close finished the survey, or is about
        // to (the lock orders the two), so run here.
        if (closed) run() else onClientThread(run)
    }

    /**
     * Flushes the batches into [session]'s recorder and finishes it. When that succeeds, or
     * the client is [ending], the session's request is removed; when it fails (`NoWaypoints`,
     * `Io`) the recording goes on, as the recorder's does, and `finish` may be called again.
     */
    private fun finishSurvey(session: WaymarkSurveySession, ending: Boolean): Result<SurveySummary> {
        session.result?.let { return it }
        if (session !in surveys && !ending) return Result.failure(IllegalStateException("the survey has not started"))
        flushMotion()
        val result = try {
            Result.success(session.recorder.finish())
        } catch (e: SurveyException) {
            Result.failure(e)
        }
        if (result.isFailure && !ending) return result
        session.result = result
        surveys -= session
        if (registrations.removeAll { it.survey === session } && current != ClientState.STOPPED) apply()
        return result
    }

    /** Feeds every survey one call; a storage failure is a condition, retried with each call. */
    private fun record(what: (SurveyRecorderInterface) -> Unit) {
        for (session in surveys) {
            session.storageFailure?.let { failure ->
                try {
                    session.recorder.resume()
                    session.storageFailure = null
                    post(session) { it.onStatus(WaymarkLocationStatus.Restored(failure)) }
                } catch (e: SurveyException) {
                    stats = stats.copy(surveyInputsLost = stats.surveyInputsLost + 1)
                    return@let
                }
            }
            if (session.storageFailure != null) continue
            try {
                what(session.recorder)
                stats = stats.copy(surveyInputs = stats.surveyInputs + 1)
            } catch (e: SurveyException.InputRejected) {
                stats = stats.copy(surveyScansRejected = stats.surveyScansRejected + 1)
            } catch (e: SurveyException.Io) {
                stats = stats.copy(surveyInputsLost = stats.surveyInputsLost + 1)
                val failure = WaymarkLocationStatus.SurveyStorageFailed(e.message ?: "storage failed")
                session.storageFailure = failure
                post(session) { it.onStatus(failure) }
            } catch (e: SurveyException) {
                stats = stats.copy(surveyInputsLost = stats.surveyInputsLost + 1)
            }
        }
    }

    private fun post(session: WaymarkSurveySession, call: (WaymarkLocationCallback) -> Unit) {
        registrations.firstOrNull { it.survey === session }?.let { post(it, call) }
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
        request = WaymarkLocationRequest.merge(registrations.map { it.request })
        if (subscription == null && engine != null) subscription = engine.subscribe(listener)
        if (watching.isEmpty()) {
            platform.availability.watch(availabilityChanged)
            watching = listOf(Cancellable { platform.availability.unwatch() }, platform.lifecycle.watch(availabilityChanged))
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
        val lifecycle = platform.lifecycle
        val now = LinkedHashSet<WaymarkLocationStatus>()

        // The background mode: no activity visible, or every caller says it is in the background.
        val visible = lifecycle.isVisible() && !request.background
        val service = lifecycle.isForegroundServiceRunning()
        val bluetoothOn = !request.ble || platform.ble.isEnabled()
        val permissions = PermissionCheck(
            availability.sdkInt(), availability::isGranted, request.wifi, request.ble, bluetoothOn, inForeground = visible || service,
        )
        now += permissions.missing
        lifecycle.foregroundServiceRefusal()?.let { now += it }
        val located = availability.isLocationEnabled()
        if (!located) now += WaymarkLocationStatus.LocationServicesOff
        // Waymark's positions are location: without precise location (in the background too,
        // where it is needed) or with location services off, the client derives none, from
        // radios or from motion.
        val positioning = permissions.located && located

        var wifiMayRun = false
        if (request.wifi) {
            val on = platform.wifi.isScanAvailable()
            if (!on) now += WaymarkLocationStatus.WifiOff
            wifiMayRun = positioning && permissions.wifiAllowed && on
        }
        var bleMayRun = false
        if (request.ble) {
            if (!bluetoothOn) now += WaymarkLocationStatus.BluetoothOff
            bleFailure?.let { now += it }
            bleMayRun = positioning && permissions.bleAllowed && bluetoothOn && bleFailure == null
        }
        for (sensor in MotionSensor.values()) {
            if (!platform.sensors.has(sensor) || sensor in sensorsRefused) now += WaymarkLocationStatus.SensorMissing(sensor)
        }

        for (c in now) if (c !in holding) emit(c)
        for (c in holding) if (c !in now) emit(WaymarkLocationStatus.Restored(c))
        holding.clear()
        holding += now

        visibleMode = visible
        // Android counts an app with a foreground service as in the foreground for its scans.
        foregroundBudget = visible || service
        setMotion(positioning, request)
        setBarometer(if (positioning && request.barometer) request.maxLatencyUs else null)
        setWifi(wifiMayRun)
        setBle(bleMayRun, lowPower = !visible)
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
        for (w in watching) w.cancel()
        watching = emptyList()
        subscription?.let {
            it.cancel()
            it.close()
        }
        subscription = null
    }

    private fun setMotion(on: Boolean, request: WaymarkLocationRequest?) {
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
                emit(WaymarkLocationStatus.WifiScanFailed)
            }
            if (wifiOn && scanInFlightSinceNs == null && nowNs >= nextScanNs(request)) startScan(nowNs)
            // An epoch waits for a scan in flight: its results would be older than the epoch.
            if (scanInFlightSinceNs == null && nowNs >= epochDueNs(request)) timerEpoch(nowNs, request)
            schedule(true)
        }
    }

    /** An epoch is due an interval after the last one, or after the sensors started. */
    private fun epochDueNs(request: WaymarkLocationRequest): Long =
        maxOf(lastEpoch(), motionStartedNs, lastQuietEpochNs) + request.advanceIntervalMs * 1_000_000L

    private fun nextScanNs(request: WaymarkLocationRequest): Long {
        val budget = WifiScanBudget.of(!foregroundBudget, platform.availability.sdkInt(), platform.wifi.isScanThrottleEnabled())
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
            emit(WaymarkLocationStatus.WifiScanThrottled)
        }
    }

    /** An epoch on the timer: the beacons heard, or motion alone. Its time is that of the
     *  newest accelerometer sample when batching holds samples back (never in the future of
     *  the motion the engine has). */
    private fun timerEpoch(nowNs: Long, request: WaymarkLocationRequest) {
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
        if (engine == null) {
            // Survey mode without an engine: nothing to record at this epoch. It does not count
            // as an epoch, so WiFi results older than it still go to the recorder.
            lastQuietEpochNs = atNs
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
        // A survey records no pressure: `waymark survey` takes none.
        if (engine == null) return
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
        if (surveys.isNotEmpty()) {
            record {
                when (sensor) {
                    MotionSensor.ACCELEROMETER -> it.pushAccelerometer(copy)
                    MotionSensor.GYROSCOPE -> it.pushGyroscope(copy)
                    MotionSensor.MAGNETOMETER -> it.pushMagnetometer(copy)
                }
            }
        }
        if (engine == null) return
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
                if (mine) emit(WaymarkLocationStatus.WifiScanFailed)
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
            bleFailure = WaymarkLocationStatus.BleScanFailed(errorCode)
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

    /** Pushes one scan to the surveys and the engine; false if the engine rejected it (counted
     *  with its reason). */
    private fun push(atNs: Long, wifi: List<WifiReading>, heard: List<BeaconReading>): Boolean {
        if (wifi.isEmpty() && heard.isEmpty()) return false
        val scan = RadioScan(atNs.toULong(), wifi, heard)
        if (surveys.isNotEmpty()) record { it.pushScan(scan) }
        if (engine == null) {
            lastEpochNs = maxOf(lastEpochNs, atNs)
            return true
        }
        return try {
            engine.pushScan(scan)
            lastEpochNs = maxOf(lastEpochNs, atNs)
            true
        } catch (e: PositioningException) {
            stats = stats.copy(scansRejected = stats.scansRejected + 1, lastRejection = e.message)
            false
        }
    }

    // --- Delivery -------------------------------------------------------------------------------

    private fun emit(status: WaymarkLocationStatus) = dispatch { it.onStatus(status) }

    private fun dispatch(call: (WaymarkLocationCallback) -> Unit) {
        for (registration in registrations) if (registration.greeted) post(registration, call)
    }

    /** Hands [call] to the caller's executor; an executor that refuses or throws (a direct one
     *  running a throwing callback) is counted, and never throws into Android's callbacks. */
    private fun post(registration: Registration, call: (WaymarkLocationCallback) -> Unit) {
        try {
            registration.executor.execute { call(registration.callback) }
        } catch (e: RuntimeException) {
            callbackFailures.incrementAndGet()
        }
    }

    companion object {
        /**
         * How long [close] waits for the client's thread to stop, ms: Android's "application not
         * responding" limit for a blocked main thread, so a close on the main thread never
         * outlasts it.
         */
        const val CLOSE_TIMEOUT_MS = 5_000L

        /** A client without an engine, for survey mode alone ([startSurvey]): it records, and
         *  makes no positions. */
        @JvmStatic
        fun forSurvey(platform: Platform): WaymarkLocationClient = WaymarkLocationClient(null, platform, Unit)

        /** The barometer's period, µs: 10 Hz, so the engine's one-second low-pass averages about
         *  ten readings (docs/accuracy.md#barometer); a stair climb takes several seconds. */
        private const val BAROMETER_PERIOD_US = 100_000
        private const val SCAN_TIMEOUT_NS = 10_000_000_000L
        private const val MIN_TICK_MS = 50L
        private const val AVAILABILITY_CHECK_NS = 5_000_000_000L
        private const val MAX_BEACON_AGE_NS = 10_000_000_000L
        private const val BLE_RETRY_MS = 30_000L
        private const val SCAN_FAILED_FEATURE_UNSUPPORTED = 4
    }
}
