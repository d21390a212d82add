//! Recovery: how many epochs of good data the engine needs to return to its normal
//! error after (a) being "kidnapped" — the person is carried to the far end of the building
//! and walks on there — or (b) ten minutes of walking without radio.
//!
//! Each run walks the simulated office as in [`crate::longrun`] (raw 100 Hz IMU in batches of
//! 50, a scan every 2 s, the default engine) and has an undisturbed twin:
//!
//! - **kidnapped**: a first walk (80-120 m) lets the engine converge; at its end the person
//!   is moved to the state farthest from there by walking distance and walks on. The twin
//!   walks on from where the first walk ended, so after the jump it walks elsewhere.
//! - **radio outage**: after 2 minutes with radio, 10 minutes of walking with no scans while
//!   the app calls `advance` every 2 s (as the replay's timer does), then radio again. The
//!   twin has radio throughout; the truth and the inertial samples are the same.
//!
//! Each run also has a **reference**: an undisturbed engine given exactly the disturbed run's
//! input from the first epoch of good data on. After an outage it is the twin. After a kidnap
//! its phone lay on a table at the far state until the jump, with radio from there, and then
//! it walks on with the kidnapped person's samples and scans (`kidnapped_run` says why a table).
//!
//! **Normal error** is the twins' error in their steady state (every epoch after the first
//! [`WARMUP_EPOCHS`]), pooled over all runs of the scenario: its median and 90th percentile.
//! (The twins' error over just the epochs after the disturbance is the same kind of walk but a
//! tenth of the data.)
//! **Tolerance** is max(1.5 × normal median, normal p90).
//!
//! A run has **recovered after r epochs** when r is the first epoch of good data (counting
//! from 1, the first scan after the disturbance) from which, for [`HOLD_EPOCHS`] consecutive
//! epochs, the error is within the tolerance *or* no more than the reference's error at that
//! epoch plus [`SAME_PLACE_M`].
//!
//! Why the reference: recovering is getting back to what the undisturbed engine does, and on a
//! given stretch of walk that is not a constant. Where the radio is ambiguous (two spots 3 m
//! apart at a stop, the first steps of a walk, which the step detector confirms one epoch
//! late) the undisturbed engine has excursions of a few metres, and the tolerance alone counted
//! them as not yet recovered, scoring never-disturbed twins as slow. An epoch at which the
//! disturbed engine is no farther from the truth than the undisturbed engine given the same
//! input is not one it is still recovering in: that error is the engine's anyway. The margin
//! is [`SAME_PLACE_M`], the agreement of engines that have forgotten their differences; with
//! none, estimates that agree up to rounding fail on the rounding. The tolerance stays, so
//! that a reference better than the normal error at some epoch does not hold back a run that
//! is within it. The rule's own noise: a reference is one undisturbed history among many; the
//! outage's reference is the same run with radio, so there the comparison is exact. Figures:
//! `docs/tuning.md#recovery-rule`; the runs: `waymark simulate --experiment recovery`.
//!
//! The first rule's figures on the disturbed runs, the references, the twins and the fresh
//! engines are reported alongside (`tolerance_recovery` and the like).

use nalgebra::Point2;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use serde::Serialize;
use std::sync::Arc;
use waymark_engine::sensors::SensorSample;
use waymark_engine::site::{Site, PSEUDO_SPACING_M};
use waymark_engine::Engine;
use waymark_engine::EngineConfig;
use waymark_engine::Error;
use waymark_sim::session::{Feeder, ImuSink, SessionConfig, SessionGenerator};
use waymark_sim::{Office, OfficeConfig};
use waymark_survey::scoring::quantile;

use crate::longrun::{BATCH_SAMPLES, SCAN_INTERVAL_NS};

/// Consecutive epochs at the normal error (by either rule) that count as recovered: 5 (10 s at
/// one scan every 2 s), so a single lucky epoch is not a recovery. A definition, not a tuned
/// value.
pub const HOLD_EPOCHS: usize = 5;

/// Two engines report "the same place" within 0.1 m: a fraction of the normal median error on
/// the simulated office (`docs/tuning.md#recovery-rule`) and of the pseudo-state spacing
/// (0.75 m, Hoang §5). A
/// definition, not a tuned value: engines that have forgotten their differences agree to
/// within rounding. Also the margin by which a recovered run's error may exceed its
/// reference's: a run reporting the reference's place, to within this, has an error within
/// this of the reference's.
pub const SAME_PLACE_M: f64 = 0.1;

