//! The C API's WGS84 (docs/c.md#latitude-and-longitude): a point of a geo-referenced site to
//! latitude/longitude and back, and geofences given as latitude/longitude polygons. A route's
//! points convert with `waymark_route_to_lat_lon` (route.rs).

use super::{fail, fail_with, string_arg, waymark_engine, waymark_result, with_handle, write};
use crate::ffi::error::PositioningError;
use ::waymark_engine::geofence::Geofence;
use ::waymark_engine::site::{LatLon, Site};
use std::ffi::c_char;

/// Floor `floor`'s point (x, y) on `site` as latitude/longitude into `*latitude_deg` and
/// `*longitude_deg`; `InputRejected` for a site without an anchor, an unknown floor, or a
/// NaN or infinite x or y.
pub(super) fn site_to_lat_lon(
    site: &Site,
    floor: u32,
    x: f64,
    y: f64,
    latitude_deg: *mut f64,
    longitude_deg: *mut f64,
) -> waymark_result {
    if latitude_deg.is_null() || longitude_deg.is_null() {
        return fail(waymark_result::NullParameter, "latitude_deg and longitude_deg must not be NULL");
    }
    if !(x.is_finite() && y.is_finite()) {
        return fail(waymark_result::InputRejected, format!("({x}, {y}) is not finite"));
    }
    if site.lat_lon(0, 0.0, 0.0).is_none() {
        return fail(
            waymark_result::InputRejected,
            "the site is not geo-referenced (its file has no anchor)",
        );
    }
    match site.lat_lon(floor as usize, x, y) {
        Some(at) => {
            write(latitude_deg, at.lat_deg);
            write(longitude_deg, at.lon_deg);
            waymark_result::Ok
        }
        None => fail(
            waymark_result::InputRejected,
            format!("floor {floor} does not exist (the site has {} floors)", site.floors().len()),
        ),
    }
}

/// The point (x, y), m, of floor `floor` of the engine's site as a WGS84 latitude and
/// longitude, degrees, into `*latitude_deg` and `*longitude_deg` (neither may be NULL).
/// Returns `InputRejected` for a site that is not geo-referenced (its file has no `anchor`),
/// an unknown floor, or a NaN or infinite x or y.
#[no_mangle]
pub extern "C" fn waymark_engine_to_lat_lon(
    engine: *const waymark_engine,
    floor: u32,
    x: f64,
    y: f64,
    latitude_deg: *mut f64,
    longitude_deg: *mut f64,
) -> waymark_result {
    with_handle(engine, |handle| site_to_lat_lon(&handle.site(), floor, x, y, latitude_deg, longitude_deg))
}

/// A WGS84 latitude and longitude, degrees, as the point of floor `floor`'s frame of the
/// engine's site, m, into `*x` and `*y` (neither may be NULL): the inverse of
/// `waymark_engine_to_lat_lon`. Returns `InputRejected` for a site that is not
/// geo-referenced, an unknown floor, or a latitude or longitude out of range or not finite.
#[no_mangle]
pub extern "C" fn waymark_engine_from_lat_lon(
    engine: *const waymark_engine,
    floor: u32,
    latitude_deg: f64,
    longitude_deg: f64,
    x: *mut f64,
    y: *mut f64,
) -> waymark_result {
    if x.is_null() || y.is_null() {
        return fail(waymark_result::NullParameter, "x and y must not be NULL");
    }
    with_handle(engine, |handle| {
        let at = LatLon { lat_deg: latitude_deg, lon_deg: longitude_deg };
        match handle.site().site_point(Some(floor as usize), at) {
            Ok(p) => {
                write(x, p.x);
                write(y, p.y);
                waymark_result::Ok
            }
            Err(e) => fail(waymark_result::InputRejected, e.to_string()),
        }
    })
}

/// Adds a polygonal geofence named `id` on `floor` from its outline in WGS84: the
/// `vertex_count` vertices are `lat_lon[0..2 * vertex_count]` as latitude, longitude pairs,
/// degrees (a GeoJSON-style ring may end on its first vertex). As
/// `waymark_engine_add_geofence_polygon` once converted to the site's metres; also returns
/// `InputRejected`, changing nothing, on a site that is not geo-referenced, for a vertex out
/// of range, fewer than three distinct vertices, or edges that cross.
#[no_mangle]
pub extern "C" fn waymark_engine_add_geofence_polygon_lat_lon(
    engine: *mut waymark_engine,
    id: *const c_char,
    floor: u32,
    lat_lon: *const f64,
    vertex_count: usize,
) -> waymark_result {
    if lat_lon.is_null() && vertex_count > 0 {
        return fail(waymark_result::NullParameter, "lat_lon must not be NULL when vertex_count > 0");
    }
    let Some(values) = vertex_count.checked_mul(2) else {
        return fail(waymark_result::InputRejected, "vertex_count is too large");
    };
    let vertices: Vec<LatLon> = if values == 0 {
        Vec::new()
    } else {
        // SAFETY: a non-NULL `lat_lon` points to `2 * vertex_count` readable doubles (the
        // header's contract); they are copied before the call returns.
        let pairs = unsafe { std::slice::from_raw_parts(lat_lon, values) };
        pairs.chunks_exact(2).map(|p| LatLon { lat_deg: p[0], lon_deg: p[1] }).collect()
    };
    with_handle(engine, |handle| {
        let id = match string_arg(id, "id") {
            Ok(id) => id,
            Err(code) => return code,
        };
        let fence = match Geofence::from_lat_lon(&handle.site(), id, floor as usize, &vertices) {
            Ok(fence) => fence,
            Err(e) => return fail_with(&PositioningError::from(e)),
        };
        match handle.call_undoable(|e| Ok(e.add_geofence(fence)?)) {
            Ok(()) => waymark_result::Ok,
            Err(e) => fail_with(&e),
        }
    })
}
