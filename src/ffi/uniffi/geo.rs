//! WGS84 for maps (docs/zones.md#latitude-and-longitude): a geo-referenced site's points,
//! routes, zones and geofences in latitude/longitude, and geofences given in it. A change
//! here is a possible breaking change for apps (CHANGELOG, "Breaking changes").

use super::{FfiFloorPoint, FfiGeofence, FfiRoute, FfiSite, ZoneKind};
use waymark_engine::geofence::{Geofence, GeofenceError};
use waymark_engine::site::{GeoError, LatLon};

/// A WGS84 latitude and longitude, degrees.
#[derive(Clone, Copy, Debug, PartialEq, uniffi::Record)]
#[uniffi(name = "LatLon")]
pub struct FfiLatLon {
    /// Degrees north.
    pub latitude_deg: f64,
    /// Degrees east.
    pub longitude_deg: f64,
}

/// A point of the site in WGS84: its floor index and latitude/longitude, degrees.
#[derive(Clone, Copy, Debug, PartialEq, uniffi::Record)]
pub struct GeoPoint {
    /// Floor index in the site file.
    pub floor: u32,
    /// Degrees north.
    pub latitude_deg: f64,
    /// Degrees east.
    pub longitude_deg: f64,
}

/// A zone's outline in WGS84, for drawing it on a map: the convex hull of the places the
/// engine puts someone in when it says they are in the zone.
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
pub struct ZoneOutline {
    /// The zone's name, as in `Site.zoneNames`.
    pub name: String,
    /// What kind of place it is.
    pub kind: ZoneKind,
    /// The floor holding most of its places.
    pub floor: u32,
    /// The outline's vertices, counter-clockwise, the last not repeating the first.
    pub outline: Vec<FfiLatLon>,
}

/// Why a conversion between the site's metres and WGS84 failed.
#[derive(Clone, Debug, PartialEq, thiserror::Error, uniffi::Error)]
#[uniffi(name = "GeoError")]
pub enum FfiGeoError {
    /// The site file has no `anchor`: it has no place on the Earth.
    #[error("the site is not geo-referenced")]
    NotGeoReferenced,
    /// A latitude, longitude or metre value is NaN, infinite or out of range, or a floor
    /// index the site does not have.
    #[error("invalid coordinate: {reason}")]
    InvalidCoordinate {
        /// Which and why.
        reason: String,
    },
    /// A geofence outline that is not a simple polygon (fewer than three distinct vertices,
    /// crossing edges, no area), or that holds no place of the site.
    #[error("invalid geofence: {reason}")]
    InvalidGeofence {
        /// What is wrong.
        reason: String,
    },
    /// A bug in Waymark; nothing changed.
    #[error("internal error: {reason}")]
    Internal {
        /// What happened.
        reason: String,
    },
}

impl From<GeoError> for FfiGeoError {
    fn from(e: GeoError) -> Self {
        match e {
            GeoError::NotGeoReferenced => FfiGeoError::NotGeoReferenced,
            e => FfiGeoError::InvalidCoordinate { reason: e.to_string() },
        }
    }
}

impl From<uniffi::UnexpectedUniFFICallbackError> for FfiGeoError {
    fn from(e: uniffi::UnexpectedUniFFICallbackError) -> Self {
        FfiGeoError::Internal { reason: format!("foreign callback failed: {}", e.reason) }
    }
}

/// Runs `f`, turning a panic into `Internal` (`ffi::panic`).
fn guarded<T>(f: impl FnOnce() -> Result<T, FfiGeoError>) -> Result<T, FfiGeoError> {
    crate::ffi::panic::or_internal(f, || FfiGeoError::Internal {
        reason: "Waymark panicked; nothing changed".into(),
    })
}

fn lat_lon(p: LatLon) -> FfiLatLon {
    FfiLatLon { latitude_deg: p.lat_deg, longitude_deg: p.lon_deg }
}

impl FfiSite {
    /// Floor `floor`'s point (x, y) in WGS84, refusing what the engine's `lat_lon` takes
    /// silently: a NaN or infinite metre value.
    fn geo(&self, floor: u32, x: f64, y: f64) -> Result<LatLon, FfiGeoError> {
        if !(x.is_finite() && y.is_finite()) {
            return Err(FfiGeoError::InvalidCoordinate { reason: format!("({x}, {y}) is not finite") });
        }
        let floors = self.inner.floors().len();
        self.inner.lat_lon(floor as usize, x, y).ok_or(if self.inner.lat_lon(0, 0.0, 0.0).is_none() {
            FfiGeoError::NotGeoReferenced
        } else {
            GeoError::UnknownFloor { floor: floor as usize, floors }.into()
        })
    }
}

