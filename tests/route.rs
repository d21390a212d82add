//! Routes on the simulated office (docs/routes.md): never shorter than the straight line,
//! as short as the walking-distance table says, never through a wall of the office's plan,
//! floor changes only on the staircase; the tracker's progress and off-route rule; typed
//! errors; and the same through the uniffi surface (the C surface's: bindings/c/test.c).

use nalgebra::Point2;
use proptest::prelude::*;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use std::sync::{Arc, OnceLock};
use waymark_engine::route::{
    Destination, FloorPoint, Route, RouteError, RouteTracker, SIGMA_PER_ACCURACY_68,
};
use waymark_engine::site::{ReachTable, Site, SiteBuilder};
use waymark_sim::{Office, OfficeConfig};

fn office() -> &'static Office {
    static OFFICE: OnceLock<Office> = OnceLock::new();
    OFFICE.get_or_init(|| Office::generate(&OfficeConfig { training_scans: 20, ..OfficeConfig::default() }))
}

/// The staircase of [`two_floors`]: the stair hall's south-east state on each floor, and its
/// walking length, m.
const STAIRS: (Point2<f64>, f64) = (Point2::new(38.5, 3.0), 8.0);

/// The office on two floors, one above the other, joined only by a staircase in the stair
/// hall's south-east corner. Zones keep their names on the ground floor and get "upstairs "
/// before them on the first.
fn two_floors() -> &'static Site {
    static SITE: OnceLock<Site> = OnceLock::new();
    SITE.get_or_init(|| {
        let one = &office().site;
        let mut b = SiteBuilder::new("two-floor office");
        let floors = [b.floor("ground", 0.0), b.floor("first", 4.0)];
        let n = one.states().len() as u32;
        for &f in &floors {
            for s in one.states() {
                b.state(f, s.position, vec![]);
            }
        }
        for f in 0..2 {
            for e in one.edges() {
                b.edge(e.a + f * n, e.b + f * n, None);
            }
        }
        let stairs =
            one.states().iter().position(|s| s.position == STAIRS.0).expect("the stair hall's corner") as u32;
        b.edge(stairs, stairs + n, Some(STAIRS.1));
        for z in one.zones() {
            b.zone(&z.name, z.kind, z.states.clone());
            b.zone(&format!("upstairs {}", z.name), z.kind, z.states.iter().map(|s| s + n).collect());
        }
        b.build(Default::default()).unwrap()
    })
}

type Segment = (Point2<f64>, Point2<f64>);

/// The walls of the office's plan, independent of its graph: each room is a 6.8 m x 10 m box
/// (five south of the aisle, y 0-10, five north, y 13-23, x 0-34) whose only opening is a 3 m
/// door on the aisle side centred on its door cell (x0 + 1.9); the stair hall (x 34-40) opens
/// onto the aisle's end (y 10-13).
fn walls() -> Vec<Segment> {
    let p = Point2::new;
    let mut w = Vec::new();
    for k in 0..5 {
        let x0 = 6.8 * k as f64;
        for (far, aisle_side) in [(0.0, 10.0), (23.0, 13.0)] {
            w.push((p(x0, far), p(x0, aisle_side)));
            w.push((p(x0 + 6.8, far), p(x0 + 6.8, aisle_side)));
            w.push((p(x0, far), p(x0 + 6.8, far)));
            w.push((p(x0, aisle_side), p(x0 + 0.4, aisle_side)));
            w.push((p(x0 + 3.4, aisle_side), p(x0 + 6.8, aisle_side)));
        }
    }
    w
}

/// Whether segments `a` and `b` cross (touching counts).
fn crosses(a: &Segment, b: &Segment) -> bool {
    let orient = |p: &Point2<f64>, q: &Point2<f64>, r: &Point2<f64>| (q - p).perp(&(r - p));
    let (d1, d2) = (orient(&b.0, &b.1, &a.0), orient(&b.0, &b.1, &a.1));
    let (d3, d4) = (orient(&a.0, &a.1, &b.0), orient(&a.0, &a.1, &b.1));
    d1 * d2 <= 0.0 && d3 * d4 <= 0.0 && !(d1 == 0.0 && d2 == 0.0)
}

