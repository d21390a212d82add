//! Reading recorded data: Indoor Location Competition 2.0 walks ([`ilc`]) and their floor plans
//! ([`floor_plan`]) or a venue's IMDF archive ([`imdf`]), and the IPIN competitions' GetSensorData logfiles ([`gsd`]). A walk
//! becomes the same calls an app makes — sensor batches, then the scan they precede — in time
//! order, whatever order the file had.

pub mod floor_plan;
pub mod gsd;
pub mod ilc;
pub mod imdf;

pub use floor_plan::{FloorPlan, FloorPlanError};
pub use gsd::{GeoFix, GsdWalk};
pub use ilc::{Event, PressureSample, ReadStats, Trace, TraceError, Waypoint};

/// Reads a walk in either format: a GetSensorData logfile ([`gsd`]), its ground truth placed
/// by `site` (the site's anchor and its floors' levels; without an anchor the walk has no
/// waypoints), or a competition walk ([`ilc`]).
pub fn read_walk(path: &std::path::Path, site: &waymark_engine::Site) -> Result<Trace, TraceError> {
    let bytes =
        std::fs::read(path).map_err(|source| TraceError::Io { path: path.display().to_string(), source })?;
    let text = String::from_utf8_lossy(&bytes);
    let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    if !gsd::is_gsd(&text) {
        return Ok(Trace::parse(&text, &name));
    }
    let walk = GsdWalk::parse(&text, &name);
    Ok(match site.anchor() {
        Some(anchor) => {
            let levels: Vec<Option<i32>> = site.floors().iter().map(|f| f.level).collect();
            walk.trace(anchor, &levels)
        }
        None => walk.trace,
    })
}
