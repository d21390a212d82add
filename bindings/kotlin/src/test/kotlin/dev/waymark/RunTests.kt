package dev.waymark

import kotlin.system.exitProcess
import org.junit.runner.Description
import org.junit.runner.JUnitCore
import org.junit.runner.notification.Failure
import org.junit.runner.notification.RunListener

/**
 * Runs the JUnit 4 test classes, prints one line per test with its time and, last, exactly
 * `N passed, N failed` (what CI reads). Exits 1 if anything failed.
 */
object RunTests {
    @JvmStatic
    fun main(args: Array<String>) {
        val core = JUnitCore()
        core.addListener(object : RunListener() {
            private val failed = HashSet<Description>()
            private var started = 0L

            override fun testStarted(description: Description) {
                started = System.nanoTime()
                println("RUN  ${description.methodName}")
            }

            override fun testFailure(failure: Failure) {
                failed.add(failure.description)
                println("FAIL ${failure.description.methodName ?: failure.description.displayName}: ${failure.message}")
                failure.exception.printStackTrace(System.out)
            }

            override fun testFinished(description: Description) {
                // The time shows which test a slow CI run spent its minutes on.
                val ms = (System.nanoTime() - started) / 1_000_000
                if (description !in failed) println("PASS ${description.methodName} ($ms ms)")
            }
        })
        val classes = arrayOf(
            WaymarkTest::class.java, ConversionsTest::class.java, GeoConversionsTest::class.java,
            ConcurrencyTest::class.java, RobustnessTest::class.java, SiteFormatsTest::class.java,
            CallbackContractTest::class.java,
            HabitsTest::class.java, RouteTest::class.java, SurveyRecorderTest::class.java,
            LocationClientTest::class.java, AndroidClientTest::class.java, SurveyModeTest::class.java,
            AndroidPackagingTest::class.java, GeoTest::class.java,
        )
        val result = core.run(*classes)
        // A failure in @BeforeClass fails the class without running any test: count each test.
        val failed = if (result.runCount == 0 && result.failureCount > 0) {
            maxOf(result.failureCount, classes.sumOf { c -> c.methods.count { it.isAnnotationPresent(org.junit.Test::class.java) } })
        } else {
            result.failureCount
        }
        val passed = result.runCount - result.failureCount
        println("${maxOf(passed, 0)} passed, $failed failed")
        System.out.flush()
        exitProcess(if (failed == 0 && passed > 0) 0 else 1)
    }
}
