use super::track::{OFF_ROUTE_ENTER_SIGMAS, OFF_ROUTE_EXIT_SIGMAS};
use super::*;
use crate::site::{BuildOptions, SiteBuilder, ZoneKind};
use std::f64::consts::PI;

/// An L: a corridor east along y = 0 (states 0-4, 3 m apart), then north from (12, 0) (states
/// 5-7), and a room state 8 at (0, 2) joined only to state 7 (a wall between it and state 0).
/// A second floor holds state 9 at (12, 0), joined to state 4 by a 6 m staircase.
fn l_site() -> Site {
    let mut b = SiteBuilder::new("L");
    let g = b.floor("G", 0.0);
    let up = b.floor("1", 4.0);
    let mut ids: Vec<u32> = (0..5).map(|k| b.state(g, Point2::new(3.0 * k as f64, 0.0), vec![])).collect();
    ids.extend((1..4).map(|k| b.state(g, Point2::new(12.0, 3.0 * k as f64), vec![])));
    for w in ids.windows(2) {
        b.edge(w[0], w[1], None);
    }
    let room = b.state(g, Point2::new(0.0, 2.0), vec![]);
    b.edge(ids[7], room, None);
    let upstairs = b.state(up, Point2::new(12.0, 0.0), vec![]);
    b.edge(ids[4], upstairs, Some(6.0));
    b.zone("room", ZoneKind::Room, vec![room]);
    b.zone("landing", ZoneKind::Stairs, vec![upstairs]);
    b.build(BuildOptions::default()).unwrap()
}

#[test]
fn turn_classes_follow_the_bands() {
    let class = |deg: f64| Turn::from_angle(deg * PI / 180.0);
    assert_eq!(class(0.0), Turn::Straight);
    assert_eq!(class(-10.9), Turn::Straight);
    assert_eq!(class(11.0), Turn::SlightLeft);
    assert_eq!(class(-30.0), Turn::SlightRight);
    assert_eq!(class(45.0), Turn::Left);
    assert_eq!(class(-90.0), Turn::Right);
    assert_eq!(class(135.0), Turn::SharpLeft);
    assert_eq!(class(-159.0), Turn::SharpRight);
    assert_eq!(class(160.0), Turn::UTurn);
    assert_eq!(class(-180.0), Turn::UTurn);
}

#[test]
fn collinear_edges_merge_and_corners_turn() {
    let site = l_site();
    let route = Route::plan(
        &site,
        &FloorPoint::new(0, 0.2, -0.3),
        &Destination::Point(FloorPoint::new(0, 12.0, 9.0)),
    )
    .unwrap();
    assert_eq!(route.states(), &[0, 1, 2, 3, 4, 5, 6, 7]);
    assert_eq!(route.legs().len(), 2, "{:?}", route.legs());
    let [east, north] = [&route.legs()[0], &route.legs()[1]];
    assert_eq!((east.distance_m, east.turn), (12.0, None));
    assert_eq!((north.distance_m, north.turn), (9.0, Some(Turn::Left)));
    assert!((north.turn_angle_rad.unwrap() - PI / 2.0).abs() < 1e-12);
    assert_eq!(route.length_m(), 21.0);
    assert!((route.start_snap_m() - 0.2f64.hypot(0.3)).abs() < 1e-12);
}

/// The room is 2 m from state 0 through the wall, 23 m on foot: the route goes round.
#[test]
fn a_route_goes_round_the_wall_to_a_zone() {
    let site = l_site();
    let route = Route::plan(&site, &FloorPoint::new(0, 0.0, 0.0), &Destination::Zone("room".into())).unwrap();
    assert_eq!(route.end().position(), Point2::new(0.0, 2.0));
    assert!((route.length_m() - (21.0 + 12.0f64.hypot(7.0))).abs() < 1e-9);
    let last = route.legs().last().unwrap();
    // Heading north, then west-south-west to the room: a sharp-ish left.
    assert_eq!(last.turn, Some(Turn::Left));
}

