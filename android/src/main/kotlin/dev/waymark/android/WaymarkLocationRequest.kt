package dev.waymark.android

/**
 * What a [WaymarkLocationClient] runs for one caller (named apart from Play services' and
 * `android.location`'s `LocationRequest`). From Java: `WaymarkLocationRequest.builder()
 * .setBle(false).build()`, or `new WaymarkLocationRequest()` for the defaults. The defaults suit a phone in the hand with
 * the app in the foreground: WiFi and BLE on, the motion sensors at 100 Hz delivered as
 * measured, an epoch at least every 2 s. Requests of several callers are merged: the client
 * runs the union of radios, the fastest rates and the foreground budget if any caller is in the
 * foreground.
 */
data class WaymarkLocationRequest @JvmOverloads constructor(
    /** Scan WiFi: the client's own scans within Android's budget, and every other app's results. */
    val wifi: Boolean = true,
    /** Scan BLE for iBeacon and Eddystone beacons. */
    val ble: Boolean = true,
    /** Accelerometer, gyroscope and magnetometer rate, Hz; the engine's step and heading
     *  detection wants 50 to 100 Hz. Above 200 Hz Android 12+ needs HIGH_SAMPLING_RATE_SENSORS. */
    val sensorRateHz: Int = 100,
    /** How long the sensor hub may hold samples before delivering them (hardware batching), ms.
     *  0 delivers them as measured; more saves power, and epochs then wait for the samples. */
    val sensorMaxLatencyMs: Long = 0,
    /** When no scan made an epoch for this long, ms, the client makes one from beacons heard or,
     *  without any, from motion alone (`advance`), so the position keeps moving between scans. */
    val advanceIntervalMs: Long = 2_000,
    /** Treat the app as in the background whatever its activities: WiFi scans within the
     *  background budget (one per 30 min) unless a location foreground service runs, BLE in
     *  low-power mode. Not needed to follow the app: the client switches by itself when no
     *  activity is visible ([Platform.lifecycle]). */
    val background: Boolean = false,
    /** Shortest interval between the client's own WiFi scans, ms; 0 scans as often as Android's
     *  budget allows. Other apps' results are taken whenever they come. */
    val wifiScanIntervalMs: Long = 0,
    /** Read the barometer, where the phone has one, for floor changes
     *  (docs/android.md#the-barometer). */
    val barometer: Boolean = true,
) {
    init {
        require(wifi || ble) { "a request scans WiFi, BLE or both: the engine positions from radio" }
        require(sensorRateHz in 1..1_000) { "sensorRateHz $sensorRateHz is not in 1..1000" }
        require(sensorMaxLatencyMs >= 0) { "sensorMaxLatencyMs is negative" }
        require(advanceIntervalMs >= 100) { "advanceIntervalMs $advanceIntervalMs is below 100 ms" }
        require(wifiScanIntervalMs >= 0) { "wifiScanIntervalMs is negative" }
    }

    /** Sensor period, µs, as `SensorManager.registerListener` takes it. */
    val sensorPeriodUs: Int get() = 1_000_000 / sensorRateHz

    /** [sensorMaxLatencyMs] in µs, as `registerListener` takes it. */
    internal val maxLatencyUs: Int get() = (sensorMaxLatencyMs * 1_000L).coerceAtMost(Int.MAX_VALUE.toLong()).toInt()

    /** Samples per FFI call: half a second of one sensor. */
    internal val batchSize: Int get() = maxOf(1, sensorRateHz / 2)

    /** A builder, for Java callers; each setter defaults as the constructor does. */
    class Builder {
        private val d = WaymarkLocationRequest()
        private var wifi = d.wifi
        private var ble = d.ble
        private var sensorRateHz = d.sensorRateHz
        private var sensorMaxLatencyMs = d.sensorMaxLatencyMs
        private var advanceIntervalMs = d.advanceIntervalMs
        private var background = d.background
        private var wifiScanIntervalMs = d.wifiScanIntervalMs
        private var barometer = d.barometer

        fun setWifi(wifi: Boolean) = apply { this.wifi = wifi }
        fun setBle(ble: Boolean) = apply { this.ble = ble }
        fun setSensorRateHz(hz: Int) = apply { sensorRateHz = hz }
        fun setSensorMaxLatencyMs(ms: Long) = apply { sensorMaxLatencyMs = ms }
        fun setAdvanceIntervalMs(ms: Long) = apply { advanceIntervalMs = ms }
        fun setBackground(background: Boolean) = apply { this.background = background }
        fun setWifiScanIntervalMs(ms: Long) = apply { wifiScanIntervalMs = ms }
        fun setBarometer(barometer: Boolean) = apply { this.barometer = barometer }

        /** The request; throws `IllegalArgumentException` as the constructor does. */
        fun build() = WaymarkLocationRequest(
            wifi, ble, sensorRateHz, sensorMaxLatencyMs, advanceIntervalMs, background, wifiScanIntervalMs, barometer,
        )
    }

    companion object {
        /** A [Builder] with the defaults. */
        @JvmStatic
        fun builder(): Builder = Builder()

        /** What the client runs for several callers at once. */
        internal fun merge(requests: Collection<WaymarkLocationRequest>): WaymarkLocationRequest = WaymarkLocationRequest(
            wifi = requests.any { it.wifi },
            ble = requests.any { it.ble },
            sensorRateHz = requests.maxOf { it.sensorRateHz },
            sensorMaxLatencyMs = requests.minOf { it.sensorMaxLatencyMs },
            advanceIntervalMs = requests.minOf { it.advanceIntervalMs },
            background = requests.all { it.background },
            wifiScanIntervalMs = requests.minOf { it.wifiScanIntervalMs },
            barometer = requests.any { it.barometer },
        )
    }
}
