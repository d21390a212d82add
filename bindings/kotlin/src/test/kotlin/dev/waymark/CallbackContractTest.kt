package dev.waymark

import java.io.File
import java.util.concurrent.CountDownLatch
import java.util.concurrent.TimeUnit
import java.util.concurrent.atomic.AtomicInteger
import org.junit.Assert.assertEquals
import org.junit.Assert.assertTrue
import org.junit.Assert.fail
import org.junit.BeforeClass
import org.junit.Test

/**
 * The callback contract of docs/errors.md#callbacks from Kotlin: a `LogSink` that calls the
 * engine on the thread that logged (it deadlocked when records were delivered under the engine's
 * lock), a slow sink that must not hold up another thread's call, and `close()` from a listener.
 * The timeouts turn a deadlock into a failure; no result depends on them.
 */
class CallbackContractTest {
    companion object {
        private lateinit var siteJson: String
        private val known = WifiReading("02:00:00:00:00:00", -60.0, 0uL)
        private val unknown = WifiReading("0a:0b:0c:0d:0e:0f", -60.0, 0uL)

        @BeforeClass
        @JvmStatic
        fun load() {
            siteJson = File(System.getProperty("waymark.site") ?: System.getenv("WAYMARK_SITE")).readText()
        }

        fun scan(t: ULong, reading: WifiReading) = RadioScan(t, listOf(reading), emptyList())
    }

    /** Calls `engine` from every record it receives. */
    class CallingSink(private val engine: PositioningEngine) : LogSink {
        val reads = AtomicInteger()

        override fun log(level: LogLevel, target: String, message: String) {
            engine.position()
            reads.incrementAndGet()
        }
    }

    @Test(timeout = 60_000)
    fun logSinkMayCallTheEngine() {
        PositioningEngine(siteJson, EngineOptions()).use { engine ->
            val sink = CallingSink(engine)
            initLogging(sink, LogLevel.DEBUG)
            try {
                // A rejected scan logs "scan rejected" at DEBUG inside the engine's lock.
                try {
                    engine.pushScan(scan(1_000_000_000uL, unknown))
                    fail("a scan of no known transmitter is rejected")
                } catch (e: PositioningException.InputRejected) {
                }
                assertTrue("the sink heard the rejection", sink.reads.get() > 0)
                engine.pushScan(scan(2_000_000_000uL, known))
            } finally {
                initLogging(null, LogLevel.ERROR)
            }
        }
    }

    /** Blocks in its first record until another thread's engine call has returned. */
    class WaitingSink(private val inSink: CountDownLatch, private val otherCallDone: CountDownLatch) : LogSink {
        @Volatile var otherReturnedFirst = false
        private val first = AtomicInteger()

        override fun log(level: LogLevel, target: String, message: String) {
            if (first.getAndIncrement() != 0) return
            inSink.countDown()
            otherReturnedFirst = otherCallDone.await(30, TimeUnit.SECONDS)
        }
    }

    @Test(timeout = 120_000)
    fun slowLogSinkDoesNotHoldUpOtherThreads() {
        PositioningEngine(siteJson, EngineOptions()).use { engine ->
            val inSink = CountDownLatch(1)
            val done = CountDownLatch(1)
            val sink = WaitingSink(inSink, done)
            // Calls the engine while the pushing thread is inside the sink.
            val other = Thread {
                inSink.await(30, TimeUnit.SECONDS)
                engine.inputStats()
                done.countDown()
            }
            initLogging(sink, LogLevel.DEBUG)
            try {
                other.start()
                try {
                    engine.pushScan(scan(1_000_000_000uL, unknown))
                } catch (e: PositioningException.InputRejected) {
                }
                other.join()
                assertTrue("another thread's call waited for the sink", sink.otherReturnedFirst)
            } finally {
                initLogging(null, LogLevel.ERROR)
            }
        }
    }

    /** Closes the engine at its first position or error. */
    class Closing(private val engine: PositioningEngine) : PositionListener {
        val positions = AtomicInteger()
        val errors = AtomicInteger()

        override fun onPosition(position: PositionEstimate) {
            positions.incrementAndGet()
            engine.close()
        }

        override fun onStatus(status: StatusUpdate) {}

        override fun onError(error: ErrorReport) {
            errors.incrementAndGet()
            engine.close()
        }
    }

    @Test(timeout = 60_000)
    fun closeFromAListenerTakesEffectWhenTheCallReturns() {
        // At a position: the scan still returns it; then the engine is closed.
        val engine = PositioningEngine(siteJson, EngineOptions())
        val closing = Closing(engine)
        val subscription = engine.subscribe(closing)
        assertEquals(1_000_000_000uL, engine.pushScan(scan(1_000_000_000uL, known)).timestampNs)
        assertEquals(1, closing.positions.get())
        try {
            engine.position()
            fail("a closed engine is closed")
        } catch (e: IllegalStateException) {
        }
        subscription.close()

        // At the error of a rejected scan.
        val rejecting = PositioningEngine(siteJson, EngineOptions())
        val closingOnError = Closing(rejecting)
        val other = rejecting.subscribe(closingOnError)
        try {
            rejecting.pushScan(scan(1_000_000_000uL, unknown))
            fail("a scan of no known transmitter is rejected")
        } catch (e: PositioningException.InputRejected) {
        }
        assertEquals(1, closingOnError.errors.get())
        try {
            rejecting.inputStats()
            fail("a closed engine is closed")
        } catch (e: IllegalStateException) {
        }
        other.close()
    }
}
