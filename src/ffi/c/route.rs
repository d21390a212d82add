//! The C API's routes (docs/routes.md): a route from a point or the engine's latest position
//! to a point or a zone, read leg by leg, and followed as positions arrive. A
//! `waymark_route` holds its own reference to the site, so it outlives the engine it came
//! from.

use super::{boundary, fail, string_arg, waymark_engine, waymark_result, with_handle, write};
use crate::ffi::delivery::lock;
use ::waymark_engine::route::{Destination, FloorPoint, Route, RouteError, RouteTracker, Turn};
use ::waymark_engine::site::Site;
use std::ffi::c_char;
use std::sync::{Arc, Mutex};

/// A route and its progress. Opaque; create with `waymark_engine_route_to_point` or
/// `waymark_engine_route_to_zone`, free with `waymark_route_free`. Thread-safe.
pub struct waymark_route {
    site: Arc<Site>,
    tracker: Mutex<RouteTracker>,
}

/// A point of the site: a floor index and a position in the site's metric frame, m.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct waymark_floor_point {
    /// Floor index in the site file.
    pub floor: u32,
    /// x, m.
    pub x: f64,
    /// y, m.
    pub y: f64,
}

/// Which way to turn onto a leg, by the angle between the legs: straight under 11°, slight
/// 11-45°, left / right 45-135°, sharp 135-160°, u-turn from 160°.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum waymark_turn {
    /// No turn is given: the first leg, a floor change, and the leg after one.
    None = 0,
    /// Under 11° either way.
    Straight = 1,
    /// 11-45° to the left.
    SlightLeft = 2,
    /// 11-45° to the right.
    SlightRight = 3,
    /// 45-135° to the left.
    Left = 4,
    /// 45-135° to the right.
    Right = 5,
    /// 135-160° to the left.
    SharpLeft = 6,
    /// 135-160° to the right.
    SharpRight = 7,
    /// 160° or more: back the way the user came.
    UTurn = 8,
}

/// A route as a whole (`waymark_route_get_info`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct waymark_route_info {
    /// Walking length, m: the sum of the legs'.
    pub length_m: f64,
    /// Number of legs; 0 when the start is already at the destination.
    pub leg_count: usize,
    /// Where it starts: the walkable place nearest the origin.
    pub start: waymark_floor_point,
    /// Where it ends.
    pub end: waymark_floor_point,
    /// Straight-line distance from the origin to `start`, m (not part of the route).
    pub start_snap_m: f64,
    /// Straight-line distance from a destination point to `end`, m; 0 for a zone.
    pub end_snap_m: f64,
}

/// One leg (`waymark_route_get_leg`): a straight walk on one floor, or a change of floor.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct waymark_route_leg {
    /// Where it starts (on `start.floor`).
    pub start: waymark_floor_point,
    /// Where it ends (on `end.floor`; another floor for a floor change).
    pub end: waymark_floor_point,
    /// Whether it changes floor.
    pub floor_change: bool,
    /// Walking distance, m.
    pub distance_m: f64,
    /// The turn onto it.
    pub turn: waymark_turn,
    /// The signed angle of that turn, degrees, positive to the left; NaN with
    /// `WAYMARK_TURN_NONE`.
    pub turn_deg: f64,
}

/// Where a position puts the user on the route (`waymark_route_update`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct waymark_route_progress {
    /// Walking distance from the route's start to the user's point on it, m.
    pub along_m: f64,
    /// Walking distance left, m.
    pub remaining_m: f64,
    /// Index of the leg the user is on (at a leg's end, the next one).
    pub leg: usize,
    /// Distance from the position to the route on its floor, m; infinite when the route does
    /// not visit that floor.
    pub distance_from_route_m: f64,
    /// The user has left the route: call `waymark_route_reroute`.
    pub off_route: bool,
    /// The user has reached the end; it stays set until a reroute.
    pub arrived: bool,
}

fn route_error(e: &RouteError) -> waymark_result {
    let code = match e {
        RouteError::UnknownZone(_) => waymark_result::UnknownZone,
        RouteError::UnknownFloor { .. } | RouteError::NotFinite(_) | RouteError::OffGraph { .. } => {
            waymark_result::OffGraph
        }
        RouteError::Unreachable { .. } => waymark_result::Unreachable,
        RouteError::NoPosition => waymark_result::NoPosition,
    };
    fail(code, e.to_string())
}

fn point(p: &waymark_floor_point) -> FloorPoint {
    FloorPoint::new(p.floor as usize, p.x, p.y)
}

fn floor_point(p: &FloorPoint) -> waymark_floor_point {
    waymark_floor_point { floor: p.floor as u32, x: p.x, y: p.y }
}

