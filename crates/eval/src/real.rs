//! The evaluation on recorded floors: the survey/test split, a site surveyed from the survey
//! walks, the test walks replayed through every configuration, and the errors at every scan
//! (truth interpolated between waypoints) and at every waypoint.
//!
//! No configuration reads a test walk's waypoints except to score it.

use nalgebra::Point2;
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;
use waymark_engine::habits::{clustered_ratio, HabitModel, HabitReport};
use waymark_engine::radio::Scan;
use waymark_engine::site::{Site, StateKind};
use waymark_engine::Engine;
use waymark_engine::EngineConfig;
use waymark_engine::EpochRecord;
use waymark_engine::SharedEmissions;
use waymark_survey::calibrate::{
    parallel_map, parallel_map_by_cost, replay_cost, survey_inputs, CalibrationError, CalibrationOptions,
    CalibrationReport, FloorData,
};
use waymark_survey::io::Trace;
use waymark_survey::replay::{replay, MotionMask, ReplayOptions, WaypointFeedback};
use waymark_survey::scoring::{decoded, score, score_scans, Estimate, Metrics, Scored, ZoneTruth};
use waymark_survey::{positioned_scans, survey, PreparedSurvey, SurveyOptions, SurveyReport};

/// Every configuration the evaluation scores, by JSON key.
pub const CONFIGURATIONS: [&str; 9] = [
    "wifi-knn",
    "wifi-mle",
    "forward-auto",
    "forward-distance-heading",
    "forward-distance",
    "forward-heading-speed",
    "forward-speed",
    "viterbi-auto",
    "fixed-lag-auto",
];

