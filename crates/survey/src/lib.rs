//! Building a Waymark site from survey walks: reading Indoor Location Competition 2.0 traces
//! and floor plans ([`io`]), fitting fingerprints and the walkable graph ([`survey`]), the
//! walkers' step model ([`motion`]), replaying walks through the engine ([`replay`]) to score
//! them ([`metrics`], [`scoring`]), and the per-site calibration a shipped site file carries,
//! chosen on held-out survey walks ([`calibrate`]).
//!
//! This crate is a tool beside the SDK: it depends on `waymark`, never the reverse, and apps
//! do not link it.

#![deny(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

mod build;
pub mod calibrate;
pub mod io;
pub mod metrics;
pub mod motion;
pub mod replay;
pub mod scoring;

pub use build::*;
pub use motion::{calibrate_motion, MotionCalibration};
