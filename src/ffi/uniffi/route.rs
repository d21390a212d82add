//! Routes for Kotlin and Swift: `Site.route`, `PositioningEngine.routeTo` and `navigateTo`,
//! and the `RouteTracker` that follows positions along a route (docs/routes.md). A change
//! here is a possible breaking change for apps (CHANGELOG, "Breaking changes").

use super::{FfiSite, PositionEstimate, PositioningEngine};
use crate::ffi::delivery::lock;
use std::sync::{Arc, Mutex};
use waymark_engine::route::{self as core, RouteTracker};
use waymark_engine::site::Site;

/// A point of the site: a floor index and a position in the site's metric frame, m.
#[derive(Clone, Copy, Debug, PartialEq, uniffi::Record)]
#[uniffi(name = "FloorPoint")]
pub struct FfiFloorPoint {
    /// Floor index in the site file.
    pub floor: u32,
    /// x in the site's metric frame, m.
    pub x: f64,
    /// y in the site's metric frame, m.
    pub y: f64,
}

/// Where a route goes.
#[derive(Clone, Debug, PartialEq, uniffi::Enum)]
#[uniffi(name = "Destination")]
pub enum FfiDestination {
    /// A point: the route ends at the walkable place nearest it on its floor.
    Point {
        /// The point.
        point: FfiFloorPoint,
    },
    /// A zone of the site (`Site.zoneNames`): the route ends at its nearest place on foot.
    Zone {
        /// The zone's name.
        name: String,
    },
}

pub use waymark_engine::route::Turn;

// The core's type, exported as it is (a uniffi remote type): its variants are what an app
// sees. The doc comments here are the ones Kotlin and Swift get.

/// Which way to turn onto a leg, by the angle between the legs: straight under 11°, slight
/// 11-45°, left / right 45-135°, sharp 135-160°, u-turn from 160°.
#[uniffi::remote(Enum)]
enum Turn {
    /// Under 11° either way.
    Straight,
    /// 11-45° to the left.
    SlightLeft,
    /// 11-45° to the right.
    SlightRight,
    /// 45-135° to the left.
    Left,
    /// 45-135° to the right.
    Right,
    /// 135-160° to the left.
    SharpLeft,
    /// 135-160° to the right.
    SharpRight,
    /// 160° or more: back the way the user came.
    UTurn,
}

/// One leg of a route: a straight walk on one floor, or a change of floor (stairs, a lift).
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
pub struct RouteLeg {
    /// The floor it starts on.
    pub floor: u32,
    /// The floor it ends on: `floor` for a walk.
    pub to_floor: u32,
    /// Whether it changes floor.
    pub floor_change: bool,
    /// Walking distance, m.
    pub distance_m: f64,
    /// The turn onto it; `null` / `nil` for the first leg, a floor change, and the leg after
    /// one.
    pub turn: Option<Turn>,
    /// The signed angle of that turn, degrees, positive to the left.
    pub turn_deg: Option<f64>,
    /// The places it passes, first to last, for drawing (each on its own floor).
    pub points: Vec<FfiFloorPoint>,
}

/// A route over the site's walkable graph.
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
#[uniffi(name = "Route")]
pub struct FfiRoute {
    /// Its legs in walking order; empty when the start is already at the destination.
    pub legs: Vec<RouteLeg>,
    /// Walking length, m: the sum of the legs'.
    pub length_m: f64,
    /// Where it starts: the walkable place nearest the origin.
    pub start: FfiFloorPoint,
    /// Where it ends.
    pub end: FfiFloorPoint,
    /// Straight-line distance from the origin to `start`, m (not part of the route).
    pub start_snap_m: f64,
    /// Straight-line distance from a destination point to `end`, m; 0 for a zone.
    pub end_snap_m: f64,
}

/// Where a position puts the user on the route.
#[derive(Clone, Copy, Debug, PartialEq, uniffi::Record)]
pub struct RouteProgress {
    /// Walking distance from the route's start to the user's point on it, m.
    pub along_m: f64,
    /// Walking distance left, m.
    pub remaining_m: f64,
    /// Index of the leg the user is on (at a leg's end, the next one).
    pub leg: u32,
    /// Distance from the position to the route on its floor, m; infinite when the route does
    /// not visit that floor.
    pub distance_from_route_m: f64,
    /// The user has left the route: call `reroute`. Set when the position is well beyond the
    /// route for its accuracy, cleared when it is back near it (docs/routes.md).
    pub off_route: bool,
    /// The user has reached the end; it stays set until a reroute.
    pub arrived: bool,
}

