@file:JvmName("WaymarkAndroid")

package dev.waymark.android

import android.annotation.SuppressLint
import android.app.Activity
import android.app.ActivityManager
import android.app.Application
import android.bluetooth.BluetoothAdapter
import android.bluetooth.BluetoothManager
import android.bluetooth.le.ScanCallback
import android.bluetooth.le.ScanFilter
import android.bluetooth.le.ScanResult
import android.bluetooth.le.ScanSettings
import android.content.BroadcastReceiver
import android.content.Context
import android.content.Intent
import android.content.IntentFilter
import android.content.pm.PackageManager
import android.hardware.Sensor
import android.hardware.SensorEvent
import android.hardware.SensorEventListener
import android.hardware.SensorManager
import android.location.LocationManager
import android.net.wifi.WifiManager
import android.os.Build
import android.os.Bundle
import android.os.Handler
import android.os.HandlerThread
import android.os.Looper
import android.os.ParcelUuid
import android.os.SystemClock
import dev.waymark.PositioningEngineInterface

/*
 * The Android shell of WaymarkLocationClient: each port of Platform.kt over the platform call
 * it names, and nothing else. Every decision (threads, rates, budgets, dedupe, statuses,
 * permissions, foreground and background) is in the plain-Kotlin client, which the JVM test
 * covers; this file is compiled by the AAR build only.
 */

/**
 * A location client on this phone, `WaymarkAndroid.createLocationClient(context, engine)` from
 * Java. The client owns a `HandlerThread` ("waymark-location"): sensor events, broadcasts,
 * BLE results, the timer and every epoch run there, and it ends with `close()`. The client
 * follows the app's activities to switch between foreground and background by itself.
 */
@JvmName("createLocationClient")
fun WaymarkLocationClient(context: Context, engine: PositioningEngineInterface): WaymarkLocationClient =
    WaymarkLocationClient(engine, AndroidPlatform.create(context.applicationContext))

/** A client for survey mode alone (no engine, no positions): [WaymarkLocationClient.startSurvey]. */
@JvmName("createSurveyClient")
fun WaymarkSurveyClient(context: Context): WaymarkLocationClient =
    WaymarkLocationClient.forSurvey(AndroidPlatform.create(context.applicationContext))

internal object AndroidPlatform {
    @Volatile private var visibility: AppVisibility? = null

    fun create(context: Context): Platform {
        val thread = HandlerThread("waymark-location").apply { start() }
        val handler = Handler(thread.looper)
        return Platform(
            clock = Clock { SystemClock.elapsedRealtimeNanos() },
            scheduler = HandlerScheduler(handler, thread),
            sensors = AndroidSensors(context, handler),
            wifi = AndroidWifi(context, handler),
            ble = AndroidBle(context),
            availability = AndroidAvailability(context, handler),
            barometer = AndroidBarometer(context, handler),
            lifecycle = visibility(context),
        )
    }

    /** The process's one [AppVisibility], fed by every activity's start and stop (on the main
     *  thread) and by [WaymarkForegroundService]. */
    fun visibility(context: Context): AppVisibility = visibility ?: synchronized(this) {
        visibility ?: run {
            val app = context.applicationContext as Application
            // Visible now if the process is in the foreground: an activity may have started
            // before the first client was made; its stop brings the count to the background.
            val state = ActivityManager.RunningAppProcessInfo()
            ActivityManager.getMyMemoryState(state)
            val visible = state.importance <= ActivityManager.RunningAppProcessInfo.IMPORTANCE_FOREGROUND
            val v = AppVisibility(HandlerScheduler(Handler(Looper.getMainLooper()), null), visible)
            app.registerActivityLifecycleCallbacks(object : Application.ActivityLifecycleCallbacks {
                override fun onActivityStarted(activity: Activity) = v.activityStarted()
                override fun onActivityStopped(activity: Activity) = v.activityStopped()
                override fun onActivityCreated(activity: Activity, savedInstanceState: Bundle?) = Unit
                override fun onActivityResumed(activity: Activity) = Unit
                override fun onActivityPaused(activity: Activity) = Unit
                override fun onActivitySaveInstanceState(activity: Activity, outState: Bundle) = Unit
                override fun onActivityDestroyed(activity: Activity) = Unit
            })
            visibility = v
            v
        }
    }

