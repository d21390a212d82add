package dev.waymark

import java.io.File
import java.util.Collections
import java.util.concurrent.CyclicBarrier
import java.util.concurrent.Executors
import java.util.concurrent.TimeUnit
import java.util.concurrent.TimeoutException
import java.util.concurrent.atomic.AtomicBoolean
import java.util.concurrent.atomic.AtomicInteger
import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertTrue
import org.junit.Assert.fail
import org.junit.BeforeClass
import org.junit.Test

/**
 * One engine hammered from eight JVM threads for a few seconds (issue 7): sensor batches, scans
 * and `advance` with clashing timestamps, reads, and listeners subscribed and cancelled all the
 * while, one of them throwing a RuntimeException from every call. No deadlock (a watchdog fails
 * the test instead of hanging), no lost or reordered listener call, and the engine goes on.
 */
class ConcurrencyTest {
    /** Records every call, in order, and whether two ever overlapped. */
    class Recorder : PositionListener {
        val timestamps: MutableList<ULong> = Collections.synchronizedList(ArrayList())
        val errors = AtomicInteger()
        private val busy = AtomicBoolean()
        @Volatile var overlapped = false

        private fun <T> enter(body: () -> T): T {
            if (busy.getAndSet(true)) overlapped = true
            try {
                return body()
            } finally {
                busy.set(false)
            }
        }

        override fun onPosition(position: PositionEstimate) = enter { timestamps.add(position.timestampNs); Unit }

        override fun onStatus(status: StatusUpdate) = enter { }

        override fun onError(error: ErrorReport) = enter { errors.incrementAndGet(); Unit }
    }

    /** Throws a RuntimeException from every call, as a buggy app's listener might. */
    class Throwing : PositionListener {
        val positions = AtomicInteger()
        val calls = AtomicInteger()

        override fun onPosition(position: PositionEstimate) {
            positions.incrementAndGet()
            calls.incrementAndGet()
            throw RuntimeException("app bug in onPosition")
        }

        override fun onStatus(status: StatusUpdate) {
            calls.incrementAndGet()
            throw RuntimeException("app bug in onStatus")
        }

        override fun onError(error: ErrorReport) {
            calls.incrementAndGet()
            throw RuntimeException("app bug in onError")
        }
    }

    /**
     * From inside its callback: subscribes another listener and cancels it, reads the engine,
     * and cancels its own subscription (as soon as it has it). Nothing may reach it after that.
     */
    class Reentrant(private val engine: PositioningEngine) : PositionListener {
        @Volatile var own: Subscription? = null
        val cancelled = AtomicBoolean()
        val afterCancel = AtomicInteger()

        override fun onPosition(position: PositionEstimate) {
            if (cancelled.get()) afterCancel.incrementAndGet()
            engine.subscribe(Recorder()).use { engine.position() }
            engine.track()
            own?.let {
                own = null
                it.cancel()
                cancelled.set(true)
                it.close()
            }
        }

        override fun onStatus(status: StatusUpdate) {}

        override fun onError(error: ErrorReport) {}
    }

    companion object {
        const val SPEED = 10L
        const val HAMMER_MS = 3_000L
        const val EPOCH_NS = 1_500_000_000UL
        private lateinit var siteJson: String
        private lateinit var walk: List<Epoch>
        /** The walk's IMU per stream, timestamps from 0, and the trace's length in ns. */
        private lateinit var imu: List<List<MotionSample>>
        private var imuNs = 0UL

        @BeforeClass
        @JvmStatic
        fun load() {
            val site = System.getProperty("waymark.site") ?: System.getenv("WAYMARK_SITE")
            val walkPath = System.getProperty("waymark.walk") ?: System.getenv("WAYMARK_WALK")
            siteJson = File(site).readText()
            walk = Walk.load(walkPath)
            val streams = listOf(walk.flatMap { it.accelerometer }, walk.flatMap { it.gyroscope }, walk.flatMap { it.magnetometer })
            val t0 = streams.minOf { it.first().timestampNs }
            imu = streams.map { s -> s.map { it.copy(timestampNs = it.timestampNs - t0) } }
            imuNs = imu.maxOf { it.last().timestampNs } + 10_000_000UL
        }
    }

    @Test(timeout = 120_000)
    fun eightThreadsHammerOneEngine() {
        PositioningEngine(siteJson, EngineOptions()).use { engine -> hammer(engine) }
    }

