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

    @Test
    fun theSessionGivesEvidenceAndTakesARefittedSiteInPlace() {
        val walk = Walk.load(setting("waymark.walk"))
        val json = File(setting("waymark.site")).readText()
        val refitted = Site.fromBytes(File(setting("waymark.packedSite")).readBytes())
        val half = walk.size / 2
        PositioningEngine(json, EngineOptions()).use { engine ->
            PositioningEngine(json, EngineOptions()).use { reference ->
                assertEquals("nothing gathered unless asked", null, engine.takeEvidence())
                engine.startEvidence()
                var accepted = 0
                walk.forEachIndexed { k, epoch ->
                    if (k == half) {
                        val before = engine.takeEvidence()!!
                        assertEquals(accepted.toULong(), before.scans)
                        assertEquals(0UL, before.scansDropped)
                        assertEquals("WMEV", String(before.bytes.copyOfRange(0, 4)))
                        // The same states: the session carries on as if nothing had been replaced.
                        assertEquals(0UL, engine.replaceSite(refitted)!!.scans)
                        assertEquals(reference.position(), engine.position())
                        accepted = 0
                    }
                    val p = WaymarkTest.pushEpoch(engine, epoch)
                    assertEquals("epoch $k", WaymarkTest.pushEpoch(reference, epoch), p)
                    if (p != null) accepted++
                }
                assertTrue("accepted scans", accepted > 5)
                assertEquals(accepted.toULong(), engine.takeEvidence()!!.scans)
                engine.stopEvidence()
                assertEquals(null, engine.takeEvidence())
                try {
                    engine.replaceSite(Site.fromBytes(File(setting("waymark.hashedSite")).readBytes()))
                    fail("a hashed site without its salt was taken")
                } catch (e: PositioningException) {
                    assertTrue(e.toString(), e is PositioningException.SaltMismatch)
                }
                assertEquals(reference.position(), engine.position())
            }
        }
        refitted.close()
    }
}
