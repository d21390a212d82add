//! Simulated walks tracked by fresh engines fed exactly as an app feeds them: raw inertial
//! batches up to each scan, then the scan: the demo, the papers' experiments and the tests.

use nalgebra::Point2;
use std::sync::Arc;
use waymark_engine::sensors::SensorSample;
use waymark_engine::site::{Site, PSEUDO_SPACING_M};
use waymark_engine::Error;
use waymark_engine::{Engine, Position};
use waymark_engine::{EngineConfig, TransitionModel};
use waymark_sim::imu::{synthesize, ImuConfig, ImuTrace};
use waymark_sim::{Office, OfficeConfig, Walk};
use waymark_survey::metrics::{EpochError, ErrorSummary};

/// Which inertial streams a run feeds to the engine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sensors {
    /// Accelerometer batches.
    pub accelerometer: bool,
    /// Gyroscope batches.
    pub gyroscope: bool,
    /// Magnetometer batches.
    pub magnetometer: bool,
}

impl Sensors {
    /// All three.
    pub const ALL: Sensors = Sensors { accelerometer: true, gyroscope: true, magnetometer: true };
    /// None: radio only.
    pub const NONE: Sensors = Sensors { accelerometer: false, gyroscope: false, magnetometer: false };
}

/// Samples of `stream` with `from < t ≤ to`.
fn between(stream: &[SensorSample], from: Option<u64>, to: u64) -> &[SensorSample] {
    let start = from.map_or(0, |f| stream.partition_point(|s| s.timestamp_ns <= f));
    let end = stream.partition_point(|s| s.timestamp_ns <= to).max(start);
    &stream[start..end]
}

/// One epoch of a tracked walk.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackPoint {
    /// Where the phone was.
    pub truth: Point2<f64>,
    /// The zone it was in.
    pub truth_zone: Option<usize>,
    /// What the engine said.
    pub position: Position,
    /// What changed about the session at that epoch (zones entered and left, ...).
    pub status: Vec<waymark_engine::StatusEvent>,
}

/// A tracked walk: every epoch's position, and the error of the Viterbi track `lag` epochs
/// behind the newest, for each lag below `lags`.
pub struct TrackedWalk {
    /// Epoch by epoch.
    pub points: Vec<TrackPoint>,
    /// `lag_errors[lag]`: errors of the smoothed estimate `lag` epochs back
    /// ([`Engine::smoothed_position`]), m.
    pub lag_errors: Vec<Vec<f64>>,
}

/// Tracks `walk` with a fresh engine on `site`, feeding the `sensors` streams of `imu` in
/// batches up to each scan.
pub fn track_walk(
    site: &Arc<Site>,
    config: &EngineConfig,
    sensors: Sensors,
    walk: &Walk,
    imu: &ImuTrace,
    lags: usize,
) -> Result<TrackedWalk, Error> {
    // The smoother keeps as many steps as the configured lag: enough for every lag scored.
    let config = EngineConfig {
        fixed_lag_epochs: config.fixed_lag_epochs.max(lags.saturating_sub(1)),
        ..config.clone()
    };
    let mut engine = Engine::new(Arc::clone(site), config)?;
    let mut points = Vec::with_capacity(walk.epochs.len());
    let mut lag_errors = vec![Vec::new(); lags];
    let mut previous = None;
    for (k, epoch) in walk.epochs.iter().enumerate() {
        let t = epoch.scan.timestamp_ns;
        if sensors.accelerometer {
            engine.push_accelerometer(between(&imu.accelerometer, previous, t));
        }
        if sensors.gyroscope {
            engine.push_gyroscope(between(&imu.gyroscope, previous, t));
        }
        if sensors.magnetometer {
            engine.push_magnetometer(between(&imu.magnetometer, previous, t));
        }
        previous = Some(t);
        // A scan where no access point was heard is rejected (and counted): nothing to score.
        let Ok(waymark_engine::Epoch { position, status, .. }) = engine.push_scan(&epoch.scan) else {
            continue;
        };
        points.push(TrackPoint { truth: epoch.truth, truth_zone: epoch.zone, position, status });
        for (lag, out) in lag_errors.iter_mut().enumerate() {
            let back = engine.smoothed_position(lag).zip(k.checked_sub(lag));
            if let Some((p, past)) = back {
                out.push(nalgebra::distance(&walk.epochs[past].truth, &Point2::new(p.x, p.y)));
            }
        }
    }
    Ok(TrackedWalk { points, lag_errors })
}

