package dev.waymark.android

import dev.waymark.ErrorReport
import dev.waymark.PositionEstimate
import dev.waymark.StatusUpdate

/**
 * What a [WaymarkLocationClient] tells a caller, on the caller's executor. Named apart from
 * Play services' `LocationCallback` and `android.location.LocationListener`, so an app may
 * import both. Every method but [onLocation] has a default (Java 8+ default methods).
 */
interface WaymarkLocationCallback {
    /** A new position: one per epoch (a WiFi scan, a BLE scan or an advance on motion alone). */
    fun onLocation(position: PositionEstimate)

    /** A problem began, ended ([WaymarkLocationStatus.Restored]) or happened; see [WaymarkLocationStatus.code]. */
    fun onStatus(status: WaymarkLocationStatus) {}

    /** The engine's own status: zone and geofence changes, motion state, track revisions. */
    fun onEngineStatus(update: StatusUpdate) {}

    /** The client was closed: nothing follows. A Flow of the client completes here. */
    fun onClientClosed() {}
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
     *  missing or only approximate, the app is in the background without background access,
     *  or location services are off. Nothing runs; the client resumes by itself. */
    PAUSED,

    /** Closed: no more updates. */
    STOPPED,
}

/**
 * A permission the client checks, with its manifest name and the [code] of the
 * [WaymarkLocationStatus.PermissionMissing] that reports it. [WaymarkPermissions] says which
 * to request on which Android version.
 */
enum class WaymarkPermission(val manifestName: String, val code: Int) {
    /** Precise location: WiFi scan results (Android 10+) and BLE scan results. Requested
     *  together with [ACCESS_COARSE_LOCATION]: Android 12+ ignores a request for it alone. */
    ACCESS_FINE_LOCATION("android.permission.ACCESS_FINE_LOCATION", 100),

    /** Approximate location: from Android 10 alone it gives no scan results. Never reported
     *  itself: without either location permission the client reports [ACCESS_FINE_LOCATION]
     *  (100), with this one alone [WaymarkLocationStatus.ApproximateLocationOnly] (107). */
    ACCESS_COARSE_LOCATION("android.permission.ACCESS_COARSE_LOCATION", 101),

    /** WiFi scans on Android 13+ (API 33). */
    NEARBY_WIFI_DEVICES("android.permission.NEARBY_WIFI_DEVICES", 102),

    /** BLE scans on Android 12+ (API 31). */
    BLUETOOTH_SCAN("android.permission.BLUETOOTH_SCAN", 103),

    /** Android 12+: what an app needs to ask the user to turn Bluetooth on
     *  (`BluetoothAdapter.ACTION_REQUEST_ENABLE`); the scans themselves do not need it. */
    BLUETOOTH_CONNECT("android.permission.BLUETOOTH_CONNECT", 104),

    /** Android 10+ (API 29): location while no activity is visible and no location foreground
     *  service runs. */
    ACCESS_BACKGROUND_LOCATION("android.permission.ACCESS_BACKGROUND_LOCATION", 105),

    /** Android 14+ (API 34): a foreground service of type `location` ([WaymarkForegroundService]).
     *  An install-time permission: missing when the app's manifest does not declare it. */
    FOREGROUND_SERVICE_LOCATION("android.permission.FOREGROUND_SERVICE_LOCATION", 106),
}

/** The three motion sensors the engine takes. */
enum class MotionSensor { ACCELEROMETER, GYROSCOPE, MAGNETOMETER }

/**
 * A coded status. Conditions (1xx) hold until a [Restored] with them says they ended; events
 * (2xx, 3xx) happened once. Codes are stable: log them, match on them, and never reuse one.
 * What an app does for each: docs/android.md#statuses.
 */
sealed class WaymarkLocationStatus(val code: Int) {
    /** The condition [previous] ended: its input runs again. */
    data class Restored(val previous: WaymarkLocationStatus) : WaymarkLocationStatus(1)

    /**
     * [permission] is not granted where it is needed; the code is the permission's
     * ([WaymarkPermission.code]: 100, 102 to 106). Without any location permission (100) nothing
     * runs (PAUSED); without ACCESS_BACKGROUND_LOCATION (105) nothing runs while the app is in
     * the background without a foreground service; without NEARBY_WIFI_DEVICES (102) WiFi
     * stops, without BLUETOOTH_SCAN (103) BLE stops; BLUETOOTH_CONNECT (104) is reported while
     * Bluetooth is off (the app cannot ask to turn it on); FOREGROUND_SERVICE_LOCATION (106)
     * while the foreground service cannot start.
     */
    data class PermissionMissing(val permission: WaymarkPermission) : WaymarkLocationStatus(permission.code)

    /** The user granted approximate location only ("Approximate" in Android 12+'s dialog):
     *  Android gives no WiFi or BLE scan results, so nothing runs (PAUSED). Request
     *  ACCESS_FINE_LOCATION again (with COARSE) to offer the upgrade to precise. */
    data object ApproximateLocationOnly : WaymarkLocationStatus(107)

    /** Location services are off: Android gives no scan results, so nothing runs (PAUSED). */
    data object LocationServicesOff : WaymarkLocationStatus(110)

    /** WiFi is off and "scanning always available" too: no WiFi scans. */
    data object WifiOff : WaymarkLocationStatus(120)

    /** Bluetooth is off: no BLE scans. */
    data object BluetoothOff : WaymarkLocationStatus(121)

    /** The phone has no such sensor: the engine positions with less motion information. */
    data class SensorMissing(val sensor: MotionSensor) : WaymarkLocationStatus(130)

    /** BLE scanning failed with `ScanCallback.SCAN_FAILED_*` [errorCode]; the client retries
     *  after 30 s, except for 4 (feature unsupported). */
    data class BleScanFailed(val errorCode: Int) : WaymarkLocationStatus(140)

    /** Android refused to start the foreground service ([reason]: the exception's message,
     *  e.g. a start from the background on Android 12+). Holds until it starts or is stopped. */
    data class ForegroundServiceFailed(val reason: String) : WaymarkLocationStatus(150)

    /** The survey recorder's storage failed ([reason]); the client retries it with each input,
     *  and what could not be written meanwhile is counted ([LocationClientStats]). */
    data class SurveyStorageFailed(val reason: String) : WaymarkLocationStatus(160)

    /** `WifiManager.startScan()` returned false: Android throttled or refused the scan. The
     *  client keeps its own budget, so this means another budget (background apps share one). */
    data object WifiScanThrottled : WaymarkLocationStatus(200)

    /** A WiFi scan the client started brought no new results (`EXTRA_RESULTS_UPDATED` false, or
     *  nothing within 10 s). */
    data object WifiScanFailed : WaymarkLocationStatus(201)

    /** The engine reported an error other than a rejected input (the client counts those in
     *  [LocationClientStats]): code and message as the engine's listener heard them. */
    data class EngineError(val error: ErrorReport) : WaymarkLocationStatus(300)
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
    /** Survey mode: motion and scan calls the recorder took. */
    val surveyInputs: Long = 0,
    /** Survey mode: scans the recorder refused (out of order, an implausible reading). */
    val surveyScansRejected: Long = 0,
    /** Survey mode: calls lost while the recorder's storage failed (SurveyStorageFailed). */
    val surveyInputsLost: Long = 0,
    /** The engine's message for the last rejected scan or advance. */
    val lastRejection: String? = null,
)
