//! Where a site sits on the Earth: its anchor in WGS84, and the conversion of site-frame
//! metres to latitude/longitude and back through the local tangent plane (east, north, up) at
//! the anchor.
//!
//! The chain is exact, with no flat-Earth shortcut: geodetic → Earth-centred Earth-fixed
//! (ECEF) → the tangent plane's east/north/up and back, on the WGS84 ellipsoid at height 0.
//! The only approximation is dropping "up" on the way in (a point 300 m away is 7 mm below
//! the plane), which moves its latitude/longitude by far less than a millimetre
//! (docs/site-files.md#geo-reference holds the formulas and their sources).

use serde::{Deserialize, Serialize};

/// WGS84 semi-major axis, m (NIMA TR8350.2, Table 3.1).
const WGS84_A: f64 = 6_378_137.0;
/// WGS84 flattening (NIMA TR8350.2, Table 3.1).
const WGS84_F: f64 = 1.0 / 298.257_223_563;
/// First eccentricity squared, e² = f(2 − f).
const WGS84_E2: f64 = WGS84_F * (2.0 - WGS84_F);

/// The largest |latitude| an anchor may have, degrees: the tangent plane's east axis is
/// undefined at a pole, and no building needs one closer than this.
pub const MAX_ANCHOR_LATITUDE_DEG: f64 = 89.0;

/// How a site frame sits on the Earth (the site file's `anchor`): the WGS84 position of its
/// origin and its axes on the ground. Site metres (x, y) become east/north ground metres by
/// `east = x·sx·cos a + y·sy·sin a`, `north = −x·sx·sin a + y·sy·cos a`, with `a` the azimuth
/// of +y and `[sx, sy]` the scale (docs/site-files.md#geo-reference).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Anchor {
    /// Latitude of the site frame's origin (x = y = 0), degrees north, WGS84.
    pub lat_deg: f64,
    /// Longitude of the site frame's origin, degrees east, WGS84.
    pub lon_deg: f64,
    /// True azimuth of the site frame's +y axis, radians clockwise from north; +x is a quarter
    /// turn clockwise from it. 0: x east, y north.
    #[serde(default)]
    pub azimuth_rad: f64,
    /// Ground metres per site-frame metre along x and along y: 1 for a frame measured in
    /// metres; a plan drawn in a map projection has its own (the competition's plans are Web
    /// Mercator scaled to their centre's latitude, docs/site-files.md#geo-reference).
    #[serde(default = "unit_scale")]
    pub scale: [f64; 2],
}

fn unit_scale() -> [f64; 2] {
    [1.0, 1.0]
}

/// A WGS84 latitude and longitude, degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LatLon {
    /// Degrees north.
    pub lat_deg: f64,
    /// Degrees east.
    pub lon_deg: f64,
}

/// Why a latitude/longitude could not become a site position.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GeoError {
    /// The site file has no `anchor`, so latitude and longitude mean nothing on it.
    #[error("the site is not geo-referenced (its file has no anchor): give x and y in the site frame")]
    NotGeoReferenced,
    /// A latitude outside ±90°, a longitude outside ±180°, or either not finite.
    #[error("invalid {field}: {value}")]
    InvalidCoordinate {
        /// `latitude` or `longitude`.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// The site's floors are drawn in frames with different origins
    /// (`floors[f].origin_m`), so a position without a floor has no one place in them.
    #[error("the site's floors have different frames: a latitude/longitude needs its floor")]
    FloorRequired,
    /// A floor index the site does not have.
    #[error("floor {floor} does not exist (the site has {floors} floors)")]
    UnknownFloor {
        /// The floor given.
        floor: usize,
        /// How many floors the site has.
        floors: usize,
    },
}

impl LatLon {
    /// Checked: both finite, latitude within ±90°, longitude within ±180°.
    pub fn new(lat_deg: f64, lon_deg: f64) -> Result<LatLon, GeoError> {
        if !(lat_deg.is_finite() && lat_deg.abs() <= 90.0) {
            return Err(GeoError::InvalidCoordinate { field: "latitude", value: lat_deg });
        }
        if !(lon_deg.is_finite() && lon_deg.abs() <= 180.0) {
            return Err(GeoError::InvalidCoordinate { field: "longitude", value: lon_deg });
        }
        Ok(LatLon { lat_deg, lon_deg })
    }

    /// Earth-centred Earth-fixed coordinates at height 0, m (TR8350.2 eq. 4-14).
    fn ecef(self) -> [f64; 3] {
        let (lat, lon) = (self.lat_deg.to_radians(), self.lon_deg.to_radians());
        let n = prime_vertical_radius(lat);
        [n * lat.cos() * lon.cos(), n * lat.cos() * lon.sin(), n * (1.0 - WGS84_E2) * lat.sin()]
    }

