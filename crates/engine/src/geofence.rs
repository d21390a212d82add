//! Geofences: regions an app defines at run time, on top of the site's zones, whose entries and
//! exits the engine reports as status events with the zones' (docs/zones.md).

use crate::site::Site;

/// A region of one floor, in the site's metric frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Geofence {
    /// The app's name for it, unique among the engine's geofences; events carry it.
    pub id: String,
    /// Index into the site's floors.
    pub floor: usize,
    /// Its outline.
    pub shape: GeofenceShape,
}

/// The outline of a [`Geofence`].
#[derive(Clone, Debug, PartialEq)]
pub enum GeofenceShape {
    /// The points within `radius_m` of (x, y), m.
    Circle {
        /// Centre, x, m.
        x: f64,
        /// Centre, y, m.
        y: f64,
        /// Radius, m; > 0.
        radius_m: f64,
    },
    /// The inside of a simple polygon (at least three vertices, in either order; the last
    /// joins the first), by the even-odd rule.
    Polygon {
        /// Vertices as (x, y), m.
        vertices: Vec<[f64; 2]>,
    },
}

/// Why a geofence was refused.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GeofenceError {
    /// Another geofence of the engine has this id.
    #[error("a geofence with id {id:?} exists already")]
    DuplicateId {
        /// The id.
        id: String,
    },
    /// The id is empty.
    #[error("a geofence needs a non-empty id")]
    EmptyId,
    /// The floor index is not one of the site's.
    #[error("geofence {id:?}: no floor {floor} (the site has {floors})")]
    UnknownFloor {
        /// The geofence.
        id: String,
        /// The floor asked for.
        floor: usize,
        /// How many floors the site has.
        floors: usize,
    },
    /// A coordinate or radius is NaN or infinite, a radius is not > 0, or a polygon has fewer
    /// than three vertices.
    #[error("geofence {id:?}: {reason}")]
    InvalidShape {
        /// The geofence.
        id: String,
        /// What is wrong.
        reason: String,
    },
    /// No state of the site lies inside it: the engine could never place anyone there.
    #[error("geofence {id:?} holds no state of the site")]
    NoStateInside {
        /// The geofence.
        id: String,
    },
}

impl Geofence {
    /// Checks the geofence against `site` and returns the indices of the states inside it,
    /// ascending: its probability at an epoch is the posterior mass on them.
    pub fn states_inside(&self, site: &Site) -> Result<Vec<u32>, GeofenceError> {
        let invalid = |reason: String| GeofenceError::InvalidShape { id: self.id.clone(), reason };
        if self.id.is_empty() {
            return Err(GeofenceError::EmptyId);
        }
        if self.floor >= site.floors().len() {
            let floors = site.floors().len();
            return Err(GeofenceError::UnknownFloor { id: self.id.clone(), floor: self.floor, floors });
        }
        match &self.shape {
            GeofenceShape::Circle { x, y, radius_m } => {
                if !(x.is_finite() && y.is_finite()) {
                    return Err(invalid(format!("centre ({x}, {y}) is not finite")));
                }
                if !(radius_m.is_finite() && *radius_m > 0.0) {
                    return Err(invalid(format!("radius {radius_m} m is not a finite value > 0")));
                }
            }
            GeofenceShape::Polygon { vertices } => {
                if vertices.len() < 3 {
                    return Err(invalid(format!(
                        "a polygon needs 3 vertices or more (got {})",
                        vertices.len()
                    )));
                }
                if let Some(k) = vertices.iter().position(|v| !(v[0].is_finite() && v[1].is_finite())) {
                    return Err(invalid(format!("vertex {k} is not finite")));
                }
            }
        }
        let inside: Vec<u32> = site
            .states()
            .iter()
            .enumerate()
            .filter(|(_, s)| s.floor == self.floor && self.contains(s.position.x, s.position.y))
            .map(|(i, _)| i as u32)
            .collect();
        if inside.is_empty() {
            return Err(GeofenceError::NoStateInside { id: self.id.clone() });
        }
        Ok(inside)
    }