/// Plans the route from `from` (NULL: the engine's latest position) to `to` and writes the new
/// handle to `out`.
fn plan(
    engine: *const waymark_engine,
    from: *const waymark_floor_point,
    to: impl FnOnce() -> Result<Destination, waymark_result>,
    out: *mut *mut waymark_route,
) -> waymark_result {
    if out.is_null() {
        return fail(waymark_result::NullParameter, "out must not be NULL");
    }
    with_handle(engine, |handle| {
        let to = match to() {
            Ok(to) => to,
            Err(code) => return code,
        };
        // SAFETY: a non-NULL `from` points to one initialised waymark_floor_point (the header's
        // contract).
        let (from, accuracy_m) = match unsafe { from.as_ref() } {
            Some(p) => (point(p), 0.0),
            None => match handle.read(|e| e.position().cloned()) {
                Ok(Some(p)) => (FloorPoint::new(p.floor, p.x, p.y), p.accuracy_m),
                Ok(None) => return fail(waymark_result::NoPosition, "no epoch has run yet"),
                Err(e) => return super::fail_with(&e),
            },
        };
        let site = handle.site();
        match Route::plan_from(&site, &from, accuracy_m, &to) {
            Ok(route) => {
                let tracker = Mutex::new(RouteTracker::new(route));
                write(out, Box::into_raw(Box::new(waymark_route { site, tracker })));
                waymark_result::Ok
            }
            Err(e) => route_error(&e),
        }
    })
}

/// The shortest walkable route on the engine's site from `from` (NULL: the engine's latest
/// position, which snaps within the site's spacing plus its accuracy; a point snaps within
/// the spacing) to the point `to`, over the walkable graph and its stairs and lifts. On
/// success `*out` holds the route; free it with `waymark_route_free`. Fails with
/// `OFF_GRAPH` (an unknown floor, a NaN or infinite coordinate, no walkable place near a
/// point), `UNREACHABLE`, or `NO_POSITION` (NULL `from` before the first epoch).
#[no_mangle]
pub extern "C" fn waymark_engine_route_to_point(
    engine: *const waymark_engine,
    from: *const waymark_floor_point,
    to: *const waymark_floor_point,
    out: *mut *mut waymark_route,
) -> waymark_result {
    let to = || {
        // SAFETY: a non-NULL `to` points to one initialised waymark_floor_point (the header's
        // contract).
        match unsafe { to.as_ref() } {
            Some(p) => Ok(Destination::Point(point(p))),
            None => Err(fail(waymark_result::NullParameter, "to must not be NULL")),
        }
    };
    plan(engine, from, to, out)
}

/// As `waymark_engine_route_to_point`, to the zone named `zone` (NUL-terminated UTF-8): the
/// route ends at the zone's walkable place nearest on foot. Also fails with `UNKNOWN_ZONE`.
#[no_mangle]
pub extern "C" fn waymark_engine_route_to_zone(
    engine: *const waymark_engine,
    from: *const waymark_floor_point,
    zone: *const c_char,
    out: *mut *mut waymark_route,
) -> waymark_result {
    plan(engine, from, || string_arg(zone, "zone").map(Destination::Zone), out)
}

/// Frees a route. NULL is ignored.
#[no_mangle]
pub extern "C" fn waymark_route_free(route: *mut waymark_route) {
    let _ = boundary(|| {
        if !route.is_null() {
            // SAFETY: `route` came from `waymark_engine_route_to_*` (Box::into_raw) and is
            // freed once, as the header requires.
            drop(unsafe { Box::from_raw(route) });
        }
        waymark_result::Ok
    });
}

/// Borrows `route`, or fails with `NullParameter`.
fn with_route(
    route: *const waymark_route,
    body: impl FnOnce(&waymark_route) -> waymark_result,
) -> waymark_result {
    boundary(|| {
        // SAFETY: a non-NULL `route` is a live handle from `waymark_engine_route_to_*` (the
        // header's contract); `waymark_route` is Sync, so a shared reference from any thread
        // is fine.
        match unsafe { route.as_ref() } {
            Some(route) => body(route),
            None => fail(waymark_result::NullParameter, "route must not be NULL"),
        }
    })
}

/// The route as a whole into `*out`.
#[no_mangle]
pub extern "C" fn waymark_route_get_info(
    route: *const waymark_route,
    out: *mut waymark_route_info,
) -> waymark_result {
    if out.is_null() {
        return fail(waymark_result::NullParameter, "out must not be NULL");
    }
    with_route(route, |route| {
        let tracker = lock(&route.tracker);
        let r = tracker.route();
        write(
            out,
            waymark_route_info {
                length_m: r.length_m(),
                leg_count: r.legs().len(),
                start: floor_point(&r.start()),
                end: floor_point(&r.end()),
                start_snap_m: r.start_snap_m(),
                end_snap_m: r.end_snap_m(),
            },
        );
        waymark_result::Ok
    })
}

