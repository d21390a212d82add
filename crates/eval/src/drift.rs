//! Radio drift in simulation (issue 62 item 4, docs/evidence.md#drift): the simulated office
//! surveyed with labelled walks, then a share of its access points move, vanish or appear
//! ([`waymark_sim::drift`]), and test walks on the drifted radio are scored on the stale site,
//! on the site refitted from walks without labels recorded after the drift (the path of
//! `waymark survey --unlabelled`, [`survey_with_unlabelled`]), with and without the rule that
//! replaces contradicted labelled fingerprints, and on a fresh labelled survey.

use crate::real::{evaluate_on, EvalError, EvalOptions};
use serde::Serialize;
use std::collections::BTreeMap;
use std::sync::Arc;
use waymark_engine::site::Site;
use waymark_sim::drift::{Drift, DriftError};
use waymark_sim::{imu, Office, OfficeConfig, Walk};
use waymark_survey::calibrate::{
    anchored_walk, survey_calibrated, survey_with_unlabelled, CalibrationOptions, CalibrationReport,
    FloorData, UnlabelledOptions, ANCHOR_FLOOR_MASS,
};
use waymark_survey::io::{Trace, Waypoint};
use waymark_survey::scoring::Metrics;
use waymark_survey::{ReplaceRule, Replaced, REPLACE_RULE};

/// Why the experiment could not run.
#[derive(Debug, thiserror::Error)]
pub enum DriftExperimentError {
    /// The drift asked for cannot be applied.
    #[error(transparent)]
    Drift(#[from] DriftError),
    /// A site could not be surveyed or scored.
    #[error(transparent)]
    Eval(#[from] EvalError),
    /// No seeds, or walks too short to score.
    #[error("{0}")]
    Empty(String),
}

impl From<waymark_survey::calibrate::CalibrationError> for DriftExperimentError {
    fn from(e: waymark_survey::calibrate::CalibrationError) -> Self {
        DriftExperimentError::Eval(e.into())
    }
}

/// The experiment's settings.
#[derive(Clone, Debug, Serialize)]
pub struct DriftExperiment {
    /// Share of the access points changed (moved, vanished or new): 0.3, issue 62's target.
    pub share: f64,
    /// Walks without labels recorded on the drifted radio: 20, issue 62's target.
    pub unlabelled_walks: usize,
    /// Labelled survey walks, before the drift and for the fresh survey after it: 12 of 150 m,
    /// what `waymark sim-export` writes (docs/surveying.md: they cover the office well enough
    /// for a surveyed site to position like the office's own).
    pub survey_walks: usize,
    /// Test walks on the drifted radio, per seed.
    pub test_walks: usize,
    /// Length of every walk, m.
    pub walk_length_m: f64,
    /// First seed (office, drift and walks).
    pub first_seed: u64,
    /// Seeds, each a new office, drift and set of walks.
    pub seeds: u64,
    /// Rounds of anchoring (`UnlabelledOptions::anchor_rounds`).
    pub anchor_rounds: usize,
    /// The rule of `refit-replace`.
    pub rule: ReplaceRule,
    /// Worker threads.
    #[serde(skip)]
    pub threads: usize,
}

impl Default for DriftExperiment {
    fn default() -> Self {
        DriftExperiment {
            share: 0.3,
            unlabelled_walks: 20,
            survey_walks: 12,
            test_walks: 10,
            walk_length_m: 150.0,
            first_seed: 0,
            seeds: 5,
            anchor_rounds: UnlabelledOptions::default().anchor_rounds,
            rule: REPLACE_RULE,
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
        }
    }
}

/// The sites a run scores, in the report's order.
pub const ARMS: [&str; 4] = ["stale", "refit", "refit-replace", "fresh"];

/// One seed's figures.
#[derive(Clone, Debug, Serialize)]
pub struct DriftRun {
    /// The seed.
    pub seed: u64,
    /// What the drift changed.
    pub drift: Drift,
    /// Forward-auto on the drifted test walks, per arm of [`ARMS`].
    pub arms: BTreeMap<String, Metrics>,
    /// Walks without labels anchored (of [`DriftExperiment::unlabelled_walks`]).
    pub anchored: u64,
    /// Mean distance of the first round's anchors from the truth, m.
    pub anchor_error_m: f64,
    /// What the rule replaced in `refit-replace`.
    pub replaced: Replaced,
}

/// The mean over seeds and its standard error (the seeds' standard deviation over √seeds).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct MeanSe {
    /// Mean over seeds.
    pub mean: f64,
    /// Its standard error.
    pub se: f64,
}

impl MeanSe {
    fn of(values: &[f64]) -> MeanSe {
        let n = values.len() as f64;
        if values.is_empty() {
            return MeanSe { mean: f64::NAN, se: f64::NAN };
        }
        let mean = values.iter().sum::<f64>() / n;
        let var = if values.len() > 1 {
            values.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / (n - 1.0)
        } else {
            f64::NAN
        };
        MeanSe { mean, se: (var / n).sqrt() }
    }
}

/// One arm over the seeds.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ArmSummary {
    /// Mean error, m.
    pub mean_m: MeanSe,
    /// 90th percentile, m.
    pub p90_m: MeanSe,
    /// Share within the 68% radius.
    pub hold_68: MeanSe,
    /// Share within the 95% radius.
    pub hold_95: MeanSe,
    /// Share on the right floor (the office has one).
    pub floor_hit: MeanSe,
    /// The arm's mean error over the fresh survey's, seed by seed.
    pub over_fresh: MeanSe,
}

