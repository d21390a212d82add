//! Per-site calibration from the survey walks alone: the walkers' step length and the site's
//! north, the fingerprint radius, γ per floor and per motion scenario, the radius factors,
//! the sparse-scan calibration and the radio fit floor, all chosen on held-out survey walks.
//! Test walks are never read.

mod floors;
mod gamma;
mod held_out;
mod radius;
mod report;
mod shipped;
mod unlabelled;

pub use floors::{
    is_gsd_building, load_building, load_gsd_building, parse_survey_fraction, repetition, survey_inputs,
    survey_subset, FloorData, WalkSplit,
};
pub use gamma::{ESTIMATE_STATES_GRID, GAMMA_GRID};
pub use held_out::MIN_SCENARIO_EPOCHS;
pub use radius::{RadiusPoint, FINGERPRINT_RADIUS_FOLDS, FINGERPRINT_RADIUS_GRID};
pub use report::{
    coverage_geojson, CalibrationReport, Coverage, CoveragePoint, FloorCalibrationReport,
    FloorReliabilityReport, GammaPoint, MotionSummary, OffMapBand, OffMapReport, SparseScansReport,
};
pub use unlabelled::{
    anchored_walk, survey_with_evidence, survey_with_unlabelled, walk_evidence, EvidenceRound,
    UnlabelledOptions, ANCHOR_FLOOR_MASS,
};
pub use waymark_engine::evidence::EVIDENCE_STATES_PER_SCAN;

use crate::io::Trace;
use crate::replay::{replay, MotionMask, ReplayOptions};
use crate::scoring::{live_estimates, quantile, score, Scored};
use crate::{PreparedSurvey, SurveyOptions, SurveyReport};
use gamma::{gamma_curve, own_gamma};
use held_out::{floor_reliability, radius_factors, tag, HeldOut, Tag, Tagged, WalkHeldOut, RUNS};
use radius::calibrate_fingerprint_radius;
use shipped::{covered_replays, CoveredGamma, HeldOutSite};
use std::sync::Arc;
use waymark_engine::sensors::MotionScenario;
use waymark_engine::site::{Calibration, FloorReliability, North, Site, SparseScans, SPARSE_BANDS};
use waymark_engine::{Engine, EngineConfig};