/// Leg `index` (from 0 to `leg_count` - 1 of `waymark_route_get_info`) into `*out`; an index out
/// of range returns `INPUT_REJECTED`.
#[no_mangle]
pub extern "C" fn waymark_route_get_leg(
    route: *const waymark_route,
    index: usize,
    out: *mut waymark_route_leg,
) -> waymark_result {
    if out.is_null() {
        return fail(waymark_result::NullParameter, "out must not be NULL");
    }
    with_route(route, |route| {
        let tracker = lock(&route.tracker);
        let r = tracker.route();
        let Some(leg) = r.legs().get(index) else {
            return fail(
                waymark_result::InputRejected,
                format!("leg {index} does not exist ({} legs)", r.legs().len()),
            );
        };
        let turn = match leg.turn {
            None => waymark_turn::None,
            Some(Turn::Straight) => waymark_turn::Straight,
            Some(Turn::SlightLeft) => waymark_turn::SlightLeft,
            Some(Turn::SlightRight) => waymark_turn::SlightRight,
            Some(Turn::Left) => waymark_turn::Left,
            Some(Turn::Right) => waymark_turn::Right,
            Some(Turn::SharpLeft) => waymark_turn::SharpLeft,
            Some(Turn::SharpRight) => waymark_turn::SharpRight,
            Some(Turn::UTurn) => waymark_turn::UTurn,
        };
        write(
            out,
            waymark_route_leg {
                start: floor_point(&r.points()[leg.first]),
                end: floor_point(&r.points()[leg.last]),
                floor_change: leg.is_floor_change(),
                distance_m: leg.distance_m,
                turn,
                turn_deg: leg.turn_angle_rad.map_or(f64::NAN, f64::to_degrees),
            },
        );
        waymark_result::Ok
    })
}

/// Takes a position (`accuracy_m`: the radius of its 68% circle, as in `waymark_position`) and
/// writes where it puts the user on the route into `*out` (may be NULL). A NaN or infinite
/// value, a negative accuracy or an unknown floor returns `OFF_GRAPH` and changes nothing.
#[no_mangle]
pub extern "C" fn waymark_route_update(
    route: *mut waymark_route,
    position: *const waymark_floor_point,
    accuracy_m: f64,
    out: *mut waymark_route_progress,
) -> waymark_result {
    with_route(route, |route| {
        // SAFETY: a non-NULL `position` points to one initialised waymark_floor_point (the
        // header's contract).
        let Some(position) = (unsafe { position.as_ref() }) else {
            return fail(waymark_result::NullParameter, "position must not be NULL");
        };
        match lock(&route.tracker).update(&point(position), accuracy_m) {
            Ok(p) => {
                write(
                    out,
                    waymark_route_progress {
                        along_m: p.along_m,
                        remaining_m: p.remaining_m,
                        leg: p.leg,
                        distance_from_route_m: p.distance_from_route_m,
                        off_route: p.off_route,
                        arrived: p.arrived,
                    },
                );
                waymark_result::Ok
            }
            Err(e) => route_error(&e),
        }
    })
}

/// Plans a new route to the same destination from `from` (NULL: the latest position given to
/// `waymark_route_update`, with its accuracy) and follows it from its start; read it again
/// with `waymark_route_get_info` and `waymark_route_get_leg`. Fails as the constructors do, or with
/// `NO_POSITION` for NULL `from` before the first update; the route is then unchanged.
#[no_mangle]
pub extern "C" fn waymark_route_reroute(
    route: *mut waymark_route,
    from: *const waymark_floor_point,
) -> waymark_result {
    with_route(route, |route| {
        // SAFETY: a non-NULL `from` points to one initialised waymark_floor_point (the header's
        // contract).
        let from = unsafe { from.as_ref() }.map(|p| (point(p), 0.0));
        match lock(&route.tracker).reroute(&route.site, from) {
            Ok(_) => waymark_result::Ok,
            Err(e) => route_error(&e),
        }
    })
}

/// The point `point` of the route's site (a route leg's start or end, say) as a WGS84
/// latitude and longitude, degrees, into `*latitude_deg` and `*longitude_deg` (neither may be
/// NULL), as `waymark_engine_to_lat_lon` converts it: the route holds its site, so this works
/// after the engine is freed.
#[no_mangle]
pub extern "C" fn waymark_route_to_lat_lon(
    route: *const waymark_route,
    point: *const waymark_floor_point,
    latitude_deg: *mut f64,
    longitude_deg: *mut f64,
) -> waymark_result {
    with_route(route, |route| {
        // SAFETY: a non-NULL `point` points to one initialised waymark_floor_point (the
        // header's contract).
        let Some(p) = (unsafe { point.as_ref() }) else {
            return fail(waymark_result::NullParameter, "point must not be NULL");
        };
        super::geo::site_to_lat_lon(&route.site, p.floor, p.x, p.y, latitude_deg, longitude_deg)
    })
}