/// The experiment's result.
#[derive(Clone, Debug, Serialize)]
pub struct DriftReport {
    /// The settings.
    pub experiment: DriftExperiment,
    /// Per seed.
    pub runs: Vec<DriftRun>,
    /// Per arm of [`ARMS`], over the seeds.
    pub summary: BTreeMap<String, ArmSummary>,
    /// Wall-clock time, s.
    pub seconds: f64,
}

/// A seed for walk `k` of kind `kind` (survey before, survey after, unlabelled, test) of
/// `seed`'s run: distinct for every walk of every run.
fn walk_seed(seed: u64, kind: u64, k: u64) -> u64 {
    seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ (kind << 40) ^ (k + 1)
}

/// A simulated walk as a recorded one: the IMU synthesised along it, its scans, and with
/// `labelled` the waypoints a surveyor taps at every state passed (a test walk's truth);
/// without, no waypoint and no floor, as a visitor's phone records it.
pub fn walk_trace(walk: &Walk, name: String, seed: u64, labelled: bool) -> Trace {
    let imu = imu::synthesize(&walk.trajectory, &imu::ImuConfig::default(), seed);
    let waypoints = if labelled {
        walk.trajectory
            .vertices()
            .iter()
            .map(|&(timestamp_ns, p)| Waypoint { timestamp_ns, x: p.x, y: p.y, floor: None })
            .collect()
    } else {
        Vec::new()
    };
    Trace {
        name,
        waypoints,
        accelerometer: imu.accelerometer,
        gyroscope: imu.gyroscope,
        magnetometer: imu.magnetometer,
        wifi_scans: walk.epochs.iter().map(|e| e.scan.clone()).collect(),
        ..Trace::default()
    }
}

/// `count` walks of `office` of kind `kind`, and the simulated walks behind them.
fn walks(
    office: &Office,
    x: &DriftExperiment,
    seed: u64,
    kind: u64,
    count: usize,
    labelled: bool,
) -> (Vec<Trace>, Vec<Walk>) {
    (0..count as u64)
        .map(|k| {
            let s = walk_seed(seed, kind, k);
            let walk = office.walk(s, x.walk_length_m);
            (walk_trace(&walk, format!("sim{seed}-{kind}-{k}"), s, labelled), walk)
        })
        .unzip()
}

/// The mean distance, m, of the anchors the stale `site` gives the walks without labels
/// ([`anchored_walk`], as the first round of [`survey_with_unlabelled`] places them) from
/// where the walker really was then.
fn anchor_error_m(
    site: &Arc<Site>,
    traces: &[Trace],
    truth: &[Walk],
    options: &CalibrationOptions,
    calibration: &CalibrationReport,
) -> Result<f64, DriftExperimentError> {
    let options = options.surveyed_with(calibration);
    let (mut sum, mut n) = (0.0, 0usize);
    for (trace, walk) in traces.iter().zip(truth) {
        let anchored =
            anchored_walk(site, trace, &options, calibration.fingerprint_radius_m / 2.0, ANCHOR_FLOOR_MASS)
                .map_err(|e| DriftExperimentError::Empty(format!("anchoring: {e}")))?;
        for w in anchored.iter().flat_map(|(_, t)| &t.waypoints) {
            let p = walk.trajectory.pose_at(w.timestamp_ns).position;
            sum += ((p.x - w.x).powi(2) + (p.y - w.y).powi(2)).sqrt();
            n += 1;
        }
    }
    Ok(if n > 0 { sum / n as f64 } else { f64::NAN })
}

