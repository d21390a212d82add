//! The C API's geofences: add a circle or a polygon, remove one. Entries and exits reach the
//! status callback (`WAYMARK_STATUS_KIND_GEOFENCE_ENTERED` / `_EXITED`; docs/zones.md).

use super::{fail, fail_with, string_arg, waymark_engine, waymark_result, with_handle, write};
use ::waymark_engine::geofence::{Geofence, GeofenceShape};
use std::ffi::c_char;

/// Adds `geofence` to the engine behind `engine`.
fn add(engine: *mut waymark_engine, id: *const c_char, floor: u32, shape: GeofenceShape) -> waymark_result {
    with_handle(engine, |handle| {
        let id = match string_arg(id, "id") {
            Ok(id) => id,
            Err(code) => return code,
        };
        let fence = Geofence { id, floor: floor as usize, shape };
        match handle.call_undoable(|e| Ok(e.add_geofence(fence)?)) {
            Ok(()) => waymark_result::Ok,
            Err(e) => fail_with(&e),
        }
    })
}

/// Adds a circular geofence named `id` (NUL-terminated UTF-8, unique among the engine's
/// geofences) on `floor`: the points within `radius_m` of (x, y), in the site's metric frame.
/// From the next position on, entering and leaving it reach the status callback, with the
/// hysteresis of the site's zones; a person already inside is reported as entering. Returns
/// `WAYMARK_RESULT_INPUT_REJECTED`, changing nothing, for an empty or taken id, an unknown
/// floor, a centre or radius that is not finite, a radius not > 0, or a circle that holds no
/// place of the site.
#[no_mangle]
pub extern "C" fn waymark_engine_add_geofence_circle(
    engine: *mut waymark_engine,
    id: *const c_char,
    floor: u32,
    x: f64,
    y: f64,
    radius_m: f64,
) -> waymark_result {
    add(engine, id, floor, GeofenceShape::Circle { x, y, radius_m })
}

/// Adds a polygonal geofence named `id` on `floor`: the inside of the polygon whose
/// `vertex_count` vertices (at least 3) are `xy[0..2 * vertex_count]` as x, y pairs in the
/// site's metric frame (the last vertex joins the first). Otherwise as
/// `waymark_engine_add_geofence_circle`; also rejected: fewer than 3 vertices, or one that is
/// not finite.
#[no_mangle]
pub extern "C" fn waymark_engine_add_geofence_polygon(
    engine: *mut waymark_engine,
    id: *const c_char,
    floor: u32,
    xy: *const f64,
    vertex_count: usize,
) -> waymark_result {
    if xy.is_null() && vertex_count > 0 {
        return fail(waymark_result::NullParameter, "xy must not be NULL when vertex_count > 0");
    }
    let Some(values) = vertex_count.checked_mul(2) else {
        return fail(waymark_result::InputRejected, "vertex_count is too large");
    };
    let vertices = if values == 0 {
        Vec::new()
    } else {
        // SAFETY: a non-NULL `xy` points to `2 * vertex_count` readable doubles (the header's
        // contract); they are copied before the call returns.
        let xy = unsafe { std::slice::from_raw_parts(xy, values) };
        xy.chunks_exact(2).map(|p| [p[0], p[1]]).collect()
    };
    add(engine, id, floor, GeofenceShape::Polygon { vertices })
}

/// Removes the geofence `id` (no exit event); `*removed` (may be NULL) says whether there was
/// one.
#[no_mangle]
pub extern "C" fn waymark_engine_remove_geofence(
    engine: *mut waymark_engine,
    id: *const c_char,
    removed: *mut bool,
) -> waymark_result {
    with_handle(engine, |handle| {
        let id = match string_arg(id, "id") {
            Ok(id) => id,
            Err(code) => return code,
        };
        match handle.call_undoable(|e| Ok(e.remove_geofence(&id))) {
            Ok(was) => {
                write(removed, was);
                waymark_result::Ok
            }
            Err(e) => fail_with(&e),
        }
    })
}
