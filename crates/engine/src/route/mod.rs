//! Wayfinding on the site's walkable graph: the shortest route from a point (or the engine's
//! position) to a point or a zone, as legs with a distance and a turn, and a tracker that
//! follows positions along it (distance remaining, current leg, arrival, off-route).
//!
//! The graph is the HMM's: its states and their walkable edges, floor changes included where
//! the site file joins two floors (stairs, lifts). A site file keeps no wall geometry; its
//! edges are where a walker can go, so a route that follows them crosses no wall the graph
//! respects (docs/routes.md#walls).

mod legs;
mod search;
mod track;

pub use legs::{Leg, Turn};
pub use track::{Progress, RouteTracker, SIGMA_PER_ACCURACY_68};

use crate::site::Site;
use nalgebra::Point2;

/// A point of the site: a floor and a position in its metric frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FloorPoint {
    /// Index into [`Site::floors`].
    pub floor: usize,
    /// x in the site's metric frame, m.
    pub x: f64,
    /// y in the site's metric frame, m.
    pub y: f64,
}

impl FloorPoint {
    /// The point on `floor` at (`x`, `y`).
    pub fn new(floor: usize, x: f64, y: f64) -> Self {
        Self { floor, x, y }
    }

    /// Its position on the floor.
    pub fn position(&self) -> Point2<f64> {
        Point2::new(self.x, self.y)
    }

    fn of_state(site: &Site, state: u32) -> Self {
        let s = &site.states()[state as usize];
        Self { floor: s.floor, x: s.position.x, y: s.position.y }
    }
}

/// Where a route goes.
#[derive(Clone, Debug, PartialEq)]
pub enum Destination {
    /// A point: the route ends at the walkable state nearest it on its floor.
    Point(FloorPoint),
    /// A zone by name: the route ends at the zone's state nearest on foot.
    Zone(String),
}

/// Why no route was made.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum RouteError {
    /// The destination names a zone the site does not have.
    #[error("the site has no zone called {0:?}")]
    UnknownZone(String),
    /// A point is on a floor the site does not have.
    #[error("floor {floor} does not exist (the site has {floors} floors)")]
    UnknownFloor {
        /// The floor asked for.
        floor: usize,
        /// How many floors the site has.
        floors: usize,
    },
    /// A coordinate or accuracy is NaN or infinite (or an accuracy is negative).
    #[error("{0} is not a finite number")]
    NotFinite(&'static str),
    /// No walkable state lies within the snapping distance of a point on its floor.
    #[error(
        "({x}, {y}) on floor {floor} is off the walkable graph: the nearest state is {nearest_m} m away, more than {tolerance_m} m"
    )]
    OffGraph {
        /// The point's floor.
        floor: usize,
        /// Its x, m.
        x: f64,
        /// Its y, m.
        y: f64,
        /// Distance to the nearest state on the floor, m (infinite on a floor without states).
        nearest_m: f64,
        /// How far a point may be from the graph, m (see `snap_tolerance_m`).
        tolerance_m: f64,
    },
    /// No walkable path joins the start to the destination.
    #[error("no walkable path from state {from} to {to}")]
    Unreachable {
        /// Index of the start's state.
        from: u32,
        /// The destination, as text.
        to: String,
    },
    /// A reroute was asked before the tracker had a position to start from.
    #[error("no position to reroute from")]
    NoPosition,
}

/// How far from the nearest walkable state on its floor a point may be, m: the site's spacing
/// (a point more than one cell ([`Site::spacing_m`]) from every state is outside the surveyed
/// area), plus the point's 68% accuracy radius when it is a position estimate, whose error
/// may carry it that much further (docs/routes.md#snapping).
pub(crate) fn snap_tolerance_m(site: &Site, accuracy_m: f64) -> f64 {
    site.spacing_m() + accuracy_m
}

/// The walkable state nearest `point` on its floor, with its distance, within
/// [`snap_tolerance_m`] for a point with `accuracy_m` (0 for a free point).
pub(crate) fn snap(site: &Site, point: &FloorPoint, accuracy_m: f64) -> Result<(u32, f64), RouteError> {
    if point.floor >= site.floors().len() {
        return Err(RouteError::UnknownFloor { floor: point.floor, floors: site.floors().len() });
    }
    if !(point.x.is_finite() && point.y.is_finite()) {
        return Err(RouteError::NotFinite("a point's coordinate"));
    }
    if !(accuracy_m.is_finite() && accuracy_m >= 0.0) {
        return Err(RouteError::NotFinite("the accuracy"));
    }
    let p = point.position();
    let nearest = site
        .states()
        .iter()
        .enumerate()
        .filter(|(_, s)| s.floor == point.floor)
        .map(|(i, s)| (i as u32, nalgebra::distance(&s.position, &p)))
        .min_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    let tolerance_m = snap_tolerance_m(site, accuracy_m);
    match nearest {
        Some((i, d)) if d <= tolerance_m => Ok((i, d)),
        other => Err(RouteError::OffGraph {
            floor: point.floor,
            x: point.x,
            y: point.y,
            nearest_m: other.map_or(f64::INFINITY, |(_, d)| d),
            tolerance_m,
        }),
    }
}