    fun register(context: Context, receiver: BroadcastReceiver, filter: IntentFilter, handler: Handler) {
        if (Build.VERSION.SDK_INT >= 33) {
            context.registerReceiver(receiver, filter, null, handler, Context.RECEIVER_NOT_EXPORTED)
        } else {
            context.registerReceiver(receiver, filter, null, handler)
        }
    }
}

/** [Scheduler] over a `Handler`; [thread], the client's own, ends with [quit]. */
internal class HandlerScheduler(private val handler: Handler, private val thread: HandlerThread?) : Scheduler {
    override fun schedule(delayMs: Long, task: Runnable): Cancellable {
        val posted = Runnable { task.run() } // its own instance, so only it is removed
        handler.postDelayed(posted, delayMs)
        return Cancellable { handler.removeCallbacks(posted) }
    }

    override fun post(task: Runnable) {
        handler.post(task)
    }

    override fun isClientThread(): Boolean = Looper.myLooper() === handler.looper

    override fun quit() {
        thread?.quitSafely()
    }
}

private class AndroidSensors(context: Context, private val handler: Handler) : MotionSensors {
    private val manager = context.getSystemService(Context.SENSOR_SERVICE) as SensorManager
    private val listeners = HashMap<MotionSensor, SensorEventListener>()

    private fun type(sensor: MotionSensor) = when (sensor) {
        MotionSensor.ACCELEROMETER -> Sensor.TYPE_ACCELEROMETER
        MotionSensor.GYROSCOPE -> Sensor.TYPE_GYROSCOPE
        MotionSensor.MAGNETOMETER -> Sensor.TYPE_MAGNETIC_FIELD
    }

    override fun has(sensor: MotionSensor) = manager.getDefaultSensor(type(sensor)) != null

    override fun start(sensor: MotionSensor, periodUs: Int, maxReportLatencyUs: Int, sink: MotionSink): Boolean {
        val hardware = manager.getDefaultSensor(type(sensor)) ?: return false
        val listener = object : SensorEventListener {
            override fun onSensorChanged(event: SensorEvent) = sink.onSample(sensor, event.timestamp, event.values)
            override fun onAccuracyChanged(s: Sensor, accuracy: Int) = Unit
        }
        if (!manager.registerListener(listener, hardware, periodUs, maxReportLatencyUs, handler)) return false
        listeners[sensor] = listener
        return true
    }

    override fun stop(sensor: MotionSensor) {
        listeners.remove(sensor)?.let { manager.unregisterListener(it) }
    }
}

private class AndroidBarometer(context: Context, private val handler: Handler) : Barometer {
    private val manager = context.getSystemService(Context.SENSOR_SERVICE) as SensorManager
    private var listener: SensorEventListener? = null

    override fun has() = manager.getDefaultSensor(Sensor.TYPE_PRESSURE) != null

    override fun start(periodUs: Int, maxReportLatencyUs: Int, sink: PressureSink): Boolean {
        val hardware = manager.getDefaultSensor(Sensor.TYPE_PRESSURE) ?: return false
        val l = object : SensorEventListener {
            override fun onSensorChanged(event: SensorEvent) = sink.onPressure(event.timestamp, event.values[0])
            override fun onAccuracyChanged(s: Sensor, accuracy: Int) = Unit
        }
        if (!manager.registerListener(l, hardware, periodUs, maxReportLatencyUs, handler)) return false
        listener = l
        return true
    }

    override fun stop() {
        listener?.let { manager.unregisterListener(it) }
        listener = null
    }
}

@SuppressLint("MissingPermission") // the client checks ACCESS_FINE_LOCATION / NEARBY_WIFI_DEVICES first
private class AndroidWifi(private val context: Context, private val handler: Handler) : WifiRadio {
    private val manager = context.getSystemService(Context.WIFI_SERVICE) as WifiManager
    private var receiver: BroadcastReceiver? = null

    @Suppress("DEPRECATION") // isScanAlwaysAvailable: still the switch that lets scans run with WiFi off
    override fun isScanAvailable() = manager.isWifiEnabled || manager.isScanAlwaysAvailable

    override fun isScanThrottleEnabled() = Build.VERSION.SDK_INT < 30 || manager.isScanThrottleEnabled

    @Suppress("DEPRECATION") // startScan: deprecated without a replacement; throttled, not removed
    override fun startScan() = manager.startScan()