/// Epochs a twin is given to converge from its cold start before its errors count as normal:
/// 10, about the 90th percentile of a fresh engine's epochs to recover by the first rule on
/// the simulated office (`docs/tuning.md#recovery-rule`).
pub const WARMUP_EPOCHS: usize = 10;

/// The target: back to normal within 10 epochs of good data.
pub const TARGET_EPOCHS: usize = 10;

/// The recovery experiment: how fast the engine finds the walker again after a kidnap or a gap.
#[derive(Clone, Debug)]
pub struct RecoveryConfig {
    /// Runs per scenario; run k uses building and walks seeded `first_seed + k`.
    pub seeds: u64,
    /// Seed of the first run.
    pub first_seed: u64,
    /// Epochs of good data scored after the disturbance: 60 (2 minutes).
    pub after_epochs: usize,
    /// Epochs with radio before the outage: 60 (2 minutes).
    pub before_outage_epochs: usize,
    /// Length of the outage, s: 600 ("10 minutes without radio").
    pub outage_s: f64,
    /// Whether each run also has the passes that put its result in context: a cold start (a
    /// fresh engine from the first epoch of good data) and, for the kidnap, the twin's own
    /// reference (the rule applied to an engine that was not disturbed). Default on; off
    /// leaves the kidnap 3 passes of 5 and the outage 2 of 3, for tests.
    pub comparisons: bool,
    /// The engine.
    pub engine: EngineConfig,
    /// The walks: the long run's, without the table (the person walks throughout, with stops)
    /// and 80-120 m long, so the first walk before a kidnap is 30-80 epochs.
    pub session: SessionConfig,
}

impl Default for RecoveryConfig {
    fn default() -> Self {
        Self {
            seeds: 20,
            first_seed: 0,
            after_epochs: 60,
            before_outage_epochs: 60,
            outage_s: 600.0,
            comparisons: true,
            engine: EngineConfig::default(),
            session: SessionConfig {
                table_chance: 0.0,
                walk_length_m: (80.0, 120.0),
                ..SessionConfig::default()
            },
        }
    }
}

/// One disturbed run and its twin.
#[derive(Clone, Debug, Serialize)]
pub struct RecoveryRun {
    /// Seed of the building and the walks.
    pub seed: u64,
    /// How far the truth jumped (kidnapped) or was walked without radio (outage), m.
    pub disturbance_m: f64,
    /// Error at the last epoch before the good data resumed, m.
    pub error_before_m: f64,
    /// Errors of the disturbed run at epochs 1.. of good data, m.
    pub errors_m: Vec<f64>,
    /// Errors of the twin at the same epochs, m. After a kidnap the twin walks on from where
    /// the first walk ended, so these are another walk's: normal error, but not paired epoch
    /// by epoch (that is `reference_errors_m`).
    pub twin_errors_m: Vec<f64>,
    /// Errors of the reference at the same epochs, m: an undisturbed engine with the same input
    /// from the first good epoch on (the twin after an outage; after a kidnap, an engine that
    /// had the phone lying where the person is put down, see `kidnapped_run`).
    pub reference_errors_m: Vec<f64>,
    /// Errors of the twin at every epoch after its first [`WARMUP_EPOCHS`], m: its steady
    /// state, which the normal error is pooled from.
    #[serde(skip)]
    pub twin_steady_errors_m: Vec<f64>,
    /// Errors of a fresh engine started at the first epoch of good data (same input from
    /// then on as the disturbed run), m.
    pub cold_errors_m: Vec<f64>,
    /// Kidnap only: errors of the twin's own reference at the same epochs (the phone lay where
    /// the twin's first walk ended until then), m; empty otherwise.
    #[serde(skip)]
    pub twin_reference_errors_m: Vec<f64>,
    /// Epochs of good data to recover (the module's rule: as good as the tolerance or as the
    /// reference); `None`: not within `after_epochs`.
    pub epochs_to_recover: Option<usize>,
    /// The same rule on the cold start, against the same reference.
    pub cold_epochs_to_recover: Option<usize>,
    /// The same rule on the twin against its own reference (kidnap only): what the rule says
    /// of an engine that was not disturbed.
    pub twin_epochs_to_recover: Option<usize>,
    /// The first rule (within the tolerance, whatever the reference does) on this run.
    pub epochs_within_tolerance: Option<usize>,
    /// The first rule on the twin.
    pub twin_epochs_within_tolerance: Option<usize>,
    /// The first rule on the reference.
    pub reference_epochs_within_tolerance: Option<usize>,
    /// The first rule on the cold start.
    pub cold_epochs_within_tolerance: Option<usize>,
    /// Error at the recovery epoch, m.
    pub error_at_recovery_m: Option<f64>,
    /// Epochs of good data until the disturbed engine reports the same place (within
    /// [`SAME_PLACE_M`], for [`HOLD_EPOCHS`] epochs) as an engine that had the same input
    /// from the first good epoch on but no disturbance before it: the twin after an outage, the
    /// fresh engine after a kidnap. `None`: not within the scored epochs, or no such engine.
    pub epochs_to_forget: Option<usize>,
    /// Whether there was an engine to compare with for `epochs_to_forget`.
    #[serde(skip)]
    pub forget_measured: bool,
    /// Filter restarts of the disturbed engine.
    pub filter_restarts: u64,
}

