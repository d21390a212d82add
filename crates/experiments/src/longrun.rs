//! The long run: a simulated day on the office at 100 Hz, in accelerated time,
//! through the engine an app holds. Checks that memory stays flat and positions finite.
//!
//! A [`SessionGenerator`] makes the day one activity at a time (walks with stops, the phone on
//! a table); a [`Feeder`] pushes accelerometer, gyroscope and magnetometer samples in batches
//! of 50 up to each epoch; a WiFi scan comes every 2 s. The same input goes, in lockstep, to
//! the engine an app holds (an [`AppEngine`] the caller brings: `waymark simulate
//! --experiment long-run` brings the SDK library's `PositioningEngine`, what Kotlin and Swift
//! apps hold, with a subscribed listener) and to a core [`Engine`], which exposes the counters
//! and memory accounting the FFI does not; their positions must agree exactly. Every report
//! interval (an hour by default) the process's resident memory (`VmRSS`, `VmHWM` from
//! `/proc/self/status`), the engine's accounted track memory and the error against the truth
//! are recorded.

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use serde::Serialize;
use std::sync::Arc;
use std::time::Instant;
use waymark_engine::hmm::ViterbiWindow;
use waymark_engine::hmm::STEP_BYTES_PER_STATE;
use waymark_engine::radio::Scan;
use waymark_engine::sensors::{MotionStats, SensorSample};
use waymark_engine::site::{Site, PSEUDO_SPACING_M};
use waymark_engine::Engine;
use waymark_engine::EngineConfig;
use waymark_engine::Error;
use waymark_sim::session::{Activity, Feeder, ImuSink, SessionConfig, SessionGenerator};
use waymark_sim::{Office, OfficeConfig};

/// One scan every 2 s: an unthrottled Android phone, the same as the replay's timer
/// ([`ReplayOptions::timer_ns`](waymark_survey::replay::ReplayOptions::timer_ns),
/// `docs/tuning.md#replay-timer`).
pub const SCAN_INTERVAL_NS: u64 = 2_000_000_000;

/// Samples per sensor batch: 50, half a second at 100 Hz, as the replay batches
/// (`io::ilc::EventOptions`); an imitation of an app, not a tuned value.
pub const BATCH_SAMPLES: usize = 50;

/// The long-run experiment: hours of one simulated session through the FFI and the core engine.
#[derive(Clone, Debug)]
pub struct LongRunConfig {
    /// Simulated length, hours (24: a day).
    pub hours: f64,
    /// Seed of the building and the session.
    pub seed: u64,
    /// A report every this many simulated seconds: 3600.
    pub report_every_s: f64,
    /// The building.
    pub office: OfficeConfig,
    /// The day's activities.
    pub session: SessionConfig,
    /// Whether the site gets pseudo states (as the demo's engine).
    pub pseudo_states: bool,
}

impl Default for LongRunConfig {
    fn default() -> Self {
        Self {
            hours: 24.0,
            seed: 0,
            report_every_s: 3600.0,
            office: OfficeConfig::default(),
            session: SessionConfig::default(),
            pseudo_states: true,
        }
    }
}

/// Counters of the engine's input, as [`waymark_engine::InputStats`] plus the motion
/// tracker's drops.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize)]
pub struct InputCounts {
    /// Scans that made an epoch.
    pub scans_accepted: u64,
    /// Scans rejected, every reason.
    pub scans_rejected: u64,
    /// Readings dropped inside accepted scans (unknown, duplicate, stale).
    pub readings_dropped: u64,
    /// Filter restarts.
    pub filter_restarts: u64,
    /// Inertial samples accepted.
    pub samples_accepted: u64,
    /// Inertial samples dropped (non-finite, out of order, backlog overflow).
    pub samples_dropped: u64,
    /// Steps counted.
    pub steps: u64,
}