    /// The point at ECEF `p`, projected along the ellipsoid's normal: the fixed-point
    /// iteration of docs/site-files.md#geo-reference, which four rounds take to 1e-12 rad
    /// near the surface.
    fn from_ecef(p: [f64; 3]) -> LatLon {
        let r = p[0].hypot(p[1]);
        let mut lat = p[2].atan2(r * (1.0 - WGS84_E2));
        for _ in 0..4 {
            let n = prime_vertical_radius(lat);
            // Anchors stay 1° off the poles (MAX_ANCHOR_LATITUDE_DEG), so cos φ > 0.017.
            let h = r / lat.cos() - n;
            lat = p[2].atan2(r * (1.0 - WGS84_E2 * n / (n + h)));
        }
        LatLon { lat_deg: lat.to_degrees(), lon_deg: p[1].atan2(p[0]).to_degrees() }
    }
}

/// Radius of curvature in the prime vertical at latitude `lat` (rad), N = a / √(1 − e² sin² φ).
fn prime_vertical_radius(lat: f64) -> f64 {
    WGS84_A / (1.0 - WGS84_E2 * lat.sin().powi(2)).sqrt()
}

impl Anchor {
    /// An anchor at `origin` with x east, y north and unit scale.
    pub fn at(origin: LatLon) -> Anchor {
        Anchor { lat_deg: origin.lat_deg, lon_deg: origin.lon_deg, azimuth_rad: 0.0, scale: [1.0, 1.0] }
    }

    /// The first value out of range, as (field, message).
    pub(crate) fn check(&self) -> Result<(), (&'static str, String)> {
        if !(self.lat_deg.is_finite() && self.lat_deg.abs() <= MAX_ANCHOR_LATITUDE_DEG) {
            return Err((
                "lat_deg",
                format!("must be within ±{MAX_ANCHOR_LATITUDE_DEG}, got {}", self.lat_deg),
            ));
        }
        if !(self.lon_deg.is_finite() && self.lon_deg.abs() <= 180.0) {
            return Err(("lon_deg", format!("must be within ±180, got {}", self.lon_deg)));
        }
        if !self.azimuth_rad.is_finite() {
            return Err(("azimuth_rad", format!("must be finite, got {}", self.azimuth_rad)));
        }
        if !self.scale.iter().all(|s| s.is_finite() && *s > 0.0) {
            return Err(("scale", format!("must be finite and > 0, got {:?}", self.scale)));
        }
        Ok(())
    }

    /// The tangent plane's unit east, north and up vectors in ECEF at the origin (the ENU
    /// rotation of TR8350.2 §4 / Navipedia "Transformations between ECEF and ENU").
    fn enu_axes(&self) -> [[f64; 3]; 3] {
        let (lat, lon) = (self.lat_deg.to_radians(), self.lon_deg.to_radians());
        let (sl, cl, so, co) = (lat.sin(), lat.cos(), lon.sin(), lon.cos());
        [[-so, co, 0.0], [-sl * co, -sl * so, cl], [cl * co, cl * so, sl]]
    }

    fn origin(&self) -> LatLon {
        LatLon { lat_deg: self.lat_deg, lon_deg: self.lon_deg }
    }

    /// Site-frame metres to east/north ground metres.
    fn to_east_north(self, x: f64, y: f64) -> [f64; 2] {
        let (sa, ca) = self.azimuth_rad.sin_cos();
        let (gx, gy) = (x * self.scale[0], y * self.scale[1]);
        [gx * ca + gy * sa, -gx * sa + gy * ca]
    }

    /// The site-frame point (x, y), m, as latitude/longitude.
    pub fn to_lat_lon(&self, x: f64, y: f64) -> LatLon {
        let [e, n] = self.to_east_north(x, y);
        let [east, north, _] = self.enu_axes();
        let o = self.origin().ecef();
        LatLon::from_ecef(std::array::from_fn(|i| o[i] + e * east[i] + n * north[i]))
    }

    /// The latitude/longitude as a site-frame point (x, y), m: the inverse of
    /// [`to_lat_lon`](Self::to_lat_lon).
    pub fn to_site(&self, at: LatLon) -> [f64; 2] {
        let (p, o) = (at.ecef(), self.origin().ecef());
        let d: [f64; 3] = std::array::from_fn(|i| p[i] - o[i]);
        let [east, north, _] = self.enu_axes();
        let dot = |v: [f64; 3]| v[0] * d[0] + v[1] * d[1] + v[2] * d[2];
        let (e, n) = (dot(east), dot(north));
        let (sa, ca) = self.azimuth_rad.sin_cos();
        [(e * ca - n * sa) / self.scale[0], (e * sa + n * ca) / self.scale[1]]
    }

