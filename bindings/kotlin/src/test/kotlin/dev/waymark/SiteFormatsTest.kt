package dev.waymark

import java.io.File
import org.junit.Assert.assertEquals
import org.junit.Assert.assertTrue
import org.junit.Assert.fail
import org.junit.Test

/** The binary site encoding (`waymark site pack`), what an app ships in its assets. */
class SiteFormatsTest {
    private fun setting(property: String): String =
        System.getProperty(property) ?: throw IllegalStateException("set -D$property=...")

    private fun replay(engine: PositioningEngine, walk: List<Epoch>): List<PositionEstimate?> =
        engine.use { walk.map { epoch -> WaymarkTest.pushEpoch(it, epoch) } }

    @Test
    fun aPackedSiteFromBytesPositionsExactlyAsItsJson() {
        val walk = Walk.load(setting("waymark.walk"))
        val packed = File(setting("waymark.packedSite")).readBytes()
        val json = File(setting("waymark.site")).readText()
        assertTrue("smaller than the JSON", packed.size < json.length)
        val fromBytes = replay(PositioningEngine.fromSiteBytes(packed, EngineOptions()), walk)
        val fromJson = replay(PositioningEngine(json, EngineOptions()), walk)
        val fromPath = replay(PositioningEngine.fromPath(setting("waymark.packedSite"), EngineOptions()), walk)
        assertTrue("positions", fromBytes.count { it != null } > walk.size / 2)
        assertEquals(fromJson, fromBytes)
        assertEquals(fromJson, fromPath)
        // The JSON's bytes load through the same constructor.
        PositioningEngine.fromSiteBytes(json.toByteArray(), EngineOptions()).close()
    }

    @Test
    fun aDamagedPackedSiteIsAnInvalidSite() {
        val packed = File(setting("waymark.packedSite")).readBytes()
        packed[packed.size / 2] = (packed[packed.size / 2].toInt() xor 0x40).toByte()
        try {
            PositioningEngine.fromSiteBytes(packed, EngineOptions()).close()
            fail("a damaged site loaded")
        } catch (e: PositioningException.InvalidSite) {
            assertTrue(e.reason, e.reason.contains("damaged"))
        }
    }

    @Test
    fun oneSharedSiteServesSeveralEnginesThatPositionAsIfEachHadItsOwn() {
        val walk = Walk.load(setting("waymark.walk"))
        val site = Site.fromBytes(File(setting("waymark.packedSite")).readBytes())
        site.use {
            assertTrue("floors", it.floorNames().isNotEmpty())
            assertEquals(Site.fromPath(setting("waymark.site")).use { json -> json.zoneNames() }, it.zoneNames())
            val own = replay(PositioningEngine.fromPath(setting("waymark.packedSite"), EngineOptions()), walk)
            val first = replay(PositioningEngine.withSite(it, EngineOptions()), walk)
            val second = replay(PositioningEngine.withSite(it, EngineOptions()), walk)
            assertTrue("positions", own.count { p -> p != null } > walk.size / 2)
            assertEquals(own, first)
            assertEquals(own, second)
        }
        try {
            Site.fromBytes("{".toByteArray()).close()
            fail("a truncated site loaded")
        } catch (e: PositioningException.InvalidSite) {
            assertTrue(e.reason, e.reason.isNotEmpty())
        }
    }
}