impl InputCounts {
    fn of(engine: &Engine) -> Self {
        let s = engine.stats();
        let m: &MotionStats = engine.motion_stats();
        let streams = [m.accelerometer, m.gyroscope, m.magnetometer];
        Self {
            scans_accepted: s.scans_accepted,
            scans_rejected: s.scans_out_of_order
                + s.scans_empty
                + s.scans_non_finite
                + s.scans_no_known_transmitter
                + s.scans_invalid_motion,
            readings_dropped: s.readings_unknown + s.readings_duplicate + s.readings_stale,
            filter_restarts: s.filter_restarts,
            samples_accepted: streams.iter().map(|x| x.accepted).sum(),
            samples_dropped: streams.iter().map(|x| x.non_finite + x.out_of_order + x.overflowed).sum(),
            steps: m.steps_total,
        }
    }
}

/// One report interval.
#[derive(Clone, Debug, Serialize)]
pub struct IntervalReport {
    /// Simulated time at the end of the interval, h.
    pub hours: f64,
    /// Wall-clock time since the start, s.
    pub wall_s: f64,
    /// Resident set of the process, kB (`VmRSS`); `None` where `/proc` is not there.
    pub rss_kb: Option<u64>,
    /// Peak resident set so far, kB (`VmHWM`).
    pub hwm_kb: Option<u64>,
    /// Bytes the engine accounts to its Viterbi window ([`Engine::track_memory_bytes`]).
    pub track_memory_bytes: usize,
    /// Bytes its fixed-lag smoother holds ([`Engine::fixed_lag_memory_bytes`]).
    pub fixed_lag_memory_bytes: usize,
    /// Epochs in the Viterbi window (the fixed-lag estimate reads from it).
    pub track_window_epochs: usize,
    /// Epochs in this interval.
    pub epochs: u64,
    /// Positions the app engine's listener received in this interval with finite x, y and
    /// accuracy.
    pub finite_positions: u64,
    /// ... and with any of them NaN or infinite.
    pub non_finite_positions: u64,
    /// Mean error of the live position against the truth, m.
    pub mean_error_m: f64,
    /// 90th percentile, m.
    pub p90_error_m: f64,
    /// Largest, m.
    pub max_error_m: f64,
    /// Share of epochs the person was walking (not standing, not the phone on a table).
    pub walking_share: f64,
    /// Share of epochs the phone lay on a table.
    pub table_share: f64,
    /// Mean error while walking / standing with the phone in hand / with the phone on a
    /// table, m (NaN when there was no such epoch).
    pub mean_error_by_activity_m: [f64; 3],
    /// Epochs where the app engine (the FFI's) and the core engine disagreed (must be 0).
    pub ffi_core_mismatches: u64,
    /// Cumulative input counters at the end of the interval.
    pub input: InputCounts,
}

/// What came out.
#[derive(Clone, Debug, Serialize)]
pub struct LongRunReport {
    /// Seed.
    pub seed: u64,
    /// Simulated hours.
    pub hours: f64,
    /// States the engine ran on.
    pub states: usize,
    /// The Viterbi window's capacity, epochs (`EngineConfig::track_window_epochs`).
    pub track_window_capacity: usize,
    /// Its bound in bytes ([`ViterbiWindow::memory_bound_bytes`]: every epoch listing every
    /// state's back-pointer, and the scores).
    pub track_memory_bound_bytes: usize,
    /// Fixed lag, epochs: the steps the fixed-lag smoother keeps.
    pub fixed_lag_epochs: usize,
    /// The smoother's bound in bytes: 2 × lag × states × `STEP_BYTES_PER_STATE` (each step's
    /// vectors over at most every state, grown by doubling).
    pub fixed_lag_memory_bound_bytes: usize,
    /// Per interval.
    pub intervals: Vec<IntervalReport>,
    /// RSS at the first report at or after 1 h, kB.
    pub rss_1h_kb: Option<u64>,
    /// RSS at the end, kB.
    pub rss_end_kb: Option<u64>,
    /// `rss_end_kb / rss_1h_kb`.
    pub rss_end_over_1h: Option<f64>,
    /// Largest activity segment the generator held, bytes (its whole buffer).
    pub generator_peak_bytes: usize,
    /// Epochs in all.
    pub epochs: u64,
    /// Positions with a non-finite field, in all.
    pub non_finite_positions: u64,
    /// Mean error over the whole run, m.
    pub mean_error_m: f64,
    /// Wall-clock time, s.
    pub wall_s: f64,
}

