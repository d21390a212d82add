package dev.waymark

import dev.waymark.android.AppVisibility
import dev.waymark.android.Availability
import dev.waymark.android.Barometer
import dev.waymark.android.BleScanner
import dev.waymark.android.BleSink
import dev.waymark.android.Cancellable
import dev.waymark.android.Clock
import dev.waymark.android.WaymarkLocationCallback
import dev.waymark.android.WaymarkLocationStatus
import dev.waymark.android.MotionSensor
import dev.waymark.android.MotionSensors
import dev.waymark.android.MotionSink
import dev.waymark.android.WaymarkPermission
import dev.waymark.android.Platform
import dev.waymark.android.PressureSink
import dev.waymark.android.Scheduler
import dev.waymark.android.WifiRadio
import dev.waymark.android.WifiResult
import dev.waymark.android.WifiSink
import java.util.EnumMap
import java.util.PriorityQueue
import java.util.concurrent.CopyOnWriteArrayList
import kotlin.math.roundToInt

/*
 * Fakes of the Android ports of WaymarkLocationClient: a clock and an event loop the test
 * drives, sensors, a WiFi radio, a BLE scanner and permissions it controls and records.
 */

class FakeClock : Clock {
    @Volatile var now = 0L
    override fun nowNs(): Long = now
}

/**
 * The client's Handler, and the platform's own events, in time order on one fake clock. The
 * test's thread plays the client's thread: posted tasks run at once (ThreadedPhone runs the
 * client on a thread of its own).
 */
class FakeScheduler(private val clock: FakeClock) : Scheduler {
    private class Task(val atNs: Long, val seq: Long, val run: Runnable) {
        var cancelled = false
    }

    private var seq = 0L
    private val queue = PriorityQueue<Task>(compareBy<Task>({ it.atNs }, { it.seq }))

    override fun schedule(delayMs: Long, task: Runnable): Cancellable = at(clock.now + delayMs * 1_000_000L, task)

    override fun post(task: Runnable) = task.run()

    override fun isClientThread() = true

    fun at(atNs: Long, task: Runnable): Cancellable = synchronized(queue) {
        val t = Task(atNs, seq++, task)
        queue += t
        Cancellable { synchronized(queue) { t.cancelled = true } }
    }

    /** Runs every task due up to [tNs], moving the clock to each task's time, then to [tNs]. */
    fun runUntil(tNs: Long) {
        while (true) {
            val next = synchronized(queue) {
                val head = queue.peek()
                if (head == null || head.atNs > tNs) null else queue.poll()
            } ?: break
            if (synchronized(queue) { next.cancelled }) continue
            clock.now = maxOf(clock.now, next.atNs)
            next.run.run()
        }
        clock.now = maxOf(clock.now, tNs)
    }

    /** Tasks scheduled and not cancelled. */
    val pending: Int get() = synchronized(queue) { queue.count { !it.cancelled } }
}

class FakeSensors(private val present: Set<MotionSensor> = MotionSensor.values().toSet()) : MotionSensors {
    val running: MutableMap<MotionSensor, MotionSink> = java.util.Collections.synchronizedMap(EnumMap<MotionSensor, MotionSink>(MotionSensor::class.java))
    /** The threads that registered or unregistered a sensor. */
    val threads: MutableSet<String> = java.util.concurrent.ConcurrentHashMap.newKeySet()
    val registrations = ArrayList<Triple<MotionSensor, Int, Int>>()
    /** Present, but registerListener returns false. */
    val refused = HashSet<MotionSensor>()

    override fun has(sensor: MotionSensor) = sensor in present

    override fun start(sensor: MotionSensor, periodUs: Int, maxReportLatencyUs: Int, sink: MotionSink): Boolean {
        threads += Thread.currentThread().name
        if (sensor !in present || sensor in refused) return false
        registrations += Triple(sensor, periodUs, maxReportLatencyUs)
        running[sensor] = sink
        return true
    }

    override fun stop(sensor: MotionSensor) {
        threads += Thread.currentThread().name
        running.remove(sensor)
    }

    fun emit(sensor: MotionSensor, s: MotionSample) {
        running[sensor]?.onSample(sensor, s.timestampNs.toLong(), floatArrayOf(s.x.toFloat(), s.y.toFloat(), s.z.toFloat()))
    }
}

