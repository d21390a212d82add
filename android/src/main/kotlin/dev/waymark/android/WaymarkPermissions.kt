package dev.waymark.android

/**
 * The runtime permissions of Android 8 to 14 as the client needs them, in plain Kotlin: which
 * to request, and what the granted ones allow ([PermissionCheck]), so the client's statuses
 * follow the platform's rules and the JVM test covers every combination.
 *
 * - Location: ACCESS_FINE_LOCATION with ACCESS_COARSE_LOCATION, in one request (Android 12+
 *   ignores a request for FINE alone). From Android 10 scan results need FINE: "Approximate"
 *   (COARSE only) gives no WiFi or BLE scan results; before Android 10 COARSE was enough.
 * - NEARBY_WIFI_DEVICES for WiFi scans on Android 13+; BLUETOOTH_SCAN for BLE scans on 12+, and
 *   BLUETOOTH_CONNECT to ask the user to turn Bluetooth on. Below their version they do not
 *   exist and are never checked.
 * - ACCESS_BACKGROUND_LOCATION (Android 10+) for location while no activity is visible and no
 *   location foreground service runs; Android 11+ grants it only in a request of its own, after
 *   the foreground ones, and only from the app's settings page.
 * - FOREGROUND_SERVICE_LOCATION (Android 14+), install-time, declared by the AAR's manifest.
 */
object WaymarkPermissions {
    /** What to request while the app is visible, for [request] on [sdkInt], in one
     *  `requestPermissions` call. */
    @JvmStatic
    @JvmOverloads
    fun foreground(sdkInt: Int, request: WaymarkLocationRequest = WaymarkLocationRequest()): List<WaymarkPermission> = buildList {
        add(WaymarkPermission.ACCESS_FINE_LOCATION)
        add(WaymarkPermission.ACCESS_COARSE_LOCATION)
        if (request.wifi && sdkInt >= 33) add(WaymarkPermission.NEARBY_WIFI_DEVICES)
        if (request.ble && sdkInt >= 31) {
            add(WaymarkPermission.BLUETOOTH_SCAN)
            add(WaymarkPermission.BLUETOOTH_CONNECT)
        }
    }

    /** What to request, in a request of its own after [foreground] was granted, for updates
     *  while the app is in the background without a foreground service; empty before Android 10. */
    @JvmStatic
    fun background(sdkInt: Int): List<WaymarkPermission> =
        if (sdkInt >= 29) listOf(WaymarkPermission.ACCESS_BACKGROUND_LOCATION) else emptyList()

    /** The manifest names of [permissions], as `requestPermissions` takes them. */
    @JvmStatic
    fun manifestNames(permissions: List<WaymarkPermission>): Array<String> = permissions.map { it.manifestName }.toTypedArray()

    /** Why a location foreground service may not start on [sdkInt] with [isGranted], or null:
     *  Android 14+ throws `SecurityException` from `startForeground` without
     *  FOREGROUND_SERVICE_LOCATION or without a location permission. */
    @JvmStatic
    fun foregroundServiceRefusal(sdkInt: Int, isGranted: (WaymarkPermission) -> Boolean): WaymarkLocationStatus? = when {
        sdkInt < 34 -> null
        !isGranted(WaymarkPermission.FOREGROUND_SERVICE_LOCATION) ->
            WaymarkLocationStatus.PermissionMissing(WaymarkPermission.FOREGROUND_SERVICE_LOCATION)
        !isGranted(WaymarkPermission.ACCESS_FINE_LOCATION) && !isGranted(WaymarkPermission.ACCESS_COARSE_LOCATION) ->
            WaymarkLocationStatus.PermissionMissing(WaymarkPermission.ACCESS_FINE_LOCATION)
        else -> null
    }
}

/**
 * What the granted permissions allow for one request: the conditions to report and which
 * inputs may run. [inForeground] is whether Android counts the app as in the foreground for
 * location: an activity visible, or a location foreground service running.
 */
internal class PermissionCheck(sdkInt: Int, isGranted: (WaymarkPermission) -> Boolean, wifi: Boolean, ble: Boolean, bluetoothOn: Boolean, inForeground: Boolean) {
    val missing = LinkedHashSet<WaymarkLocationStatus>()

    /** Scan results may be had: precise location, and background access where needed. */
    val located: Boolean
    val wifiAllowed: Boolean
    val bleAllowed: Boolean

    init {
        val coarse = isGranted(WaymarkPermission.ACCESS_COARSE_LOCATION)
        // Scan results need precise location from Android 10 (API 29); before, either will do.
        val precise = isGranted(WaymarkPermission.ACCESS_FINE_LOCATION) || (coarse && sdkInt < 29)
        when {
            precise -> Unit
            coarse -> missing += WaymarkLocationStatus.ApproximateLocationOnly
            else -> missing += WaymarkLocationStatus.PermissionMissing(WaymarkPermission.ACCESS_FINE_LOCATION)
        }
        // Only once the app has location at all: the background request comes after it.
        val background = inForeground || sdkInt < 29 || isGranted(WaymarkPermission.ACCESS_BACKGROUND_LOCATION)
        if (precise && !background) missing += WaymarkLocationStatus.PermissionMissing(WaymarkPermission.ACCESS_BACKGROUND_LOCATION)
        located = precise && background

        val nearby = sdkInt < 33 || isGranted(WaymarkPermission.NEARBY_WIFI_DEVICES)
        if (wifi && !nearby) missing += WaymarkLocationStatus.PermissionMissing(WaymarkPermission.NEARBY_WIFI_DEVICES)
        wifiAllowed = wifi && nearby

        val scan = sdkInt < 31 || isGranted(WaymarkPermission.BLUETOOTH_SCAN)
        if (ble && !scan) missing += WaymarkLocationStatus.PermissionMissing(WaymarkPermission.BLUETOOTH_SCAN)
        val connect = sdkInt < 31 || isGranted(WaymarkPermission.BLUETOOTH_CONNECT)
        if (ble && !bluetoothOn && !connect) missing += WaymarkLocationStatus.PermissionMissing(WaymarkPermission.BLUETOOTH_CONNECT)
        bleAllowed = ble && scan
    }
}
