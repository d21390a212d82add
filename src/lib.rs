#![doc = include_str!("../README.md")]
#![deny(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

// The engine and what an app hands it and gets back: private modules, their types re-exported
// below.
mod config;
mod engine;
mod error;
mod fix;
mod history;

// The building blocks under the engine, public for Rust apps and for the tools that build site
// files: the site model and its file formats, radio fingerprints, the motion pipeline, the HMM,
// habit models, routes on the walkable graph, the survey recorder, and the binding surface
// Kotlin, Swift and C see.
pub mod ffi;
pub mod geofence;
pub mod habits;
pub mod hmm;
pub mod radio;
pub mod recorder;
pub mod route;
pub mod sensors;
pub mod site;

pub use config::{
    EngineConfig, HipeConfig, HoangConfig, TransitionModel, ZoneHysteresis, DEFAULT_ESTIMATE_STATES,
};
pub use engine::{
    Engine, EngineSnapshot, Epoch, InputStats, Position, ScanTiming, SharedEmissions, StatusEvent,
    TrackPoint, FAULT_INJECTION_MID_EPOCH_NS, MAX_RSSI_DBM,
};
pub use error::{Error, InputError};
pub use fix::PositionFix;
pub use geofence::{Geofence, GeofenceError, GeofenceShape};
pub use history::{EpochInput, EpochRecord};
pub use radio::{Reading, Salt, Scan, TransmitterId};
pub use recorder::{RecorderError, RecorderOptions, RecordingStats, SurveyRecorder};
pub use route::{Destination, FloorPoint, Progress, Route, RouteError, RouteTracker};
pub use site::{Site, SiteError, Zone, ZoneKind};

/// Nanoseconds in a millisecond: the FFIs and site files give ages in ms, the engine keeps ns.
pub(crate) const NS_PER_MS: u64 = 1_000_000;

uniffi::setup_scaffolding!();