    override fun scanResults() = manager.scanResults.map { WifiResult(it.BSSID, it.level, it.timestamp) }

    override fun listen(sink: WifiSink) {
        val r = object : BroadcastReceiver() {
            override fun onReceive(c: Context, intent: Intent) =
                sink.onScanResults(intent.getBooleanExtra(WifiManager.EXTRA_RESULTS_UPDATED, false))
        }
        AndroidPlatform.register(context, r, IntentFilter(WifiManager.SCAN_RESULTS_AVAILABLE_ACTION), handler)
        receiver = r
    }

    override fun stopListening() {
        receiver?.let { context.unregisterReceiver(it) }
        receiver = null
    }
}

@SuppressLint("MissingPermission") // the client checks BLUETOOTH_SCAN / ACCESS_FINE_LOCATION first
private class AndroidBle(context: Context) : BleScanner {
    private val adapter: BluetoothAdapter? = (context.getSystemService(Context.BLUETOOTH_SERVICE) as BluetoothManager?)?.adapter
    private var callback: ScanCallback? = null

    override fun isEnabled() = adapter?.isEnabled == true

    override fun start(lowPower: Boolean, sink: BleSink) {
        val scanner = adapter?.bluetoothLeScanner ?: return sink.onScanFailed(ScanCallback.SCAN_FAILED_INTERNAL_ERROR)
        val cb = object : ScanCallback() {
            override fun onScanResult(callbackType: Int, result: ScanResult) = deliver(result)
            override fun onBatchScanResults(results: MutableList<ScanResult>) = results.forEach { deliver(it) }
            override fun onScanFailed(errorCode: Int) = sink.onScanFailed(errorCode)

            fun deliver(r: ScanResult) = sink.onAdvertisement(r.device.address, r.rssi, r.timestampNanos, r.scanRecord?.bytes)
        }
        // Filters: Android 8.1+ delivers nothing with the screen off to an unfiltered scan.
        val filters = listOf(
            ScanFilter.Builder()
                .setManufacturerData(BleAdvertisements.APPLE_COMPANY_ID, byteArrayOf(0x02, 0x15), byteArrayOf(-1, -1))
                .build(),
            ScanFilter.Builder().setServiceUuid(ParcelUuid.fromString(EDDYSTONE_UUID)).build(),
        )
        val settings = ScanSettings.Builder()
            .setScanMode(if (lowPower) ScanSettings.SCAN_MODE_LOW_POWER else ScanSettings.SCAN_MODE_LOW_LATENCY)
            .build()
        callback = cb
        scanner.startScan(filters, settings, cb)
    }

    override fun stop() {
        val cb = callback ?: return
        callback = null
        // With Bluetooth already off there is no scanner, and no scan left to stop.
        adapter?.bluetoothLeScanner?.stopScan(cb)
    }

    private companion object {
        const val EDDYSTONE_UUID = "0000feaa-0000-1000-8000-00805f9b34fb"
    }
}

private class AndroidAvailability(private val context: Context, private val handler: Handler) : Availability {
    private val location = context.getSystemService(Context.LOCATION_SERVICE) as LocationManager
    private var receiver: BroadcastReceiver? = null

    override fun sdkInt() = Build.VERSION.SDK_INT

    override fun isGranted(permission: WaymarkPermission) =
        context.checkSelfPermission(permission.manifestName) == PackageManager.PERMISSION_GRANTED

    override fun isLocationEnabled() = if (Build.VERSION.SDK_INT >= 28) {
        location.isLocationEnabled
    } else {
        location.isProviderEnabled(LocationManager.GPS_PROVIDER) || location.isProviderEnabled(LocationManager.NETWORK_PROVIDER)
    }

    override fun watch(onChange: Runnable) {
        val r = object : BroadcastReceiver() {
            override fun onReceive(c: Context, intent: Intent) = onChange.run()
        }
        val filter = IntentFilter().apply {
            addAction(LocationManager.MODE_CHANGED_ACTION)
            addAction(WifiManager.WIFI_STATE_CHANGED_ACTION)
            addAction(BluetoothAdapter.ACTION_STATE_CHANGED)
        }
        AndroidPlatform.register(context, r, filter, handler)
        receiver = r
    }

    override fun unwatch() {
        receiver?.let { context.unregisterReceiver(it) }
        receiver = null
    }
}
