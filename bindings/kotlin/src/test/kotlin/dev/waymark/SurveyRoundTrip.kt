package dev.waymark

import java.io.File
import kotlin.math.hypot
import org.junit.Assert.assertEquals
import org.junit.Assert.assertTrue

/**
 * The end of every record → survey → position test: `waymark survey` builds a site from the
 * walk files recorded under `dir/F1`, and an engine on it positions the demo office's test walk
 * (never surveyed) within 1.5 × the error of the engine on the office's own site.
 */
object SurveyRoundTrip {
    private val cli = System.getProperty("waymark.cli")
    private val siteJson by lazy { File(System.getProperty("waymark.site")).readText() }
    private val walk by lazy { Walk.load(System.getProperty("waymark.walk")) }

    /** Runs `body` with a new temporary folder named from `prefix`, deleted afterwards. */
    fun <T> inTempDir(prefix: String, body: (File) -> T): T {
        val dir = java.nio.file.Files.createTempDirectory(prefix).toFile()
        try {
            return body(dir)
        } finally {
            dir.deleteRecursively()
        }
    }

    /** The exported walks (`*.json`) in `dir`, by name. */
    fun walkFiles(dir: File): List<File> = dir.listFiles { f -> f.name.endsWith(".json") }!!.sortedBy { it.name }

    /** The engine's mean error over the test walk's scans; closes it. */
    fun meanError(engine: PositioningEngine): Double {
        val errors = ArrayList<Double>()
        engine.use {
            for (epoch in walk) {
                it.pushAccelerometer(epoch.accelerometer)
                it.pushGyroscope(epoch.gyroscope)
                it.pushMagnetometer(epoch.magnetometer)
                try {
                    val p = it.pushScan(epoch.scan())
                    errors.add(hypot(p.x - epoch.truthX, p.y - epoch.truthY))
                } catch (e: PositioningException.InputRejected) {
                }
            }
        }
        assertTrue("${errors.size} positions", errors.size > 20)
        return errors.average()
    }

    /** Surveys `dir/F1` into `dir/site.json` and checks its error; `label` names the run. */
    fun check(dir: File, label: String) {
        val site = File(dir, "site.json")
        val process = ProcessBuilder(cli, "survey", File(dir, "F1").path, "--out", site.path, "--name", "office")
            .redirectErrorStream(true).start()
        val output = process.inputStream.bufferedReader().readText()
        assertEquals(output, 0, process.waitFor())
        val surveyed = meanError(PositioningEngine(site.readText(), EngineOptions()))
        val demo = meanError(PositioningEngine(siteJson, EngineOptions()))
        println("$label: mean error %.2f m on its site, %.2f m on the office's".format(surveyed, demo))
        assertTrue("$surveyed m against $demo m", surveyed <= 1.5 * demo)
    }
}