/// Why a site could not be read or calibrated.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationError {
    /// A folder could not be listed.
    #[error("cannot list {path}: {source}")]
    Io {
        /// The folder.
        path: String,
        /// Why.
        source: std::io::Error,
    },
    /// A walk could not be read.
    #[error(transparent)]
    Trace(#[from] crate::io::TraceError),
    /// A floor's plan is there but could not be read or is not valid.
    #[error(transparent)]
    Plan(#[from] crate::io::FloorPlanError),
    /// The survey could not build a site.
    #[error(transparent)]
    Site(#[from] waymark_engine::site::SiteError),
    /// The walks give nothing to survey.
    #[error("{0}")]
    Empty(String),
    /// Walks without labels could not be made map evidence, or it could not refit the map.
    #[error("map evidence: {0}")]
    Evidence(String),
}

/// How a site is surveyed and calibrated, and its walks replayed.
#[derive(Clone, Debug)]
pub struct CalibrationOptions {
    /// How the site is surveyed.
    pub survey: SurveyOptions,
    /// The engine as shipped (γ, models...). Its reading-age limit, unless set here, is the
    /// one the survey's sites carry (`SurveyOptions::max_reading_age_ns`), as in an app.
    pub engine: EngineConfig,
    /// How walks are replayed.
    pub replay: ReplayOptions,
    /// The site's north, when not estimated from the survey.
    pub north: North,
    /// Worker threads for replays.
    pub threads: usize,
    /// Whether the calibration chooses the fingerprint radius ([`FINGERPRINT_RADIUS_GRID`]);
    /// off: `survey.fingerprint_radius_m` as given.
    pub calibrate_fingerprint_radius: bool,
    /// The share of each scan's posterior that map evidence keeps, its most probable states
    /// first ([`walk_evidence`]); 1 keeps all of it.
    pub evidence_mass: f64,
    /// The most states of each scan's posterior that map evidence keeps, most probable first
    /// ([`walk_evidence`], [`EVIDENCE_STATES_PER_SCAN`]); 0 keeps every state.
    pub evidence_states: usize,
}

impl Default for CalibrationOptions {
    fn default() -> Self {
        Self {
            survey: SurveyOptions::default(),
            engine: EngineConfig::default(),
            replay: ReplayOptions::default(),
            north: North::default(),
            threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
            calibrate_fingerprint_radius: true,
            evidence_mass: 1.0,
            evidence_states: EVIDENCE_STATES_PER_SCAN,
        }
    }
}

impl CalibrationOptions {
    /// How the calibration replays its held-out walks: as `replay`, but with every scan (the
    /// site a phone gets is surveyed from unthrottled walks, and its calibration replays them
    /// both ways, see [`SparseScans`]), and without fixed-lag
    /// estimates: the calibration scores the live positions.
    pub fn calibration_replay(&self) -> ReplayOptions {
        ReplayOptions { min_scan_interval_ns: None, fixed_lag: false, ..self.replay }
    }

    /// The engine the calibration replays its held-out walks with: `engine` without the
    /// Viterbi track and without the fixed-lag smoother's steps, which nothing it scores reads
    /// ([`calibration_replay`](Self::calibration_replay) scores the live positions, and those
    /// are the same either way).
    pub fn calibration_engine(&self) -> EngineConfig {
        EngineConfig { track: false, fixed_lag_epochs: 0, ..self.engine.clone() }
    }

    /// [`calibration_replay`](Self::calibration_replay) with the scans throttled as
    /// [`throttled_replay`](Self::throttled_replay) throttles them.
    fn calibration_throttled_replay(&self) -> ReplayOptions {
        ReplayOptions {
            min_scan_interval_ns: self.throttled_replay().min_scan_interval_ns,
            ..self.calibration_replay()
        }
    }

    /// `replay` with the scans throttled as Android 9+ throttles a foreground app
    /// ([`ANDROID_THROTTLE_NS`](crate::replay::ANDROID_THROTTLE_NS)).
    pub fn throttled_replay(&self) -> ReplayOptions {
        ReplayOptions { min_scan_interval_ns: Some(crate::replay::ANDROID_THROTTLE_NS), ..self.replay }
    }

    /// These options with the survey as [`survey_calibrated`] made the site: its fingerprint
    /// radius, no longer searched. What surveys the same site again from some of its walks
    /// must use them, or it would fit its held-out sites at another radius.
    pub fn surveyed_with(&self, calibration: &CalibrationReport) -> CalibrationOptions {
        let mut options = self.clone();
        options.survey.fingerprint_radius_m = calibration.fingerprint_radius_m;
        options.calibrate_fingerprint_radius = false;
        options
    }
}

/// `f` over `items` on `threads` worker threads, results in input order.
pub fn parallel_map<T: Sync, R: Send>(items: &[T], threads: usize, f: impl Fn(&T) -> R + Sync) -> Vec<R> {
    let order: Vec<usize> = (0..items.len()).collect();
    parallel_map_in(items, &order, threads, f)
}

/// [`parallel_map`], taking the items of greatest `cost` first: the workers then end
/// together, where in input order the last long item may run alone (longest processing time
/// first, Graham 1969). Results in input order.
pub fn parallel_map_by_cost<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    cost: impl Fn(&T) -> u64,
    f: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    let mut order: Vec<usize> = (0..items.len()).collect();
    // Stable: equal costs keep input order.
    order.sort_by_key(|&k| std::cmp::Reverse(cost(&items[k])));
    parallel_map_in(items, &order, threads, f)
}

/// The cost of replaying `trace`, for [`parallel_map_by_cost`]: its duration in
/// seconds (an epoch per scan or per timer tick) and its scans.
pub fn replay_cost(trace: &Trace) -> u64 {
    let times = trace
        .accelerometer
        .iter()
        .map(|s| s.timestamp_ns)
        .chain(trace.wifi_scans.iter().map(|s| s.timestamp_ns));
    let (first, last) = times.fold((u64::MAX, 0), |(a, b), t| (a.min(t), b.max(t)));
    last.saturating_sub(first) / 1_000_000_000 + trace.wifi_scans.len() as u64
}

/// `f` over `items` taken in `order` (a permutation of their indices) on `threads` worker
/// threads, results in input order.
fn parallel_map_in<T: Sync, R: Send>(
    items: &[T],
    order: &[usize],
    threads: usize,
    f: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    let threads = threads.max(1).min(items.len().max(1));
    if threads == 1 {
        return items.iter().map(f).collect();
    }
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut done: Vec<(usize, R)> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..threads)
            .map(|_| {
                scope.spawn(|| {
                    let mut mine = Vec::new();
                    loop {
                        let n = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(&k) = order.get(n) else { break };
                        mine.push((k, f(&items[k])));
                    }
                    mine
                })
            })
            .collect();
        // A worker that panicked loses its share; the caller sees fewer results.
        workers.into_iter().flat_map(|w| w.join().unwrap_or_default()).collect()
    });
    done.sort_by_key(|(k, _)| *k);
    done.into_iter().map(|(_, r)| r).collect()
}

/// Builds a held-out site's walking-distance tables at the calibration engine's radius into
/// the site's cache, where its engines find them, taking the rows it can from those of
/// `whole`, the site of every walk, which it differs from only around the walk left out: the
/// same tables, at a fraction of the cost of building each from scratch
/// (`docs/tuning.md#evaluation-speed`). A site over the site budget is left without them: its
/// engines are then refused with the budget's error (docs/errors.md#site-limits).
fn held_out_reach(site: &Site, whole: &Site, options: &CalibrationOptions) {
    let _ = site.reach_tables_from(whole, options.calibration_engine().reach_radius_m);
}

/// Steps of the survey's calibration, for progress: one per survey walk (each is held out
/// once) and one per fold and radius of the fingerprint radius's cross-validation: at most,
/// since its search usually stops after three or four radii (the bar then ends early).
pub fn calibration_steps(floors: &[FloorData], options: &CalibrationOptions) -> usize {
    let radius = if options.calibrate_fingerprint_radius {
        FINGERPRINT_RADIUS_GRID.len() * FINGERPRINT_RADIUS_FOLDS
    } else {
        0
    };
    // The leave-one-walk-out pass, the walks it finds covered end to end again, then the
    // shipped engine's pass.
    3 * floors.iter().map(|f| f.survey.len()).sum::<usize>() + radius
}

