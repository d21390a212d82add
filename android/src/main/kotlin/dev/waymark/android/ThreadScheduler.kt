package dev.waymark.android

import java.util.concurrent.ScheduledFuture
import java.util.concurrent.ScheduledThreadPoolExecutor
import java.util.concurrent.ThreadFactory
import java.util.concurrent.TimeUnit

/**
 * A [Scheduler] on a thread of its own, for the client outside Android (a JVM service, the
 * tests); on Android the client runs on a `HandlerThread` (AndroidPlatform.kt). Tasks run one
 * at a time in the order they were posted; [quit] lets the posted ones run, then ends the
 * thread.
 */
class ThreadScheduler @JvmOverloads constructor(name: String = "waymark-location") : Scheduler {
    @Volatile private var thread: Thread? = null

    private val executor = ScheduledThreadPoolExecutor(1, ThreadFactory { r ->
        Thread(r, name).also {
            it.isDaemon = true
            thread = it
        }
    }).apply {
        removeOnCancelPolicy = true
        executeExistingDelayedTasksAfterShutdownPolicy = false
    }

    override fun schedule(delayMs: Long, task: Runnable): Cancellable {
        val future: ScheduledFuture<*> = try {
            executor.schedule(task, delayMs, TimeUnit.MILLISECONDS)
        } catch (e: java.util.concurrent.RejectedExecutionException) {
            return Cancellable {} // quit: nothing runs any more
        }
        return Cancellable { future.cancel(false) }
    }

    override fun post(task: Runnable) {
        try {
            executor.execute(task)
        } catch (e: java.util.concurrent.RejectedExecutionException) {
            // quit: the client is closed, and its tasks are no-ops
        }
    }

    override fun isClientThread(): Boolean = Thread.currentThread() === thread

    override fun quit() {
        executor.shutdown()
    }

    /** Waits until the thread ended after [quit]; for tests and orderly JVM shutdowns. */
    fun awaitTermination(timeoutMs: Long): Boolean = executor.awaitTermination(timeoutMs, TimeUnit.MILLISECONDS)
}
