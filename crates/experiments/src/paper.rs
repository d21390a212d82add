//! The papers' artificial-data experiments on the same simulated walks: Hoang Table 1 (RSSI
//! only, + step detection with and without the censoring model, + pseudo states) and HIPE
//! Table 5 (the four MDI scenarios and the MLE fingerprint baseline). Motion always comes from
//! raw synthetic IMU samples through the engine's own tracker.

use crate::experiment::{errors, track_walk, walk_seed, Sensors};
use serde::Serialize;
use std::sync::Arc;
use waymark_engine::radio::RssiModel;
use waymark_engine::site::{Site, PSEUDO_SPACING_M};
use waymark_engine::Error;
use waymark_engine::{EngineConfig, TransitionModel};
use waymark_sim::imu::{synthesize, ImuConfig};
use waymark_sim::{Office, OfficeConfig, Walk};
use waymark_survey::metrics::{EpochError, ErrorSummary};

/// The papers' artificial-data experiments on one simulated building: Hoang et al. Table 1
/// and HIPE Table 5.
#[derive(Clone, Debug)]
pub struct PaperExperiment {
    /// Seed of the building and the walks.
    pub seed: u64,
    /// Walks: 100 (Hoang §6.1: "averaged over 100 experiments").
    pub runs: usize,
    /// Walk length: about 200 m (Hoang §6.1).
    pub walk_length_m: f64,
    /// The building.
    pub office: OfficeConfig,
    /// The phone's inertial sensors.
    pub imu: ImuConfig,
}

impl Default for PaperExperiment {
    fn default() -> Self {
        Self {
            seed: 0,
            runs: 100,
            walk_length_m: 200.0,
            office: OfficeConfig::default(),
            imu: ImuConfig::default(),
        }
    }
}

/// Hoang Table 1: mean positioning error, m.
#[derive(Clone, Debug, Serialize)]
pub struct HoangTable1 {
    /// RSSI only (paper: 1.74 m).
    pub rssi_only: f64,
    /// RSSI + step detection, fingerprints fitted ignoring censoring (paper: 1.42 m).
    pub rssi_step_uncensored: f64,
    /// RSSI + step detection (paper: 1.37 m).
    pub rssi_step: f64,
    /// RSSI + step detection + pseudo states (paper: 1.02 m).
    pub rssi_step_pseudo: f64,
}

/// One row of HIPE Table 5.
#[derive(Clone, Debug, Serialize)]
pub struct Table5Row {
    /// Root mean square error, m.
    pub rmse_m: f64,
    /// Mean error, m.
    pub mean_m: f64,
    /// Largest error, m.
    pub max_m: f64,
}

impl From<&ErrorSummary> for Table5Row {
    fn from(s: &ErrorSummary) -> Self {
        Self { rmse_m: s.rmse_m, mean_m: s.mean_error_m, max_m: s.max_error_m }
    }
}

/// HIPE Table 5 on the same walks.
#[derive(Clone, Debug, Serialize)]
pub struct HipeTable5 {
    /// Measured distance and heading.
    pub distance_heading: Table5Row,
    /// Measured distance only (no gyroscope, no magnetometer).
    pub distance: Table5Row,
    /// Measured heading and assumed speed (no accelerometer steps).
    pub heading_speed: Table5Row,
    /// Assumed speed only (no inertial sensors).
    pub speed: Table5Row,
    /// Maximum-likelihood fingerprinting, no HMM.
    pub mle: Table5Row,
}

/// The results of a [`PaperExperiment`], per paper table.
#[derive(Clone, Debug, Serialize)]
pub struct PaperReport {
    /// Hoang Table 1.
    pub hoang_table1: HoangTable1,
    /// HIPE Table 5.
    pub hipe_table5: HipeTable5,
    /// Full summaries of every method, by the same names.
    pub summaries: Vec<(String, ErrorSummary)>,
    /// Mean error of the smoothed estimate `lag` epochs behind the newest (the fixed-lag
    /// estimate, `Engine::smoothed_position`), for lag 0..=12, with
    /// the default engine (Hoang transitions, full motion, pseudo states).
    pub fixed_lag_mean_error_m: Vec<(usize, f64)>,
    /// Room-level accuracy of each method (El Gemayel et al. §II-B): the share of epochs whose
    /// most likely zone (one of the ten rooms, the aisle, the stair hall) was the true one.
    pub room_accuracy: Vec<(String, f64)>,
    /// Surveyed and pseudo states.
    pub surveyed_states: usize,
    /// States after adding pseudo states (Hoang: 81 + 125).
    pub states_with_pseudo: usize,
    /// Epochs scored per method.
    pub epochs: usize,
}

struct Method {
    name: &'static str,
    site: Arc<Site>,
    config: EngineConfig,
    sensors: Sensors,
}

/// HIPE's MLE baseline: each scan alone, the most likely surveyed state.
fn mle(site: &Site, walk: &Walk) -> Vec<EpochError> {
    let radio = site.radio();
    let mut ln = vec![0.0; site.states().len()];
    walk.epochs
        .iter()
        .filter_map(|epoch| {
            let resolved = radio.resolve(&epoch.scan, None);
            if resolved.observations.is_empty() {
                return None;
            }
            radio.ln_likelihood(&resolved.observations, &mut ln);
            let best = ln.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?.0;
            let at = site.states()[best].position;
            Some(EpochError {
                error_m: nalgebra::distance(&epoch.truth, &at),
                accuracy_m: f64::NAN,
                floor_correct: true,
                zone_correct: Some(site.zone_of(best) == epoch.zone),
            })
        })
        .collect()
}

