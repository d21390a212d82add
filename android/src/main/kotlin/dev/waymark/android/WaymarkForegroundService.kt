package dev.waymark.android

import android.app.Notification
import android.app.Service
import android.content.Context
import android.content.Intent
import android.content.pm.PackageManager
import android.content.pm.ServiceInfo
import android.os.Build
import android.os.IBinder

/**
 * A foreground service of type `location` that keeps the app's clients positioning while no
 * activity is visible: Android then counts the app as in the foreground for location (no
 * ACCESS_BACKGROUND_LOCATION needed) and for WiFi scans (the foreground budget). It holds no
 * client: every client of the process follows it through [AppVisibility], and reports why it
 * could not start as a status (PermissionMissing(FOREGROUND_SERVICE_LOCATION),
 * ForegroundServiceFailed).
 *
 * Start it while the app is visible (Android 12+ refuses a start from the background) with
 * the notification it shows, and stop it when tracking ends:
 *
 * ```
 * WaymarkForegroundService.start(context, 1, notification)
 * WaymarkForegroundService.stop(context)
 * ```
 *
 * The app's manifest declares it (docs/android.md#background-tracking); the AAR's does not,
 * so apps that do not track in the background declare no location foreground service to
 * Google Play. Every decision is in [AppVisibility] and [WaymarkPermissions], which the JVM
 * test covers; this file is compiled by the AAR build only.
 */
class WaymarkForegroundService : Service() {
    private var started = false

    override fun onBind(intent: Intent?): IBinder? = null

    override fun onStartCommand(intent: Intent?, flags: Int, startId: Int): Int {
        val visibility = AndroidPlatform.visibility(this)
        val notification = intent?.let { notificationOf(it) }
        if (intent == null || notification == null) {
            // Restarted by the system without its intent: nothing to show, so nothing to run.
            stopSelf(startId)
            return START_NOT_STICKY
        }
        val refusal = visibility.foregroundServiceStarting(Build.VERSION.SDK_INT) { isGranted(this, it) }
        if (refusal != null) {
            stopSelf(startId)
            return START_NOT_STICKY
        }
        try {
            if (Build.VERSION.SDK_INT >= 29) {
                startForeground(intent.getIntExtra(EXTRA_ID, 1), notification, ServiceInfo.FOREGROUND_SERVICE_TYPE_LOCATION)
            } else {
                startForeground(intent.getIntExtra(EXTRA_ID, 1), notification)
            }
            started = true
            visibility.foregroundServiceStarted()
        } catch (e: RuntimeException) {
            // SecurityException (Android 14 without the permissions), or
            // ForegroundServiceStartNotAllowedException (Android 12+, from the background).
            visibility.foregroundServiceFailed(e.message ?: e.javaClass.name)
            stopSelf(startId)
        }
        return START_NOT_STICKY
    }

    override fun onDestroy() {
        // A refusal stays reported until the app stops the service or starts it again.
        if (started) AndroidPlatform.visibility(this).foregroundServiceStopped()
        super.onDestroy()
    }

    @Suppress("DEPRECATION") // the typed getParcelableExtra is API 33+
    private fun notificationOf(intent: Intent): Notification? = if (Build.VERSION.SDK_INT >= 33) {
        intent.getParcelableExtra(EXTRA_NOTIFICATION, Notification::class.java)
    } else {
        intent.getParcelableExtra(EXTRA_NOTIFICATION)
    }

    companion object {
        private const val EXTRA_NOTIFICATION = "dev.waymark.android.NOTIFICATION"
        private const val EXTRA_ID = "dev.waymark.android.NOTIFICATION_ID"

        private fun isGranted(context: Context, permission: WaymarkPermission) =
            context.checkSelfPermission(permission.manifestName) == PackageManager.PERMISSION_GRANTED

        /**
         * Starts the service, showing [notification] with [notificationId] (its channel is the
         * app's). Checks first what Android 14 would throw for, so a refused start is a status
         * and never a crash; returns false when it did not start.
         */
        @JvmStatic
        fun start(context: Context, notificationId: Int, notification: Notification): Boolean {
            val visibility = AndroidPlatform.visibility(context)
            if (visibility.foregroundServiceStarting(Build.VERSION.SDK_INT) { isGranted(context, it) } != null) return false
            val intent = Intent(context, WaymarkForegroundService::class.java)
                .putExtra(EXTRA_NOTIFICATION, notification)
                .putExtra(EXTRA_ID, notificationId)
            return try {
                if (Build.VERSION.SDK_INT >= 26) context.startForegroundService(intent) else context.startService(intent)
                true
            } catch (e: RuntimeException) {
                // IllegalStateException: a start from the background (Android 8+ and 12+).
                visibility.foregroundServiceFailed(e.message ?: e.javaClass.name)
                false
            }
        }

        /** Stops the service; the clients go back to the background rules. */
        @JvmStatic
        fun stop(context: Context) {
            context.stopService(Intent(context, WaymarkForegroundService::class.java))
            AndroidPlatform.visibility(context).foregroundServiceStopped()
        }
    }
}