/// Shares of the held-out scans on the map that a radio fit floor may call unexplained: the
/// floor's candidates are those quantiles of their fits, and the held-out walks replayed with
/// the engine as shipped choose between them, as they choose γ. 5% is a one-sided test at 5%,
/// one scan on the map in twenty; 20% the lower quintile. Where the survey is sparse, a scan on
/// the map fits worse, and its 5% quantile let walkers beyond the map be pulled onto whatever
/// fitted least badly. Each candidate costs the calibration two replays of every walk
/// (`docs/tuning.md#radio-fit-floor`).
const RADIO_FIT_FLOOR_SHARES: [f64; 2] = [0.05, 0.2];

/// A candidate radio fit floor from the sorted fits of held-out scans on the map: their
/// quantile at `share`, and never below 0. A fit of 0 is a scan the best fingerprint explains
/// no better than no fingerprint at all, which is what "unexplained" means; on a sparse survey
/// a state fitted from near-empty scans scores about that for any scan, so the held-out fits
/// never fall below it and the quantile came out just under 0: no scan was then ever
/// unexplained, and walkers beyond the map were pulled onto that state on another floor
/// (`docs/tuning.md#radio-fit-floor`).
fn radio_fit_floor(sorted_fits: &[f64], share: f64) -> f64 {
    quantile(sorted_fits, share).max(0.0)
}

/// The candidate floors ([`RADIO_FIT_FLOOR_SHARES`]) from the sorted fits, with the share each
/// is the quantile at, the same floor once: none from fewer than
/// [`MIN_SCENARIO_EPOCHS`] fits (a 5% quantile then rests on ten below).
fn radio_fit_floor_candidates(sorted_fits: &[f64]) -> Vec<(f64, Option<f64>)> {
    if sorted_fits.len() < MIN_SCENARIO_EPOCHS {
        return vec![(0.0, None)];
    }
    let mut candidates: Vec<(f64, Option<f64>)> = Vec::new();
    for share in RADIO_FIT_FLOOR_SHARES {
        let floor = radio_fit_floor(sorted_fits, share);
        if !matches!(candidates.last(), Some(c) if c.1 == Some(floor)) {
            candidates.push((share, Some(floor)));
        }
    }
    candidates
}

/// Refuses survey walks that cannot place a single scan, saying what is wrong with them: a
/// scan is placed between two waypoints, so at least one walk needs two of them and a scan in
/// between (otherwise the survey would fail later with "a site needs at least one state").
fn check_survey_walks(walks: &[&Trace]) -> Result<(), CalibrationError> {
    let placed = |t: &&&Trace| {
        let (Some(first), Some(last)) = (t.waypoints.first(), t.waypoints.last()) else { return false };
        t.waypoints.len() >= 2
            && t.wifi_scans.iter().any(|s| (first.timestamp_ns..=last.timestamp_ns).contains(&s.timestamp_ns))
    };
    if walks.iter().any(|t| placed(&t)) {
        return Ok(());
    }
    let count = |f: fn(&Trace) -> bool| walks.iter().filter(|t| f(t)).count();
    let lines: usize = walks.iter().map(|t| t.stats.lines).sum();
    let malformed: usize = walks.iter().map(|t| t.stats.malformed).sum();
    Err(CalibrationError::Empty(format!(
        "no survey walk has a scan between two waypoints, so none places a fingerprint: {} walks read, \
         {} with no waypoint, {} with one, {} with no WiFi or beacon scan; {lines} data lines, {malformed} malformed",
        walks.len(),
        count(|t| t.waypoints.is_empty()),
        count(|t| t.waypoints.len() == 1),
        count(|t| t.wifi_scans.is_empty() && t.beacons.is_empty()),
    )))
}

/// How often the survey's walkers changed floor, per second (docs/accuracy.md#barometer): the
/// floor changes between consecutive waypoints of every survey walk, over the time between
/// each walk's first and last waypoint, as the posterior mean of a Poisson rate under a flat
/// prior, (changes + 1) / time (Gelman et al., Bayesian Data Analysis, 3rd ed., §2.6). A walk
/// filed under one floor whose waypoints name none stays on it. `None` for a site of one floor
/// or walks of no duration.
fn floor_change_rate(floors: &[FloorData]) -> Option<f64> {
    if floors.len() < 2 {
        return None;
    }
    let (mut changes, mut seconds) = (0u64, 0.0);
    for (f, floor) in floors.iter().enumerate() {
        for walk in &floor.survey {
            let on = walk.waypoints.iter().map(|w| w.floor.unwrap_or(f)).collect::<Vec<_>>();
            changes += on.windows(2).filter(|w| w[0] != w[1]).count() as u64;
            if let (Some(first), Some(last)) = (walk.waypoints.first(), walk.waypoints.last()) {
                seconds += last.timestamp_ns.saturating_sub(first.timestamp_ns) as f64 * 1e-9;
            }
        }
    }
    (seconds > 0.0).then(|| (changes as f64 + 1.0) / seconds)
}