/// Why no route was made, or a position was not taken.
#[derive(Clone, Debug, PartialEq, thiserror::Error, uniffi::Error)]
#[uniffi(name = "RouteError")]
pub enum FfiRouteError {
    /// The destination names a zone the site does not have.
    #[error("unknown zone: {name}")]
    UnknownZone {
        /// The name asked for.
        name: String,
    },
    /// A point is not on the walkable graph: its floor does not exist, a coordinate or the
    /// accuracy is NaN or infinite, or no walkable place is near enough (docs/routes.md).
    #[error("off the walkable graph: {reason}")]
    OffGraph {
        /// Which and why.
        reason: String,
    },
    /// No walkable path joins the start to the destination (no stairs or lift between their
    /// floors, say).
    #[error("unreachable: {reason}")]
    Unreachable {
        /// Between what.
        reason: String,
    },
    /// There is no position to start from yet (`routeTo` before the first epoch, `reroute`
    /// before the first `update`).
    #[error("no position yet")]
    NoPosition,
    /// A bug in Waymark; nothing changed.
    #[error("internal error: {reason}")]
    Internal {
        /// What happened.
        reason: String,
    },
}

impl From<core::RouteError> for FfiRouteError {
    fn from(e: core::RouteError) -> Self {
        match e {
            core::RouteError::UnknownZone(name) => FfiRouteError::UnknownZone { name },
            e @ (core::RouteError::UnknownFloor { .. }
            | core::RouteError::NotFinite(_)
            | core::RouteError::OffGraph { .. }) => FfiRouteError::OffGraph { reason: e.to_string() },
            e @ core::RouteError::Unreachable { .. } => FfiRouteError::Unreachable { reason: e.to_string() },
            core::RouteError::NoPosition => FfiRouteError::NoPosition,
        }
    }
}

impl From<uniffi::UnexpectedUniFFICallbackError> for FfiRouteError {
    fn from(e: uniffi::UnexpectedUniFFICallbackError) -> Self {
        FfiRouteError::Internal { reason: format!("foreign callback failed: {}", e.reason) }
    }
}

/// Runs `f`, turning a panic into `Internal` (`ffi::panic`).
fn guarded<T>(f: impl FnOnce() -> Result<T, FfiRouteError>) -> Result<T, FfiRouteError> {
    crate::ffi::panic::or_internal(f, || FfiRouteError::Internal {
        reason: "Waymark panicked; nothing changed".into(),
    })
}

fn point(p: &FfiFloorPoint) -> core::FloorPoint {
    core::FloorPoint::new(p.floor as usize, p.x, p.y)
}

fn floor_point(p: &core::FloorPoint) -> FfiFloorPoint {
    FfiFloorPoint { floor: p.floor as u32, x: p.x, y: p.y }
}

fn destination(d: &FfiDestination) -> core::Destination {
    match d {
        FfiDestination::Point { point: p } => core::Destination::Point(point(p)),
        FfiDestination::Zone { name } => core::Destination::Zone(name.clone()),
    }
}

fn route(r: &core::Route) -> FfiRoute {
    let legs = r
        .legs()
        .iter()
        .map(|l| RouteLeg {
            floor: l.floor as u32,
            to_floor: l.to_floor as u32,
            floor_change: l.is_floor_change(),
            distance_m: l.distance_m,
            turn: l.turn,
            turn_deg: l.turn_angle_rad.map(f64::to_degrees),
            points: r.points()[l.first..=l.last].iter().map(floor_point).collect(),
        })
        .collect();
    FfiRoute {
        legs,
        length_m: r.length_m(),
        start: floor_point(&r.start()),
        end: floor_point(&r.end()),
        start_snap_m: r.start_snap_m(),
        end_snap_m: r.end_snap_m(),
    }
}

fn progress(p: &core::Progress) -> RouteProgress {
    RouteProgress {
        along_m: p.along_m,
        remaining_m: p.remaining_m,
        leg: u32::try_from(p.leg).unwrap_or(u32::MAX),
        distance_from_route_m: p.distance_from_route_m,
        off_route: p.off_route,
        arrived: p.arrived,
    }
}