/// Every property a route must have on `site`, from `from` to a destination.
fn check(site: &Site, route: &Route, from: &FloorPoint) {
    let (start, end) = (route.start(), route.end());
    // Never shorter than the straight line: between its ends, and (with the snaps) between
    // the points it was asked for on one floor.
    let straight = nalgebra::distance(&start.position(), &end.position());
    assert!(route.length_m() >= straight - 1e-9, "{} < {straight}", route.length_m());
    if from.floor == end.floor {
        let asked = nalgebra::distance(&from.position(), &end.position());
        assert!(route.length_m() + route.start_snap_m() >= asked - 1e-9);
    }
    // Each step is an edge of the graph (so a floor changes only where the site joins two
    // floors), walked at its length.
    let states = route.states();
    for (k, w) in states.windows(2).enumerate() {
        let mut edges = site.neighbours(w[0] as usize);
        let edge = edges.find(|n| n.0 == w[1]);
        let length = edge.unwrap_or_else(|| panic!("{} - {} is not an edge", w[0], w[1])).1;
        let step = route.distances_m()[k + 1] - route.distances_m()[k];
        assert!((step - length).abs() < 1e-9);
    }
    // The legs chain, add up, and a floor changes in a floor-change leg only.
    let legs = route.legs();
    assert!((legs.iter().map(|l| l.distance_m).sum::<f64>() - route.length_m()).abs() < 1e-9);
    for (k, leg) in legs.iter().enumerate() {
        assert_eq!(leg.first, if k == 0 { 0 } else { legs[k - 1].last });
        let floors: Vec<usize> =
            states[leg.first..=leg.last].iter().map(|&s| site.states()[s as usize].floor).collect();
        if leg.is_floor_change() {
            assert!(floors.windows(2).all(|f| f[0] != f[1]), "a floor-change leg walks on a floor");
            assert_eq!(leg.turn, None);
        } else {
            assert!(floors.iter().all(|&f| f == leg.floor));
            // A walk leg is one straight line of cells.
            for p in &leg.points {
                let (a, b) = (leg.start(), leg.end());
                let off = (b - a).perp(&(p - a)).abs() / (b - a).norm();
                assert!(off <= route.half_cell_m() + 1e-9, "{off} m off its leg's line");
            }
            let after_walk = k > 0 && !legs[k - 1].is_floor_change();
            assert_eq!(leg.turn.is_some(), after_walk);
        }
    }
    if !legs.is_empty() {
        assert_eq!(legs.last().unwrap().last, states.len() - 1);
    }
    // No walked segment crosses a wall of the plan.
    let walls = walls();
    for w in states.windows(2) {
        let (a, b) = (&site.states()[w[0] as usize], &site.states()[w[1] as usize]);
        if a.floor == b.floor {
            for wall in &walls {
                assert!(
                    !crosses(&(a.position, b.position), wall),
                    "{:?} - {:?} crosses {wall:?}",
                    a.position,
                    b.position
                );
            }
        }
    }
}

/// The walking distance between states `a` and `b` by the engine's own look-up table (an
/// independent Dijkstra).
fn table_distance(site: &Site, a: u32, b: u32) -> Option<f64> {
    static OFFICE: OnceLock<ReachTable> = OnceLock::new();
    static TWO_FLOORS: OnceLock<ReachTable> = OnceLock::new();
    let cell = if std::ptr::eq(site, &office().site) { &OFFICE } else { &TWO_FLOORS };
    assert!(std::ptr::eq(site, &office().site) || std::ptr::eq(site, two_floors()));
    let table = cell.get_or_init(|| ReachTable::build(site, 1000.0));
    table.reachable(a as usize, 1000.0).iter().find(|e| e.0 == b).map(|e| f64::from(e.1))
}