#[test]
fn floor_changes_are_their_own_leg() {
    let site = l_site();
    let route =
        Route::plan(&site, &FloorPoint::new(0, 0.0, 0.0), &Destination::Zone("landing".into())).unwrap();
    assert_eq!(route.legs().len(), 2);
    let stairs = &route.legs()[1];
    assert!(stairs.is_floor_change());
    assert_eq!((stairs.floor, stairs.to_floor, stairs.distance_m, stairs.turn), (0, 1, 6.0, None));
    assert_eq!(route.length_m(), 18.0);
}

/// A grid path that zig-zags along a diagonal stays within half a cell of one line: one leg.
#[test]
fn a_zig_zag_within_half_a_cell_is_one_leg() {
    let mut b = SiteBuilder::new("zig");
    let f = b.floor("G", 0.0);
    let points = [(0.0, 0.0), (1.0, 0.0), (2.0, 0.5), (3.0, 0.5), (4.0, 1.0), (5.0, 1.0)];
    let ids: Vec<u32> = points.iter().map(|&(x, y)| b.state(f, Point2::new(x, y), vec![])).collect();
    for w in ids.windows(2) {
        b.edge(w[0], w[1], None);
    }
    let site = b.build(BuildOptions::default()).unwrap();
    let route =
        Route::plan(&site, &FloorPoint::new(0, 0.0, 0.0), &Destination::Point(FloorPoint::new(0, 5.0, 1.0)))
            .unwrap();
    assert_eq!(route.legs().len(), 1, "{:?}", route.legs());
}

#[test]
fn errors_are_typed() {
    let site = l_site();
    let here = FloorPoint::new(0, 0.0, 0.0);
    assert_eq!(
        Route::plan(&site, &here, &Destination::Zone("kitchen".into())),
        Err(RouteError::UnknownZone("kitchen".into()))
    );
    assert!(matches!(
        Route::plan(&site, &FloorPoint::new(5, 0.0, 0.0), &Destination::Zone("room".into())),
        Err(RouteError::UnknownFloor { floor: 5, floors: 2 })
    ));
    assert!(matches!(
        Route::plan(&site, &FloorPoint::new(0, f64::NAN, 0.0), &Destination::Zone("room".into())),
        Err(RouteError::NotFinite(_))
    ));
    // 3 m is the spacing: a point 10 m from every state is off the graph, unless its accuracy
    // radius covers the gap.
    let far = FloorPoint::new(0, -10.0, 0.0);
    assert!(matches!(
        Route::plan(&site, &far, &Destination::Zone("room".into())),
        Err(RouteError::OffGraph { .. })
    ));
    assert!(Route::plan_from(&site, &far, 8.0, &Destination::Zone("room".into())).is_ok());
    // An island state with no edge.
    let mut b = SiteBuilder::new("islands");
    let f = b.floor("G", 0.0);
    let a = b.state(f, Point2::new(0.0, 0.0), vec![]);
    let c = b.state(f, Point2::new(3.0, 0.0), vec![]);
    b.state(f, Point2::new(6.0, 0.0), vec![]);
    b.edge(a, c, None);
    let islands = b.build(BuildOptions::default()).unwrap();
    assert!(matches!(
        Route::plan(
            &islands,
            &FloorPoint::new(0, 0.0, 0.0),
            &Destination::Point(FloorPoint::new(0, 6.0, 0.0))
        ),
        Err(RouteError::Unreachable { from: 0, .. })
    ));
}

#[test]
fn already_there_is_an_empty_route() {
    let site = l_site();
    let route = Route::plan(&site, &FloorPoint::new(0, 0.1, 2.0), &Destination::Zone("room".into())).unwrap();
    assert!(route.legs().is_empty());
    assert_eq!(route.length_m(), 0.0);
    let mut tracker = RouteTracker::new(route);
    let progress = tracker.update(&FloorPoint::new(0, 0.0, 2.0), 1.0).unwrap();
    assert!(progress.arrived && !progress.off_route);
    assert_eq!((progress.remaining_m, progress.leg), (0.0, 0));
}