/// Distribution of epochs to recover over the runs of a scenario.
#[derive(Clone, Debug, Serialize)]
pub struct RecoveryDistribution {
    /// Runs.
    pub runs: usize,
    /// Median epochs to recover (a run that did not recover counts as `after_epochs` + 1).
    pub median: f64,
    /// 90th percentile, nearest rank.
    pub p90: f64,
    /// Largest.
    pub max: f64,
    /// Share of runs recovered within [`TARGET_EPOCHS`].
    pub within_target: f64,
    /// Runs that did not recover within `after_epochs`.
    pub not_recovered: usize,
}

/// One scenario's result.
#[derive(Clone, Debug, Serialize)]
pub struct ScenarioReport {
    /// `kidnapped` or `radio_outage`.
    pub scenario: String,
    /// Normal error: the twins' median over the scored epochs, m.
    pub normal_median_m: f64,
    /// ... and 90th percentile, m.
    pub normal_p90_m: f64,
    /// max(1.5 × median, p90), m.
    pub tolerance_m: f64,
    /// The references' error over the scored epochs, pooled: median and 90th percentile, m. An
    /// undisturbed engine: these should be the normal error's.
    pub reference_error_m: [f64; 2],
    /// Epochs to recover, disturbed runs (the module's rule).
    pub recovery: RecoveryDistribution,
    /// The same rule on fresh engines started at the first epoch of good data (`None`
    /// without the cold-start passes).
    pub cold_recovery: Option<RecoveryDistribution>,
    /// The same rule on the undisturbed twins against their own references: the rule's own
    /// noise (kidnap only; the outage's reference is the twin itself).
    pub twin_recovery: Option<RecoveryDistribution>,
    /// The first rule (the error within the tolerance for [`HOLD_EPOCHS`] epochs), disturbed
    /// runs.
    pub tolerance_recovery: RecoveryDistribution,
    /// The first rule on the undisturbed twins.
    pub twin_tolerance_recovery: RecoveryDistribution,
    /// The first rule on the references (undisturbed, same input as the disturbed runs).
    pub reference_tolerance_recovery: RecoveryDistribution,
    /// The first rule on the fresh engines (`None` without the cold-start passes).
    pub cold_tolerance_recovery: Option<RecoveryDistribution>,
    /// Epochs until the disturbed engine reports what an engine with the same input and no
    /// disturbance reports (`None` without the cold-start passes for the kidnap).
    pub forget: Option<RecoveryDistribution>,
    /// Median error at the recovery epoch, m.
    pub median_error_at_recovery_m: f64,
    /// Median over runs of the error just before good data resumed, m.
    pub median_error_before_m: f64,
    /// Mean error over epochs 11..after_epochs of the disturbed runs, the references and the
    /// twins, m.
    pub settled_mean_error_m: [f64; 3],
    /// Every run.
    pub runs: Vec<RecoveryRun>,
}

