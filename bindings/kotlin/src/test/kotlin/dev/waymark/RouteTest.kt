package dev.waymark

import org.junit.Assert.assertEquals
import org.junit.Assert.assertFalse
import org.junit.Assert.assertNull
import org.junit.Assert.assertTrue
import org.junit.Assert.fail
import org.junit.Test

/** Routes through the bindings (docs/routes.md), on the simulated office of `waymark sim-export`. */
class RouteTest {
    private fun setting(property: String): String =
        System.getProperty(property) ?: throw IllegalStateException("set -D$property=...")

    private fun site(): Site = Site.fromPath(setting("waymark.site"))

    @Test
    fun aRouteToAZoneComesAsLegsWithTurns() {
        site().use { site ->
            // From room 1's far corner to room 10, across the aisle.
            val route = site.route(FloorPoint(0u, 4.9, 2.0), Destination.Zone("room 10"))
            assertTrue("legs", route.legs.size >= 3)
            assertEquals(route.lengthM, route.legs.sumOf { it.distanceM }, 1e-9)
            val straight = Math.hypot(route.end.x - route.start.x, route.end.y - route.start.y)
            assertTrue("never shorter than the straight line", route.lengthM >= straight)
            assertNull("the first leg has no turn", route.legs[0].turn)
            assertTrue("later legs turn", route.legs.drop(1).all { it.turn != null && it.turnDeg != null })
            assertTrue("one floor", route.legs.none { it.floorChange })
            // Each leg starts where the one before ended.
            route.legs.zipWithNext { a, b -> assertEquals(a.points.last(), b.points.first()) }
            assertEquals(route.start, route.legs.first().points.first())
            assertEquals(route.end, route.legs.last().points.last())
        }
    }

    @Test
    fun aTrackerFollowsTheRouteAndNoticesADetour() {
        site().use { site ->
            val tracker = RouteTracker(site, FloorPoint(0u, 1.9, 9.0), Destination.Zone("stair hall"))
            tracker.use {
                val route = it.route()
                val first = it.updatePoint(route.start, 2.0)
                assertFalse(first.offRoute)
                assertEquals(route.lengthM, first.remainingM, 1e-9)
                assertEquals(0u, first.leg)
                // Deep in room 2 (x 6.8-13.6, y 0-10), off the aisle: off the route.
                assertTrue(it.updatePoint(FloorPoint(0u, 10.0, 3.0), 2.0).offRoute)
                // Rerouting from there leads on, and the new route is followed from its start.
                val again = it.reroute()
                assertEquals(route.end, again.end)
                assertFalse(it.updatePoint(FloorPoint(0u, 10.0, 3.0), 2.0).offRoute)
                val there = it.updatePoint(again.end, 1.0)
                assertTrue(there.arrived)
                assertEquals(0.0, there.remainingM, 1e-9)
            }
        }
    }

    @Test
    fun routeErrorsAreTyped() {
        site().use { site ->
            try {
                site.route(FloorPoint(0u, 4.9, 2.0), Destination.Zone("kitchen"))
                fail("an unknown zone routed")
            } catch (e: RouteException.UnknownZone) {
                assertEquals("kitchen", e.name)
            }
            for (bad in listOf(FloorPoint(7u, 1.0, 1.0), FloorPoint(0u, Double.NaN, 1.0), FloorPoint(0u, 500.0, 1.0))) {
                try {
                    site.route(bad, Destination.Point(FloorPoint(0u, 4.9, 2.0)))
                    fail("$bad routed")
                } catch (e: RouteException.OffGraph) {
                    assertTrue(e.reason, e.reason.isNotEmpty())
                }
            }
        }
    }

    @Test
    fun theEngineRoutesFromItsPosition() {
        val walk = Walk.load(setting("waymark.walk"))
        PositioningEngine.fromPath(setting("waymark.site"), EngineOptions()).use { engine ->
            try {
                engine.routeTo(Destination.Zone("room 10"))
                fail("routed before the first position")
            } catch (e: RouteException.NoPosition) {
            }
            walk.take(10).forEach { WaymarkTest.pushEpoch(engine, it) }
            val position = engine.position()!!
            val route = engine.routeTo(Destination.Zone("room 10"))
            assertTrue("starts near the position", Math.hypot(route.start.x - position.x, route.start.y - position.y) <= route.startSnapM + 1e-9)
            engine.navigateTo(Destination.Zone("room 10")).use { tracker ->
                assertEquals(route, tracker.route())
                val progress = tracker.update(position)
                assertEquals(route.lengthM - progress.alongM, progress.remainingM, 1e-9)
            }
        }
    }
}
