//! Waymark's indoor positioning engine, in pure Rust: an [`Engine`] over a surveyed [`Site`]
//! takes raw inertial samples and WiFi / BLE scans and returns position, floor, zone and
//! accuracy radii, one [`Epoch`] per scan, fused by a hidden Markov model.
//!
//! This crate is what Rust apps and Waymark's tools (survey, simulator, evaluation, the
//! `waymark` command) depend on. Mobile apps link the SDK library instead, the `waymark`
//! crate at the repository's root: the same engine behind uniffi (Kotlin, Swift) and a C
//! ABI. The repository's README.md shows a session from site file to learned habits in
//! Rust; it is a doctest of this crate.
#![forbid(unsafe_code)]
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
// habit models, routes on the walkable graph and the survey recorder.
pub mod evidence;
pub mod geofence;
pub mod habits;
pub mod hmm;
pub mod radio;
pub mod recorder;
pub mod route;
pub mod sensors;
pub mod site;

pub use config::{
    EngineConfig, MovementVectorConfig, RegionsConfig, TransitionModel, ZoneHysteresis,
    DEFAULT_ESTIMATE_STATES,
};
pub use engine::{
    Engine, Epoch, InputStats, Position, ScanTiming, SessionEvidence, SharedEmissions, StatusEvent,
    TrackPoint, MAX_RSSI_DBM,
};
#[cfg(feature = "fault-injection")]
pub use engine::{EngineSnapshot, FAULT_INJECTION_MID_EPOCH_NS};
pub use error::{Error, InputError};
pub use fix::PositionFix;
pub use geofence::{Geofence, GeofenceError, GeofenceShape};
pub use history::{EpochInput, EpochRecord};
pub use radio::{Reading, Salt, Scan, TransmitterId};
pub use recorder::{RecorderError, RecorderOptions, RecordingStats, SurveyRecorder};
pub use route::{Destination, FloorPoint, Progress, Route, RouteError, RouteTracker};
pub use site::{Site, SiteError, Zone, ZoneKind};

/// The README's Rust example, compiled and run by `cargo test --doc` and nothing else.
#[cfg(doctest)]
#[doc = include_str!("../../../README.md")]
struct ReadmeDoctests;

/// Nanoseconds in a millisecond: the FFIs and site files give ages in ms, the engine keeps ns.
pub(crate) const NS_PER_MS: u64 = 1_000_000;
