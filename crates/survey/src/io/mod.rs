//! Reading recorded data: Indoor Location Competition 2.0 walks ([`ilc`]) and their floor plans
//! ([`floor_plan`]). A walk becomes the same calls an app makes — sensor batches, then the scan
//! they precede — in time order, whatever order the file had.

pub mod floor_plan;
pub mod ilc;

pub use floor_plan::{FloorPlan, FloorPlanError};
pub use ilc::{Event, ReadStats, Trace, TraceError, Waypoint};
