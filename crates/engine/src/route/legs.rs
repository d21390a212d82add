//! A route's legs: runs of nearly collinear edges merged into straight walks, and floor
//! changes, each with the turn at its start (docs/routes.md#legs).

use crate::site::Site;
use nalgebra::{Point2, Vector2};

/// The turn classes' upper bounds, degrees of the signed angle between two legs' directions:
/// straight below 11°, slight below 45°, left/right to 135°, sharp below 160°, u-turn from
/// 160°. Valhalla's turn types (`baldr/turn.cc`: straight 0-10°, slight 11-44°, right
/// 45-135°, sharp 136-159°, reverse 160-200°), on a continuous angle.
pub const TURN_BANDS_DEG: [f64; 4] = [11.0, 45.0, 135.0, 160.0];

/// An edge joins the leg before it only while it turns less than this from the leg's line:
/// within Valhalla's straight and slight classes ([`TURN_BANDS_DEG`]), so what a leg absorbs
/// is never a turn the walker would be told about.
pub const MERGE_MAX_DEVIATION_RAD: f64 = TURN_BANDS_DEG[1] * std::f64::consts::PI / 180.0;

/// Which way to turn onto a leg.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Turn {
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
    /// 160° or more: back the way the walker came.
    UTurn,
}

impl Turn {
    /// The class of a signed angle, radians, positive to the left (counter-clockwise in the
    /// site's frame, x east and y north), by bands at 11°, 45°, 135° and 160°.
    pub fn from_angle(angle_rad: f64) -> Turn {
        let degrees = angle_rad.to_degrees();
        let left = degrees > 0.0;
        let a = degrees.abs();
        match TURN_BANDS_DEG.iter().take_while(|&&edge| a >= edge).count() {
            0 => Turn::Straight,
            1 if left => Turn::SlightLeft,
            1 => Turn::SlightRight,
            2 if left => Turn::Left,
            2 => Turn::Right,
            3 if left => Turn::SharpLeft,
            3 => Turn::SharpRight,
            _ => Turn::UTurn,
        }
    }

    /// Its name in instructions and JSON: `straight`, `slight_left`, ..., `u_turn`.
    pub fn name(self) -> &'static str {
        match self {
            Turn::Straight => "straight",
            Turn::SlightLeft => "slight_left",
            Turn::SlightRight => "slight_right",
            Turn::Left => "left",
            Turn::Right => "right",
            Turn::SharpLeft => "sharp_left",
            Turn::SharpRight => "sharp_right",
            Turn::UTurn => "u_turn",
        }
    }
}

/// One leg of a route: a straight walk on one floor, or a change of floor (stairs, a lift).
#[derive(Clone, Debug, PartialEq)]
pub struct Leg {
    /// The floor it starts on.
    pub floor: usize,
    /// The floor it ends on: `floor` for a walk.
    pub to_floor: usize,
    /// Walking distance, m.
    pub distance_m: f64,
    /// The turn onto it from the leg before; `None` for the first leg, a floor change and the
    /// leg after one (the walker's heading off stairs or out of a lift is not known).
    pub turn: Option<Turn>,
    /// Signed angle of that turn, radians, positive to the left.
    pub turn_angle_rad: Option<f64>,
    /// Positions of the states it walks through, first to last (each on its own floor).
    pub points: Vec<Point2<f64>>,
    /// Index in the route's states of its first state; its last is the next leg's first.
    pub first: usize,
    /// Index in the route's states of its last state.
    pub last: usize,
}

impl Leg {
    /// Whether it changes floor.
    pub fn is_floor_change(&self) -> bool {
        self.floor != self.to_floor
    }

    /// Its start, on `floor`.
    pub fn start(&self) -> Point2<f64> {
        self.points[0]
    }

    /// Its end, on `to_floor`.
    pub fn end(&self) -> Point2<f64> {
        self.points[self.points.len() - 1]
    }

    fn direction(&self) -> Vector2<f64> {
        self.end() - self.start()
    }
}

fn signed_angle(from: &Vector2<f64>, to: &Vector2<f64>) -> f64 {
    (from.x * to.y - from.y * to.x).atan2(from.dot(to))
}

/// Distance from `p` to the line through `a` and `b` (to `a` when they coincide).
fn off_line(p: &Point2<f64>, a: &Point2<f64>, b: &Point2<f64>) -> f64 {
    let d = b - a;
    let n = d.norm();
    if n == 0.0 {
        return nalgebra::distance(p, a);
    }
    (d.x * (p.y - a.y) - d.y * (p.x - a.x)).abs() / n
}

/// The legs of the state path `path` (with walking distances `along`). A walk leg takes the
/// next edge on its floor while the edge turns less than [`MERGE_MAX_DEVIATION_RAD`] from the
/// leg's line and every state of the leg stays within `half_cell_m` of the line from its first
/// state to the new last: it is then one straight walk down one corridor of cells, however the
/// grid's edges zig-zag. Consecutive edges between floors make one floor-change leg.
pub(super) fn build(site: &Site, path: &[u32], along: &[f64], half_cell_m: f64) -> Vec<Leg> {
    let states = site.states();
    let at = |k: usize| &states[path[k] as usize];
    let mut legs: Vec<Leg> = Vec::new();
    // The leg being built: index of its first state in `path`.
    let mut first = 0;
    for k in 0..path.len().saturating_sub(1) {
        let (a, b) = (at(k), at(k + 1));
        let changes_floor = a.floor != b.floor;
        if k > first {
            let leg_changes_floor = at(first).floor != at(k).floor;
            let joins = if changes_floor || leg_changes_floor {
                // One flight after another, never back to the floor the leg left.
                changes_floor && leg_changes_floor && at(first).floor != b.floor
            } else {
                let line = b.position - at(first).position;
                let edge = b.position - a.position;
                let turn = if edge.norm() == 0.0 {
                    0.0
                } else {
                    signed_angle(&(a.position - at(first).position), &edge)
                };
                line.norm() > 0.0
                    && turn.abs() < MERGE_MAX_DEVIATION_RAD
                    && (first..=k)
                        .all(|j| off_line(&at(j).position, &at(first).position, &b.position) <= half_cell_m)
            };
            if !joins {
                legs.push(leg(site, path, along, first, k, legs.last()));
                first = k;
            }
        }
    }
    if path.len() > 1 {
        legs.push(leg(site, path, along, first, path.len() - 1, legs.last()));
    }
    legs
}

fn leg(site: &Site, path: &[u32], along: &[f64], first: usize, last: usize, before: Option<&Leg>) -> Leg {
    let states = site.states();
    let points: Vec<Point2<f64>> = path[first..=last].iter().map(|&s| states[s as usize].position).collect();
    let mut leg = Leg {
        floor: states[path[first] as usize].floor,
        to_floor: states[path[last] as usize].floor,
        distance_m: along[last] - along[first],
        turn: None,
        turn_angle_rad: None,
        points,
        first,
        last,
    };
    if let Some(before) = before.filter(|b| !b.is_floor_change() && !leg.is_floor_change()) {
        let (from, to) = (before.direction(), leg.direction());
        if from.norm() > 0.0 && to.norm() > 0.0 {
            let angle = signed_angle(&from, &to);
            leg.turn = Some(Turn::from_angle(angle));
            leg.turn_angle_rad = Some(angle);
        }
    }
    leg
}