/// Both scenarios.
#[derive(Clone, Debug, Serialize)]
pub struct RecoveryReport {
    /// Consecutive epochs within tolerance that count as recovered.
    pub hold_epochs: usize,
    /// The target, epochs.
    pub target_epochs: usize,
    /// One scan (or timer epoch) every this many seconds.
    pub epoch_s: f64,
    /// Kidnapped.
    pub kidnapped: ScenarioReport,
    /// Ten minutes without radio.
    pub radio_outage: ScenarioReport,
}

/// The first epoch (1-based) from which `errors` stay ≤ `tolerance` for `hold` epochs (the
/// first rule).
pub fn epochs_to_recover(errors: &[f64], tolerance: f64, hold: usize) -> Option<usize> {
    first_held(&errors.iter().map(|&e| e <= tolerance).collect::<Vec<_>>(), hold)
}

/// The module's rule: the first epoch (1-based) from which, for `hold` epochs, each error is
/// ≤ `tolerance` or ≤ the reference's error at that epoch + `margin`. An epoch without a
/// reference error counts only by the tolerance; a non-finite error (no estimate) never counts.
pub fn epochs_to_match(
    errors: &[f64],
    reference: &[f64],
    tolerance: f64,
    margin: f64,
    hold: usize,
) -> Option<usize> {
    let normal: Vec<bool> = errors
        .iter()
        .enumerate()
        .map(|(i, &e)| {
            e.is_finite() && (e <= tolerance || reference.get(i).is_some_and(|&r| e <= r + margin))
        })
        .collect();
    first_held(&normal, hold)
}

/// The first index (1-based) from which `hold` consecutive flags are set.
fn first_held(flags: &[bool], hold: usize) -> Option<usize> {
    let hold = hold.max(1);
    (0..flags.len().saturating_sub(hold - 1)).find(|&i| flags[i..i + hold].iter().all(|&f| f)).map(|i| i + 1)
}

struct EngineSink<'a>(&'a mut Engine);

impl ImuSink for EngineSink<'_> {
    fn accelerometer(&mut self, batch: &[SensorSample]) {
        self.0.push_accelerometer(batch);
    }
    fn gyroscope(&mut self, batch: &[SensorSample]) {
        self.0.push_gyroscope(batch);
    }
    fn magnetometer(&mut self, batch: &[SensorSample]) {
        self.0.push_magnetometer(batch);
    }
}

/// Walking distances from `from` over the office's graph (Dijkstra; the office is small).
fn walking_distances(office: &Office, from: u32) -> Vec<f64> {
    let n = office.points().len();
    let mut distance = vec![f64::INFINITY; n];
    let mut done = vec![false; n];
    distance[from as usize] = 0.0;
    for _ in 0..n {
        let Some(i) = (0..n).filter(|&i| !done[i]).min_by(|&a, &b| distance[a].total_cmp(&distance[b]))
        else {
            break;
        };
        done[i] = true;
        for &j in office.neighbours(i as u32) {
            let d = distance[i] + nalgebra::distance(&office.points()[i], &office.points()[j as usize]);
            if d < distance[j as usize] {
                distance[j as usize] = d;
            }
        }
    }
    distance
}

/// The state farthest from `from` by walking distance.
fn farthest(office: &Office, from: u32) -> (u32, f64) {
    walking_distances(office, from)
        .into_iter()
        .enumerate()
        .filter(|(_, d)| d.is_finite())
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map_or((from, 0.0), |(i, d)| (i as u32, d))
}

/// The building of run `seed` and its site (with pseudo states, as the demo's engine).
fn building(seed: u64) -> Result<(Office, Arc<Site>), Error> {
    let office = Office::generate(&OfficeConfig { seed, ..OfficeConfig::default() });
    let site = Arc::new(office.site.with_pseudo_states(PSEUDO_SPACING_M));
    Ok((office, site))
}

/// When every session starts, ns.
const START_NS: u64 = 1_000_000_000;

/// What one pass over a session produced: the error and the truth at every epoch.
#[derive(Default)]
struct Pass {
    errors: Vec<f64>,
    truths: Vec<Point2<f64>>,
    /// The live estimate at every epoch (`None` if the epoch was rejected).
    positions: Vec<Option<Point2<f64>>>,
    restarts: u64,
}

