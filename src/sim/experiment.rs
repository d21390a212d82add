//! Hoang §6.1's experiment: random walks through a simulated office, each tracked by a fresh
//! engine, errors pooled over all epochs.

use super::{Office, OfficeConfig};
use crate::config::EngineConfig;
use crate::engine::{Engine, Position};
use crate::error::Error;
use crate::eval::{EpochError, ErrorSummary};
use nalgebra::Point2;
use std::sync::Arc;

/// What to run.
#[derive(Clone, Debug, PartialEq)]
pub struct Experiment {
    /// The building (its seed also seeds the walks).
    pub office: OfficeConfig,
    /// Number of walks: 100 (Hoang §6.1: "averaged over 100 experiments").
    pub walks: usize,
    /// Length of each walk, m: 200 (Hoang §6.1: "of about 200 m").
    pub walk_length_m: f64,
    /// The engine under test.
    pub engine: EngineConfig,
}

impl Default for Experiment {
    fn default() -> Self {
        Self {
            office: OfficeConfig::default(),
            walks: 100,
            walk_length_m: 200.0,
            engine: EngineConfig::default(),
        }
    }
}

/// One epoch of a tracked walk.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackPoint {
    /// Where the phone was.
    pub truth: Point2<f64>,
    /// What the engine said.
    pub position: Position,
}

/// What came out.
#[derive(Clone, Debug)]
pub struct ExperimentReport {
    /// Pooled error figures.
    pub summary: ErrorSummary,
    /// The first walk, epoch by epoch.
    pub first_track: Vec<TrackPoint>,
    /// States in the site.
    pub states: usize,
    /// Access points in the building.
    pub access_points: usize,
}

/// Runs the experiment.
pub fn run(experiment: &Experiment) -> Result<ExperimentReport, Error> {
    let office = Office::generate(&experiment.office);
    let site = Arc::new(office.site.clone());
    let mut errors = Vec::new();
    let mut first_track = Vec::new();
    for w in 0..experiment.walks {
        // Walk seeds are derived from the building's so that one --seed fixes everything.
        let walk = office.walk(
            experiment.office.seed.wrapping_mul(1_000_003).wrapping_add(w as u64),
            experiment.walk_length_m,
        );
        let mut engine = Engine::new(Arc::clone(&site), experiment.engine.clone())?;
        for epoch in &walk.epochs {
            // A scan where no access point was heard is rejected (and counted) by the engine;
            // it has no position to score.
            let Ok(position) = engine.push_scan(&epoch.scan) else {
                continue;
            };
            errors.push(EpochError {
                error_m: nalgebra::distance(&epoch.truth, &Point2::new(position.x, position.y)),
                accuracy_m: position.accuracy_m,
                floor_correct: position.floor == 0,
            });
            if w == 0 {
                first_track.push(TrackPoint { truth: epoch.truth, position });
            }
        }
    }
    Ok(ExperimentReport {
        summary: ErrorSummary::new(&errors),
        first_track,
        states: site.states().len(),
        access_points: office.field.access_points.len(),
    })
}