/// `VmRSS` and `VmHWM` of this process, kB, from `/proc/self/status` (Linux).
pub fn process_memory_kb() -> (Option<u64>, Option<u64>) {
    let Ok(status) = std::fs::read_to_string("/proc/self/status") else { return (None, None) };
    let field = |name: &str| {
        status
            .lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|rest| rest.trim().trim_end_matches("kB").trim().parse().ok())
    };
    (field("VmRSS:"), field("VmHWM:"))
}

/// The engine an app holds, fed the same input as the core engine in lockstep. The simulator
/// depends on the engine crate alone, so the caller brings it: the CLI's long run wraps the
/// SDK library's `PositioningEngine` (crates/cli/src/app_engine.rs).
pub trait AppEngine: ImuSink {
    /// One scan: the position it returned, as (x, y), or `None` when it was rejected.
    fn push_scan(&mut self, scan: &Scan) -> Option<(f64, f64)>;
    /// The positions its listener has heard so far: (all fields finite, some field NaN or
    /// infinite).
    fn positions_heard(&self) -> (u64, u64);
}

/// The two engines fed in lockstep.
struct Engines {
    app: Box<dyn AppEngine>,
    core: Engine,
}

impl ImuSink for Engines {
    // A rejected batch is counted by each engine; the core's counters say the same.
    fn accelerometer(&mut self, batch: &[SensorSample]) {
        self.core.push_accelerometer(batch);
        self.app.accelerometer(batch);
    }

    fn gyroscope(&mut self, batch: &[SensorSample]) {
        self.core.push_gyroscope(batch);
        self.app.gyroscope(batch);
    }

    fn magnetometer(&mut self, batch: &[SensorSample]) {
        self.core.push_magnetometer(batch);
        self.app.magnetometer(batch);
    }
}

/// Nearest-rank quantile of unsorted values (sorts them).
fn quantile(values: &mut [f64], q: f64) -> f64 {
    values.sort_by(f64::total_cmp);
    waymark_survey::scoring::quantile(values, q)
}