/// Scores a track (by zone too: the simulated office has zones).
pub fn errors(points: &[TrackPoint]) -> Vec<EpochError> {
    points
        .iter()
        .map(|p| EpochError {
            error_m: nalgebra::distance(&p.truth, &Point2::new(p.position.x, p.position.y)),
            accuracy_m: p.position.accuracy_m,
            floor_correct: p.position.floor == 0,
            zone_correct: Some(p.position.zone == p.truth_zone),
        })
        .collect()
}

/// Random walks through the simulated office, each tracked by a fresh engine.
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
    /// Inertial streams fed to it.
    pub sensors: Sensors,
    /// The phone's inertial sensors.
    pub imu: ImuConfig,
    /// Whether the site gets pseudo states (Hoang §5).
    pub pseudo_states: bool,
}

impl Default for Experiment {
    fn default() -> Self {
        Self {
            office: OfficeConfig::default(),
            walks: 100,
            walk_length_m: 200.0,
            engine: EngineConfig::default(),
            sensors: Sensors::ALL,
            imu: ImuConfig::default(),
            pseudo_states: true,
        }
    }
}

impl Experiment {
    /// Hoang's "RSSI only": surveyed states, uniform reach, no inertial sensors.
    pub fn rssi_only() -> Self {
        Self {
            engine: EngineConfig { transition: TransitionModel::Reach, ..EngineConfig::default() },
            sensors: Sensors::NONE,
            pseudo_states: false,
            ..Self::default()
        }
    }
}

/// What came out.
#[derive(Clone, Debug)]
pub struct ExperimentReport {
    /// Pooled error figures.
    pub summary: ErrorSummary,
    /// The first walk, epoch by epoch.
    pub first_track: Vec<TrackPoint>,
    /// Surveyed states in the site.
    pub surveyed_states: usize,
    /// States the engine ran on (with pseudo states, if any).
    pub states: usize,
    /// Access points in the building.
    pub access_points: usize,
}

/// The seed of walk `w` of a building seeded `seed`: one `--seed` fixes everything.
pub fn walk_seed(seed: u64, w: usize) -> u64 {
    seed.wrapping_mul(1_000_003).wrapping_add(w as u64)
}

/// Runs the experiment.
pub fn run(experiment: &Experiment) -> Result<ExperimentReport, Error> {
    let office = Office::generate(&experiment.office);
    let surveyed = office.site.states().len();
    let site = Arc::new(if experiment.pseudo_states {
        office.site.with_pseudo_states(PSEUDO_SPACING_M)
    } else {
        office.site.clone()
    });
    let mut all = Vec::new();
    let mut first_track = Vec::new();
    for w in 0..experiment.walks {
        let seed = walk_seed(experiment.office.seed, w);
        let walk = office.walk(seed, experiment.walk_length_m);
        let imu = synthesize(&walk.trajectory, &experiment.imu, seed);
        let tracked = track_walk(&site, &experiment.engine, experiment.sensors, &walk, &imu, 0)?;
        all.extend(errors(&tracked.points));
        if w == 0 {
            first_track = tracked.points;
        }
    }
    Ok(ExperimentReport {
        summary: ErrorSummary::new(&all),
        first_track,
        surveyed_states: surveyed,
        states: site.states().len(),
        access_points: office.field.access_points.len(),
    })
}