/// Runs `epochs` epochs of a session; `radio(k, t)` says whether epoch k (from 1) at `t` has a
/// scan (else the app's timer calls `advance`); `setup` may change the generator first. With
/// `fresh_from`, a new engine replaces the old one just before that epoch's input (a cold
/// start: the uniform prior, no memory of what came before).
#[allow(clippy::too_many_arguments)]
fn pass(
    office: &Office,
    site: &Arc<Site>,
    config: &RecoveryConfig,
    seed: u64,
    epochs: usize,
    setup: impl FnOnce(&mut Feeder),
    radio: impl Fn(usize, u64) -> bool,
    fresh_from: Option<usize>,
) -> Result<Pass, Error> {
    let mut engine = Engine::new(Arc::clone(site), config.engine.clone())?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x4ec0_7e47);
    let start_state = rng.random_range(0..office.points().len()) as u32;
    let start_ns = START_NS;
    let generator =
        SessionGenerator::new(office, config.session.clone(), rng.random(), start_state, start_ns);
    let mut feeder = Feeder::new(generator, BATCH_SAMPLES);
    setup(&mut feeder);
    let mut scan_rng = ChaCha8Rng::seed_from_u64(rng.random());
    let mut out = Pass::default();
    for k in 1..=epochs {
        let t = start_ns + k as u64 * SCAN_INTERVAL_NS;
        if fresh_from == Some(k) {
            engine = Engine::new(Arc::clone(site), config.engine.clone())?;
        }
        let truth = feeder.feed_until(t, &mut EngineSink(&mut engine));
        // The scan is drawn whether or not it is delivered, so both twins see the same radio.
        let scan = office.field.scan_at(truth, t, &mut scan_rng);
        let result = if radio(k, t) { engine.push_scan(&scan) } else { engine.advance(t) };
        let position = result.ok().map(|e| Point2::new(e.position.x, e.position.y));
        out.errors.push(position.map_or(f64::INFINITY, |p| nalgebra::distance(&truth, &p)));
        out.positions.push(position);
        out.truths.push(truth);
    }
    out.restarts = engine.stats().filter_restarts;
    Ok(out)
}

/// The end of the first segment of the session of run `seed`, and the state it ends at.
fn first_segment_end(office: &Office, config: &RecoveryConfig, seed: u64) -> (u64, u32) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x4ec0_7e47);
    let start_state = rng.random_range(0..office.points().len()) as u32;
    let mut generator =
        SessionGenerator::new(office, config.session.clone(), rng.random(), start_state, START_NS);
    let first = generator.next_segment();
    (first.end_ns, first.end_state)
}

fn kidnapped_run(config: &RecoveryConfig, seed: u64) -> Result<RecoveryRun, Error> {
    let (office, site) = building(seed)?;
    let (jump_ns, at) = first_segment_end(&office, config, seed);
    let (far, disturbance_m) = farthest(&office, at);
    // Epochs up to the jump, then `after_epochs` of good data.
    let before = ((jump_ns - START_NS) / SCAN_INTERVAL_NS) as usize;
    let epochs = before + config.after_epochs;
    let teleport = |feeder: &mut Feeder| feeder.generator_mut().teleport(far);
    let disturbed = pass(&office, &site, config, seed, epochs, teleport, |_, _| true, None)?;
    let twin = pass(&office, &site, config, seed, epochs, |_| {}, |_, _| true, None)?;
    // The reference: an engine that was never carried off. Until the jump the phone lies on a
    // table at `far` (radio from there, with the same fading draws), then the person walks on
    // with exactly the disturbed run's samples and scans. An engine that walked to `far` would
    // need a walk ending there at the jump, which the generator cannot make without changing
    // the random stream the walk after the jump is drawn from; a table is the session's own
    // kind of stillness (`SessionGenerator::table`), after which walks start as usual.
    let lie_at = |state: u32| {
        let lying = SessionGenerator::new(&office, config.session.clone(), seed ^ 0x7ab1e, state, START_NS)
            .table((jump_ns - START_NS) as f64 * 1e-9);
        move |feeder: &mut Feeder| {
            feeder.replace_segment(lying);
            feeder.generator_mut().teleport(state);
        }
    };
    let reference = pass(&office, &site, config, seed, epochs, lie_at(far), |_, _| true, None)?;
    let (cold, twin_reference) = match config.comparisons {
        true => (
            pass(&office, &site, config, seed, epochs, teleport, |_, _| true, Some(before + 1))?,
            // The twin's own reference, the same way: the rule applied to an engine that was
            // not disturbed, whose history differs from its reference's as the kidnapped one's
            // does (a walk, not a table).
            pass(&office, &site, config, seed, epochs, lie_at(at), |_, _| true, None)?,
        ),
        false => (Pass::default(), Pass::default()),
    };
    let mut run = run_result(
        seed,
        disturbance_m,
        before,
        [&disturbed, &twin, &reference, &cold],
        // The kidnapped engine has forgotten its past when it says what a fresh engine says.
        config.comparisons.then_some(&cold),
    );
    // The references walk exactly what their runs walk from the first good epoch on.
    debug_assert_eq!(disturbed.truths[before..], reference.truths[before..]);
    debug_assert!(!config.comparisons || twin.truths[before..] == twin_reference.truths[before..]);
    run.twin_reference_errors_m = twin_reference.errors.get(before..).unwrap_or_default().to_vec();
    Ok(run)
}