fn point_strategy(floors: usize) -> impl Strategy<Value = FloorPoint> {
    // The office is 40 m x 23 m; its outermost states are 1.5-3 m inside its walls.
    (0..floors, 1.0..39.0f64, 1.0..22.0f64).prop_map(|(f, x, y)| FloorPoint::new(f, x, y))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    /// Random pairs of points on the office: every route has every property, and is as short
    /// as the look-up table's walking distance.
    #[test]
    fn office_routes_are_short_and_respect_walls(from in point_strategy(1), to in point_strategy(1)) {
        let site = &office().site;
        let route = Route::plan(site, &from, &Destination::Point(to)).unwrap();
        check(site, &route, &from);
        let expected = table_distance(site, route.states()[0], *route.states().last().unwrap()).unwrap();
        prop_assert!((route.length_m() - expected).abs() < 1e-3, "{} against {expected}", route.length_m());
    }

    /// On two floors: a route between floors takes the staircase once, and only there; a route
    /// on one floor never leaves it.
    #[test]
    fn two_floor_routes_take_the_stairs(from in point_strategy(2), to in point_strategy(2)) {
        let site = two_floors();
        let route = Route::plan(site, &from, &Destination::Point(to)).unwrap();
        check(site, &route, &from);
        let changes: Vec<_> = route.legs().iter().filter(|l| l.is_floor_change()).collect();
        if from.floor == to.floor {
            prop_assert!(changes.is_empty());
        } else {
            prop_assert_eq!(changes.len(), 1);
            let stairs = changes[0];
            prop_assert_eq!((stairs.floor, stairs.to_floor), (from.floor, to.floor));
            prop_assert_eq!((stairs.start(), stairs.end()), (STAIRS.0, STAIRS.0));
            prop_assert!((stairs.distance_m - STAIRS.1).abs() < 1e-9);
        }
        let expected = table_distance(site, route.states()[0], *route.states().last().unwrap()).unwrap();
        prop_assert!((route.length_m() - expected).abs() < 1e-3);
    }

    /// To every zone from anywhere: the route ends in the zone, at its state nearest on foot.
    #[test]
    fn zone_routes_end_at_the_nearest_state_of_the_zone(from in point_strategy(2), zone in 0usize..24) {
        let site = two_floors();
        let name = site.zones()[zone].name.clone();
        let route = Route::plan(site, &from, &Destination::Zone(name)).unwrap();
        check(site, &route, &from);
        let end = *route.states().last().unwrap();
        prop_assert_eq!(site.zone_of(end as usize), Some(zone));
        let start = route.states()[0];
        for &s in &site.zones()[zone].states {
            prop_assert!(table_distance(site, start, s).unwrap() >= route.length_m() - 1e-3);
        }
    }
}

/// Room 1 to room 10, across the aisle: out of the door, along the aisle, in at the other
/// door, each turn where the plan has it.
#[test]
fn room_to_room_goes_through_both_doors() {
    let site = &office().site;
    let route =
        Route::plan(site, &FloorPoint::new(0, 4.9, 2.0), &Destination::Zone("room 10".into())).unwrap();
    let names: Vec<Option<&str>> = route.legs().iter().map(|l| l.turn.map(|t| t.name())).collect();
    assert!(route.legs().len() >= 3, "{names:?}");
    assert_eq!(names[0], None);
    let zones: Vec<Option<&str>> = route
        .states()
        .iter()
        .map(|&s| site.zone_of(s as usize).map(|z| site.zones()[z].name.as_str()))
        .collect();
    assert_eq!(zones.first(), Some(&Some("room 1")));
    assert!(zones.contains(&Some("aisle")));
    assert_eq!(zones.last(), Some(&Some("room 10")));
    check(site, &route, &FloorPoint::new(0, 4.9, 2.0));
}

#[test]
fn errors_are_typed() {
    let site = two_floors();
    let here = FloorPoint::new(0, 1.7, 11.5);
    assert_eq!(
        Route::plan(site, &here, &Destination::Zone("kitchen".into())),
        Err(RouteError::UnknownZone("kitchen".into()))
    );
    for bad in
        [FloorPoint::new(2, 1.7, 11.5), FloorPoint::new(0, f64::NAN, 1.0), FloorPoint::new(0, 100.0, 100.0)]
    {
        let e = Route::plan(site, &bad, &Destination::Point(here)).unwrap_err();
        assert!(
            matches!(
                e,
                RouteError::UnknownFloor { .. } | RouteError::NotFinite(_) | RouteError::OffGraph { .. }
            ),
            "{e:?}"
        );
    }
    // The office alone has one floor; without the stairs, the first floor is out of reach.
    let office = &office().site;
    let mut b = SiteBuilder::new("no stairs");
    let floors = [b.floor("ground", 0.0), b.floor("first", 4.0)];
    for &f in &floors {
        for s in office.states() {
            b.state(f, s.position, vec![]);
        }
    }
    let unlinked = b.build(Default::default()).unwrap();
    assert!(matches!(
        Route::plan(&unlinked, &here, &Destination::Point(FloorPoint::new(1, 1.7, 11.5))),
        Err(RouteError::Unreachable { .. })
    ));
}