    /// Whether (x, y) on the geofence's floor lies inside it (on a circle's edge counts).
    pub fn contains(&self, x: f64, y: f64) -> bool {
        match &self.shape {
            GeofenceShape::Circle { x: cx, y: cy, radius_m } => (x - cx).hypot(y - cy) <= *radius_m,
            GeofenceShape::Polygon { vertices } => {
                // Crossing number: a ray towards +x crosses the outline an odd number of times.
                let mut inside = false;
                let mut previous = vertices[vertices.len() - 1];
                for &v in vertices {
                    if (v[1] > y) != (previous[1] > y) {
                        let crossing_x = v[0] + (y - v[1]) / (previous[1] - v[1]) * (previous[0] - v[0]);
                        if x < crossing_x {
                            inside = !inside;
                        }
                    }
                    previous = v;
                }
                inside
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::site::{BuildOptions, SiteBuilder};
    use nalgebra::Point2;

    /// A 5 × 5 grid of states 1 m apart on floor 0, and one state on floor 1.
    fn grid() -> Site {
        let mut b = SiteBuilder::new("grid");
        let ground = b.floor("G", 0.0);
        let first = b.floor("1", 4.0);
        for i in 0..25 {
            b.state(ground, Point2::new(f64::from(i % 5), f64::from(i / 5)), vec![]);
        }
        b.state(first, Point2::new(2.0, 2.0), vec![]);
        b.build(BuildOptions::default()).unwrap()
    }

    fn fence(floor: usize, shape: GeofenceShape) -> Geofence {
        Geofence { id: "f".into(), floor, shape }
    }

    #[test]
    fn a_circle_holds_the_states_within_its_radius_on_its_floor() {
        let site = grid();
        let circle = fence(0, GeofenceShape::Circle { x: 2.0, y: 2.0, radius_m: 1.0 });
        // The centre and its four neighbours; not the floor above's state at (2, 2).
        assert_eq!(circle.states_inside(&site).unwrap(), vec![7, 11, 12, 13, 17]);
        let above = fence(1, GeofenceShape::Circle { x: 2.0, y: 2.0, radius_m: 1.0 });
        assert_eq!(above.states_inside(&site).unwrap(), vec![25]);
    }

    #[test]
    fn a_polygon_holds_what_is_inside_it_in_either_orientation() {
        let site = grid();
        // An L over the first two rows and the first column's third row.
        let l = vec![[-0.5, -0.5], [4.5, -0.5], [4.5, 1.5], [0.5, 1.5], [0.5, 2.5], [-0.5, 2.5]];
        let mut reversed = l.clone();
        reversed.reverse();
        let expected: Vec<u32> = (0..10).chain([10]).collect();
        for vertices in [l, reversed] {
            assert_eq!(fence(0, GeofenceShape::Polygon { vertices }).states_inside(&site).unwrap(), expected);
        }
    }

    #[test]
    fn bad_geofences_are_refused_with_a_reason() {
        let site = grid();
        let circle = |x: f64, radius_m: f64| GeofenceShape::Circle { x, y: 0.0, radius_m };
        let refused = |f: Geofence| f.states_inside(&site).unwrap_err();
        assert_eq!(
            refused(Geofence { id: String::new(), floor: 0, shape: circle(0.0, 1.0) }),
            GeofenceError::EmptyId
        );
        assert!(matches!(refused(fence(2, circle(0.0, 1.0))), GeofenceError::UnknownFloor { floors: 2, .. }));
        for shape in [circle(f64::NAN, 1.0), circle(0.0, 0.0), circle(0.0, f64::INFINITY), circle(0.0, -1.0)]
        {
            assert!(matches!(refused(fence(0, shape)), GeofenceError::InvalidShape { .. }));
        }
        let two = GeofenceShape::Polygon { vertices: vec![[0.0, 0.0], [1.0, 1.0]] };
        assert!(matches!(refused(fence(0, two)), GeofenceError::InvalidShape { .. }));
        let nan = GeofenceShape::Polygon { vertices: vec![[0.0, 0.0], [1.0, f64::NAN], [1.0, 0.0]] };
        assert!(matches!(refused(fence(0, nan)), GeofenceError::InvalidShape { .. }));
        assert_eq!(refused(fence(0, circle(50.0, 1.0))), GeofenceError::NoStateInside { id: "f".into() });
    }
}