/// Runs the long session; `app` makes the app's engine from the site file (JSON), and
/// `progress` sees each interval as it completes.
pub fn run(
    config: &LongRunConfig,
    app: impl FnOnce(&str) -> Result<Box<dyn AppEngine>, String>,
    mut progress: impl FnMut(&IntervalReport),
) -> Result<LongRunReport, Error> {
    let started = Instant::now();
    let office = Office::generate(&OfficeConfig { seed: config.seed, ..config.office.clone() });
    let site = if config.pseudo_states {
        office.site.with_pseudo_states(PSEUDO_SPACING_M)
    } else {
        office.site.clone()
    };
    let states = site.states().len();
    let site_json = site.to_json();
    let site = Arc::new(Site::from_json(site_json.as_bytes())?);
    let engine_config = EngineConfig::default();
    let core = Engine::new(Arc::clone(&site), engine_config.clone())?;
    let app =
        app(&site_json).map_err(|e| Error::InvalidConfig(format!("the app engine refused the site: {e}")))?;
    drop((site, site_json));
    let mut engines = Engines { app, core };

    let mut rng = ChaCha8Rng::seed_from_u64(config.seed ^ 0x10_4e_2a_11);
    let start_state = rng.random_range(0..office.points().len()) as u32;
    let start_ns = 1_000_000_000;
    let generator =
        SessionGenerator::new(&office, config.session.clone(), rng.random(), start_state, start_ns);
    let mut feeder = Feeder::new(generator, BATCH_SAMPLES);

    let total_epochs = (config.hours.max(0.0) * 3600e9 / SCAN_INTERVAL_NS as f64).round() as u64;
    let epochs_per_report = ((config.report_every_s * 1e9 / SCAN_INTERVAL_NS as f64).round() as u64).max(1);
    let mut intervals = Vec::new();
    let mut errors = Vec::with_capacity(epochs_per_report as usize);
    let (mut walking, mut table, mut mismatches, mut interval_epochs) = (0u64, 0u64, 0u64, 0u64);
    let mut seen = (0u64, 0u64);
    let mut by_activity = [(0.0, 0u64); 3];
    let (mut error_sum, mut scored) = (0.0, 0u64);
    for k in 1..=total_epochs {
        let t = start_ns + k * SCAN_INTERVAL_NS;
        let truth = feeder.feed_until(t, &mut engines);
        let segment = feeder.segment();
        walking += u64::from(segment.walking_at(t));
        table += u64::from(segment.activity == Activity::Table);
        let scan = office.field.scan_at(truth, t, &mut rng);
        let core_result = engines.core.push_scan(&scan).map(|epoch| epoch.position);
        let app_result = engines.app.push_scan(&scan);
        match (&core_result, app_result) {
            (Ok(c), Some((x, y))) => {
                if c.x.to_bits() != x.to_bits() || c.y.to_bits() != y.to_bits() {
                    mismatches += 1;
                }
                let error = nalgebra::distance(&truth, &nalgebra::Point2::new(c.x, c.y));
                if error.is_finite() {
                    let activity = if segment.walking_at(t) {
                        0
                    } else if segment.activity == Activity::Table {
                        2
                    } else {
                        1
                    };
                    by_activity[activity].0 += error;
                    by_activity[activity].1 += 1;
                    errors.push(error);
                    error_sum += error;
                    scored += 1;
                }
            }
            (Err(_), None) => {}
            _ => mismatches += 1,
        }
        interval_epochs += 1;
        if k % epochs_per_report == 0 || k == total_epochs {
            let (rss_kb, hwm_kb) = process_memory_kb();
            let (finite, non_finite) = engines.app.positions_heard();
            let n = interval_epochs as f64;
            let mean_error_m = errors.iter().sum::<f64>() / errors.len().max(1) as f64;
            let p90_error_m = quantile(&mut errors, 0.9);
            let report = IntervalReport {
                hours: (k * SCAN_INTERVAL_NS) as f64 / 3600e9,
                wall_s: started.elapsed().as_secs_f64(),
                rss_kb,
                hwm_kb,
                track_memory_bytes: engines.core.track_memory_bytes(),
                fixed_lag_memory_bytes: engines.core.fixed_lag_memory_bytes(),
                track_window_epochs: engines.core.track().len(),
                epochs: interval_epochs,
                finite_positions: finite - seen.0,
                non_finite_positions: non_finite - seen.1,
                mean_error_m,
                p90_error_m,
                max_error_m: errors.last().copied().unwrap_or(f64::NAN),
                walking_share: walking as f64 / n,
                table_share: table as f64 / n,
                mean_error_by_activity_m: by_activity
                    .map(|(sum, n)| if n > 0 { sum / n as f64 } else { f64::NAN }),
                ffi_core_mismatches: mismatches,
                input: InputCounts::of(&engines.core),
            };
            interval_epochs = 0;
            by_activity = [(0.0, 0); 3];
            seen = (finite, non_finite);
            errors.clear();
            walking = 0;
            table = 0;
            mismatches = 0;
            progress(&report);
            intervals.push(report);
        }
    }
    let rss_at = |hours: f64| intervals.iter().find(|i| i.hours >= hours - 1e-9).and_then(|i| i.rss_kb);
    let rss_1h_kb = rss_at(1.0);
    let rss_end_kb = intervals.last().and_then(|i| i.rss_kb);
    let track_window_capacity = engine_config.track_window_epochs;
    Ok(LongRunReport {
        seed: config.seed,
        hours: config.hours,
        states,
        track_window_capacity,
        track_memory_bound_bytes: ViterbiWindow::memory_bound_bytes(states, track_window_capacity),
        fixed_lag_epochs: engine_config.fixed_lag_epochs,
        fixed_lag_memory_bound_bytes: 2 * engine_config.fixed_lag_epochs * states * STEP_BYTES_PER_STATE,
        rss_1h_kb,
        rss_end_kb,
        rss_end_over_1h: rss_1h_kb.zip(rss_end_kb).map(|(a, b)| b as f64 / a as f64),
        generator_peak_bytes: feeder.peak_segment_bytes(),
        epochs: intervals.iter().map(|i| i.epochs).sum(),
        non_finite_positions: intervals.iter().map(|i| i.non_finite_positions).sum(),
        mean_error_m: error_sum / scored.max(1) as f64,
        wall_s: started.elapsed().as_secs_f64(),
        intervals,
    })
}
