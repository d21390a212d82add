//! Following a route as positions arrive: how far along it the walker is, what is left, which
//! leg they are on, whether they arrived, and whether they left it (docs/routes.md#progress).

use super::{Destination, FloorPoint, Route, RouteError};
use crate::site::Site;

/// σ of one coordinate of a position's error per metre of its 68% radius: the 68% circle of an
/// isotropic 2-D Gaussian has radius σ·√(2 ln(1/0.32)) = 1.5096 σ. Its distance to a straight
/// route errs by one coordinate, N(0, σ²).
pub const SIGMA_PER_ACCURACY_68: f64 = 1.0 / 1.509_596;

/// A walker on the route is declared off it when their position is more than this many σ
/// beyond the route's half-cell: 2.576, the normal's two-sided 99% quantile, so a walker on
/// the route with independent position errors trips it on 1% of positions.
pub const OFF_ROUTE_ENTER_SIGMAS: f64 = 2.576;

/// An off-route walker is back on the route when their position is within this many σ of the
/// route's half-cell: 1, the two-sided 68% quantile, the same confidence as the accuracy
/// radius. The band between the two thresholds is the hysteresis that keeps noise from
/// flapping the flag.
pub const OFF_ROUTE_EXIT_SIGMAS: f64 = 1.0;

/// Where a position puts the walker on the route.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Progress {
    /// Walking distance from the route's start to the walker's point on it, m.
    pub along_m: f64,
    /// Walking distance left to the route's end, m.
    pub remaining_m: f64,
    /// Index of the leg the walker is on (at a leg's end, the next one: the turn to make now).
    pub leg: usize,
    /// Distance from the position to the route on its floor, m; infinite when the route does
    /// not visit the position's floor.
    pub distance_from_route_m: f64,
    /// Whether the walker has left the route (docs/routes.md#progress): reroute.
    pub off_route: bool,
    /// Whether the walker has reached the route's end; it stays set until a reroute.
    pub arrived: bool,
}

/// Follows one route as positions arrive. Deterministic: the same positions give the same
/// progress.
#[derive(Clone, Debug)]
pub struct RouteTracker {
    route: Route,
    off_route: bool,
    arrived: bool,
    along_m: f64,
    /// The latest position and its 68% radius, for rerouting.
    last: Option<(FloorPoint, f64)>,
}

impl RouteTracker {
    /// A tracker at the start of `route`, on it.
    pub fn new(route: Route) -> Self {
        Self { route, off_route: false, arrived: false, along_m: 0.0, last: None }
    }

    /// The route followed.
    pub fn route(&self) -> &Route {
        &self.route
    }

    /// Takes a position (`accuracy_m`: the radius of its 68% circle) and says where it puts the
    /// walker. A NaN or infinite coordinate, a negative or non-finite accuracy, or an unknown
    /// floor is an error and changes nothing.
    ///
    /// The position is matched to the nearest point of the route on its floor; when several
    /// parts of the route come within half a cell of that distance (a route that passes near
    /// itself), to the one nearest along the route to the previous match, so the progress does
    /// not jump between them.
    pub fn update(&mut self, position: &FloorPoint, accuracy_m: f64) -> Result<Progress, RouteError> {
        if !(position.x.is_finite() && position.y.is_finite()) {
            return Err(RouteError::NotFinite("a position's coordinate"));
        }
        if !(accuracy_m.is_finite() && accuracy_m >= 0.0) {
            return Err(RouteError::NotFinite("the accuracy"));
        }
        let r = &self.route;
        if position.floor >= r.floors {
            return Err(RouteError::UnknownFloor { floor: position.floor, floors: r.floors });
        }
        let candidates = self.candidates(position);
        let nearest = candidates.iter().map(|c| c.0).fold(f64::INFINITY, f64::min);
        let matched = candidates
            .iter()
            .filter(|c| c.0 <= nearest + r.half_cell_m)
            .min_by(|a, b| (a.1 - self.along_m).abs().total_cmp(&(b.1 - self.along_m).abs()));
        if let Some(&(_, along)) = matched {
            self.along_m = along;
        }
        let sigma = accuracy_m * SIGMA_PER_ACCURACY_68;
        let enter = r.half_cell_m + OFF_ROUTE_ENTER_SIGMAS * sigma;
        let exit = r.half_cell_m + OFF_ROUTE_EXIT_SIGMAS * sigma;
        if self.off_route {
            self.off_route = nearest > exit;
        } else {
            self.off_route = nearest > enter;
        }
        let end = r.points[r.points.len() - 1];
        if !self.off_route
            && position.floor == end.floor
            && nalgebra::distance(&position.position(), &end.position()) <= exit
        {
            self.arrived = true;
        }
        self.last = Some((*position, accuracy_m));
        let leg = r.legs.iter().filter(|l| r.along[l.first] <= self.along_m).count().saturating_sub(1);
        Ok(Progress {
            along_m: self.along_m,
            remaining_m: (r.length_m() - self.along_m).max(0.0),
            leg,
            distance_from_route_m: nearest,
            off_route: self.off_route,
            arrived: self.arrived,
        })
    }

    /// (distance, along) of the position's nearest point on each part of the route on its
    /// floor: each edge on the floor, and the end on this floor of each edge between floors.
    fn candidates(&self, position: &FloorPoint) -> Vec<(f64, f64)> {
        let r = &self.route;
        let p = position.position();
        let mut out = Vec::new();
        if r.points.len() == 1 && r.points[0].floor == position.floor {
            out.push((nalgebra::distance(&p, &r.points[0].position()), 0.0));
        }
        for k in 0..r.points.len().saturating_sub(1) {
            let (a, b) = (r.points[k], r.points[k + 1]);
            if a.floor == b.floor {
                if a.floor != position.floor {
                    continue;
                }
                let (pa, pb) = (a.position(), b.position());
                let d = pb - pa;
                let t = if d.norm_squared() > 0.0 {
                    ((p - pa).dot(&d) / d.norm_squared()).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let on = pa + d * t;
                out.push((nalgebra::distance(&p, &on), r.along[k] + t * (r.along[k + 1] - r.along[k])));
            } else {
                for (end, along) in [(a, r.along[k]), (b, r.along[k + 1])] {
                    if end.floor == position.floor {
                        out.push((nalgebra::distance(&p, &end.position()), along));
                    }
                }
            }
        }
        out
    }

    /// Plans a new route to the same destination from `from` (with its 68% radius), or, with
    /// `None`, from the latest position given to [`update`](Self::update); the tracker starts
    /// again at its beginning. On an error the tracker keeps its route.
    pub fn reroute(&mut self, site: &Site, from: Option<(FloorPoint, f64)>) -> Result<&Route, RouteError> {
        let (point, accuracy_m) = from.or(self.last).ok_or(RouteError::NoPosition)?;
        let destination: Destination = self.route.destination.clone();
        let route = Route::plan_from(site, &point, accuracy_m, &destination)?;
        *self = RouteTracker { last: self.last, ..RouteTracker::new(route) };
        Ok(&self.route)
    }
}
