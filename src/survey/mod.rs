//! Survey walks → a site file: reference states on a regular spacing over where the surveyors
//! walked, fingerprints fitted from the scans near each, the walkable graph, the site's north
//! and the walkers' step length.

pub mod motion;

pub use motion::{calibrate_motion, MotionCalibration};