/// Runs both papers' experiments.
pub fn run_papers(experiment: &PaperExperiment) -> Result<PaperReport, Error> {
    let office_em = Office::generate(&OfficeConfig { seed: experiment.seed, ..experiment.office.clone() });
    let office_naive = Office::generate(&OfficeConfig {
        seed: experiment.seed,
        model: RssiModel::NaiveGaussian,
        ..experiment.office.clone()
    });
    let surveyed = Arc::new(office_em.site.clone());
    let pseudo = Arc::new(office_em.site.with_pseudo_states(PSEUDO_SPACING_M));
    let naive = Arc::new(office_naive.site.clone());
    // Hoang's fixed Σ_v, as the paper simulates it.
    let with = |transition| {
        let mut config = EngineConfig { transition, ..EngineConfig::default() };
        config.movement_vector.measured_spread = false;
        config
    };
    let methods = [
        Method {
            name: "rssi_only",
            site: Arc::clone(&surveyed),
            config: with(TransitionModel::Reach),
            sensors: Sensors::NONE,
        },
        Method {
            name: "rssi_step_uncensored",
            site: Arc::clone(&naive),
            config: with(TransitionModel::MovementVector),
            sensors: Sensors::ALL,
        },
        Method {
            name: "rssi_step",
            site: Arc::clone(&surveyed),
            config: with(TransitionModel::MovementVector),
            sensors: Sensors::ALL,
        },
        Method {
            name: "rssi_step_pseudo",
            site: Arc::clone(&pseudo),
            config: with(TransitionModel::MovementVector),
            sensors: Sensors::ALL,
        },
        Method {
            name: "distance_heading",
            site: Arc::clone(&pseudo),
            config: with(TransitionModel::Regions),
            sensors: Sensors::ALL,
        },
        Method {
            name: "distance",
            site: Arc::clone(&pseudo),
            config: with(TransitionModel::Regions),
            sensors: Sensors { accelerometer: true, ..Sensors::NONE },
        },
        Method {
            name: "heading_speed",
            site: Arc::clone(&pseudo),
            config: with(TransitionModel::Regions),
            sensors: Sensors { accelerometer: false, ..Sensors::ALL },
        },
        Method {
            name: "speed",
            site: Arc::clone(&pseudo),
            config: with(TransitionModel::Regions),
            sensors: Sensors::NONE,
        },
    ];
    let mut scored: Vec<Vec<EpochError>> = vec![Vec::new(); methods.len() + 1];
    let mut lags: Vec<Vec<f64>> = vec![Vec::new(); 13];
    for run in 0..experiment.runs {
        let seed = walk_seed(experiment.seed, run);
        let walk = office_em.walk(seed, experiment.walk_length_m);
        let imu = synthesize(&walk.trajectory, &experiment.imu, seed);
        for (m, method) in methods.iter().enumerate() {
            let lag_count = if method.name == "rssi_step_pseudo" { lags.len() } else { 0 };
            let tracked = track_walk(&method.site, &method.config, method.sensors, &walk, &imu, lag_count)?;
            scored[m].extend(errors(&tracked.points));
            for (sink, e) in lags.iter_mut().zip(tracked.lag_errors) {
                sink.extend(e);
            }
        }
        scored[methods.len()].extend(mle(&surveyed, &walk));
    }
    let summaries: Vec<(String, ErrorSummary)> = methods
        .iter()
        .map(|m| m.name.to_owned())
        .chain(std::iter::once("mle".to_owned()))
        .zip(scored.iter().map(|e| ErrorSummary::new(e)))
        .collect();
    let get = |name: &str| &summaries.iter().find(|(n, _)| n == name).expect("every method is summarised").1;
    Ok(PaperReport {
        hoang_table1: HoangTable1 {
            rssi_only: get("rssi_only").mean_error_m,
            rssi_step_uncensored: get("rssi_step_uncensored").mean_error_m,
            rssi_step: get("rssi_step").mean_error_m,
            rssi_step_pseudo: get("rssi_step_pseudo").mean_error_m,
        },
        hipe_table5: HipeTable5 {
            distance_heading: get("distance_heading").into(),
            distance: get("distance").into(),
            heading_speed: get("heading_speed").into(),
            speed: get("speed").into(),
            mle: get("mle").into(),
        },
        fixed_lag_mean_error_m: lags
            .iter()
            .enumerate()
            .map(|(lag, e)| (lag, e.iter().sum::<f64>() / e.len().max(1) as f64))
            .collect(),
        surveyed_states: surveyed.states().len(),
        states_with_pseudo: pseudo.states().len(),
        epochs: get("rssi_only").epochs,
        room_accuracy: summaries.iter().map(|(n, s)| (n.clone(), s.zone_hit.unwrap_or(f64::NAN))).collect(),
        summaries,
    })
}