fn outage_run(config: &RecoveryConfig, seed: u64) -> Result<RecoveryRun, Error> {
    let (office, site) = building(seed)?;
    let before = config.before_outage_epochs;
    let outage = (config.outage_s * 1e9 / SCAN_INTERVAL_NS as f64).round() as usize;
    let epochs = before + outage + config.after_epochs;
    let radio = |k: usize, _| k <= before || k > before + outage;
    let disturbed = pass(&office, &site, config, seed, epochs, |_| {}, radio, None)?;
    let twin = pass(&office, &site, config, seed, epochs, |_| {}, |_, _| true, None)?;
    let cold = match config.comparisons {
        true => pass(&office, &site, config, seed, epochs, |_| {}, radio, Some(before + outage + 1))?,
        false => Pass::default(),
    };
    // How far the person walked without radio: the path length between epochs, sampled at
    // the epochs (a lower bound of the path).
    let walked: f64 =
        disturbed.truths[before..=before + outage].windows(2).map(|w| nalgebra::distance(&w[0], &w[1])).sum();
    // After the outage the twin has had the same input; the disturbed engine has forgotten the
    // outage when it says what the twin says.
    Ok(run_result(seed, walked, before + outage, [&disturbed, &twin, &twin, &cold], Some(&twin)))
}

/// Splits the disturbed, twin, reference and cold-start passes at the last epoch before good
/// data (`last_bad`, 1-based).
fn run_result(
    seed: u64,
    disturbance_m: f64,
    last_bad: usize,
    [disturbed, twin, reference, cold]: [&Pass; 4],
    same_input: Option<&Pass>,
) -> RecoveryRun {
    let epochs_to_forget = same_input.and_then(|same_input| {
        let apart: Vec<f64> = disturbed.positions[last_bad..]
            .iter()
            .zip(&same_input.positions[last_bad..])
            .map(|(a, b)| match (a, b) {
                (Some(a), Some(b)) => nalgebra::distance(a, b),
                _ => f64::INFINITY,
            })
            .collect();
        epochs_to_recover(&apart, SAME_PLACE_M, HOLD_EPOCHS)
    });
    RecoveryRun {
        epochs_to_forget,
        forget_measured: same_input.is_some(),
        seed,
        disturbance_m,
        error_before_m: last_bad.checked_sub(1).map_or(f64::NAN, |i| disturbed.errors[i]),
        errors_m: disturbed.errors[last_bad..].to_vec(),
        twin_errors_m: twin.errors[last_bad..].to_vec(),
        reference_errors_m: reference.errors[last_bad..].to_vec(),
        twin_steady_errors_m: twin.errors.get(WARMUP_EPOCHS..).unwrap_or_default().to_vec(),
        cold_errors_m: cold.errors.get(last_bad..).unwrap_or_default().to_vec(),
        twin_reference_errors_m: Vec::new(),
        epochs_to_recover: None,
        cold_epochs_to_recover: None,
        twin_epochs_to_recover: None,
        epochs_within_tolerance: None,
        twin_epochs_within_tolerance: None,
        reference_epochs_within_tolerance: None,
        cold_epochs_within_tolerance: None,
        error_at_recovery_m: None,
        filter_restarts: disturbed.restarts,
    }
}

