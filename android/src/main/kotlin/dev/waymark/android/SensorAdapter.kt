package dev.waymark.android

import android.content.Context
import android.hardware.Sensor
import android.hardware.SensorEvent
import android.hardware.SensorEventListener
import android.hardware.SensorManager
import android.net.wifi.WifiManager
import dev.waymark.MotionSample
import dev.waymark.PositioningEngine
import dev.waymark.RadioScan

/**
 * The thin Android shell: registers for the accelerometer, gyroscope and magnetometer at
 * ~100 Hz, batches samples (one FFI call per [batchSize] samples, not per sample), and forwards
 * WiFi scan results. All conversion lives in [Conversions].
 */
class SensorAdapter(
    context: Context,
    private val engine: PositioningEngine,
    private val batchSize: Int = 50,
) : SensorEventListener {
    private val sensors = context.getSystemService(Context.SENSOR_SERVICE) as SensorManager
    private val wifi = context.applicationContext.getSystemService(Context.WIFI_SERVICE) as WifiManager
    private val batches = HashMap<Int, MutableList<MotionSample>>()

    /** Starts listening; sensors a phone lacks are simply absent (Waymark adapts per epoch). */
    fun start() {
        for (type in listOf(Sensor.TYPE_ACCELEROMETER, Sensor.TYPE_GYROSCOPE, Sensor.TYPE_MAGNETIC_FIELD)) {
            sensors.getDefaultSensor(type)?.let { sensors.registerListener(this, it, 10_000) }
        }
    }

    /** Stops listening and flushes what is batched. */
    fun stop() {
        sensors.unregisterListener(this)
        synchronized(batches) { batches.keys.toList().forEach { flush(it) } }
    }

    override fun onSensorChanged(event: SensorEvent) {
        synchronized(batches) {
            val batch = batches.getOrPut(event.sensor.type) { ArrayList(batchSize) }
            batch.add(Conversions.sample(event.timestamp, event.values))
            if (batch.size >= batchSize) flush(event.sensor.type)
        }
    }

    override fun onAccuracyChanged(sensor: Sensor, accuracy: Int) = Unit

    /** Call from the `SCAN_RESULTS_AVAILABLE_ACTION` receiver. */
    @Suppress("MissingPermission")
    fun onScanResults() {
        synchronized(batches) { batches.keys.toList().forEach { flush(it) } }
        val results = wifi.scanResults
        if (results.isEmpty()) return
        val scanTimeNs = Conversions.scanTimeNs(results.map { it.timestamp })
        val readings = results.map { Conversions.wifi(it.BSSID, it.level, it.timestamp, scanTimeNs) }
        runCatching { engine.pushScan(RadioScan(scanTimeNs.toULong(), readings, emptyList())) }
    }

    private fun flush(type: Int) {
        val batch = batches[type] ?: return
        if (batch.isEmpty()) return
        val copy = batch.toList()
        batch.clear()
        when (type) {
            Sensor.TYPE_ACCELEROMETER -> engine.pushAccelerometer(copy)
            Sensor.TYPE_GYROSCOPE -> engine.pushGyroscope(copy)
            Sensor.TYPE_MAGNETIC_FIELD -> engine.pushMagnetometer(copy)
        }
    }
}
