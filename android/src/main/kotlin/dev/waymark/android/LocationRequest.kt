package dev.waymark.android

/**
 * What a [WaymarkLocationClient] runs for one caller. The defaults suit a phone in the hand with
 * the app in the foreground: WiFi and BLE on, the motion sensors at 100 Hz delivered as
 * measured, an epoch at least every 2 s. Requests of several callers are merged: the client
 * runs the union of radios, the fastest rates and the foreground budget if any caller is in the
 * foreground.
 */
data class LocationRequest(
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
    /** The app is in the background: WiFi scans within the background budget (one per 30 min),
     *  BLE in low-power mode. Re-request with the same callback when the app changes sides. */
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

    internal companion object {
        /** What the client runs for several callers at once. */
        fun merge(requests: Collection<LocationRequest>): LocationRequest = LocationRequest(
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