/// Calibrates a site from its survey walks: the walkers' step length and the site's north
/// (from waypoints and steps, [`crate::calibrate_motion`]), then γ per floor by
/// leave-one-walk-out, Hoang §6.2's jackknife with a walk as the unit: each survey walk is
/// replayed, at each γ of [`GAMMA_GRID`] with the motion and with it withheld, on the site
/// surveyed from every other walk (all floors), and each floor takes the γ of least mean
/// held-out error over its walks. The pooled curve gives the site-wide γ. The radius factors
/// are the 68th and 95th percentiles of error ÷ radius over the held-out epochs on the map,
/// replayed again with the engine as shipped but without factors: pooled over the floors,
/// because a percentile needs many epochs and the engine applies one factor whatever floor
/// it believes. Test walks are never read.
pub fn calibrate(
    floors: &[FloorData],
    options: &CalibrationOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<(Calibration, North, CalibrationReport), CalibrationError> {
    let (site, _, report) = survey_calibrated(floors, options, progress)?;
    Ok((*site.calibration(), site.north(), report))
}

/// [`calibrate`], then the site from all survey walks with that calibration and north, each
/// floor with its γ.
pub fn survey_calibrated(
    floors: &[FloorData],
    options: &CalibrationOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<(Site, SurveyReport, CalibrationReport), CalibrationError> {
    let mut report = CalibrationReport::default();
    let all: Vec<&Trace> = floors.iter().flat_map(|f| &f.survey).collect();
    check_survey_walks(&all)?;
    let motion = crate::calibrate_motion(&all, &options.engine.motion);
    let north = motion.as_ref().map_or(options.north, |m| m.north());
    let mut calibration = Calibration {
        step_length: motion.as_ref().map(|m| m.step_length),
        floor_change_rate_hz: floor_change_rate(floors),
        ..Calibration::default()
    };
    report.motion = motion.as_ref().map(|m| MotionSummary {
        step_length: m.step_length,
        heading_offset_deg: m.heading_offset_rad.to_degrees(),
        walks: m.walks,
    });
    let mut survey_options = options.survey.clone();
    if options.calibrate_fingerprint_radius {
        let (radius, curve) = calibrate_fingerprint_radius(floors, north, calibration, options, progress)?;
        report.fingerprint_radius_mean_error_m = curve;
        survey_options.fingerprint_radius_m = radius.unwrap_or(survey_options.fingerprint_radius_m);
    }
    report.fingerprint_radius_m = survey_options.fingerprint_radius_m;
    let inputs = survey_inputs(floors);
    let prepared = PreparedSurvey::new("eval", &inputs, north, &survey_options)?;
    let full = prepared.fit(&|_, _| true, None, options.threads);
    let (site, survey) = prepared.assemble(&full)?;
    // The site of every walk: each held-out site takes its walking-distance rows from it.
    let whole = &site;
    // Every survey walk held out once, replayed at each γ with the motion as the sensors give
    // it and with the motion withheld.
    // Each picks the γ of its scenario; all four fit the radius factors of every scenario.
    let masks = [MotionMask::Auto, MotionMask::Speed, MotionMask::Distance, MotionMask::HeadingSpeed];
    let jobs: Vec<(usize, usize)> = floors
        .iter()
        .enumerate()
        .flat_map(|(f, floor)| (0..floor.survey.len()).map(move |w| (f, w)))
        .collect();
    let cost = |&(f, w): &(usize, usize)| replay_cost(&floors[f].survey[w]);
    // With the motion as the sensors give it, each epoch is also scored with each M of eq. 4,
    // unless the configuration sets M.
    let grid: &'static [usize] =
        if options.engine.estimate_states.is_none() { &ESTIMATE_STATES_GRID } else { &[] };
    let held_out: Vec<Option<WalkHeldOut>> = parallel_map_by_cost(&jobs, options.threads, cost, |&(f, w)| {
        let held = HeldOutSite::build(&prepared, &full, whole, options, (f, w));
        let site = held.as_ref().and_then(|h| h.site.clone().with_calibration(calibration).ok());
        let result = held.zip(site).map(|(held, site)| {
            let site = Arc::new(site);
            // The scan likelihoods of this walk on this site, computed by its first replay.
            let (shared, mapped) = (&held.shared, &held.mapped);
            let trace = &floors[f].survey[w];
            let mut tagged = Vec::with_capacity(GAMMA_GRID.len());
            // Per γ, per M of `grid`: the epochs of the first run.
            let mut by_m = Vec::with_capacity(GAMMA_GRID.len());
            let per_gamma: HeldOut = GAMMA_GRID
                .iter()
                .map(|&gamma| {
                    let mut scored_by_m = Vec::new();
                    let runs: [Vec<Tag>; RUNS] = std::array::from_fn(|run| {
                        let config =
                            EngineConfig { rssi_weight: Some(gamma), ..options.calibration_engine() };
                        let Ok(mut engine) = Engine::new(Arc::clone(&site), config) else {
                            return Vec::new();
                        };
                        // Of a copy of this very site: cannot fail.
                        let _ = engine.share_emissions(Arc::clone(shared));
                        let replay_options = ReplayOptions {
                            mask: masks[run],
                            estimate_states_grid: if run == 0 { grid } else { &[] },
                            ..options.calibration_replay()
                        };
                        let r = replay(&mut engine, trace, &replay_options);
                        if run == 0 {
                            scored_by_m = (r.by_estimate_states.iter())
                                .map(|p| score(trace, f, &live_estimates(&site, p)).0)
                                .collect();
                        }
                        tag(&site, trace, f, mapped, &r.positions)
                    });
                    let plain = std::array::from_fn(|m| runs[m].iter().map(|t| t.scored).collect());
                    tagged.push(runs);
                    by_m.push(scored_by_m);
                    plain
                })
                .collect();
            WalkHeldOut { scored: per_gamma, refitted: held.refitted, tagged, by_m }
        });
        progress();
        result
    });
    report.sites = held_out.iter().flatten().count();
    report.refitted_share = held_out.iter().flatten().map(|h| h.refitted as f64).sum::<f64>()
        / (report.sites.max(1) * site.states().len().max(1)) as f64;
    // Pooled over every floor's walks.
    let walks: Vec<&HeldOut> = held_out.iter().flatten().map(|h| &h.scored).collect();
    let (pooled, best) = gamma_curve(&walks, 0);
    let (pooled_still, best_still) = gamma_curve(&walks, 1);
    report.gamma_mean_error_m = pooled.iter().map(|p| (p.gamma, p.mean_error_m)).collect();
    report.gamma_without_movement_mean_error_m =
        pooled_still.iter().map(|p| (p.gamma, p.mean_error_m)).collect();
    calibration.rssi_weight = best.map(|k| pooled[k].gamma);
    calibration.rssi_weight_without_movement = best_still.map(|k| pooled_still[k].gamma);
    // M: the grid's of least pooled held-out error at a γ, and those errors.
    let estimate_states_at = |gamma: Option<f64>| -> (Vec<(usize, f64)>, Option<u32>) {
        let Some(g) = gamma.and_then(|gamma| GAMMA_GRID.iter().position(|&x| x == gamma)) else {
            return (Vec::new(), None);
        };
        let curve: Vec<(usize, f64)> = (grid.iter().enumerate())
            .filter_map(|(k, &m)| {
                let epochs =
                    held_out.iter().flatten().flat_map(|h| h.by_m.get(g).and_then(|by_m| by_m.get(k)));
                let (total, n) = epochs.fold((0.0, 0), |(t, n), e| {
                    (t + e.iter().map(Scored::penalised_m).sum::<f64>(), n + e.len())
                });
                (n > 0).then(|| (m, total / n as f64))
            })
            .collect();
        let least = curve.iter().min_by(|a, b| a.1.total_cmp(&b.1)).map(|p| p.0 as u32);
        (curve, least)
    };
    // Distance only and heading only: their own γ when it beats the γ without movement on
    // their own held-out curve by more than its standard error (`own_gamma`).
    for (mask, scenario) in [(2, MotionScenario::Distance), (3, MotionScenario::HeadingSpeed)] {
        let (curve, best) = gamma_curve(&walks, mask);
        let own = own_gamma(&curve, best, calibration.rssi_weight_without_movement);
        calibration.rssi_weight_by_scenario.set(scenario, own);
        report.gamma_by_scenario.set(scenario, Some(curve));
    }
    let floor_walks = |f: usize| -> Vec<&HeldOut> {
        (jobs.iter().zip(&held_out))
            .filter(|((ff, _), _)| *ff == f)
            .filter_map(|(_, h)| h.as_ref().map(|h| &h.scored))
            .collect()
    };
    // Each floor's own γ without a movement likelihood, as the site-wide one.
    let still: Vec<Option<f64>> = (0..floors.len())
        .map(|f| {
            let (curve, best) = gamma_curve(&floor_walks(f), 1);
            own_gamma(&curve, best, calibration.rssi_weight_without_movement)
        })
        .collect();
    // The radio fit floor's candidates: quantiles of the fits of the held-out scans on the
    // map. A scan's fit is the map's, before γ weighs it, so any γ's replays give the same.
    let mut fits_on_map: Vec<f64> = (held_out.iter().flatten())
        .flat_map(|h| h.tagged.first())
        .flat_map(|runs| &runs[0])
        .filter(|t| t.beyond_map_m == 0.0)
        .filter_map(|t| t.radio_fit)
        .collect();
    fits_on_map.sort_by(f64::total_cmp);
    let floor_candidates = radio_fit_floor_candidates(&fits_on_map);
    report.radio_fit_scans = fits_on_map.len();
    // γ with a movement likelihood again, on the held-out walks that the rest of the survey
    // covers end to end, replayed with the engine as shipped (the first scan and the gaps at
    // the γ without one, the lower candidate radio fit floor, M at the γ above) at each γ of
    // the grid, steady and throttled. A walk left out takes its stretch of
    // map with it where no other walk went; the walks that then leave their map and come back
    // want the radio weighed more to find it again, which the site surveyed from every walk
    // does not ask of a walker where it was surveyed: the same reason the 68% radius factor
    // is fitted on the map (`docs/tuning.md#gamma`). Kept from the replays above where the
    // covered walks have fewer than `MIN_SCENARIO_EPOCHS` epochs.
    let covered: Vec<bool> = (held_out.iter())
        .map(|h| h.as_ref().and_then(|h| h.tagged.first()).is_some_and(|runs| shipped::covered(&runs[0])))
        .collect();
    let first_look = Calibration {
        estimate_states: estimate_states_at(calibration.rssi_weight).1,
        radio_fit_floor: floor_candidates[0].1,
        ..calibration
    };
    let first_weights: Vec<[Option<f64>; 2]> = still.iter().map(|&s| [None, s]).collect();
    let replays = covered_replays(
        (&prepared, &full, whole),
        (floors, &jobs, &covered),
        (first_look, &first_weights),
        options,
        progress,
    );
    let as_shipped = CoveredGamma::of(&replays, &jobs, floors.len());
    let enough = as_shipped.epochs >= MIN_SCENARIO_EPOCHS;
    if enough {
        calibration.rssi_weight = as_shipped.best.or(calibration.rssi_weight);
        // Scans far apart: their own γ when it beats the site-wide one on the throttled
        // replays by more than its standard error.
        calibration.sparse_scans.rssi_weight = as_shipped.sparse_gamma(calibration.rssi_weight);
    }
    report.covered_walks = as_shipped.walks;
    report.covered_epochs = as_shipped.epochs;
    report.gamma_covered_mean_error_m = as_shipped.curve.iter().map(|p| (p.gamma, p.mean_error_m)).collect();
    report.sparse_scans.gamma = as_shipped.sparse_curve.clone();
    let (m_curve, m) = estimate_states_at(calibration.rssi_weight);
    report.estimate_states_mean_error_m = m_curve;
    calibration.estimate_states = m;
    report.estimate_states = calibration.estimate_states;
    // Per floor.
    let mut weights = Vec::with_capacity(floors.len());
    let mut by_scenario: [Vec<&Tag>; 4] = Default::default();
    // The same with the epochs off the map, for the 95% factors.
    let mut every_by_scenario: [Vec<&Tag>; 4] = Default::default();
    let mut off_map: Vec<&Tag> = Vec::new();
    for (f, floor) in floors.iter().enumerate() {
        let mine = floor_walks(f);
        let mine_tagged: Vec<&Vec<Tagged>> = jobs
            .iter()
            .zip(&held_out)
            .filter(|((ff, _), _)| *ff == f)
            .filter_map(|(_, h)| h.as_ref().map(|h| &h.tagged))
            .collect();
        let (curve, best) = gamma_curve(&mine, 0);
        let (curve_still, best_still) = gamma_curve(&mine, 1);
        // The floor's own γ on the curve the site-wide one was chosen on.
        let (deciding, deciding_best) =
            if enough { as_shipped.floors[f].clone() } else { (curve.clone(), best) };
        let gamma = own_gamma(&deciding, deciding_best, calibration.rssi_weight);
        let g = gamma.or(calibration.rssi_weight).and_then(|g| GAMMA_GRID.iter().position(|&x| x == g));
        let gamma_still = own_gamma(&curve_still, best_still, calibration.rssi_weight_without_movement);
        let g_still = gamma_still.or(calibration.rssi_weight_without_movement);
        let g_still = g_still.and_then(|g| GAMMA_GRID.iter().position(|&x| x == g));
        // Each epoch at the γ the engine gives it: only distance-and-heading epochs have
        // Hoang's movement likelihood (eq. 11); distance only and heading only (HIPE's ring
        // and sector) run at their scenario's γ if the site has one, and they and speed only
        // otherwise at the γ chosen without one.
        let at = |g: Option<f64>| g.and_then(|g| GAMMA_GRID.iter().position(|&x| x == g));
        let chosen = MotionScenario::ALL.map(|sc| match sc {
            MotionScenario::DistanceHeading => g,
            _ => at(calibration.rssi_weight_by_scenario.get(sc)).or(g_still),
        });
        for scenario in MotionScenario::ALL {
            let Some(chosen) = chosen[scenario.index()] else { continue };
            for walk in &mine_tagged {
                for (m, run) in walk[chosen].iter().enumerate() {
                    for t in run.iter().filter(|t| t.scenario == scenario) {
                        every_by_scenario[scenario.index()].push(t);
                        if t.beyond_map_m > 0.0 {
                            if m == 0 {
                                report.epochs_off_map += 1;
                                off_map.push(t);
                            }
                            continue;
                        }
                        by_scenario[scenario.index()].push(t);
                    }
                }
            }
        }
        let floor_report = FloorCalibrationReport {
            name: floor.name.clone(),
            walks: mine.iter().filter(|w| w.iter().any(|m| !m[0].is_empty())).count(),
            epochs: g.map_or(0, |g| mine.iter().map(|w| w[g][0].len()).sum()),
            rssi_weight: gamma,
            rssi_weight_without_movement: still[f],
            best_rssi_weight: deciding_best.map(|k| deciding[k].gamma),
            jackknife_se_m: deciding_best.map(|k| deciding[k].jackknife_se_m),
            gamma: curve,
            gamma_covered: if enough { deciding } else { Vec::new() },
            gamma_without_movement: curve_still,
            coverage: Coverage::default(),
        };
        weights.push([floor_report.rssi_weight, floor_report.rssi_weight_without_movement]);
        report.floors.push(floor_report);
    }
    // The forced scenarios' factors, from the runs with the motion withheld at each γ; the
    // scenarios the engine as shipped positions enough epochs in get theirs from its own
    // replays below.
    for scenario in MotionScenario::ALL {
        let (points, every) = (&by_scenario[scenario.index()], &every_by_scenario[scenario.index()]);
        report.scenario_epochs[scenario.index()] = points.len();
        let scale = if points.len() >= MIN_SCENARIO_EPOCHS { radius_factors(points, every) } else { None };
        calibration.accuracy_scale_by_scenario.set(scenario, scale);
    }
    report.rssi_weight = calibration.rssi_weight;
    report.floor_change_rate_hz = calibration.floor_change_rate_hz;
    report.rssi_weight_without_movement = calibration.rssi_weight_without_movement;
    report.rssi_weight_by_scenario = calibration.rssi_weight_by_scenario;
    // The held-out walks again with the engine as shipped (every calibrated value) but no
    // radius factor, steady and throttled, with each candidate radio fit floor: the steady
    // replays choose the floor, by least mean error, as γ is chosen. At that floor they give
    // the posterior's own radii as the engine will report them, each epoch at the γ the engine
    // gives it (the first scan's without a movement likelihood, and the floor's, which the
    // calibration's runs above, each at one γ throughout, do not give it), for the radius
    // factors of the scenarios it positions epochs in and of the sparse bands; and how it does
    // off the map. Fitted on the runs above instead, the factors did not hold on the engine as
    // shipped (`docs/tuning.md#radius-factors`).
    let unscaled = Calibration {
        accuracy_scale: None,
        accuracy_scale_by_scenario: Default::default(),
        sparse_scans: SparseScans {
            accuracy_scale_by_since: Default::default(),
            floor_reliability: Default::default(),
            ..calibration.sparse_scans
        },
        floor_reliability: Default::default(),
        ..calibration
    };
    // Per walk, per candidate floor: (steady, throttled); empty where a replay failed.
    let by_floor: Vec<Vec<(Vec<Tag>, Vec<Tag>)>> =
        parallel_map_by_cost(&jobs, options.threads, cost, |&(f, w)| {
            let tags = HeldOutSite::build(&prepared, &full, whole, options, (f, w)).and_then(|held| {
                let trace = &floors[f].survey[w];
                let run = |floor: Option<f64>, replay_options: &ReplayOptions| {
                    let calibration = Calibration { radio_fit_floor: floor, ..unscaled };
                    held.replay(calibration, &weights, options, replay_options, trace, f)
                };
                (floor_candidates.iter())
                    .map(|&(_, floor)| {
                        Some((
                            run(floor, &options.calibration_replay())?,
                            run(floor, &options.calibration_throttled_replay())?,
                        ))
                    })
                    .collect::<Option<Vec<_>>>()
            });
            progress();
            tags.unwrap_or_default()
        });
    // The floor of least mean error over the steady held-out epochs, the smaller share on a tie.
    let complete: Vec<&Vec<(Vec<Tag>, Vec<Tag>)>> =
        by_floor.iter().filter(|c| c.len() == floor_candidates.len()).collect();
    report.radio_fit_floor_mean_error_m = (floor_candidates.iter().enumerate())
        .filter_map(|(k, &(share, floor))| {
            let epochs = complete.iter().flat_map(|c| &c[k].0);
            let (total, n) = epochs.fold((0.0, 0), |(t, n), e| (t + e.scored.penalised_m(), n + 1));
            Some((share, floor?, total / n.max(1) as f64))
        })
        .collect();
    let chosen = (report.radio_fit_floor_mean_error_m.iter().enumerate())
        .min_by(|a, b| a.1 .2.total_cmp(&b.1 .2).then(a.0.cmp(&b.0)))
        .map_or(0, |(k, _)| k);
    calibration.radio_fit_floor = floor_candidates.get(chosen).and_then(|c| c.1);
    report.radio_fit_floor = calibration.radio_fit_floor;
    report.radio_fit_floor_share = calibration.radio_fit_floor.and(floor_candidates.get(chosen).map(|c| c.0));
    let shipped: Vec<(Vec<Tag>, Vec<Tag>)> =
        by_floor.into_iter().map(|c| c.into_iter().nth(chosen).unwrap_or_default()).collect();
    for (f, floor_report) in report.floors.iter_mut().enumerate() {
        let mine = jobs.iter().zip(&shipped).filter(|((ff, _), _)| *ff == f);
        let tags =
            mine.flat_map(|(&(_, w), s)| s.0.iter().map(move |t| (floors[f].survey[w].name.as_str(), t)));
        floor_report.coverage = Coverage::of(tags);
    }
    let tags: Vec<&Tag> = shipped.iter().flat_map(|s| &s.0).collect();
    let on: Vec<&Tag> = tags.iter().copied().filter(|t| t.beyond_map_m == 0.0).collect();
    calibration.accuracy_scale = radius_factors(&on, &tags);
    report.epochs = on.len();
    for scenario in MotionScenario::ALL {
        let points: Vec<&Tag> = on.iter().copied().filter(|t| t.scenario == scenario).collect();
        if points.len() >= MIN_SCENARIO_EPOCHS {
            let every: Vec<&Tag> = tags.iter().copied().filter(|t| t.scenario == scenario).collect();
            report.scenario_epochs[scenario.index()] = points.len();
            calibration.accuracy_scale_by_scenario.set(scenario, radius_factors(&points, &every));
        }
    }
    // Per band: (on the map, every epoch).
    let mut by_band: [(Vec<&Tag>, Vec<&Tag>); SPARSE_BANDS] = Default::default();
    for t in shipped.iter().flat_map(|s| &s.1) {
        if let Some(band) = t.band {
            if t.beyond_map_m == 0.0 {
                by_band[band].0.push(t);
            }
            by_band[band].1.push(t);
        }
    }
    for (band, (points, every)) in by_band.iter().enumerate() {
        report.sparse_scans.epochs_by_since[band] = points.len();
        calibration.sparse_scans.accuracy_scale_by_since[band] =
            if points.len() >= MIN_SCENARIO_EPOCHS { radius_factors(points, every) } else { None };
    }
    // The floor probability, on a site of several floors: how often the floor was right per
    // band of the posterior's mass on it, over the held-out epochs on the map of both replays,
    // in the sparse regime and out of it (docs/accuracy.md#floor-probability).
    if site.floors().len() > 1 {
        let on_map = || shipped.iter().flat_map(|s| s.0.iter().chain(&s.1)).filter(|t| t.beyond_map_m == 0.0);
        for (sparse, report, table) in [
            (false, &mut report.floor_reliability, &mut calibration.floor_reliability),
            (
                true,
                &mut report.sparse_scans.floor_reliability,
                &mut calibration.sparse_scans.floor_reliability,
            ),
        ] {
            let points = on_map().filter(|t| t.band.is_some() == sparse);
            let points = points.filter_map(|t| Some((t.scored.floor_probability?, t.scored.floor_correct)));
            let (fitted, counts) = floor_reliability(points);
            report.epochs_right_by_band = counts;
            let epochs: usize = counts.iter().map(|c| c[1]).sum();
            *table = if epochs >= MIN_SCENARIO_EPOCHS { fitted } else { FloorReliability::default() };
            report.calibration = *table;
        }
    }
    report.sparse_scans.calibration = calibration.sparse_scans;
    report.accuracy_scale = calibration.accuracy_scale;
    report.accuracy_scale_by_scenario = calibration.accuracy_scale_by_scenario;
    report.off_map_without_floor = OffMapReport::of(&off_map, &calibration);
    let off: Vec<&Tag> = tags.iter().copied().filter(|t| t.beyond_map_m > 0.0).collect();
    report.off_map = OffMapReport::of(&off, &calibration);
    report.on_map = OffMapReport::of_on_map(&on, &calibration);
    let site = site.with_calibration(calibration)?.with_floor_rssi_weights(&weights)?;
    Ok((site, survey, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::ilc::Waypoint;
    use std::path::PathBuf;

    #[test]
    fn the_floor_change_rate_counts_the_walks_changes_over_their_time() {
        let at = |s: u64, floor: Option<usize>| Waypoint {
            timestamp_ns: s * 1_000_000_000,
            x: 0.0,
            y: 0.0,
            floor,
        };
        let walk = |waypoints: Vec<Waypoint>| Trace { waypoints, ..Trace::default() };
        let floor = |name: &str, survey: Vec<Trace>| FloorData {
            name: name.into(),
            dir: PathBuf::new(),
            plan: None,
            survey,
            test: Vec::new(),
            geo: None,
        };
        // 100 s filed under the ground floor that climbs once and comes back (2 changes), and
        // 100 s upstairs that names no floor: (2 + 1) / 200 s.
        let floors = [
            floor("G", vec![walk(vec![at(0, None), at(40, Some(1)), at(60, Some(1)), at(100, Some(0))])]),
            floor("1", vec![walk(vec![at(0, None), at(100, None)])]),
        ];
        assert_eq!(floor_change_rate(&floors), Some(3.0 / 200.0));
        // No change at all still allows one in the time walked; one floor, none.
        assert_eq!(floor_change_rate(&floors[1..]), None);
        let still = [floor("G", vec![walk(vec![at(0, None), at(50, None)])]), floor("1", Vec::new())];
        assert_eq!(floor_change_rate(&still), Some(1.0 / 50.0));
    }

    #[test]
    fn the_radio_fit_floor_is_the_held_out_quantile_and_never_below_zero() {
        // Twenty fits from 0.5 up: the 5th percentile is the first.
        let fits: Vec<f64> = (0..20).map(|i| 0.5 + 0.1 * f64::from(i)).collect();
        assert_eq!(radio_fit_floor(&fits, 0.05), 0.5);
        // Held-out fits that never fall below a near-empty state's -0.04: no better than no
        // fingerprint is unexplained.
        let fits: Vec<f64> = (0..20).map(|i| -0.04 + 0.1 * f64::from(i)).collect();
        assert_eq!(radio_fit_floor(&fits, 0.05), 0.0);
    }

    #[test]
    fn the_candidate_floors_are_quantiles_each_once() {
        // 200 fits 0.01 apart from -0.2: the 5% and 20% quantiles, 0 for one below.
        let fits: Vec<f64> = (0..200).map(|i| -0.2 + 0.01 * f64::from(i)).collect();
        let candidates = radio_fit_floor_candidates(&fits);
        let floors: Vec<(f64, f64)> = candidates.iter().map(|&(s, f)| (s, f.unwrap())).collect();
        assert_eq!(floors.len(), 2, "{floors:?}");
        assert_eq!(floors[0], (0.05, 0.0), "the 5% quantile is below 0");
        assert!((floors[1].1 - quantile(&fits, 0.2)).abs() < 1e-12 && floors[1].0 == 0.2);
        // Both quantiles below 0: one candidate.
        let low: Vec<f64> = fits.iter().map(|f| f - 1.0).collect();
        assert_eq!(radio_fit_floor_candidates(&low), vec![(0.05, Some(0.0))]);
        // Too few fits for a 5% quantile: no floor.
        assert_eq!(radio_fit_floor_candidates(&fits[..MIN_SCENARIO_EPOCHS - 1]), vec![(0.0, None)]);
    }
}