/// Why evaluation could not start.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// The floors could not be read, or the site surveyed and calibrated.
    #[error(transparent)]
    Calibration(#[from] CalibrationError),
    /// The survey could not build a site.
    #[error(transparent)]
    Site(#[from] waymark_engine::site::SiteError),
    /// The engine rejected its configuration.
    #[error(transparent)]
    Engine(#[from] waymark_engine::Error),
    /// Nothing to evaluate.
    #[error("{0}")]
    Empty(String),
    /// Habits could not be learned.
    #[error(transparent)]
    Habits(#[from] waymark_engine::habits::HabitError),
}

/// One configuration's figures.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ConfigurationReport {
    /// All floors together, scored at every WiFi scan between the first and last waypoint of
    /// each test walk, with the latest estimate at or before it ([`score_scans`]).
    pub pooled: Metrics,
    /// Per floor.
    pub floors: BTreeMap<String, Metrics>,
    /// All floors, scored at the test walks' waypoints (the latest estimate at or before each).
    pub waypoints: Metrics,
}

/// Weighted k-NN on raw survey scans (k = 5, weights 1/(d + 1 dB) — the 1 dB, one RSSI
/// reporting step, only keeps an exact match finite — and a missing reading counts as the
/// clip level): the classic fingerprinting baseline, one scan at a time
/// (`docs/tuning.md#knn-baseline`).
pub struct Knn {
    k: usize,
    clip_dbm: f64,
    /// Reference (floor, position, Σ (rssi − clip)²).
    references: Vec<(usize, Point2<f64>, f64)>,
    /// Per transmitter: (reference, rssi − clip).
    by_transmitter: HashMap<waymark_engine::TransmitterId, Vec<(u32, f64)>>,
}

impl Knn {
    /// From positioned survey scans per floor.
    pub fn new(k: usize, clip_dbm: f64, scans: impl IntoIterator<Item = (usize, Point2<f64>, Scan)>) -> Knn {
        let mut knn = Knn { k, clip_dbm, references: Vec::new(), by_transmitter: HashMap::new() };
        for (floor, p, scan) in scans {
            let r = knn.references.len() as u32;
            let mut energy = 0.0;
            for (id, v) in knn.levels(&scan) {
                energy += v * v;
                knn.by_transmitter.entry(id).or_default().push((r, v));
            }
            knn.references.push((floor, p, energy));
        }
        knn
    }

    /// (transmitter, rssi − clip) once per transmitter, the strongest reading kept.
    fn levels(&self, scan: &Scan) -> Vec<(waymark_engine::TransmitterId, f64)> {
        let mut best: HashMap<&waymark_engine::TransmitterId, f64> = HashMap::new();
        for r in scan.readings.iter().filter(|r| r.rssi_dbm.is_finite()) {
            let v = (r.rssi_dbm - self.clip_dbm).max(0.0);
            let e = best.entry(&r.transmitter).or_insert(v);
            *e = e.max(v);
        }
        best.into_iter().map(|(id, v)| (id.clone(), v)).collect()
    }

    /// The estimate for one scan: floor by weighted vote, position the weighted mean of the k
    /// nearest on that floor; the radius is the weighted RMS spread of those neighbours.
    pub fn locate(&self, scan: &Scan) -> Option<(usize, Point2<f64>, f64)> {
        let levels = self.levels(scan);
        let own: f64 = levels.iter().map(|(_, v)| v * v).sum();
        // ‖a − b‖² = Σa² + Σb² − 2 Σ_common a·b.
        let mut cross = vec![0.0; self.references.len()];
        for (id, v) in &levels {
            for &(r, w) in self.by_transmitter.get(id).map_or(&[][..], |l| &l[..]) {
                cross[r as usize] += v * w;
            }
        }
        let mut d: Vec<(f64, usize)> = self
            .references
            .iter()
            .enumerate()
            .map(|(r, (_, _, energy))| ((own + energy - 2.0 * cross[r]).max(0.0).sqrt(), r))
            .collect();
        let k = self.k.min(d.len());
        if k == 0 {
            return None;
        }
        d.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
        let nearest = &d[..k];
        let weight = |dist: f64| 1.0 / (dist + 1.0);
        let mut votes: BTreeMap<usize, f64> = BTreeMap::new();
        for &(dist, r) in nearest {
            *votes.entry(self.references[r].0).or_default() += weight(dist);
        }
        let floor = votes.into_iter().max_by(|a, b| a.1.total_cmp(&b.1))?.0;
        let on_floor: Vec<(f64, Point2<f64>)> = nearest
            .iter()
            .filter(|(_, r)| self.references[*r].0 == floor)
            .map(|&(dist, r)| (weight(dist), self.references[r].1))
            .collect();
        let total: f64 = on_floor.iter().map(|w| w.0).sum();
        let mean = on_floor.iter().fold(Point2::origin(), |acc, (w, p)| acc + p.coords * (w / total));
        let spread =
            (on_floor.iter().map(|(w, p)| w * (p - mean).norm_squared()).sum::<f64>() / total).sqrt();
        Some((floor, mean, spread))
    }
}

/// How the evaluation runs.
#[derive(Clone, Debug, Default)]
pub struct EvalOptions {
    /// How the site is surveyed and calibrated, and the walks replayed.
    pub calibration: CalibrationOptions,
    /// Configurations to run (keys of [`CONFIGURATIONS`]); empty: all.
    pub configurations: Vec<String>,
    /// Habits every engine configuration starts with ([`survey_habits`]); `None`: none.
    pub habits: Option<Arc<HabitModel>>,
}

impl EvalOptions {
    /// These options with the survey as
    /// [`survey_calibrated`](waymark_survey::calibrate::survey_calibrated) made the site
    /// ([`CalibrationOptions::surveyed_with`]). What surveys the same site again from some of
    /// its walks ([`survey_habits`]) must use them.
    pub fn surveyed_with(&self, calibration: &CalibrationReport) -> EvalOptions {
        EvalOptions { calibration: self.calibration.surveyed_with(calibration), ..self.clone() }
    }
}

/// What the evaluation reports.
#[derive(Clone, Debug, Serialize)]
pub struct EvalReport {
    /// Per configuration key.
    pub configurations: BTreeMap<String, ConfigurationReport>,
    /// What the survey built.
    pub survey: SurveyReport,
    /// What the survey calibrated (γ, radius factors, step length, north).
    pub calibration: CalibrationReport,
    /// Step counting × step length and heading against the test walks' waypoints.
    pub pdr: super::pdr::PdrReport,
    /// Test walks replayed.
    pub test_walks: usize,
    /// The share of each floor's survey walks the site was surveyed and calibrated from
    /// (`--survey-fraction`, [`survey_subset`](waymark_survey::calibrate::survey_subset)).
    pub survey_fraction: f64,
    /// States in the site.
    pub states: usize,
    /// Wall-clock time of the whole evaluation, s.
    pub seconds: f64,
    /// Every configuration again with habits learned from the survey walks (`--habits`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub habits: Option<HabitsComparison>,
    /// Every configuration again with the test walks' scans throttled as Android 9+ throttles
    /// a foreground app (`--throttle`), on the same site.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub throttled: Option<BTreeMap<String, ConfigurationReport>>,
    /// With the survey walks F left out given back without labels (`--unlabelled-rest`):
    /// each round of refitting the map with their evidence (docs/evidence.md#refitting).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub evidence_rounds: Option<Vec<waymark_survey::calibrate::EvidenceRound>>,
}

/// The configurations run with habits learned from the survey walks ([`survey_habits`]).
#[derive(Clone, Debug, Serialize)]
pub struct HabitsComparison {
    /// What the learning pass did.
    pub learning: HabitReport,
    /// How the strength was chosen.
    pub selection: HabitSelection,
    /// Learning time (survey replays and Baum-Welch), s.
    pub learning_seconds: f64,
    /// Per configuration key, with the habits.
    pub configurations: BTreeMap<String, ConfigurationReport>,
}

/// One test walk's estimates per configuration, for plots, and its scored points.
#[derive(Clone, Debug, Default)]
pub struct WalkResult {
    /// Floor index.
    pub floor: usize,
    /// Walk name.
    pub name: String,
    /// Estimates per configuration key.
    pub estimates: BTreeMap<String, Vec<Estimate>>,
    /// Per configuration key, the points this walk adds to [`ConfigurationReport::pooled`]:
    /// what a resampling over walks draws from
    /// ([`bootstrap_se`](crate::benchmark::bootstrap_se)).
    pub scored: BTreeMap<String, Vec<Scored>>,
    /// Per configuration key, the points this walk adds to [`ConfigurationReport::waypoints`].
    pub scored_waypoints: BTreeMap<String, Vec<Scored>>,
}

/// Builds the site from the survey walks of `floors` (one multi-floor site).
pub fn survey_site(floors: &[FloorData], options: &EvalOptions) -> Result<(Site, SurveyReport), EvalError> {
    let inputs = survey_inputs(floors);
    Ok(survey("eval", &inputs, options.calibration.north, &options.calibration.survey)?)
}

/// HIPE's single-point MLE: the state whose fingerprints best explain `scan` alone; `None`
/// when no reading is of a transmitter the site knows. `ln` is scratch, one entry per state.
fn most_likely_state(site: &Site, scan: &Scan, ln: &mut Vec<f64>) -> Option<usize> {
    let radio = site.radio();
    let resolved = radio.resolve(scan, None);
    if resolved.observations.is_empty() {
        return None;
    }
    ln.resize(site.states().len(), 0.0);
    radio.ln_likelihood(&resolved.observations, ln);
    // Among the states with a fingerprint: an unsurveyed one has nothing to match.
    let states = site.states();
    (0..ln.len())
        .filter(|&i| states[i].kind != StateKind::Unsurveyed)
        .max_by(|&a, &b| ln[a].total_cmp(&ln[b]))
}

/// Runs every configuration over every test walk of `floors` on `site`.
pub fn evaluate_on(
    site: &Arc<Site>,
    floors: &[FloorData],
    options: &EvalOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<(BTreeMap<String, ConfigurationReport>, Vec<WalkResult>), EvalError> {
    let wanted =
        |key: &str| options.configurations.is_empty() || options.configurations.iter().any(|c| c == key);
    let engine_config = options.calibration.engine.clone();
    // The Viterbi configuration smooths whole walks: a window longer than any test walk.
    let longest =
        floors.iter().flat_map(|f| &f.test).map(|t| t.wifi_scans.len() * 2 + 64).max().unwrap_or(64);
    Engine::new(Arc::clone(site), engine_config.clone())?;
    let wifi_only = SurveyOptions {
        events: waymark_survey::io::ilc::EventOptions { beacons: false, ..options.calibration.survey.events },
        ..options.calibration.survey.clone()
    };
    let wifi_only = &wifi_only;
    let knn = wanted("wifi-knn").then(|| {
        Knn::new(
            5,
            options.calibration.survey.build.fit.clip_dbm,
            floors.iter().enumerate().flat_map(|(f, floor)| {
                floor.survey.iter().flat_map(move |w| {
                    positioned_scans(w, wifi_only).into_iter().map(move |(p, s)| (f, p, s))
                })
            }),
        )
    });
    let jobs: Vec<(usize, &Trace)> =
        floors.iter().enumerate().flat_map(|(f, floor)| floor.test.iter().map(move |t| (f, t))).collect();
    let zone_truth = ZoneTruth::new(site);
    let run_walk = |&(floor, trace): &(usize, &Trace)| -> WalkResult {
        let mut result = WalkResult { floor, name: trace.name.clone(), ..WalkResult::default() };
        // The single-scan baselines are WiFi fingerprinting, as their names say.
        let scans: Vec<Scan> = trace
            .scans(&wifi_only.events)
            .into_iter()
            .map(|mut s| {
                s.readings.retain(|r| r.age_ns <= options.calibration.survey.max_reading_age_ns);
                s
            })
            .collect();
        if let Some(knn) = &knn {
            let estimates = scans
                .iter()
                .filter_map(|s| {
                    let (f, p, spread) = knn.locate(s)?;
                    Some(Estimate {
                        timestamp_ns: s.timestamp_ns,
                        floor: f,
                        x: p.x,
                        y: p.y,
                        accuracy_m: spread,
                        accuracy_95_m: 2.0 * spread,
                        zone: zone_truth.as_ref().and_then(|z| z.zone_at(f, p.x, p.y)),
                        floor_probability: None,
                    })
                })
                .collect();
            result.estimates.insert("wifi-knn".into(), estimates);
        }
        if wanted("wifi-mle") {
            let mut ln = vec![0.0; site.states().len()];
            let estimates = scans
                .iter()
                .filter_map(|s| {
                    let best = most_likely_state(site, s, &mut ln)?;
                    let state = &site.states()[best];
                    let cell = site.spacing_m() / 2.0;
                    Some(Estimate {
                        timestamp_ns: s.timestamp_ns,
                        floor: state.floor,
                        x: state.position.x,
                        y: state.position.y,
                        accuracy_m: cell,
                        accuracy_95_m: 2.0 * cell,
                        zone: site.zone_of(best),
                        floor_probability: None,
                    })
                })
                .collect();
            result.estimates.insert("wifi-mle".into(), estimates);
        }
        let engine_runs: [(&str, MotionMask); 5] = [
            ("forward-auto", MotionMask::Auto),
            ("forward-distance-heading", MotionMask::DistanceHeading),
            ("forward-distance", MotionMask::Distance),
            ("forward-heading-speed", MotionMask::HeadingSpeed),
            ("forward-speed", MotionMask::Speed),
        ];
        // The walk's scan likelihoods on the site, computed by its first run.
        let shared = SharedEmissions::new(site);
        for (key, mask) in engine_runs {
            let smoothing = key == "forward-auto" && (wanted("viterbi-auto") || wanted("fixed-lag-auto"));
            if !wanted(key) && !smoothing {
                continue;
            }
            let mut config = engine_config.clone();
            if smoothing {
                config.track_window_epochs = longest;
            }
            // Only viterbi-auto reads a track.
            config.track = key == "forward-auto" && wanted("viterbi-auto");
            let Ok(mut engine) = Engine::new(Arc::clone(site), config) else { continue };
            // Of this very site: cannot fail.
            let _ = engine.share_emissions(Arc::clone(&shared));
            if let Some(habits) = &options.habits {
                engine.set_habits(HabitModel::clone(habits));
            }
            // Fixed-lag estimates only where they are scored.
            let replay_options = ReplayOptions { mask, fixed_lag: smoothing, ..options.calibration.replay };
            let r = replay(&mut engine, trace, &replay_options);
            let [live, lagged, viterbi] = decoded(site, &r);
            if smoothing {
                if wanted("viterbi-auto") {
                    result.estimates.insert("viterbi-auto".into(), viterbi);
                }
                if wanted("fixed-lag-auto") {
                    result.estimates.insert("fixed-lag-auto".into(), lagged);
                }
            }
            if wanted(key) {
                result.estimates.insert(key.into(), live);
            }
        }
        progress();
        result
    };
    let cost = |&(_, trace): &(usize, &Trace)| replay_cost(trace);
    let mut results: Vec<WalkResult> =
        parallel_map_by_cost(&jobs, options.calibration.threads, cost, run_walk);
    for (result, &(f, trace)) in results.iter_mut().zip(&jobs) {
        for key in CONFIGURATIONS.iter().filter(|k| wanted(k)) {
            let Some(estimates) = result.estimates.get(*key) else { continue };
            let (epochs, waypoints) = score_scans(trace, f, estimates, zone_truth.as_ref());
            result.scored.insert(key.to_string(), epochs);
            result.scored_waypoints.insert(key.to_string(), waypoints);
        }
    }
    Ok((pooled_reports(floors, &results), results))
}

/// Each configuration's figures over the scored points of `results` (walks of `floors`), in
/// the walks' order: all of them, per floor, and at the waypoints.
pub fn pooled_reports(floors: &[FloorData], results: &[WalkResult]) -> BTreeMap<String, ConfigurationReport> {
    let mut reports = BTreeMap::new();
    for key in CONFIGURATIONS {
        let mut pooled = Vec::new();
        let mut at_waypoints = Vec::new();
        let mut per_floor: BTreeMap<String, Vec<Scored>> = BTreeMap::new();
        let mut any = false;
        for result in results {
            let Some(epochs) = result.scored.get(key) else { continue };
            any = true;
            per_floor.entry(floors[result.floor].name.clone()).or_default().extend_from_slice(epochs);
            pooled.extend_from_slice(epochs);
            at_waypoints.extend_from_slice(result.scored_waypoints.get(key).map_or(&[][..], Vec::as_slice));
        }
        if !any {
            continue;
        }
        reports.insert(
            key.to_string(),
            ConfigurationReport {
                pooled: Metrics::new(&pooled),
                floors: per_floor.iter().map(|(name, points)| (name.clone(), Metrics::new(points))).collect(),
                waypoints: Metrics::new(&at_waypoints),
            },
        );
    }
    reports
}

/// What one fold of the crowd protocol surveyed ([`evaluate_crowd`]).
#[derive(Clone, Debug, Serialize)]
pub struct CrowdFold {
    /// Test walks scored in this fold.
    pub test_walks: usize,
    /// The other folds' test walks given without labels.
    pub unlabelled_walks: usize,
    /// States of the fold's refitted site.
    pub states: usize,
    /// What each round of refitting gathered and changed.
    pub evidence_rounds: Vec<waymark_survey::calibrate::EvidenceRound>,
}

/// Which walks a survey is given without labels, besides its labelled survey walks
/// (docs/evidence.md#refitting).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WithoutLabels<'a> {
    /// The survey walks the survey fraction leaves out, given back without labels.
    pub rest: bool,
    /// Test walks of these repetitions (`_repetitionRR` in a competition file's name): not
    /// scored, given without labels.
    pub test_unlabelled: &'a [u32],
    /// Test walks of these repetitions: not scored, surveyed with their labels (the baseline of
    /// `test_unlabelled` on the same test walks).
    pub test_labelled: &'a [u32],
}

impl WithoutLabels<'_> {
    /// Whether any walk is given without labels.
    pub fn any(&self) -> bool {
        self.rest || !self.test_unlabelled.is_empty()
    }
}

/// `floors` with `fraction` of each floor's survey walks kept
/// ([`FloorData::keep_survey_fraction`]) and the test walks `given` names moved out, and the
/// walks given without labels (waypoints removed): the split `waymark eval --survey-fraction
/// --unlabelled-rest --test-as-unlabelled --test-as-labelled` and the benchmark's rows make.
pub fn split_without_labels(
    floors: Vec<FloorData>,
    fraction: f64,
    given: WithoutLabels,
) -> (Vec<FloorData>, Vec<Trace>) {
    let mut unlabelled: Vec<Trace> = Vec::new();
    let floors = (floors.into_iter())
        .map(|mut f| {
            if given.rest {
                let keep = waymark_survey::calibrate::survey_subset(f.survey.len(), fraction);
                let dropped = f.survey.iter().enumerate().filter(|(i, _)| keep.binary_search(i).is_err());
                unlabelled.extend(dropped.map(|(_, w)| Trace { waypoints: Vec::new(), ..w.clone() }));
            }
            f.keep_survey_fraction(fraction);
            let chosen = |reps: &[u32], t: &Trace| {
                waymark_survey::calibrate::repetition(&t.name).is_some_and(|r| reps.contains(&r))
            };
            for trace in std::mem::take(&mut f.test) {
                if chosen(given.test_unlabelled, &trace) {
                    unlabelled.push(Trace { waypoints: Vec::new(), ..trace });
                } else if chosen(given.test_labelled, &trace) {
                    f.survey.push(trace);
                } else {
                    f.test.push(trace);
                }
            }
            f
        })
        .collect();
    (floors, unlabelled)
}

/// What the crowd protocol measured ([`evaluate_crowd`]).
pub struct CrowdReport {
    /// Per configuration key, pooled over every fold's walks.
    pub configurations: BTreeMap<String, ConfigurationReport>,
    /// Every test walk, fold after fold.
    pub walks: Vec<WalkResult>,
    /// Each fold's survey.
    pub folds: Vec<CrowdFold>,
}

/// Fold `fold` of `folds` of the crowd protocol: `floors` with only the fold's test walks (walk
/// i of all floors' test walks, in order, when i mod `folds` = `fold`), and every other test
/// walk without its waypoints.
pub fn crowd_fold(floors: &[FloorData], folds: usize, fold: usize) -> (Vec<FloorData>, Vec<Trace>) {
    let mut index = 0;
    let mut unlabelled = Vec::new();
    let fold_floors = (floors.iter())
        .map(|floor| {
            let mut test = Vec::new();
            for trace in &floor.test {
                if index % folds == fold {
                    test.push(trace.clone());
                } else {
                    unlabelled.push(Trace { waypoints: Vec::new(), ..trace.clone() });
                }
                index += 1;
            }
            FloorData { test, ..floor.clone() }
        })
        .collect();
    (fold_floors, unlabelled)
}

/// The crowd protocol (docs/evidence.md#the-crowd-protocol): the test walks in `folds` folds
/// (walk i of all floors' test walks, in order, in fold i mod `folds`), each fold's walks
/// scored on the site surveyed from the labelled survey walks and refitted with every other
/// fold's test walks given without waypoints and without their floor
/// ([`survey_with_unlabelled`](waymark_survey::calibrate::survey_with_unlabelled) with
/// `rounds`): the map a venue's visitors would have refitted, scored on walks it never saw.
pub fn evaluate_crowd(
    floors: &[FloorData],
    options: &EvalOptions,
    folds: usize,
    rounds: waymark_survey::calibrate::UnlabelledOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<CrowdReport, EvalError> {
    if folds < 2 {
        return Err(EvalError::Empty(format!("the crowd protocol needs at least 2 folds, not {folds}")));
    }
    let mut results = Vec::new();
    let mut reports = Vec::new();
    for fold in 0..folds {
        let (fold_floors, unlabelled) = crowd_fold(floors, folds, fold);
        let (site, _, calibration, evidence_rounds) = waymark_survey::calibrate::survey_with_unlabelled(
            &fold_floors,
            &unlabelled,
            &options.calibration,
            rounds,
            progress,
        )?;
        let states = site.states().len();
        let (_, walks) =
            evaluate_on(&Arc::new(site), &fold_floors, &options.surveyed_with(&calibration), progress)?;
        reports.push(CrowdFold {
            test_walks: walks.len(),
            unlabelled_walks: unlabelled.len(),
            states,
            evidence_rounds,
        });
        results.extend(walks);
    }
    Ok(CrowdReport { configurations: pooled_reports(floors, &results), walks: results, folds: reports })
}

/// Radius confirmed around a survey walk's waypoint, in grid spacings: √2/2 reaches the
/// states of the cell the waypoint is in (a waypoint is a surveyor's tap on the plan, not a
/// state), so every confirmation names one to four states.
pub const WAYPOINT_FEEDBACK_SPACINGS: f64 = std::f64::consts::FRAC_1_SQRT_2;

/// The strengths the evaluation with habits tries on held-out survey walks: every other value of
/// the pass's grid ([`STRENGTHS`](waymark_engine::habits::STRENGTHS)) up to 100, where the habits no
/// longer change any configuration (`docs/tuning.md#habit-strength`). Four replays per survey
/// walk.
pub const HELD_OUT_STRENGTHS: [f64; 3] = [1.0, 10.0, 100.0];

/// How one strength did on held-out survey walks: per decoder, the mean error with the other
/// half's habits minus the mean error without habits, and its standard error over walks, m
/// (`[difference, standard error]`; negative: the habits helped).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct HeldOutStrength {
    /// κ, as applied to the half's habits.
    pub strength: f64,
    /// The live positions (`forward-auto`).
    pub forward_m: [f64; 2],
    /// The fixed-lag estimates (`fixed-lag-auto`).
    pub fixed_lag_m: [f64; 2],
    /// The Viterbi track (`viterbi-auto`).
    pub viterbi_m: [f64; 2],
}

impl HeldOutStrength {
    /// The three decoders' `[difference, standard error]`.
    fn decoders(&self) -> [[f64; 2]; 3] {
        [self.forward_m, self.fixed_lag_m, self.viterbi_m]
    }
}

/// How the evaluation with habits chose the strength of the survey walks' habits.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct HabitSelection {
    /// Survey walks replayed with the other half's habits.
    pub walks: usize,
    /// Epochs scored (without habits).
    pub epochs: usize,
    /// The learning pass's own choice, by how well habits predict held-out moves.
    pub pass_strength: Option<f64>,
    /// Per strength of [`HELD_OUT_STRENGTHS`].
    pub strengths: Vec<HeldOutStrength>,
    /// The strength applied to the habits of all survey walks (`None`: none applied): the
    /// chosen half's κ times the ratio of all walks' epochs to a half's, since a multiplier
    /// depends on its counts relative to κ.
    pub strength: Option<f64>,
}