    /// The true bearing, degrees clockwise from north in [0, 360), of a direction given in
    /// radians clockwise from the site's +y axis (a position's heading).
    pub fn bearing_deg(&self, heading_rad: f64) -> f64 {
        let [e, n] = self.to_east_north(heading_rad.sin(), heading_rad.cos());
        e.atan2(n).to_degrees().rem_euclid(360.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// Ground distance between two points, m: Vincenty's inverse formula would do; the chord
    /// between their ECEF points differs from the arc by under a micrometre at building scale.
    fn chord(a: LatLon, b: LatLon) -> f64 {
        let (p, q) = (a.ecef(), b.ecef());
        ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt()
    }

    #[test]
    fn ecef_round_trips_to_the_nanodegree() {
        for (lat, lon) in [(0.0, 0.0), (30.29, 120.07), (-45.5, -73.2), (60.0, 24.0), (88.9, 179.9)] {
            let p = LatLon::new(lat, lon).unwrap();
            let back = LatLon::from_ecef(p.ecef());
            assert_relative_eq!(back.lat_deg, lat, epsilon = 1e-9);
            assert_relative_eq!(back.lon_deg, lon, epsilon = 1e-9);
        }
    }

    #[test]
    fn metres_become_the_right_ground_distance_and_direction() {
        let anchor = Anchor::at(LatLon::new(30.29, 120.07).unwrap());
        let origin = anchor.to_lat_lon(0.0, 0.0);
        assert_relative_eq!(origin.lat_deg, 30.29, epsilon = 1e-12);
        // 300 m east and 200 m north: the chord is the plane distance to within millimetres.
        let p = anchor.to_lat_lon(300.0, 200.0);
        assert_relative_eq!(chord(origin, p), 300f64.hypot(200.0), epsilon = 5e-3);
        assert!(p.lat_deg > 30.29 && p.lon_deg > 120.07);
        // One degree of latitude at 30°N is 110 852 m (meridian arc, WGS84).
        let north = anchor.to_site(LatLon::new(30.2901, 120.07).unwrap());
        assert_relative_eq!(north[1], 11.0852, epsilon = 1e-3);
        assert_relative_eq!(north[0], 0.0, epsilon = 1e-6);
    }

    #[test]
    fn site_and_lat_lon_convert_both_ways_with_rotation_and_scale() {
        let anchor = Anchor { lat_deg: -33.86, lon_deg: 151.21, azimuth_rad: 0.7, scale: [0.999, 1.004] };
        // To the micrometre: the tangent plane's height above the ellipsoid (25 mm at 565 m) is
        // dropped on the way back along a normal tilted by 565 m / 6 400 km.
        for (x, y) in [(0.0, 0.0), (12.5, -7.25), (-250.0, 310.0), (400.0, 400.0)] {
            let back = anchor.to_site(anchor.to_lat_lon(x, y));
            assert_relative_eq!(back[0], x, epsilon = 1e-5);
            assert_relative_eq!(back[1], y, epsilon = 1e-5);
        }
    }

    #[test]
    fn a_rotated_frame_turns_positions_and_bearings() {
        let origin = LatLon::new(60.0, 24.0).unwrap();
        let quarter = Anchor { azimuth_rad: std::f64::consts::FRAC_PI_2, ..Anchor::at(origin) };
        // +y points east: 100 m along y is 100 m east, at the origin's latitude.
        let p = quarter.to_site(quarter.to_lat_lon(0.0, 100.0));
        assert_relative_eq!(p[1], 100.0, epsilon = 1e-6);
        let east = Anchor::at(origin).to_site(quarter.to_lat_lon(0.0, 100.0));
        assert_relative_eq!(east[0], 100.0, epsilon = 1e-6);
        assert_relative_eq!(east[1], 0.0, epsilon = 1e-3);
        assert_relative_eq!(quarter.bearing_deg(0.0), 90.0, epsilon = 1e-9);
        assert_relative_eq!(quarter.bearing_deg(300f64.to_radians()), 30.0, epsilon = 1e-9);
        assert_relative_eq!(
            Anchor::at(origin).bearing_deg(-0.5),
            360.0 - 0.5f64.to_degrees(),
            epsilon = 1e-9
        );
    }

    #[test]
    fn bad_coordinates_and_anchors_are_refused() {
        for (lat, lon, field) in [
            (f64::NAN, 0.0, "latitude"),
            (90.5, 0.0, "latitude"),
            (0.0, 181.0, "longitude"),
            (0.0, f64::INFINITY, "longitude"),
        ] {
            assert!(
                matches!(LatLon::new(lat, lon), Err(GeoError::InvalidCoordinate { field: f, .. }) if f == field)
            );
        }
        let good = Anchor::at(LatLon::new(1.0, 2.0).unwrap());
        assert!(good.check().is_ok());
        for (bad, field) in [
            (Anchor { lat_deg: 89.5, ..good }, "lat_deg"),
            (Anchor { lon_deg: -200.0, ..good }, "lon_deg"),
            (Anchor { azimuth_rad: f64::NAN, ..good }, "azimuth_rad"),
            (Anchor { scale: [1.0, 0.0], ..good }, "scale"),
        ] {
            assert_eq!(bad.check().unwrap_err().0, field);
        }
    }
}
