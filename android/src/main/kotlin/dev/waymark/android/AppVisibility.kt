package dev.waymark.android

import java.util.concurrent.CopyOnWriteArrayList

/**
 * The app's side of Android's background limits, kept for every client of the process: whether
 * an activity is started, and the state of the location foreground service. On Android the
 * activities' lifecycle callbacks and [WaymarkForegroundService] feed it (AndroidPlatform.kt);
 * here it is plain Kotlin, fed by the test. Thread-safe.
 *
 * The app is visible while at least one activity is started. It becomes invisible
 * [STOP_DELAY_MS] after the last one stopped, unless another started meanwhile, so a rotation
 * or a hop between two activities does not flip the client to the background and back
 * (androidx `ProcessLifecycleOwner` waits 700 ms for the same reason).
 */
class AppVisibility @JvmOverloads constructor(
    private val scheduler: Scheduler,
    initiallyVisible: Boolean = false,
) : AppLifecycle {
    private val lock = Any()
    private val watchers = CopyOnWriteArrayList<Runnable>()
    private var started = 0
    private var visible = initiallyVisible
    private var pendingStop: Cancellable? = null
    private var serviceRunning = false
    private var serviceRefusal: WaymarkLocationStatus? = null

    /** `onActivityStarted`. */
    fun activityStarted() {
        val changed = synchronized(lock) {
            started++
            pendingStop?.cancel()
            pendingStop = null
            val was = visible
            visible = true
            !was
        }
        if (changed) notifyWatchers()
    }

    /** `onActivityStopped`. */
    fun activityStopped() {
        synchronized(lock) {
            if (started > 0) started--
            if (started > 0 || !visible) return
            pendingStop?.cancel()
            pendingStop = scheduler.schedule(STOP_DELAY_MS) { becameInvisible() }
        }
    }

    private fun becameInvisible() {
        val changed = synchronized(lock) {
            pendingStop = null
            if (started > 0 || !visible) return
            visible = false
            true
        }
        if (changed) notifyWatchers()
    }

    /**
     * The foreground service is about to call `startForeground` on [sdkInt] with [isGranted]:
     * returns why it may not ([WaymarkPermissions.foregroundServiceRefusal]), which clients
     * report until the service starts or is stopped, or null.
     */
    fun foregroundServiceStarting(sdkInt: Int, isGranted: (WaymarkPermission) -> Boolean): WaymarkLocationStatus? {
        val refusal = WaymarkPermissions.foregroundServiceRefusal(sdkInt, isGranted)
        if (refusal != null) setService(running = false, refusal = refusal)
        return refusal
    }

    /** `startForeground` returned: the app counts as in the foreground for location and WiFi. */
    fun foregroundServiceStarted() = setService(running = true, refusal = null)

    /** `startForeground` threw ([reason]: its message). */
    fun foregroundServiceFailed(reason: String) =
        setService(running = false, refusal = WaymarkLocationStatus.ForegroundServiceFailed(reason))

    /** The service stopped (`onDestroy`), or the app gave up starting it. */
    fun foregroundServiceStopped() = setService(running = false, refusal = null)

    private fun setService(running: Boolean, refusal: WaymarkLocationStatus?) {
        val changed = synchronized(lock) {
            val changed = running != serviceRunning || refusal != serviceRefusal
            serviceRunning = running
            serviceRefusal = refusal
            changed
        }
        if (changed) notifyWatchers()
    }

    override fun isVisible(): Boolean = synchronized(lock) { visible }

    override fun isForegroundServiceRunning(): Boolean = synchronized(lock) { serviceRunning }

    override fun foregroundServiceRefusal(): WaymarkLocationStatus? = synchronized(lock) { serviceRefusal }

    override fun watch(onChange: Runnable): Cancellable {
        watchers += onChange
        return Cancellable { watchers.remove(onChange) }
    }

    private fun notifyWatchers() {
        for (w in watchers) w.run()
    }

    companion object {
        /**
         * How long after the last activity stopped the app counts as in the background, ms:
         * AndroidX's `ProcessLifecycleOwner` delay (its `TIMEOUT_MS`), long enough that an
         * activity destroyed and recreated by a configuration change (a rotation) sends nothing.
         */
        const val STOP_DELAY_MS = 700L
    }
}