fn distribution(epochs: &[Option<usize>], after_epochs: usize) -> RecoveryDistribution {
    let mut values: Vec<f64> = epochs.iter().map(|e| e.unwrap_or(after_epochs + 1) as f64).collect();
    values.sort_by(f64::total_cmp);
    RecoveryDistribution {
        runs: values.len(),
        median: quantile(&values, 0.5),
        p90: quantile(&values, 0.9),
        max: values.last().copied().unwrap_or(f64::NAN),
        within_target: epochs.iter().filter(|e| e.is_some_and(|r| r <= TARGET_EPOCHS)).count() as f64
            / epochs.len().max(1) as f64,
        not_recovered: epochs.iter().filter(|e| e.is_none()).count(),
    }
}

fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    sum / n.max(1) as f64
}

/// Scores the runs of one scenario against the pooled normal error of their twins.
fn score(scenario: &str, mut runs: Vec<RecoveryRun>, after_epochs: usize) -> ScenarioReport {
    let mut normal: Vec<f64> = runs.iter().flat_map(|r| r.twin_steady_errors_m.iter().copied()).collect();
    normal.sort_by(f64::total_cmp);
    let (median, p90) = (quantile(&normal, 0.5), quantile(&normal, 0.9));
    let tolerance = (1.5 * median).max(p90);
    for run in &mut runs {
        let matched_to = |errors: &[f64], reference: &[f64]| {
            epochs_to_match(errors, reference, tolerance, SAME_PLACE_M, HOLD_EPOCHS)
        };
        let matched = |errors: &[f64]| matched_to(errors, &run.reference_errors_m);
        let within = |errors: &[f64]| epochs_to_recover(errors, tolerance, HOLD_EPOCHS);
        run.epochs_to_recover = matched(&run.errors_m);
        run.cold_epochs_to_recover = matched(&run.cold_errors_m);
        run.twin_epochs_to_recover = (!run.twin_reference_errors_m.is_empty())
            .then(|| matched_to(&run.twin_errors_m, &run.twin_reference_errors_m))
            .flatten();
        run.epochs_within_tolerance = within(&run.errors_m);
        run.twin_epochs_within_tolerance = within(&run.twin_errors_m);
        run.reference_epochs_within_tolerance = within(&run.reference_errors_m);
        run.cold_epochs_within_tolerance = within(&run.cold_errors_m);
        run.error_at_recovery_m = run.epochs_to_recover.map(|r| run.errors_m[r - 1]);
    }
    let mut reference: Vec<f64> = runs.iter().flat_map(|r| r.reference_errors_m.iter().copied()).collect();
    reference.sort_by(f64::total_cmp);
    let mut at_recovery: Vec<f64> = runs.iter().filter_map(|r| r.error_at_recovery_m).collect();
    at_recovery.sort_by(f64::total_cmp);
    let mut before: Vec<f64> = runs.iter().map(|r| r.error_before_m).collect();
    before.sort_by(f64::total_cmp);
    let settled = |errors: fn(&RecoveryRun) -> &[f64]| {
        mean(runs.iter().flat_map(|r| errors(r).iter().skip(TARGET_EPOCHS).copied()))
    };
    let has_forget = runs.iter().all(|r| r.forget_measured);
    let of = |f: fn(&RecoveryRun) -> Option<usize>| {
        distribution(&runs.iter().map(f).collect::<Vec<_>>(), after_epochs)
    };
    let has_cold = runs.iter().all(|r| !r.cold_errors_m.is_empty());
    ScenarioReport {
        scenario: scenario.to_owned(),
        normal_median_m: median,
        normal_p90_m: p90,
        tolerance_m: tolerance,
        reference_error_m: [quantile(&reference, 0.5), quantile(&reference, 0.9)],
        recovery: of(|r| r.epochs_to_recover),
        cold_recovery: has_cold.then(|| of(|r| r.cold_epochs_to_recover)),
        twin_recovery: runs
            .iter()
            .all(|r| !r.twin_reference_errors_m.is_empty())
            .then(|| of(|r| r.twin_epochs_to_recover)),
        tolerance_recovery: of(|r| r.epochs_within_tolerance),
        twin_tolerance_recovery: of(|r| r.twin_epochs_within_tolerance),
        reference_tolerance_recovery: of(|r| r.reference_epochs_within_tolerance),
        cold_tolerance_recovery: has_cold.then(|| of(|r| r.cold_epochs_within_tolerance)),
        forget: has_forget.then(|| of(|r| r.epochs_to_forget)),
        median_error_at_recovery_m: quantile(&at_recovery, 0.5),
        median_error_before_m: quantile(&before, 0.5),
        settled_mean_error_m: [
            settled(|r| &r.errors_m),
            settled(|r| &r.reference_errors_m),
            settled(|r| &r.twin_errors_m),
        ],
        runs,
    }
}

