//! Geofences as Kotlin and Swift see them.

use waymark_engine::geofence::{Geofence, GeofenceShape};

/// A point of the site's metric frame, m.
#[derive(Clone, Copy, Debug, PartialEq, uniffi::Record)]
pub struct SitePoint {
    /// x, m.
    pub x: f64,
    /// y, m.
    pub y: f64,
}

/// The outline of a geofence, in the site's metric frame.
#[derive(Clone, Debug, PartialEq, uniffi::Enum)]
#[uniffi(name = "GeofenceShape")]
pub enum FfiGeofenceShape {
    /// The points within `radius_m` of (x, y).
    Circle {
        /// Centre, x, m.
        x: f64,
        /// Centre, y, m.
        y: f64,
        /// Radius, m; > 0.
        radius_m: f64,
    },
    /// The inside of a simple polygon of three vertices or more (the last joins the first).
    Polygon {
        /// Its vertices.
        vertices: Vec<SitePoint>,
    },
}

/// A region of one floor whose entries and exits the engine reports as
/// `StatusUpdate.GeofenceEntered` and `GeofenceExited` (docs/zones.md).
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
#[uniffi(name = "Geofence")]
pub struct FfiGeofence {
    /// The app's name for it, unique among the engine's geofences; the events carry it.
    pub id: String,
    /// Floor index, as in `PositionEstimate.floor`.
    pub floor: u32,
    /// Its outline.
    pub shape: FfiGeofenceShape,
}

impl From<FfiGeofence> for Geofence {
    fn from(g: FfiGeofence) -> Self {
        let shape = match g.shape {
            FfiGeofenceShape::Circle { x, y, radius_m } => GeofenceShape::Circle { x, y, radius_m },
            FfiGeofenceShape::Polygon { vertices } => {
                GeofenceShape::Polygon { vertices: vertices.iter().map(|p| [p.x, p.y]).collect() }
            }
        };
        Geofence { id: g.id, floor: g.floor as usize, shape }
    }
}

impl From<&Geofence> for FfiGeofence {
    fn from(g: &Geofence) -> Self {
        let shape = match &g.shape {
            GeofenceShape::Circle { x, y, radius_m } => {
                FfiGeofenceShape::Circle { x: *x, y: *y, radius_m: *radius_m }
            }
            GeofenceShape::Polygon { vertices } => FfiGeofenceShape::Polygon {
                vertices: vertices.iter().map(|v| SitePoint { x: v[0], y: v[1] }).collect(),
            },
        };
        FfiGeofence { id: g.id.clone(), floor: g.floor as u32, shape }
    }
}