/// The strength whose worst decoder gains most, among those that make every decoder better
/// by more than one standard error on held-out walks; `None` when none does. Strict on
/// purpose: positioning is what habits are for, and an improvement within the noise of the
/// held-out walks is no evidence that they transfer (the one-standard-error rule of
/// cross-validation: Breiman et al. 1984, §3.4.3; Hastie, Tibshirani & Friedman, *Elements
/// of Statistical Learning* §7.10, preferring the simpler model, no habits).
pub fn choose_held_out_strength(points: &[HeldOutStrength]) -> Option<f64> {
    let worst = |p: &HeldOutStrength| p.decoders().iter().map(|d| d[0]).fold(f64::NEG_INFINITY, f64::max);
    points
        .iter()
        .filter(|p| p.decoders().iter().all(|d| d[0] + d[1] < 0.0))
        .min_by(|a, b| worst(a).total_cmp(&worst(b)))
        .map(|p| p.strength)
}

/// Habits learned from the survey walks (El Gemayel §III-A and §IV-C): each survey
/// walk replayed through the engine as shipped, its waypoints given as the surveyor's
/// feedback, then one Baum-Welch pass over all of them. Test walks are never read.
///
/// The strength is chosen by positioning error ([`HabitSelection`]), by two-fold
/// cross-fitting: a site surveyed from the even survey walks of each floor (with the full
/// site's calibration), habits learned there from the same walks, and the odd walks replayed
/// on it without feedback, at each of [`HELD_OUT_STRENGTHS`] and without habits; then the
/// halves swapped. The learning pass alone chooses by move prediction, as the engine on a
/// phone must (it has no truth); here the survey's waypoints are the truth, and predicting the
/// surveyors' moves slightly better can make the track worse. Held out in the radio too,
/// since a walk replayed on a site surveyed from itself is explained by the radio alone
/// (`docs/tuning.md#habit-strength`).
///
/// `options` are those `site` was surveyed with: after
/// [`survey_calibrated`](waymark_survey::calibrate::survey_calibrated), its
/// [`EvalOptions::surveyed_with`].
pub fn survey_habits(
    site: &Arc<Site>,
    floors: &[FloorData],
    options: &EvalOptions,
) -> Result<(HabitModel, HabitReport, HabitSelection), EvalError> {
    let config = EngineConfig { history_epochs: usize::MAX, ..options.calibration.engine.clone() };
    // (floor, walk within the floor, trace) of every survey walk.
    let jobs: Vec<(usize, usize, &Trace)> = floors
        .iter()
        .enumerate()
        .flat_map(|(f, floor)| floor.survey.iter().enumerate().map(move |(w, t)| (f, w, t)))
        .collect();
    let learn_on = |site: &Arc<Site>, walks: &[&(usize, usize, &Trace)]| {
        let radius_m = site.spacing_m() * WAYPOINT_FEEDBACK_SPACINGS;
        let histories: Vec<Vec<EpochRecord>> =
            parallel_map(walks, options.calibration.threads, |&&(floor, _, trace)| {
                let Ok(mut engine) = Engine::new(Arc::clone(site), config.clone()) else { return Vec::new() };
                let feedback = Some(WaypointFeedback { floor, radius_m });
                replay(&mut engine, trace, &ReplayOptions { feedback, ..options.calibration.replay });
                engine.history().iter().cloned().collect()
            });
        let sequences: Vec<&[EpochRecord]> = histories.iter().map(Vec::as_slice).collect();
        let (reach, _) = site.reach_tables(config.reach_radius_m)?;
        let mut model = HabitModel::new(site);
        let report = model.learn(site, &reach, &sequences, &config.habits)?;
        Ok::<_, EvalError>((model, report))
    };
    let (mut model, report) = learn_on(site, &jobs.iter().collect::<Vec<_>>())?;
    let mut selection = HabitSelection { pass_strength: report.strength, ..HabitSelection::default() };
    if let Some(given) = config.habits.strength {
        // `--habit-strength`: applied as given.
        selection.strength = Some(given);
        return Ok((model, report, selection));
    }
    let inputs = survey_inputs(floors);
    let prepared = PreparedSurvey::new("eval", &inputs, site.north(), &options.calibration.survey)?;
    let weights: Vec<[Option<f64>; 2]> =
        site.floors().iter().map(|f| [f.rssi_weight, f.rssi_weight_without_movement]).collect();
    let per_walk = HELD_OUT_STRENGTHS.len() + 1;
    // Per held-out walk, per strength (without habits first), per decoder: (Σ error, epochs).
    let mut scored: Vec<[(f64, usize); 3]> = Vec::new();
    let mut half_epochs = 0.0;
    for half in 0..2 {
        let keep = |_: usize, w: usize| w % 2 == half;
        let fits = prepared.fit(&keep, None, options.calibration.threads);
        let half_site = Arc::new(
            prepared
                .assemble(&fits)?
                .0
                .with_calibration(*site.calibration())?
                .with_floor_rssi_weights(&weights)?,
        );
        let (train, held): (Vec<_>, Vec<_>) = jobs.iter().partition(|j| keep(j.0, j.1));
        let (habits, _) = learn_on(&half_site, &train)?;
        half_epochs += 0.5 * habits.epochs() as f64;
        let runs: Vec<(&Trace, usize, Option<f64>)> = held
            .iter()
            .flat_map(|&&(f, _, t)| {
                std::iter::once(None).chain(HELD_OUT_STRENGTHS.map(Some)).map(move |s| (t, f, s))
            })
            .collect();
        let results = parallel_map(&runs, options.calibration.threads, |&(trace, floor, strength)| {
            let window =
                EngineConfig { track_window_epochs: trace.wifi_scans.len() * 2 + 64, ..config.clone() };
            let mut engine = Engine::new(Arc::clone(&half_site), window).ok()?;
            if let Some(kappa) = strength {
                let mut h = habits.clone();
                h.set_strength(Some(kappa)).ok()?;
                engine.set_habits(h);
            }
            let r = replay(&mut engine, trace, &options.calibration.replay);
            Some(decoded(&half_site, &r).map(|estimates| {
                let points = score(trace, floor, &estimates).0;
                (points.iter().map(Scored::penalised_m).sum(), points.len())
            }))
        });
        // A walk counts only with every one of its runs: the differences are paired.
        for walk in results.chunks(per_walk) {
            if let Some(runs) = walk.iter().copied().collect::<Option<Vec<_>>>() {
                scored.extend(runs);
            }
        }
    }
    selection.walks = scored.len() / per_walk;
    selection.epochs = scored.iter().step_by(per_walk).map(|s| s[0].1).sum();
    for (g, &kappa) in HELD_OUT_STRENGTHS.iter().enumerate() {
        let decoder = |d: usize| -> [f64; 2] {
            // Paired per walk: Σ error with − Σ error without over the walk's epochs, weighted
            // by its epochs; the standard error over walks (the epochs of one walk are not
            // independent).
            let clusters: Vec<(f64, f64)> = scored
                .chunks(per_walk)
                .map(|walk| (walk[0][d].1 as f64, walk[g + 1][d].0 - walk[0][d].0))
                .collect();
            clustered_ratio(&clusters).map_or([f64::NAN, f64::NAN], |(mean, se)| [mean, se])
        };
        selection.strengths.push(HeldOutStrength {
            strength: kappa,
            forward_m: decoder(0),
            fixed_lag_m: decoder(1),
            viterbi_m: decoder(2),
        });
    }
    selection.strength = choose_held_out_strength(&selection.strengths)
        .map(|kappa| kappa * model.epochs() as f64 / half_epochs.max(1.0));
    model.set_strength(selection.strength)?;
    Ok((model, report, selection))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every test walk is scored in exactly one fold and given without labels in every other;
    /// the survey walks stay labelled in every fold.
    #[test]
    fn each_test_walk_is_scored_once_and_unlabelled_in_the_other_folds() {
        let walk = |name: String| Trace {
            name,
            waypoints: vec![waymark_survey::io::ilc::Waypoint {
                timestamp_ns: 1,
                x: 0.0,
                y: 0.0,
                floor: None,
            }],
            ..Trace::default()
        };
        let floors: Vec<FloorData> = [("B1", 4), ("F1", 3)]
            .iter()
            .map(|&(name, tests)| FloorData {
                name: name.into(),
                dir: name.into(),
                plan: None,
                survey: vec![walk(format!("{name}-survey"))],
                test: (0..tests).map(|i| walk(format!("{name}-test{i}"))).collect(),
                geo: None,
            })
            .collect();
        for folds in [2, 3, 7] {
            let mut scored: Vec<String> = Vec::new();
            for fold in 0..folds {
                let (fold_floors, unlabelled) = crowd_fold(&floors, folds, fold);
                let tests: Vec<&Trace> = fold_floors.iter().flat_map(|f| &f.test).collect();
                assert_eq!(tests.len() + unlabelled.len(), 7);
                assert!(unlabelled.iter().all(|t| t.waypoints.is_empty()));
                assert!(tests.iter().all(|t| !unlabelled.iter().any(|u| u.name == t.name)));
                assert!(fold_floors.iter().all(|f| f.survey.len() == 1 && !f.survey[0].waypoints.is_empty()));
                scored.extend(tests.iter().map(|t| t.name.clone()));
            }
            scored.sort();
            let mut all: Vec<String> = floors.iter().flat_map(|f| &f.test).map(|t| t.name.clone()).collect();
            all.sort();
            assert_eq!(scored, all, "{folds} folds");
        }
    }

    /// HIPE's single-scan MLE answers with a state that has a fingerprint: a scan barely heard
    /// is explained best by an unsurveyed state (which heard nothing), but that would be a
    /// guess from silence, not a match.
    #[test]
    fn single_scan_mle_matches_only_states_with_a_fingerprint() {
        use waymark_engine::radio::{Reading, TransmitterId};
        use waymark_engine::site::{BuildOptions, SiteBuilder};
        let ap = |k: u8| TransmitterId::wifi(&format!("02:00:00:00:00:{k:02x}")).unwrap();
        let scan = |timestamp_ns: u64, heard: &[(u8, f64)]| Scan {
            timestamp_ns,
            readings: heard
                .iter()
                .map(|&(k, rssi_dbm)| Reading { transmitter: ap(k), rssi_dbm, age_ns: 0 })
                .collect(),
        };
        let mut b = SiteBuilder::new("mle");
        let f = b.floor("G", 0.0);
        let surveyed: Vec<u32> = [(0.0, -45.0), (3.0, -60.0)]
            .iter()
            .map(|&(x, level)| {
                let scans =
                    (0..10).map(|n| scan(n, &[(1, level + if n % 2 == 0 { 2.0 } else { -2.0 })])).collect();
                b.state(f, Point2::new(x, 0.0), scans)
            })
            .collect();
        let unsurveyed = b.unsurveyed_state(f, Point2::new(6.0, 0.0));
        b.edge(surveyed[0], surveyed[1], None);
        b.edge(surveyed[1], unsurveyed, None);
        let site = b.build(BuildOptions::default()).unwrap();
        let faint = scan(100, &[(1, -94.0)]);
        let mut ln = Vec::new();
        assert_eq!(most_likely_state(&site, &faint, &mut ln), Some(surveyed[1] as usize));
        // Without the rule the unsurveyed state would have won.
        assert!(ln[unsurveyed as usize] > ln[surveyed[1] as usize], "{ln:?}");
        assert_eq!(most_likely_state(&site, &scan(101, &[(1, -44.0)]), &mut ln), Some(surveyed[0] as usize));
        // Nothing the site knows: no answer.
        assert_eq!(most_likely_state(&site, &scan(102, &[(9, -50.0)]), &mut ln), None);
    }

    /// A strength is applied only when it makes every decoder better by more than one standard
    /// error; among those, the one whose worst decoder gains most.
    #[test]
    fn habits_apply_only_when_every_decoder_gains_beyond_its_error() {
        let point = |strength, f: [f64; 2], l: [f64; 2], v: [f64; 2]| HeldOutStrength {
            strength,
            forward_m: f,
            fixed_lag_m: l,
            viterbi_m: v,
        };
        // F1's held-out figures (`docs/tuning.md#habit-strength`): nothing applied.
        let f1 = [
            point(1.0, [0.011, 0.019], [-0.029, 0.022], [0.010, 0.025]),
            point(10.0, [0.002, 0.005], [0.005, 0.004], [-0.001, 0.001]),
            point(100.0, [0.001, 0.0], [0.001, 0.001], [0.0, 0.0]),
        ];
        assert_eq!(choose_held_out_strength(&f1), None);
        // Forward and fixed-lag gain beyond their errors but the Viterbi track only within
        // its own: nothing applied.
        let one_within = [point(1.0, [-0.3, 0.1], [-0.3, 0.1], [-0.05, 0.1])];
        assert_eq!(choose_held_out_strength(&one_within), None);
        // Two strengths clear; κ = 10's worst decoder (−0.2) beats κ = 1's (−0.1).
        let two = [
            point(1.0, [-0.5, 0.1], [-0.4, 0.1], [-0.2 + 0.1, 0.05]),
            point(10.0, [-0.3, 0.05], [-0.2, 0.05], [-0.25, 0.05]),
            point(100.0, [-0.01, 0.001], [-0.01, 0.001], [-0.01, 0.001]),
        ];
        assert_eq!(choose_held_out_strength(&two), Some(10.0));
        // A NaN (no epochs) never counts as a gain.
        assert_eq!(choose_held_out_strength(&[point(1.0, [f64::NAN; 2], [-1.0, 0.1], [-1.0, 0.1])]), None);
        assert_eq!(choose_held_out_strength(&[]), None);
    }
}