/// A route: the states it walks through and the legs they make.
#[derive(Clone, Debug, PartialEq)]
pub struct Route {
    /// The point it was asked from.
    origin: FloorPoint,
    destination: Destination,
    /// States walked through, first the start's, last the destination's.
    path: Vec<u32>,
    /// Walking distance from the start to each state of `path`, m.
    along: Vec<f64>,
    /// Each state of `path` as a point.
    points: Vec<FloorPoint>,
    /// How many floors the site has.
    floors: usize,
    legs: Vec<Leg>,
    start_snap_m: f64,
    end_snap_m: f64,
    /// The site's cell half-width, m: how far from its line a leg's states and an on-route
    /// walker may be.
    half_cell_m: f64,
}

/// The length a route gives the edge between states `a` and `b` of walking length `length_m`:
/// the length, but never less than the straight line between the states on the plan (a site
/// file may give an edge less; no walk is shorter than the straight line).
pub(crate) fn edge_cost(site: &Site, a: u32, b: u32, length_m: f64) -> f64 {
    let (sa, sb) = (&site.states()[a as usize], &site.states()[b as usize]);
    length_m.max(nalgebra::distance(&sa.position, &sb.position))
}

impl Route {
    /// The shortest walkable route from `from` (a free point: snapped within the site's
    /// spacing) to `to`.
    pub fn plan(site: &Site, from: &FloorPoint, to: &Destination) -> Result<Route, RouteError> {
        Route::plan_from(site, from, 0.0, to)
    }

    /// As [`plan`](Self::plan), from a position estimate whose 68% radius is `accuracy_m`
    /// (it widens the snapping tolerance: `snap_tolerance_m`).
    pub fn plan_from(
        site: &Site,
        from: &FloorPoint,
        accuracy_m: f64,
        to: &Destination,
    ) -> Result<Route, RouteError> {
        let (start, start_snap_m) = snap(site, from, accuracy_m)?;
        let (path, end_snap_m) = match to {
            Destination::Point(p) => {
                let (goal, d) = snap(site, p, 0.0)?;
                let path =
                    search::shortest_path(site, start, |s| s == goal, Some(goal)).ok_or_else(|| {
                        RouteError::Unreachable {
                            from: start,
                            to: format!("state {goal} ({}, {}) on floor {}", p.x, p.y, p.floor),
                        }
                    })?;
                (path, d)
            }
            Destination::Zone(name) => {
                let zone = site.zone_index(name).ok_or_else(|| RouteError::UnknownZone(name.clone()))?;
                let path =
                    search::shortest_path(site, start, |s| site.zone_of(s as usize) == Some(zone), None)
                        .ok_or_else(|| RouteError::Unreachable {
                            from: start,
                            to: format!("zone {name:?}"),
                        })?;
                (path, 0.0)
            }
        };
        let mut along = Vec::with_capacity(path.len());
        let mut total = 0.0;
        along.push(0.0);
        for w in path.windows(2) {
            let length = site
                .neighbours(w[0] as usize)
                .filter(|&(v, _)| v == w[1])
                .map(|(_, l)| edge_cost(site, w[0], w[1], l))
                .fold(f64::INFINITY, f64::min);
            total += length;
            along.push(total);
        }
        let half_cell_m = site.spacing_m() / 2.0;
        let legs = legs::build(site, &path, &along, half_cell_m);
        let points = path.iter().map(|&s| FloorPoint::of_state(site, s)).collect();
        Ok(Route {
            origin: *from,
            destination: to.clone(),
            path,
            along,
            points,
            floors: site.floors().len(),
            legs,
            start_snap_m,
            end_snap_m,
            half_cell_m,
        })
    }

    /// The legs, in walking order; empty when the start is already at the destination.
    pub fn legs(&self) -> &[Leg] {
        &self.legs
    }

    /// Walking length from the start state to the end state, m: the sum of the legs'.
    pub fn length_m(&self) -> f64 {
        self.along.last().copied().unwrap_or(0.0)
    }

    /// The states walked through, as indices into [`Site::states`].
    pub fn states(&self) -> &[u32] {
        &self.path
    }

    /// Walking distance from the start to each of [`states`](Self::states), m.
    pub fn distances_m(&self) -> &[f64] {
        &self.along
    }

    /// Each of [`states`](Self::states) as a point.
    pub fn points(&self) -> &[FloorPoint] {
        &self.points
    }

    /// Where the route starts: the walkable state the origin snapped to.
    pub fn start(&self) -> FloorPoint {
        self.points[0]
    }

    /// Where the route ends: the destination's state.
    pub fn end(&self) -> FloorPoint {
        self.points[self.points.len() - 1]
    }

    /// The point the route was asked from.
    pub fn origin(&self) -> FloorPoint {
        self.origin
    }

    /// Where it was asked to go.
    pub fn destination(&self) -> &Destination {
        &self.destination
    }

    /// Straight-line distance from the origin to the state it snapped to, m (not part of the
    /// route: the site does not know the walls between them).
    pub fn start_snap_m(&self) -> f64 {
        self.start_snap_m
    }

    /// Straight-line distance from a destination point to the state it snapped to, m (0 for
    /// a zone).
    pub fn end_snap_m(&self) -> f64 {
        self.end_snap_m
    }

    /// Half the site's spacing, m: how far from a leg's line its states may lie, and the
    /// route's half-width for the tracker.
    pub fn half_cell_m(&self) -> f64 {
        self.half_cell_m
    }
}

#[cfg(test)]
mod tests;
