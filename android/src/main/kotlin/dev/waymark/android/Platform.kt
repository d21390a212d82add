package dev.waymark.android

/*
 * The platform ports of [WaymarkLocationClient]. Each is what the client needs of Android, in
 * plain Kotlin, so all the client's logic runs (and is tested) on the JVM; AndroidPlatform.kt
 * adapts them to SensorManager, WifiManager, BluetoothLeScanner, Handler and Context.
 */

/** Everything the client runs on. [barometer] defaults to a phone without one, [lifecycle] to
 *  an app that is always visible (an app that tells the client nothing). */
class Platform @JvmOverloads constructor(
    val clock: Clock,
    val scheduler: Scheduler,
    val sensors: MotionSensors,
    val wifi: WifiRadio,
    val ble: BleScanner,
    val availability: Availability,
    val barometer: Barometer = Barometer.NONE,
    val lifecycle: AppLifecycle = AppLifecycle.ALWAYS_VISIBLE,
)

/** The monotonic clock of every input: `SystemClock.elapsedRealtimeNanos()` on Android, the
 *  clock of `SensorEvent.timestamp`, `ScanResult.timestamp` (in µs) and BLE `timestampNanos`. */
fun interface Clock {
    fun nowNs(): Long
}

/**
 * The client's own thread: a `HandlerThread` on Android ([ThreadScheduler] on the JVM). Every
 * input, epoch, engine call and timer of the client runs on it, never on the thread that
 * requested updates, so the app's main thread only enqueues.
 */
interface Scheduler {
    /** Runs [task] on the client's thread after [delayMs]. */
    fun schedule(delayMs: Long, task: Runnable): Cancellable

    /** Runs [task] on the client's thread as soon as it is free, after the tasks posted before. */
    fun post(task: Runnable)

    /** Whether the calling thread is the client's thread. */
    fun isClientThread(): Boolean

    /** The client closed: the thread ends after the tasks posted so far (`quitSafely`). */
    fun quit() {}
}

/** A scheduled task or a registration, cancelled at most once. */
fun interface Cancellable {
    fun cancel()
}

/** The accelerometer, gyroscope and magnetometer: `SensorManager`. */
interface MotionSensors {
    /** Whether the phone has [sensor]. */
    fun has(sensor: MotionSensor): Boolean

    /** `registerListener(listener, sensor, periodUs, maxReportLatencyUs)`; false if refused. */
    fun start(sensor: MotionSensor, periodUs: Int, maxReportLatencyUs: Int, sink: MotionSink): Boolean

    /** Unregisters [sensor]. */
    fun stop(sensor: MotionSensor)
}

/** One `SensorEvent`: ns on the shared clock, values in SI units. */
fun interface MotionSink {
    fun onSample(sensor: MotionSensor, timestampNs: Long, values: FloatArray)
}

/** The barometer, `Sensor.TYPE_PRESSURE`: many phones have one, some do not, and a phone
 *  without one loses only the floor changes it gives (docs/android.md#the-barometer). */
interface Barometer {
    /** Whether the phone has one. */
    fun has(): Boolean

    /** `registerListener(listener, sensor, periodUs, maxReportLatencyUs)`; false if refused. */
    fun start(periodUs: Int, maxReportLatencyUs: Int, sink: PressureSink): Boolean

    /** Unregisters it. */
    fun stop()

    companion object {
        /** A phone without a barometer. */
        val NONE: Barometer = object : Barometer {
            override fun has() = false
            override fun start(periodUs: Int, maxReportLatencyUs: Int, sink: PressureSink) = false
            override fun stop() = Unit
        }
    }
}

/** One `TYPE_PRESSURE` `SensorEvent`: ns on the shared clock, `values[0]` in hPa. */
fun interface PressureSink {
    fun onPressure(timestampNs: Long, hpa: Float)
}

/** One `ScanResult` of `WifiManager.getScanResults()`. */
data class WifiResult(val bssid: String, val levelDbm: Int, val timestampUs: Long)

/** `WifiManager` and its `SCAN_RESULTS_AVAILABLE_ACTION` receiver. */
interface WifiRadio {
    /** WiFi is on, or off with "scanning always available". */
    fun isScanAvailable(): Boolean

    /** Android throttles scans (`isScanThrottleEnabled()`; developer options turn it off). */
    fun isScanThrottleEnabled(): Boolean

    /** `startScan()`. */
    fun startScan(): Boolean

    /** `getScanResults()`: the last scan's results, whoever asked for the scan. */
    fun scanResults(): List<WifiResult>

    /** Registers the receiver: [sink] hears every scan's end, this app's or another's. */
    fun listen(sink: WifiSink)

    /** Unregisters it. */
    fun stopListening()
}

/** `SCAN_RESULTS_AVAILABLE_ACTION` with its `EXTRA_RESULTS_UPDATED`. */
fun interface WifiSink {
    fun onScanResults(updated: Boolean)
}

/** `BluetoothLeScanner`. */
interface BleScanner {
    /** Bluetooth is on. */
    fun isEnabled(): Boolean

    /** `startScan(filters, settings, callback)`, low-power mode when [lowPower]. */
    fun start(lowPower: Boolean, sink: BleSink)

    /** `stopScan(callback)`. */
    fun stop()
}

/** A `ScanCallback`. */
interface BleSink {
    /** One advertisement: its address, RSSI, `timestampNanos` and raw `scanRecord.bytes`. */
    fun onAdvertisement(address: String, rssiDbm: Int, timestampNs: Long, scanRecord: ByteArray?)

    /** `onScanFailed(errorCode)`. */
    fun onScanFailed(errorCode: Int)
}

/** Permissions and switches, and a way to hear when they change. */
interface Availability {
    /** `Build.VERSION.SDK_INT`. */
    fun sdkInt(): Int

    /** `checkSelfPermission(permission) == PERMISSION_GRANTED`. */
    fun isGranted(permission: WaymarkPermission): Boolean

    /** `LocationManager.isLocationEnabled()`. */
    fun isLocationEnabled(): Boolean

    /** Calls [onChange] when location, WiFi or Bluetooth is switched (broadcasts). WaymarkPermission
     *  grants have no broadcast: the client re-checks on its timer. */
    fun watch(onChange: Runnable)

    /** Stops watching. */
    fun unwatch()
}

/**
 * What Android's background limits depend on: whether the app is visible (an activity
 * started) and whether a location foreground service holds it in the foreground. The client
 * switches between the foreground and background modes by itself as these change
 * ([AppVisibility] is the implementation; on Android it follows the activities' lifecycle).
 */
interface AppLifecycle {
    /** An activity of the app is started (visible). */
    fun isVisible(): Boolean

    /** A foreground service of type `location` runs ([WaymarkForegroundService]). */
    fun isForegroundServiceRunning(): Boolean

    /** Why the foreground service the app started does not run, while that holds; null when it
     *  runs or was not asked for. */
    fun foregroundServiceRefusal(): WaymarkLocationStatus?

    /** Calls [onChange] on any thread when one of the above changes, until cancelled. */
    fun watch(onChange: Runnable): Cancellable

    companion object {
        /** An app that is always visible and never runs a foreground service. */
        @JvmField
        val ALWAYS_VISIBLE: AppLifecycle = object : AppLifecycle {
            override fun isVisible() = true
            override fun isForegroundServiceRunning() = false
            override fun foregroundServiceRefusal(): WaymarkLocationStatus? = null
            override fun watch(onChange: Runnable) = Cancellable {}
        }
    }
}