/// Runs both scenarios over `config.seeds` runs; `progress` is told after each run.
pub fn run(
    config: &RecoveryConfig,
    mut progress: impl FnMut(&str, &RecoveryRun),
) -> Result<RecoveryReport, Error> {
    let seeds = config.first_seed..config.first_seed.saturating_add(config.seeds);
    let mut kidnapped = Vec::new();
    for seed in seeds.clone() {
        let run = kidnapped_run(config, seed)?;
        progress("kidnapped", &run);
        kidnapped.push(run);
    }
    let mut outage = Vec::new();
    for seed in seeds {
        let run = outage_run(config, seed)?;
        progress("radio_outage", &run);
        outage.push(run);
    }
    Ok(RecoveryReport {
        hold_epochs: HOLD_EPOCHS,
        target_epochs: TARGET_EPOCHS,
        epoch_s: SCAN_INTERVAL_NS as f64 * 1e-9,
        kidnapped: score("kidnapped", kidnapped, config.after_epochs),
        radio_outage: score("radio_outage", outage, config.after_epochs),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovery_is_the_first_epoch_of_a_run_within_tolerance() {
        let e = [5.0, 0.5, 0.4, 3.0, 0.5, 0.4, 0.3, 0.2, 0.1, 0.9];
        assert_eq!(epochs_to_recover(&e, 1.0, 5), Some(5));
        assert_eq!(epochs_to_recover(&e, 1.0, 1), Some(2));
        assert_eq!(epochs_to_recover(&e, 0.05, 1), None);
        assert_eq!(epochs_to_recover(&e[..3], 1.0, 5), None);
    }

    #[test]
    fn a_run_has_recovered_once_it_is_within_tolerance_or_no_worse_than_its_reference() {
        let tolerance = 1.0;
        let m = SAME_PLACE_M;
        // Shared excursions: the reference has them too, so they are the engine's normal error.
        let reference = [0.3, 0.4, 2.5, 3.0, 0.2, 2.0, 0.3, 0.4, 0.3, 0.2];
        let shared = [4.0, 0.4, 2.5, 2.9, 0.3, 2.0 + m, 0.3, 0.4, 0.3, 0.2];
        assert_eq!(epochs_to_match(&shared, &reference, tolerance, m, 5), Some(2));
        // The first rule holds the same run until its last excursion is over.
        assert_eq!(epochs_to_recover(&shared, tolerance, 5), None);
        assert_eq!(epochs_to_recover(&shared[..], tolerance, 4), Some(7));
        // Worse than the reference beyond the tolerance: not recovered until it is not.
        let behind = [4.0, 3.5, 3.0, 3.0 + 2.0 * m, 0.5, 0.4, 0.3, 0.4, 0.3, 0.2];
        assert_eq!(epochs_to_match(&behind, &reference, tolerance, m, 5), Some(5));
        let lost = [4.0, 3.5, 3.0, 3.5, 3.0, 3.5, 3.0, 3.5, 3.0, 3.5];
        assert_eq!(epochs_to_match(&lost, &reference, tolerance, m, 5), None);
        // Within the tolerance counts even where the reference is better.
        let normal = [0.9; 10];
        assert_eq!(epochs_to_match(&normal, &[0.0; 10], tolerance, m, 5), Some(1));
        // No estimate never counts; no reference leaves the tolerance.
        let mut gap = normal;
        gap[2] = f64::INFINITY;
        assert_eq!(epochs_to_match(&gap, &[f64::INFINITY; 10], tolerance, m, 5), Some(4));
        assert_eq!(epochs_to_match(&shared, &[], tolerance, m, 5), None);
    }
}
