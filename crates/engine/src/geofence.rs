//! Geofences: regions an app defines at run time, on top of the site's zones, whose entries and
//! exits the engine reports as status events with the zones' (docs/zones.md).

use crate::site::{GeoError, LatLon, Site};
use geo::Validation;

/// Smallest area of a polygonal geofence, m²: less is a line or a point, with no inside.
pub(crate) const MIN_POLYGON_AREA_M2: f64 = 1e-6;

/// How many vertices stand for a circle's outline in latitude/longitude
/// ([`Geofence::outline_lat_lon`]): the polygon lies within 0.12% of the radius of the circle.
pub const CIRCLE_OUTLINE_VERTICES: usize = 64;

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
    /// The inside of a simple polygon (at least three distinct vertices, in either order; the
    /// last joins the first, and may repeat it), by the even-odd rule. Its edges may not cross
    /// or touch one another.
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
    /// than three distinct vertices or edges that cross one another.
    #[error("geofence {id:?}: {reason}")]
    InvalidShape {
        /// The geofence.
        id: String,
        /// What is wrong.
        reason: String,
    },
    /// A geofence given in latitude/longitude on a site that has no anchor.
    #[error("geofence {id:?}: the site is not geo-referenced (its file has no anchor): give it in the site's metres")]
    NotGeoReferenced {
        /// The geofence.
        id: String,
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
                // geo closes the ring itself (a repeated first vertex is kept as one) and checks
                // it the OGC Simple Features way: three distinct points, no self-intersection.
                let ring: Vec<(f64, f64)> = vertices.iter().map(|v| (v[0], v[1])).collect();
                let polygon = geo::Polygon::new(geo::LineString::from(ring), vec![]);
                if let Err(e) = polygon.check_validation() {
                    return Err(invalid(format!("not a simple polygon: {e}")));
                }
                // geo takes a ring that goes out and back along one line (no inside) as valid.
                if geo::Area::unsigned_area(&polygon) < MIN_POLYGON_AREA_M2 {
                    return Err(invalid("not a simple polygon: it has no area".into()));
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

    /// A polygonal geofence from its outline in WGS84 latitude/longitude on a geo-referenced
    /// site, converted to floor `floor`'s frame (as [`Site::site_point`]) and checked as
    /// [`states_inside`](Self::states_inside) checks it: the outline may end on its first
    /// vertex or not; it must have three distinct vertices, every one in range, and edges that
    /// do not cross.
    pub fn from_lat_lon(
        site: &Site,
        id: impl Into<String>,
        floor: usize,
        vertices: &[LatLon],
    ) -> Result<Geofence, GeofenceError> {
        let id = id.into();
        let mut metres = Vec::with_capacity(vertices.len());
        for (k, v) in vertices.iter().enumerate() {
            let p = site.site_point(Some(floor), *v).map_err(|e| match e {
                GeoError::NotGeoReferenced => GeofenceError::NotGeoReferenced { id: id.clone() },
                GeoError::UnknownFloor { floor, floors } => {
                    GeofenceError::UnknownFloor { id: id.clone(), floor, floors }
                }
                e => GeofenceError::InvalidShape { id: id.clone(), reason: format!("vertex {k}: {e}") },
            })?;
            metres.push([p.x, p.y]);
        }
        // The closing vertex adds nothing to the even-odd test; drop it (within a micrometre,
        // as the conversion leaves it).
        if metres.len() > 3 {
            let (first, last) = (metres[0], metres[metres.len() - 1]);
            if (first[0] - last[0]).hypot(first[1] - last[1]) < 1e-6 {
                metres.pop();
            }
        }
        let fence = Geofence { id, floor, shape: GeofenceShape::Polygon { vertices: metres } };
        fence.states_inside(site)?;
        Ok(fence)
    }

    /// The outline in WGS84 latitude/longitude, for drawing on a map: a polygon's vertices,
    /// or [`CIRCLE_OUTLINE_VERTICES`] points on a circle. Fails on a site without an anchor
    /// or for a floor the site does not have.
    pub fn outline_lat_lon(&self, site: &Site) -> Result<Vec<LatLon>, GeoError> {
        let floors = site.floors().len();
        let unknown = GeoError::UnknownFloor { floor: self.floor, floors };
        let metres: Vec<[f64; 2]> = match &self.shape {
            GeofenceShape::Polygon { vertices } => vertices.clone(),
            GeofenceShape::Circle { x, y, radius_m } => (0..CIRCLE_OUTLINE_VERTICES)
                .map(|k| {
                    let a = std::f64::consts::TAU * k as f64 / CIRCLE_OUTLINE_VERTICES as f64;
                    [x + radius_m * a.cos(), y + radius_m * a.sin()]
                })
                .collect(),
        };
        site.lat_lon(0, 0.0, 0.0).ok_or(GeoError::NotGeoReferenced)?;
        metres.iter().map(|p| site.lat_lon(self.floor, p[0], p[1]).ok_or_else(|| unknown.clone())).collect()
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
        // A bow tie crosses itself; three points on a line have no inside.
        let bowtie = vec![[0.0, 0.0], [4.0, 4.0], [4.0, 0.0], [0.0, 4.0]];
        let line = vec![[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]];
        for vertices in [bowtie, line] {
            let e = refused(fence(0, GeofenceShape::Polygon { vertices }));
            assert!(
                matches!(&e, GeofenceError::InvalidShape { reason, .. } if reason.contains("simple")),
                "{e}"
            );
        }
    }

    fn anchored() -> Site {
        let anchor =
            crate::site::Anchor { lat_deg: 30.29, lon_deg: 120.07, azimuth_rad: 0.3, scale: [1.0, 1.0] };
        grid().with_anchor(Some(anchor)).unwrap()
    }

    #[test]
    fn a_lat_lon_polygon_is_the_metre_one_to_the_centimetre() {
        let site = anchored();
        let square = [[-0.5, -0.5], [2.5, -0.5], [2.5, 2.5], [-0.5, 2.5]];
        let mut outline: Vec<LatLon> = square.iter().map(|p| site.lat_lon(0, p[0], p[1]).unwrap()).collect();
        // Closed, as GeoJSON rings are: the repeated vertex is dropped.
        outline.push(outline[0]);
        let fence = Geofence::from_lat_lon(&site, "sq", 0, &outline).unwrap();
        let GeofenceShape::Polygon { vertices } = &fence.shape else { panic!("{fence:?}") };
        assert_eq!(vertices.len(), 4);
        for (got, want) in vertices.iter().zip(square) {
            assert!((got[0] - want[0]).hypot(got[1] - want[1]) < 0.01, "{got:?} vs {want:?}");
        }
        let metres = Geofence {
            id: "m".into(),
            floor: 0,
            shape: GeofenceShape::Polygon { vertices: square.to_vec() },
        };
        assert_eq!(fence.states_inside(&site).unwrap(), metres.states_inside(&site).unwrap());
        // And back: the outline in lat/lon is the one given.
        for (got, want) in fence.outline_lat_lon(&site).unwrap().iter().zip(&outline) {
            let back = site.site_point(Some(0), *got).unwrap();
            let given = site.site_point(Some(0), *want).unwrap();
            assert!((back - given).norm() < 0.01);
        }
        let circle = Geofence {
            id: "c".into(),
            floor: 0,
            shape: GeofenceShape::Circle { x: 2.0, y: 2.0, radius_m: 1.5 },
        };
        let ring = circle.outline_lat_lon(&site).unwrap();
        assert_eq!(ring.len(), CIRCLE_OUTLINE_VERTICES);
        for p in ring {
            let m = site.site_point(Some(0), p).unwrap();
            assert!(((m.x - 2.0).hypot(m.y - 2.0) - 1.5).abs() < 0.01);
        }
    }

    #[test]
    fn bad_lat_lon_geofences_are_refused_with_a_type() {
        let site = anchored();
        let at = |x: f64, y: f64| site.lat_lon(0, x, y).unwrap();
        let bowtie = [at(0.0, 0.0), at(4.0, 4.0), at(4.0, 0.0), at(0.0, 4.0)];
        assert!(matches!(
            Geofence::from_lat_lon(&site, "b", 0, &bowtie),
            Err(GeofenceError::InvalidShape { reason, .. }) if reason.contains("self-intersection")
        ));
        let nan = [at(0.0, 0.0), LatLon { lat_deg: f64::NAN, lon_deg: 120.07 }, at(4.0, 0.0)];
        assert!(matches!(
            Geofence::from_lat_lon(&site, "n", 0, &nan),
            Err(GeofenceError::InvalidShape { reason, .. }) if reason.starts_with("vertex 1")
        ));
        let two = [at(0.0, 0.0), at(4.0, 4.0), at(0.0, 0.0)];
        assert!(matches!(
            Geofence::from_lat_lon(&site, "t", 0, &two),
            Err(GeofenceError::InvalidShape { .. })
        ));
        let square = [at(0.0, 0.0), at(4.0, 0.0), at(4.0, 4.0)];
        assert!(matches!(
            Geofence::from_lat_lon(&site, "f", 7, &square),
            Err(GeofenceError::UnknownFloor { floor: 7, .. })
        ));
        assert_eq!(
            Geofence::from_lat_lon(&grid(), "g", 0, &square),
            Err(GeofenceError::NotGeoReferenced { id: "g".into() })
        );
        let fence = Geofence {
            id: "c".into(),
            floor: 0,
            shape: GeofenceShape::Circle { x: 2.0, y: 2.0, radius_m: 1.0 },
        };
        assert_eq!(fence.outline_lat_lon(&grid()), Err(GeoError::NotGeoReferenced));
    }
}
