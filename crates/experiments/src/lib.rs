//! The papers' experiments and Waymark's own measurements on the simulator (`waymark-sim`):
//! simulated walks tracked by engines fed as an app feeds them (the demo), Hoang Table 1 and
//! HIPE Table 5, the motion tracker alone, the long run, recovery after a kidnap or a radio
//! outage, and El Gemayel's Baum-Welch experiment (§IV). Everything is seeded and deterministic.

#![deny(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod baum_welch;
mod experiment;
pub mod longrun;
pub mod motion_eval;
mod paper;
pub mod recovery;

pub use experiment::{
    errors, run, track_walk, walk_seed, Experiment, ExperimentReport, Sensors, TrackPoint, TrackedWalk,
};
pub use paper::{run_papers, HipeTable5, HoangTable1, PaperExperiment, PaperReport, Table5Row};