class FakeBarometer(private val present: Boolean) : Barometer {
    @Volatile var sink: PressureSink? = null
    /** (periodUs, maxReportLatencyUs) of each registration. */
    val registrations = ArrayList<Pair<Int, Int>>()
    /** Present, but registerListener returns false. */
    var refuse = false

    override fun has() = present

    override fun start(periodUs: Int, maxReportLatencyUs: Int, sink: PressureSink): Boolean {
        if (!present || refuse) return false
        registrations += periodUs to maxReportLatencyUs
        this.sink = sink
        return true
    }

    override fun stop() {
        sink = null
    }

    fun emit(timestampNs: Long, hpa: Float) {
        sink?.onPressure(timestampNs, hpa)
    }
}

class FakeWifi(private val clock: FakeClock) : WifiRadio {
    var available = true
    var throttleEnabled = true
    /** What startScan() returns. */
    var accept = true
    /** startScan() calls, ns. */
    val startCalls = ArrayList<Long>()
    /** A scan started and not yet answered. */
    var pending = false
    @Volatile var results: List<WifiResult> = emptyList()
    @Volatile var sink: WifiSink? = null
    /** The threads that started scans, read results or registered the receiver. */
    val threads: MutableSet<String> = java.util.concurrent.ConcurrentHashMap.newKeySet()

    override fun isScanAvailable() = available
    override fun isScanThrottleEnabled() = throttleEnabled

    override fun startScan(): Boolean {
        threads += Thread.currentThread().name
        startCalls += clock.now
        if (accept) pending = true
        return accept
    }

    override fun scanResults(): List<WifiResult> {
        threads += Thread.currentThread().name
        return results
    }

    override fun listen(sink: WifiSink) {
        threads += Thread.currentThread().name
        this.sink = sink
    }

    override fun stopListening() {
        sink = null
    }

    /** A scan's end, as the SCAN_RESULTS_AVAILABLE_ACTION receiver hears it. */
    fun broadcast(results: List<WifiResult>, updated: Boolean = true) {
        if (updated) this.results = results
        pending = false
        sink?.onScanResults(updated)
    }
}

class FakeBle : BleScanner {
    var enabled = true
    @Volatile var sink: BleSink? = null
    var starts = 0
    var lowPower = false
    /** Fails the next start with this code, as onScanFailed from inside startScan. */
    var failNextStartWith: Int? = null

    override fun isEnabled() = enabled

    override fun start(lowPower: Boolean, sink: BleSink) {
        starts++
        this.lowPower = lowPower
        this.sink = sink
        failNextStartWith?.let {
            failNextStartWith = null
            sink.onScanFailed(it)
        }
    }

    override fun stop() {
        sink = null
    }
}

class FakeAvailability(@Volatile var sdk: Int = 34) : Availability {
    val granted: MutableSet<WaymarkPermission> = java.util.concurrent.ConcurrentHashMap.newKeySet<WaymarkPermission>().apply {
        addAll(WaymarkPermission.values())
    }
    var locationOn = true
    var watcher: Runnable? = null

    override fun sdkInt() = sdk
    override fun isGranted(permission: WaymarkPermission) = permission in granted
    override fun isLocationEnabled() = locationOn

    override fun watch(onChange: Runnable) {
        watcher = onChange
    }

    override fun unwatch() {
        watcher = null
    }
}

/** Everything a client runs on, faked. */
class FakePhone(sensorsPresent: Set<MotionSensor> = MotionSensor.values().toSet(), hasBarometer: Boolean = false) {
    val clock = FakeClock()
    val scheduler = FakeScheduler(clock)
    val sensors = FakeSensors(sensorsPresent)
    val wifi = FakeWifi(clock)
    val ble = FakeBle()
    val availability = FakeAvailability()
    val barometer = FakeBarometer(hasBarometer)
    /** The app's activities and foreground service, on the same fake clock. */
    val lifecycle = AppVisibility(scheduler, initiallyVisible = true)
    val platform = Platform(clock, scheduler, sensors, wifi, ble, availability, barometer, lifecycle)

    /** Nothing of the phone runs: no sensor, no barometer, no receiver, no BLE scan. */
    val idle: Boolean get() =
        sensors.running.isEmpty() && barometer.sink == null && wifi.sink == null && ble.sink == null

