package dev.waymark.android

/**
 * Android's WiFi scan budget, kept by the app so it never spends a scan Android would refuse.
 * Android 9+ (API 28) lets a foreground app start 4 scans in any 2-minute window, and Android
 * 8+ (API 26) lets background apps start one scan per 30 minutes, all of them together;
 * developer options can turn throttling off (API 29+). Source: Android developers, "Wi-Fi
 * scanning overview", section "Wi-Fi scanning throttling"
 * (developer.android.com/develop/connectivity/wifi/wifi-scan#wifi-scan-throttling).
 *
 * Android keeps a scan in the window until it is strictly older than the window
 * (WifiScanRequestProxy), so [windowNs] adds a second of margin; scans are spread evenly
 * ([spacingNs]) rather than spent in a burst, so positions are corrected every 30 s instead of
 * four times in 6 s and then not for two minutes.
 */
class WifiScanBudget(val maxScans: Int, val windowNs: Long) {
    init {
        require(maxScans >= 1 && windowNs > 0)
    }

    /** The shortest interval between two scans: the window shared evenly. */
    val spacingNs: Long get() = windowNs / maxScans

    /** The earliest time a scan may start, given the app's past scans (oldest first). */
    fun nextAllowedNs(history: List<Long>): Long {
        if (history.isEmpty()) return Long.MIN_VALUE
        val spaced = history.last() + spacingNs
        val windowed = if (history.size >= maxScans) history[history.size - maxScans] + windowNs else Long.MIN_VALUE
        return maxOf(spaced, windowed)
    }

    companion object {
        private const val MARGIN_NS = 1_000_000_000L
        private const val MINUTE_NS = 60_000_000_000L

        /** Foreground apps, Android 9+: 4 scans per 2 minutes. */
        val FOREGROUND = WifiScanBudget(4, 2 * MINUTE_NS + MARGIN_NS)

        /** Background apps, Android 8+: 1 scan per 30 minutes. */
        val BACKGROUND = WifiScanBudget(1, 30 * MINUTE_NS + MARGIN_NS)

        /** Throttling off (before Android 8 or 9, or in developer options): a scan takes 2 to 4 s,
         *  so one every 5 s. */
        val UNTHROTTLED = WifiScanBudget(1, 5_000_000_000L)

        /** The budget Android applies to this app. */
        fun of(background: Boolean, sdkInt: Int, throttleEnabled: Boolean): WifiScanBudget = when {
            !throttleEnabled -> UNTHROTTLED
            background && sdkInt >= 26 -> BACKGROUND
            !background && sdkInt >= 28 -> FOREGROUND
            else -> UNTHROTTLED
        }
    }
}