    private fun hammer(engine: PositioningEngine) {
        // Subscribed before the start and never cancelled: they must hear everything.
        val throwing = Throwing()
        val steady = Recorder()
        val s0 = engine.subscribe(throwing)
        val s1 = engine.subscribe(steady)
        val ok = AtomicInteger()
        val rejected = AtomicInteger()
        val reentrant = Collections.synchronizedList(ArrayList<Reentrant>())
        val failures = Collections.synchronizedList(ArrayList<Throwable>())
        val start = CyclicBarrier(8)
        val t0 = System.nanoTime()
        fun now(): ULong = ((System.nanoTime() - t0) * SPEED).toULong()
        fun running() = System.nanoTime() - t0 < HAMMER_MS * 1_000_000
        fun epoch(push: () -> PositionEstimate) {
            try {
                val p = push()
                assertTrue("$p", p.x.isFinite() && p.y.isFinite() && p.accuracyM > 0.0)
                ok.incrementAndGet()
            } catch (e: PositioningException.InputRejected) {
                rejected.incrementAndGet() // another thread's epoch was later
            }
        }

        val work = ArrayList<() -> Unit>()
        // 0-2: one thread per inertial stream, the walk's samples up to "now", in time order.
        for (stream in 0 until 3) work.add {
            val samples = imu[stream]
            var k = 0
            var round = 0UL
            while (running()) {
                val until = now()
                val batch = ArrayList<MotionSample>()
                while (true) {
                    val s = samples[k]
                    val t = s.timestampNs + round * imuNs
                    if (t > until) break
                    batch.add(s.copy(timestampNs = t))
                    if (++k == samples.size) { k = 0; round++ }
                }
                when (stream) {
                    0 -> engine.pushAccelerometer(batch)
                    1 -> engine.pushGyroscope(batch)
                    else -> engine.pushMagnetometer(batch)
                }
                Thread.sleep(5)
            }
        }
        // 3-4: scans at "now", racing each other and 5: the loser of a race is rejected.
        for (thread in 0 until 2) work.add {
            var n = thread
            while (running()) {
                val t = now()
                val wifi = walk[((t / EPOCH_NS) % walk.size.toULong()).toInt()].wifi
                epoch { engine.pushScan(RadioScan(t, wifi, emptyList())) }
                Thread.sleep(2L + n++ % 5)
            }
        }
        // 5: advance, sometimes to a time already passed.
        work.add {
            var n = 0
            while (running()) {
                val t = if (n++ % 4 == 3 && now() > EPOCH_NS) now() - EPOCH_NS else now()
                epoch { engine.advance(t) }
                Thread.sleep(3)
            }
        }
        // 6: reads.
        work.add {
            while (running()) {
                engine.position()?.let { assertTrue(it.x.isFinite() && it.y.isFinite()) }
                assertTrue(engine.track().all { it.x.isFinite() && it.y.isFinite() })
                engine.fixedLagPosition()
                Thread.yield()
            }
        }
        // 7: listeners coming and going: cancelled, closed, or cancelling themselves inside
        // their own callback.
        work.add {
            var n = 0
            while (running()) {
                val subscription = engine.subscribe(Recorder())
                Thread.sleep(1)
                if (n % 2 == 0) subscription.cancel()
                subscription.close()
                if (n % 10 == 0) {
                    val r = Reentrant(engine)
                    r.own = engine.subscribe(r)
                    reentrant.add(r)
                }
                n++
            }
        }

        val pool = Executors.newFixedThreadPool(8) { r -> Thread(r).apply { isDaemon = true } }
        try {
            val futures = work.map { body ->
                pool.submit {
                    try {
                        start.await()
                        body()
                    } catch (t: Throwable) {
                        failures.add(t)
                    }
                }
            }
            for (f in futures) {
                try {
                    f.get(60, TimeUnit.SECONDS)
                } catch (e: TimeoutException) {
                    fail("a thread was still running after 60 s: deadlock")
                }
            }
        } finally {
            pool.shutdownNow()
        }
        if (failures.isNotEmpty()) throw AssertionError("a thread failed", failures.first())

        println("hammer: ${ok.get()} epochs, ${rejected.get()} rejected")
        assertTrue("${ok.get()} epochs: the hammer did little", ok.get() > 50)
        // No lost, doubled or reordered call; the throwing listener was called as often.
        val heard = ArrayList(steady.timestamps)
        assertEquals("positions heard / epochs accepted", ok.get(), heard.size)
        assertTrue("positions out of order", heard.zipWithNext().all { (a, b) -> a < b })
        assertEquals(rejected.get(), steady.errors.get())
        assertFalse("a listener was called from two threads at once", steady.overlapped)
        assertEquals(ok.get(), throwing.positions.get())
        assertTrue(reentrant.isNotEmpty())
        assertTrue("none cancelled itself", reentrant.any { it.cancelled.get() })
        for (r in reentrant) assertEquals("heard after cancelling itself", 0, r.afterCancel.get())
        reentrant.forEach { it.own?.close() }
        // Still usable, and every listener still hears.
        val last = engine.position()!!.timestampNs
        engine.advance(last + EPOCH_NS)
        assertEquals(ok.get() + 1, steady.timestamps.size)
        assertEquals(ok.get() + 1, throwing.positions.get())
        s0.close()
        s1.close()
    }
}