    /**
     * Replays the simulated walk: its motion samples in time order, the timers between them,
     * and at each epoch the scan's results, broadcast 300 ms after the scan's time when the
     * client asked for a scan since the previous epoch or when [passive] says another app did.
     * With [pressureHpa], the barometer reads it every 100 ms between the epochs' motion.
     */
    fun replay(
        walk: List<Epoch>,
        passive: (Int) -> Boolean = { false },
        pressureHpa: ((Long) -> Float)? = null,
        afterEpoch: (Int) -> Unit = {},
    ) {
        var nextPressureNs = walk.first().timestampNs.toLong()
        for ((k, epoch) in walk.withIndex()) {
            val samples = epoch.accelerometer.map { MotionSensor.ACCELEROMETER to it } +
                epoch.gyroscope.map { MotionSensor.GYROSCOPE to it } +
                epoch.magnetometer.map { MotionSensor.MAGNETOMETER to it }
            for ((sensor, s) in samples.sortedBy { it.second.timestampNs }) {
                val t = s.timestampNs.toLong()
                while (pressureHpa != null && nextPressureNs <= t) {
                    scheduler.runUntil(nextPressureNs)
                    barometer.emit(nextPressureNs, pressureHpa(nextPressureNs))
                    nextPressureNs += 100_000_000L
                }
                scheduler.runUntil(t)
                sensors.emit(sensor, s)
            }
            val t = epoch.timestampNs.toLong()
            scheduler.runUntil(t)
            if (wifi.pending || passive(k)) {
                val results = epoch.wifi.map { WifiResult(it.bssid, it.rssiDbm.roundToInt(), t / 1_000L) }
                wifi.pending = false
                scheduler.at(t + 300_000_000L) { wifi.broadcast(results) }
            }
            afterEpoch(k)
        }
        scheduler.runUntil(walk.last().timestampNs.toLong() + 1_000_000_000L)
    }
}

/** Hears a client; records what and on which executor. */
class RecordingCallback : WaymarkLocationCallback {
    val positions = CopyOnWriteArrayList<PositionEstimate>()
    val statuses = CopyOnWriteArrayList<WaymarkLocationStatus>()
    val engineStatuses = CopyOnWriteArrayList<StatusUpdate>()

    override fun onLocation(position: PositionEstimate) {
        positions += position
    }

    override fun onStatus(status: WaymarkLocationStatus) {
        statuses += status
    }

    override fun onEngineStatus(update: StatusUpdate) {
        engineStatuses += update
    }
}

/** A real engine that records what the client pushes into it. */
class RecordingEngine(private val inner: PositioningEngine) : PositioningEngineInterface by inner, AutoCloseable {
    val scans = ArrayList<RadioScan>()
    val advances = ArrayList<Long>()
    var accelerometerCalls = 0
    var accelerometerSamples = 0
    var newestAccelerometerNs = Long.MIN_VALUE
    /** For each pushed scan: the newest accelerometer sample pushed before it. */
    val motionBeforeScan = ArrayList<Long>()
    var pressureReadings = 0
    var newestPressureNs = Long.MIN_VALUE
    /** For each pushed scan: the newest barometer reading pushed before it. */
    val pressureBeforeScan = ArrayList<Long>()

    override fun pushPressure(batch: List<PressureReading>): UInt {
        pressureReadings += batch.size
        batch.lastOrNull()?.let { newestPressureNs = maxOf(newestPressureNs, it.timestampNs.toLong()) }
        return inner.pushPressure(batch)
    }

    override fun pushAccelerometer(batch: List<MotionSample>): UInt {
        accelerometerCalls++
        accelerometerSamples += batch.size
        batch.lastOrNull()?.let { newestAccelerometerNs = maxOf(newestAccelerometerNs, it.timestampNs.toLong()) }
        return inner.pushAccelerometer(batch)
    }

    override fun pushScan(scan: RadioScan): PositionEstimate {
        scans += scan
        motionBeforeScan += newestAccelerometerNs
        pressureBeforeScan += newestPressureNs
        return inner.pushScan(scan)
    }

    override fun close() = inner.close()

    override fun advance(timestampNs: ULong): PositionEstimate {
        advances += timestampNs.toLong()
        return inner.advance(timestampNs)
    }
}
