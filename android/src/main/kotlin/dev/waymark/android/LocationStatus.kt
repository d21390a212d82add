package dev.waymark.android

import dev.waymark.ErrorReport
import dev.waymark.PositionEstimate
import dev.waymark.StatusUpdate

/** What a [WaymarkLocationClient] tells a caller; called on the caller's executor. */
interface LocationCallback {
    /** A new position: one per epoch (a WiFi scan, a BLE scan or an advance on motion alone). */
    fun onLocation(position: PositionEstimate)

    /** A problem began, ended ([LocationStatus.Restored]) or happened; see [LocationStatus.code]. */
    fun onStatus(status: LocationStatus) {}

    /** The engine's own status: zone and geofence changes, motion state, track revisions. */
    fun onEngineStatus(update: StatusUpdate) {}
}

/** Where the client is: see [WaymarkLocationClient.state]. */
enum class ClientState {
    /** No caller has requested updates. */
    IDLE,

    /** Every requested input runs. */
    RUNNING,

    /** Positions come, but a requested input is unavailable (a radio off, a sensor missing). */
    DEGRADED,

    /** A caller requested updates, but no position may be made: the location permission is
     *  missing or location services are off. Nothing runs; the client resumes by itself. */
    PAUSED,

    /** Closed: no more updates. */
    STOPPED,
}

/** A runtime permission the client needs, with its manifest name. */
enum class Permission(val manifestName: String) {
    /** WiFi and BLE scan results on every version: Waymark derives location from them. */
    ACCESS_FINE_LOCATION("android.permission.ACCESS_FINE_LOCATION"),

    /** WiFi scans on Android 13+ (API 33). */
    NEARBY_WIFI_DEVICES("android.permission.NEARBY_WIFI_DEVICES"),

    /** BLE scans on Android 12+ (API 31). */
    BLUETOOTH_SCAN("android.permission.BLUETOOTH_SCAN"),
}

/** The three motion sensors the engine takes. */
enum class MotionSensor { ACCELEROMETER, GYROSCOPE, MAGNETOMETER }

/**
 * A coded status. Conditions (1xx) hold until a [Restored] with them says they ended; events
 * (2xx, 3xx) happened once. Codes are stable: log them, match on them, and never reuse one.
 * What an app does for each: docs/android.md#statuses.
 */
sealed class LocationStatus(val code: Int) {
    /** The condition [previous] ended: its input runs again. */
    data class Restored(val previous: LocationStatus) : LocationStatus(1)

    /** A permission is not granted. Without ACCESS_FINE_LOCATION nothing runs (PAUSED); without
     *  the other two, the radio that needs it stops. */
    data class PermissionMissing(val permission: Permission) : LocationStatus(100)

    /** Location services are off: Android gives no scan results, so nothing runs (PAUSED). */
    data object LocationServicesOff : LocationStatus(110)

    /** WiFi is off and "scanning always available" too: no WiFi scans. */
    data object WifiOff : LocationStatus(120)

    /** Bluetooth is off: no BLE scans. */
    data object BluetoothOff : LocationStatus(121)

    /** The phone has no such sensor: the engine positions with less motion information. */
    data class SensorMissing(val sensor: MotionSensor) : LocationStatus(130)

    /** BLE scanning failed with `ScanCallback.SCAN_FAILED_*` [errorCode]; the client retries
     *  after 30 s, except for 4 (feature unsupported). */
    data class BleScanFailed(val errorCode: Int) : LocationStatus(140)

    /** `WifiManager.startScan()` returned false: Android throttled or refused the scan. The
     *  client keeps its own budget, so this means another budget (background apps share one). */
    data object WifiScanThrottled : LocationStatus(200)

    /** A WiFi scan the client started brought no new results (`EXTRA_RESULTS_UPDATED` false, or
     *  nothing within 10 s). */
    data object WifiScanFailed : LocationStatus(201)

    /** The engine reported an error other than a rejected input (the client counts those in
     *  [LocationClientStats]): code and message as the engine's listener heard them. */
    data class EngineError(val error: ErrorReport) : LocationStatus(300)
}

/** What a client did and dropped since it was made; every drop is counted here. */
data class LocationClientStats(
    /** `startScan()` calls that returned true. */
    val wifiScansStarted: Long = 0,
    /** `startScan()` calls that returned false. */
    val wifiScansRefused: Long = 0,
    /** WiFi result sets pushed to the engine. */
    val wifiScansPushed: Long = 0,
    /** Of those, results no scan of this client asked for (another app's scan). */
    val wifiScansPassive: Long = 0,
    /** Result sets not pushed because they were pushed already (same scan time). */
    val wifiScansDuplicate: Long = 0,
    /** Result sets not pushed because an epoch after their time had been made. */
    val wifiScansLate: Long = 0,
    /** Scans of beacons alone pushed to the engine. */
    val bleScansPushed: Long = 0,
    /** BLE advertisements that were neither iBeacon nor Eddystone. */
    val bleAdvertisementsIgnored: Long = 0,
    /** Epochs from motion alone (`advance`). */
    val advances: Long = 0,
    /** Scans the engine rejected; [lastRejection] says why. */
    val scansRejected: Long = 0,
    /** Advances the engine rejected. */
    val advancesRejected: Long = 0,
    /** Motion sample batches pushed (one FFI call each). */
    val motionBatches: Long = 0,
    /** Barometer reading batches pushed (one FFI call each). */
    val pressureBatches: Long = 0,
    /** Callback deliveries the executor refused or threw from. */
    val callbackFailures: Long = 0,
    /** The engine's message for the last rejected scan or advance. */
    val lastRejection: String? = null,
)