#[test]
fn the_tracker_follows_turns_and_leaves_with_hysteresis() {
    let site = l_site();
    let route =
        Route::plan(&site, &FloorPoint::new(0, 0.0, 0.0), &Destination::Point(FloorPoint::new(0, 12.0, 9.0)))
            .unwrap();
    let mut t = RouteTracker::new(route);
    let at = |t: &mut RouteTracker, x: f64, y: f64, r: f64| t.update(&FloorPoint::new(0, x, y), r).unwrap();
    let p = at(&mut t, 6.0, 0.5, 2.0);
    assert_eq!((p.along_m, p.remaining_m, p.leg, p.off_route, p.arrived), (6.0, 15.0, 0, false, false));
    // At the corner, the next leg is the one to take.
    assert_eq!(at(&mut t, 12.0, 0.0, 2.0).leg, 1);
    // Half-cell 1.5 m, σ = 2 m / 1.5096: enter beyond 1.5 + 2.576 σ = 4.91 m, exit within
    // 1.5 + σ = 2.82 m.
    let sigma = 2.0 * SIGMA_PER_ACCURACY_68;
    let enter = 1.5 + OFF_ROUTE_ENTER_SIGMAS * sigma;
    let exit = 1.5 + OFF_ROUTE_EXIT_SIGMAS * sigma;
    assert!((enter - 4.913).abs() < 1e-3 && (exit - 2.825).abs() < 1e-3);
    assert!(!at(&mut t, 12.0 + enter - 0.01, 4.0, 2.0).off_route);
    assert!(at(&mut t, 12.0 + enter + 0.01, 4.0, 2.0).off_route);
    // In the band, it stays off; within the exit threshold it is back on.
    assert!(at(&mut t, 12.0 + exit + 0.01, 4.0, 2.0).off_route);
    assert!(at(&mut t, 12.0 + enter - 0.01, 4.0, 2.0).off_route);
    assert!(!at(&mut t, 12.0 + exit - 0.01, 4.0, 2.0).off_route);
    // A vaguer position needs to be further out.
    assert!(!at(&mut t, 12.0 + enter + 0.01, 4.0, 3.0).off_route);
    // The other floor is not on this route: off it, whatever the accuracy.
    let upstairs = t.update(&FloorPoint::new(1, 12.0, 4.0), 50.0).unwrap();
    assert!(upstairs.off_route && upstairs.distance_from_route_m.is_infinite());
    assert!(!at(&mut t, 12.0, 5.0, 2.0).arrived, "not within reach of the end yet");
    let there = at(&mut t, 12.0, 8.5, 1.0);
    assert!(there.arrived && there.leg == 1 && (there.remaining_m - 0.5).abs() < 1e-12);
    // Bad input changes nothing.
    assert!(t.update(&FloorPoint::new(0, f64::INFINITY, 0.0), 1.0).is_err());
    assert!(t.update(&FloorPoint::new(0, 0.0, 0.0), -1.0).is_err());
    assert!(matches!(t.update(&FloorPoint::new(7, 0.0, 0.0), 1.0), Err(RouteError::UnknownFloor { .. })));
    assert_eq!(at(&mut t, 12.0, 8.5, 1.0), there);
}

#[test]
fn reroute_starts_from_the_latest_position() {
    let site = l_site();
    let route =
        Route::plan(&site, &FloorPoint::new(0, 0.0, 0.0), &Destination::Zone("landing".into())).unwrap();
    let mut t = RouteTracker::new(route);
    assert_eq!(t.reroute(&site, None).unwrap_err(), RouteError::NoPosition);
    assert!(t.update(&FloorPoint::new(0, 12.0, 6.0), 1.0).unwrap().off_route);
    let again = t.reroute(&site, None).unwrap();
    assert_eq!(again.states(), &[6, 5, 4, 9]);
    assert_eq!(again.destination(), &Destination::Zone("landing".into()));
    let p = t.update(&FloorPoint::new(0, 12.0, 6.0), 1.0).unwrap();
    assert!(!p.off_route && p.along_m == 0.0 && p.remaining_m == 12.0);
    // A failed reroute keeps the route.
    assert!(t.reroute(&site, Some((FloorPoint::new(0, 100.0, 0.0), 0.0))).is_err());
    assert_eq!(t.route().states(), &[6, 5, 4, 9]);
}