#[uniffi::export(name = "Site")]
impl FfiSite {
    /// Whether the site has a place on the Earth (its file has an `anchor`): without one,
    /// every latitude/longitude method throws `NotGeoReferenced`.
    pub fn is_geo_referenced(&self) -> bool {
        self.inner.lat_lon(0, 0.0, 0.0).is_some()
    }

    /// A point of the site in WGS84. Throws `NotGeoReferenced`, or `InvalidCoordinate` for
    /// an unknown floor or a NaN or infinite x or y.
    pub fn to_lat_lon(&self, point: FfiFloorPoint) -> Result<FfiLatLon, FfiGeoError> {
        guarded(|| Ok(lat_lon(self.geo(point.floor, point.x, point.y)?)))
    }

    /// A WGS84 latitude/longitude as a point of floor `floor`'s frame, m: the inverse of
    /// `toLatLon`. Throws `NotGeoReferenced`, or `InvalidCoordinate` for an unknown floor or
    /// a latitude or longitude out of range.
    pub fn from_lat_lon(&self, floor: u32, at: FfiLatLon) -> Result<FfiFloorPoint, FfiGeoError> {
        guarded(|| {
            let at = LatLon { lat_deg: at.latitude_deg, lon_deg: at.longitude_deg };
            let p = self.inner.site_point(Some(floor as usize), at)?;
            Ok(FfiFloorPoint { floor, x: p.x, y: p.y })
        })
    }

    /// A route's legs in WGS84, for drawing: one polyline per leg, each point on its own
    /// floor (a floor change goes from one floor to the next). Throws as `toLatLon`.
    pub fn route_lat_lon(&self, route: FfiRoute) -> Result<Vec<Vec<GeoPoint>>, FfiGeoError> {
        guarded(|| {
            route
                .legs
                .iter()
                .map(|leg| {
                    leg.points
                        .iter()
                        .map(|p| {
                            let g = self.geo(p.floor, p.x, p.y)?;
                            Ok(GeoPoint { floor: p.floor, latitude_deg: g.lat_deg, longitude_deg: g.lon_deg })
                        })
                        .collect()
                })
                .collect()
        })
    }

    /// Every zone's outline in WGS84, in the site file's order. Throws `NotGeoReferenced`.
    pub fn zone_outlines(&self) -> Result<Vec<ZoneOutline>, FfiGeoError> {
        guarded(|| {
            (0..self.inner.zones().len())
                .map(|z| {
                    let zone = &self.inner.zones()[z];
                    let (floor, ring) = self.inner.zone_outline(z).ok_or_else(|| FfiGeoError::Internal {
                        reason: format!("zone {z} has no outline"),
                    })?;
                    let outline = ring
                        .iter()
                        .map(|p| Ok(lat_lon(self.geo(floor as u32, p[0], p[1])?)))
                        .collect::<Result<_, FfiGeoError>>()?;
                    Ok(ZoneOutline { name: zone.name.clone(), kind: zone.kind, floor: floor as u32, outline })
                })
                .collect()
        })
    }

    /// A polygonal geofence from its outline in WGS84 (a GeoJSON ring may end on its first
    /// vertex), in the site's metres, to give to `PositioningEngine.addGeofence`. Checked:
    /// every vertex in range, three distinct vertices or more, no crossing edges, some place
    /// of the site inside. Throws `NotGeoReferenced`, `InvalidCoordinate` (an unknown floor,
    /// a vertex out of range) or `InvalidGeofence`.
    pub fn geofence_from_lat_lon(
        &self,
        id: String,
        floor: u32,
        outline: Vec<FfiLatLon>,
    ) -> Result<FfiGeofence, FfiGeoError> {
        guarded(|| {
            let vertices: Vec<LatLon> = outline
                .iter()
                .map(|p| LatLon { lat_deg: p.latitude_deg, lon_deg: p.longitude_deg })
                .collect();
            match Geofence::from_lat_lon(&self.inner, id, floor as usize, &vertices) {
                Ok(fence) => Ok(FfiGeofence::from(&fence)),
                Err(GeofenceError::NotGeoReferenced { .. }) => Err(FfiGeoError::NotGeoReferenced),
                Err(e @ GeofenceError::UnknownFloor { .. }) => {
                    Err(FfiGeoError::InvalidCoordinate { reason: e.to_string() })
                }
                Err(e) => Err(FfiGeoError::InvalidGeofence { reason: e.to_string() }),
            }
        })
    }

    /// A geofence's outline in WGS84: a polygon's vertices, or 64 points on a circle. Throws
    /// `NotGeoReferenced`, or `InvalidCoordinate` for an unknown floor.
    pub fn geofence_lat_lon(&self, geofence: FfiGeofence) -> Result<Vec<FfiLatLon>, FfiGeoError> {
        guarded(|| {
            Ok(Geofence::from(geofence).outline_lat_lon(&self.inner)?.into_iter().map(lat_lon).collect())
        })
    }
}