/// A walker following the route with position noise of their accuracy: progress goes down to
/// arrival and the route is almost never declared left; walking off into a room is declared
/// within a few positions, and rerouting from there leads on.
#[test]
fn a_noisy_walk_along_the_route_stays_on_it_and_a_detour_leaves_it() {
    let site = &office().site;
    let route =
        Route::plan(site, &FloorPoint::new(0, 1.9, 9.0), &Destination::Zone("stair hall".into())).unwrap();
    let mut tracker = RouteTracker::new(route.clone());
    let accuracy_m = 2.0;
    let sigma = accuracy_m * SIGMA_PER_ACCURACY_68;
    let noise = Normal::new(0.0, sigma).unwrap();
    let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(7);
    let (mut positions, mut off, mut last_remaining) = (0, 0, f64::INFINITY);
    let points = route.points();
    for w in points.windows(2) {
        for k in 0..10 {
            let t = k as f64 / 10.0;
            let truth = w[0].position() + (w[1].position() - w[0].position()) * t;
            let seen = FloorPoint::new(0, truth.x + noise.sample(&mut rng), truth.y + noise.sample(&mut rng));
            let p = tracker.update(&seen, accuracy_m).unwrap();
            positions += 1;
            off += usize::from(p.off_route);
            // The position's own error along the route (σ) moves the progress back and forth;
            // it never jumps back further than 4 σ.
            assert!(
                p.remaining_m <= last_remaining + 4.0 * sigma,
                "progress jumped back: {p:?} after {last_remaining}"
            );
            last_remaining = last_remaining.min(p.remaining_m);
        }
    }
    let end = points.last().unwrap();
    let p = tracker.update(end, accuracy_m).unwrap();
    assert!(p.arrived && p.remaining_m < 1e-9 && p.leg == route.legs().len() - 1);
    // 1% expected for independent errors (docs/routes.md#progress).
    assert!(off * 50 <= positions, "{off} of {positions} positions off the route");

    // Into room 2 (x 6.8-13.6, y 0-10) instead of along the aisle.
    let mut tracker = RouteTracker::new(route);
    let detour = [(8.0, 11.0), (8.5, 9.0), (9.0, 7.0), (9.5, 5.0), (10.0, 3.0)];
    let flags: Vec<bool> = detour
        .iter()
        .map(|&(x, y)| tracker.update(&FloorPoint::new(0, x, y), accuracy_m).unwrap().off_route)
        .collect();
    // On the aisle and in the door: on the route; deep in the room: off it, and it stays so.
    assert!(!flags[0] && !flags[1] && flags[4], "{flags:?}");
    assert!(flags.windows(2).all(|f| f[0] <= f[1]), "{flags:?}");
    let again = tracker.reroute(site, None).unwrap().clone();
    assert_eq!(site.zone_of(again.states()[0] as usize), site.zone_index("room 2"));
    assert!(!tracker.update(&FloorPoint::new(0, 10.0, 3.0), accuracy_m).unwrap().off_route);
}

/// The uniffi surface: `Site.route`, `RouteTracker`, typed errors, from Rust.
#[test]
fn the_uniffi_surface_routes_and_tracks() {
    use waymark as api;
    let site = Arc::new(api::FfiSite::from_bytes(two_floors().to_json().into_bytes()).unwrap());
    let from = api::FfiFloorPoint { floor: 0, x: 4.9, y: 2.0 };
    let to = api::FfiDestination::Zone { name: "upstairs room 10".into() };
    let route = site.route(from, to.clone()).unwrap();
    let core = Route::plan(
        two_floors(),
        &FloorPoint::new(0, 4.9, 2.0),
        &Destination::Zone("upstairs room 10".into()),
    )
    .unwrap();
    assert_eq!(route.legs.len(), core.legs().len());
    assert!((route.length_m - core.length_m()).abs() < 1e-9);
    assert_eq!(route.legs.iter().filter(|l| l.floor_change).count(), 1);
    assert_eq!(route.legs[0].turn, None);
    assert_eq!(route.legs[1].turn, core.legs()[1].turn);
    let tracker = api::FfiRouteTracker::new(Arc::clone(&site), from, to).unwrap();
    assert_eq!(tracker.route(), route);
    let p = tracker.update_point(api::FfiFloorPoint { floor: 0, x: 4.9, y: 2.5 }, 1.0).unwrap();
    assert!(!p.off_route && (p.remaining_m - route.length_m).abs() < 1.0);
    assert!(matches!(
        tracker.update_point(api::FfiFloorPoint { floor: 9, x: 0.0, y: 0.0 }, 1.0),
        Err(api::FfiRouteError::OffGraph { .. })
    ));
    assert!(matches!(
        site.route(from, api::FfiDestination::Zone { name: "nope".into() }),
        Err(api::FfiRouteError::UnknownZone { .. })
    ));
    let rerouted = tracker.reroute().unwrap();
    assert_eq!(rerouted.end, route.end);
}