#[uniffi::export(name = "Site")]
impl FfiSite {
    /// The shortest walkable route from `from` to `destination`, over the site's walkable
    /// graph, floor changes included where the site has stairs or lifts. `from` snaps to the
    /// nearest walkable place on its floor within the site's spacing. Throws `UnknownZone`,
    /// `OffGraph` or `Unreachable`.
    pub fn route(&self, from: FfiFloorPoint, destination: FfiDestination) -> Result<FfiRoute, FfiRouteError> {
        guarded(|| {
            Ok(route(&core::Route::plan(&self.inner, &point(&from), &self::destination(&destination))?))
        })
    }
}

#[uniffi::export]
impl PositioningEngine {
    /// The route from the latest position to `destination` (the position snaps within the
    /// site's spacing plus its accuracy). Throws `NoPosition` before the first epoch, else as
    /// `Site.route`.
    pub fn route_to(&self, destination: FfiDestination) -> Result<FfiRoute, FfiRouteError> {
        guarded(|| {
            let tracker = self.tracker_to(&destination)?;
            Ok(route(tracker.route()))
        })
    }

    /// A tracker on the route from the latest position to `destination`, to follow it as
    /// positions arrive (`RouteTracker.update`). Throws as `routeTo`.
    pub fn navigate_to(&self, destination: FfiDestination) -> Result<Arc<FfiRouteTracker>, FfiRouteError> {
        guarded(|| {
            let tracker = self.tracker_to(&destination)?;
            Ok(Arc::new(FfiRouteTracker { site: self.handle.site(), inner: Mutex::new(tracker) }))
        })
    }
}

impl PositioningEngine {
    fn tracker_to(&self, to: &FfiDestination) -> Result<RouteTracker, FfiRouteError> {
        let position = self
            .handle
            .read(|e| e.position().cloned())
            .map_err(|e| FfiRouteError::Internal { reason: e.to_string() })?
            .ok_or(FfiRouteError::NoPosition)?;
        let from = core::FloorPoint::new(position.floor, position.x, position.y);
        let route =
            core::Route::plan_from(&self.handle.site(), &from, position.accuracy_m, &destination(to))?;
        let mut tracker = RouteTracker::new(route);
        tracker.update(&from, position.accuracy_m)?;
        Ok(tracker)
    }
}

/// Follows a route as positions arrive: distance remaining, the current leg, arrival, and
/// whether the user left the route (then call `reroute`). Thread-safe.
#[derive(uniffi::Object)]
#[uniffi(name = "RouteTracker")]
pub struct FfiRouteTracker {
    site: Arc<Site>,
    inner: Mutex<RouteTracker>,
}

#[uniffi::export(name = "RouteTracker")]
impl FfiRouteTracker {
    /// A tracker on the route from `from` to `destination` on `site`; throws as `Site.route`.
    #[uniffi::constructor]
    pub fn new(
        site: Arc<FfiSite>,
        from: FfiFloorPoint,
        destination: FfiDestination,
    ) -> Result<Arc<Self>, FfiRouteError> {
        guarded(|| {
            let route = core::Route::plan(&site.inner, &point(&from), &self::destination(&destination))?;
            Ok(Arc::new(Self { site: Arc::clone(&site.inner), inner: Mutex::new(RouteTracker::new(route)) }))
        })
    }

    /// The route followed.
    pub fn route(&self) -> FfiRoute {
        route(lock(&self.inner).route())
    }

    /// Takes a position from the engine and says where it puts the user on the route.
    /// Throws `OffGraph`, changing nothing, for a NaN or infinite value or an unknown floor.
    pub fn update(&self, position: PositionEstimate) -> Result<RouteProgress, FfiRouteError> {
        let at = FfiFloorPoint { floor: position.floor, x: position.x, y: position.y };
        self.update_point(at, position.accuracy_m)
    }

    /// As `update`, from a position given as a point and the radius of its 68% circle, m.
    pub fn update_point(
        &self,
        point: FfiFloorPoint,
        accuracy_m: f64,
    ) -> Result<RouteProgress, FfiRouteError> {
        guarded(|| Ok(progress(&lock(&self.inner).update(&self::point(&point), accuracy_m)?)))
    }

    /// Plans a new route to the same destination from the latest position given to
    /// `update`, and follows it from its start. Throws `NoPosition` before the first
    /// update, else as `Site.route`; on an error the tracker keeps its route.
    pub fn reroute(&self) -> Result<FfiRoute, FfiRouteError> {
        guarded(|| Ok(route(lock(&self.inner).reroute(&self.site, None)?)))
    }
}