/// Forward-auto on the floor's test walks on `site`.
fn score(
    site: impl Into<Arc<Site>>,
    floors: &[FloorData],
    options: &EvalOptions,
    calibration: &CalibrationReport,
) -> Result<Metrics, EvalError> {
    let options = options.surveyed_with(calibration);
    let (reports, _) = evaluate_on(&site.into(), floors, &options, &|| ())?;
    reports
        .get("forward-auto")
        .map(|r| r.pooled.clone())
        .ok_or_else(|| EvalError::Empty("forward-auto was not scored".into()))
}

/// One seed's run.
pub fn run_seed(x: &DriftExperiment, seed: u64) -> Result<DriftRun, DriftExperimentError> {
    let office = Office::generate(&OfficeConfig { seed, ..OfficeConfig::default() });
    let (drifted, drift) = office.drifted(x.share, walk_seed(seed, 0, 0))?;
    let (before, _) = walks(&office, x, seed, 1, x.survey_walks, true);
    let (after, _) = walks(&drifted, x, seed, 2, x.survey_walks, true);
    let (unlabelled, unlabelled_truth) = walks(&drifted, x, seed, 3, x.unlabelled_walks, false);
    let (test, _) = walks(&drifted, x, seed, 4, x.test_walks, true);
    let floor = |survey: Vec<Trace>| FloorData {
        name: "office".into(),
        dir: Default::default(),
        plan: None,
        survey,
        test: test.clone(),
        geo: None,
    };
    let options = EvalOptions {
        calibration: CalibrationOptions { threads: x.threads, ..CalibrationOptions::default() },
        configurations: vec!["forward-auto".into()],
        habits: None,
    };
    let stale_floors = [floor(before)];
    let mut arms = BTreeMap::new();
    let (site, _, calibration) = survey_calibrated(&stale_floors, &options.calibration, &|| ())?;
    let site = Arc::new(site);
    let anchor_error_m =
        anchor_error_m(&site, &unlabelled, &unlabelled_truth, &options.calibration, &calibration)?;
    arms.insert("stale".to_string(), score(site, &stale_floors, &options, &calibration)?);
    let mut anchored = 0;
    let mut replaced = Replaced::default();
    for (arm, replace_contradicted) in [("refit", false), ("refit-replace", true)] {
        let rounds = UnlabelledOptions {
            replace: replace_contradicted.then_some(x.rule),
            anchor_rounds: x.anchor_rounds,
            ..UnlabelledOptions::default()
        };
        let (site, _, calibration, history) =
            survey_with_unlabelled(&stale_floors, &unlabelled, &options.calibration, rounds, &|| ())?;
        anchored = history.iter().map(|r| r.walks).max().unwrap_or(0);
        if replace_contradicted {
            replaced = history.last().map(|r| r.replaced).unwrap_or_default();
        }
        arms.insert(arm.to_string(), score(site, &stale_floors, &options, &calibration)?);
    }
    let fresh_floors = [floor(after)];
    let (site, _, calibration) = survey_calibrated(&fresh_floors, &options.calibration, &|| ())?;
    arms.insert("fresh".to_string(), score(site, &fresh_floors, &options, &calibration)?);
    Ok(DriftRun { seed, drift, arms, anchored, anchor_error_m, replaced })
}

/// Every seed's run, `on_run` called after each, and the summary over them.
pub fn run(
    x: &DriftExperiment,
    mut on_run: impl FnMut(&DriftRun),
) -> Result<DriftReport, DriftExperimentError> {
    if x.seeds == 0 || x.test_walks == 0 || x.survey_walks == 0 {
        return Err(DriftExperimentError::Empty(
            "seeds, survey walks and test walks must be at least 1".into(),
        ));
    }
    let started = std::time::Instant::now();
    let mut runs = Vec::new();
    for seed in x.first_seed..x.first_seed + x.seeds {
        let r = run_seed(x, seed)?;
        on_run(&r);
        runs.push(r);
    }
    let summary = ARMS
        .iter()
        .map(|&arm| {
            let take = |f: &dyn Fn(&Metrics) -> f64| {
                MeanSe::of(&runs.iter().map(|r| f(&r.arms[arm])).collect::<Vec<_>>())
            };
            let over_fresh = MeanSe::of(
                &runs.iter().map(|r| r.arms[arm].mean_m / r.arms["fresh"].mean_m).collect::<Vec<_>>(),
            );
            let summary = ArmSummary {
                mean_m: take(&|m| m.mean_m),
                p90_m: take(&|m| m.p90_m),
                hold_68: take(&|m| m.accuracy_68_hit),
                hold_95: take(&|m| m.accuracy_95_hit),
                floor_hit: take(&|m| m.floor_hit),
                over_fresh,
            };
            (arm.to_string(), summary)
        })
        .collect();
    Ok(DriftReport { experiment: x.clone(), runs, summary, seconds: started.elapsed().as_secs_f64() })
}
