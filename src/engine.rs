//! The positioning session: takes inertial batches and scans in time order, runs one HMM epoch
//! per scan (or per [`Engine::advance`] without radio), and publishes positions, status
//! changes and track revisions to whoever polls or listens.
//!
//! The engine is single-threaded and deterministic, so a replay is exact; the FFI layer puts
//! it behind a lock.

use crate::config::{EngineConfig, TransitionModel};
use crate::error::{Error, InputError};
use crate::fix::{self, PositionFix};
use crate::habits::{FixError, HabitError, HabitModel, HabitPrior, HabitReport, Habitual};
use crate::history::{EpochInput, EpochRecord, History};
use crate::hmm::{
    estimate, ForwardFilter, HipeRegion, HipeTransition, HoangTransition, Transition, UniformReach,
    ViterbiWindow,
};
use crate::radio::{Scan, ScanHasher};
use crate::sensors::{
    BatchReport, MdiScenario, MotionState, MotionStats, MotionTracker, MotionUpdate, SensorSample,
};
use crate::site::{most_likely_zone, ReachTable, Site, SparseScans, SPARSE_SCAN_GAP_S};
use std::sync::Arc;

/// The highest RSSI a scan may report, dBm: +100 dBm is 10 kW at the antenna, where WiFi and
/// BLE transmit at most +36 dBm EIRP. A higher value is a corrupt producer, and one far higher
/// (found by fuzzing, `engine_calls`: `f64::MAX` dBm) makes every state's log-likelihood
/// -∞, so no state explains the scan. Values at or below the clip level are fine: they read as
/// "not heard".
pub const MAX_RSSI_DBM: f64 = 100.0;

/// With the `fault-injection` feature (test builds only), an epoch (a scan or an advance) at
/// this time panics after it has stepped the filter and the track, moved the clock, raised the
/// counters and told the listeners, just before it stores the position: as half-done as an
/// epoch gets. The engine must come out of it exactly as it was before the call.
pub const FAULT_INJECTION_MID_EPOCH_NS: u64 = u64::MAX - 8;

/// Where the phone is, after one epoch.
#[derive(Clone, Debug, PartialEq)]
pub struct Position {
    /// Time of the epoch (the scan's timestamp), ns.
    pub timestamp_ns: u64,
    /// Floor index into the site's floors.
    pub floor: usize,
    /// Posterior probability of that floor.
    pub floor_probability: f64,
    /// The most likely zone, an index into the site's zones: the zone holding the most
    /// posterior mass, or `None` when the site has no zones or more mass lies outside every
    /// zone than in any one of them.
    pub zone: Option<usize>,
    /// Posterior probability of `zone` (of being in no zone when it is `None`).
    pub zone_probability: f64,
    /// East-ish coordinate in the site's metric frame, m.
    pub x: f64,
    /// North-ish coordinate in the site's metric frame, m.
    pub y: f64,
    /// Radius of the circle around (x, y) that holds the true position with probability 0.68
    /// (the configured `accuracy_mass`), m. Always > 0.
    pub accuracy_m: f64,
    /// Radius of the circle holding the true position with probability 0.95, m; ≥ `accuracy_m`.
    pub accuracy_95_m: f64,
    /// Direction of travel, radians clockwise from the site's +y axis, when the sensors gave a
    /// trustworthy absolute heading this epoch.
    pub heading_rad: Option<f64>,
    /// One standard deviation of `heading_rad`, rad.
    pub heading_accuracy_rad: Option<f64>,
    /// Walking, stationary, or unknown (no accelerometer).
    pub motion_state: MotionState,
    /// The motion information this epoch had (HIPE Table 1).
    pub scenario: MdiScenario,
    /// Steps detected since the previous epoch.
    pub steps: u32,
    /// ln p(scan | earlier input): how well the radio map explains this scan; `None` for an
    /// epoch without a scan. Very low values mean the phone hears what the map does not expect.
    pub radio_log_evidence: Option<f64>,
    /// How much better, per reading, the state that best explains this scan does than a state
    /// with no fingerprint, nats; `None` for an epoch without a scan. Below the site's
    /// [`radio_fit_floor`](crate::site::Calibration::radio_fit_floor) the map does not explain
    /// the scan and the engine positions by the motion alone.
    pub radio_fit: Option<f64>,
    /// Distance walked since the radio last explained a scan, m (0 while it does): the phone is
    /// probably beyond the surveyed area, up to this far from the states the estimate stands
    /// on, and both radii include it. The steps' length when measured, else HIPE's assumed
    /// speed (1 m/s) over the time walking or of unknown motion.
    pub beyond_radio_m: f64,
}

/// One point of the smoothed track.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackPoint {
    /// Epoch time, ns.
    pub timestamp_ns: u64,
    /// Index of the state on the most likely path ([`Engine::track`]), or holding the most
    /// smoothed mass ([`Engine::fixed_lag_position`]).
    pub state: u32,
    /// The floor.
    pub floor: usize,
    /// x, m: the state's on the track, the smoothed estimate's for the fixed-lag position.
    pub x: f64,
    /// y, m, likewise.
    pub y: f64,
}

/// Something about the session changed.
#[derive(Clone, Debug, PartialEq)]
pub enum StatusEvent {
    /// The motion information available changed (a sensor stopped, the compass became
    /// disturbed, ...).
    ScenarioChanged {
        /// When, ns.
        timestamp_ns: u64,
        /// Before.
        from: MdiScenario,
        /// Now.
        to: MdiScenario,
    },
    /// The person started or stopped walking.
    MotionStateChanged {
        /// When, ns.
        timestamp_ns: u64,
        /// Before.
        from: MotionState,
        /// Now.
        to: MotionState,
    },
}

/// Receives what the engine publishes. Only `on_position` is required.
pub trait PositionListener: Send {
    /// Called after each epoch, on the thread that pushed the input.
    fn on_position(&mut self, position: &Position);
    /// Called when the motion scenario or state changes.
    fn on_status(&mut self, _status: &StatusEvent) {}
    /// Called when the most likely track changed for epochs before the latest one (a later
    /// observation showed an earlier position was wrong): the revised points, oldest first.
    fn on_track_revised(&mut self, _revised: &[TrackPoint]) {}
}

impl<F: FnMut(&Position) + Send> PositionListener for F {
    fn on_position(&mut self, position: &Position) {
        self(position)
    }
}

/// Identifies a subscription for [`Engine::unsubscribe`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SubscriptionId(u64);

/// What the engine took and what it dropped, by reason.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct InputStats {
    /// Scans that made an epoch.
    pub scans_accepted: u64,
    /// Scans rejected because their timestamp was not after the last epoch.
    pub scans_out_of_order: u64,
    /// Scans rejected for having no readings.
    pub scans_empty: u64,
    /// Scans rejected for a NaN, infinite or impossible (below -1000 dBm) RSSI.
    pub scans_non_finite: u64,
    /// Scans rejected for an RSSI above [`MAX_RSSI_DBM`].
    pub scans_rssi_too_high: u64,
    /// Scans rejected because no reading was of a known transmitter.
    pub scans_no_known_transmitter: u64,
    /// Scans rejected because the motion given with them was invalid
    /// ([`Engine::push_scan_with_motion`]).
    pub scans_invalid_motion: u64,
    /// Readings of transmitters not in the site (in accepted scans).
    pub readings_unknown: u64,
    /// Repeated readings of one transmitter within a scan (in accepted scans).
    pub readings_duplicate: u64,
    /// Readings older than `max_reading_age_ns` (in accepted scans).
    pub readings_stale: u64,
    /// Epochs without a scan ([`Engine::advance`]).
    pub motion_epochs: u64,
    /// Epochs without a scan rejected: a timestamp not after the last epoch, or invalid motion
    /// given with it ([`Engine::advance_with_motion`]).
    pub advances_rejected: u64,
    /// Times the filter restarted from the uniform prior: after a gap too long to bridge, or
    /// when no state could explain a scan.
    pub filter_restarts: u64,
    /// Accepted scans the map did not explain (a radio fit below the site's floor): their
    /// epochs moved by the motion alone.
    pub scans_unexplained: u64,
    /// Position fixes that made an epoch ([`Engine::push_fix`]).
    pub fixes_accepted: u64,
    /// Position fixes rejected: a timestamp not after the last epoch, a NaN or infinite
    /// coordinate, an accuracy not > 0, an unknown floor, or too far from every state.
    pub fixes_rejected: u64,
    /// User feedback taken ([`Engine::confirm_zone`], [`Engine::confirm_position`]).
    pub feedback_accepted: u64,
    /// User feedback rejected: a timestamp before the last epoch, an unknown zone or floor, a
    /// NaN or infinite coordinate, a radius not > 0, or no state within the radius.
    pub feedback_rejected: u64,
}

/// Everything an engine holds that decides its later answers, for tests that check a call
/// changed nothing (a rejected scan must leave the engine as it was). Not a stable API: the
/// internals are compared through their `Debug` renderings, which show every field.
#[doc(hidden)]
#[derive(Clone, Debug, PartialEq)]
pub struct EngineSnapshot {
    /// Time of the last epoch.
    pub last_epoch_ns: Option<u64>,
    /// The latest position.
    pub position: Option<Position>,
    /// The posterior over the site's states.
    pub posterior: Vec<f64>,
    /// The track as last published to listeners.
    pub published_track: Vec<TrackPoint>,
    /// Counts of accepted and dropped input (a test decides whether these count as state).
    pub stats: InputStats,
    /// The active subscriptions, and the next id.
    pub subscriptions: (Vec<SubscriptionId>, u64),
    /// `Debug` of the forward filter, the Viterbi window and the motion tracker.
    pub internals: String,
    /// The epoch history with its feedback.
    pub history: Vec<EpochRecord>,
}

/// A positioning session on one site.
pub struct Engine {
    site: Arc<Site>,
    config: EngineConfig,
    reach: Arc<ReachTable>,
    /// The surveyed map's own table ([`ReachTable::build_surveyed`]) when the site has
    /// unsurveyed states: the prediction's while the radio explains what it hears.
    map_reach: Option<Arc<ReachTable>>,
    /// Whether the running epoch predicts over the whole table: it or the one before was
    /// beyond the map.
    whole_reach: bool,
    filter: ForwardFilter,
    viterbi: ViterbiWindow,
    tracker: MotionTracker,
    ln_emission: Vec<f64>,
    scratch: Vec<(f64, f64)>,
    last_epoch_ns: Option<u64>,
    latest: Option<Position>,
    published_track: Vec<TrackPoint>,
    listeners: Vec<(SubscriptionId, Box<dyn PositionListener>)>,
    next_subscription: u64,
    stats: InputStats,
    /// γ in effect per floor (the configuration's, else the floor's, else the site's) in
    /// epochs with and without a movement likelihood.
    rssi_weight: Vec<[Option<f64>; 2]>,
    /// γ before the engine has a floor: the configuration's, else the site-wide one.
    site_rssi_weight: [Option<f64>; 2],
    /// γ per motion scenario in epochs without a movement likelihood (the site's calibration),
    /// before the floor's.
    scenario_rssi_weight: [Option<f64>; 4],
    /// Factors on the 68% and 95% radii (the site's calibration), per motion scenario.
    accuracy_scale: [[f64; 2]; 4],
    /// Hashes scans' ids with the site's salt when the site's ids are hashed.
    id_hasher: Option<ScanHasher>,
    /// What the running epoch may change, as it was before (see [`Engine::atomically`]).
    undo: Undo,
    /// Posterior mass per zone, recomputed at each epoch.
    zone_mass: Vec<f64>,
    /// Recent epochs and the user's feedback, for a later learning pass.
    history: History,
    /// What the user's walks taught ([`Engine::learn_habits`]), and its transition multipliers.
    habits: HabitModel,
    habit_prior: HabitPrior,
    /// The site's [`radio_fit_floor`](crate::site::Calibration::radio_fit_floor), when the
    /// configuration takes the site's calibration.
    radio_fit_floor: Option<f64>,
    /// The radio fit of the scan of the running epoch, and whether it is below the floor.
    epoch_radio_fit: Option<(f64, bool)>,
    /// The site's [`StateKind::Unsurveyed`](crate::site::StateKind::Unsurveyed) states: they
    /// hold the estimate only from a scan the map does not explain until one it does.
    unsurveyed: Vec<usize>,
    /// Scans in a row, up to the latest, that the map did not explain.
    unexplained_run: u32,
    /// The site's calibration for scans far apart.
    sparse_scans: SparseScans,
    /// When the latest accepted scan came, and how long after the one before.
    scan_timing: ScanTiming,
}

/// When the latest scan an engine accepted came and how long after the one before it: whether
/// the engine is in the sparse regime ([`SPARSE_SCAN_GAP_S`]) and how long since its scan.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ScanTiming {
    /// The latest scan's time, ns.
    pub last_ns: Option<u64>,
    /// Its gap to the scan before it, ns.
    pub gap_ns: Option<u64>,
}

impl ScanTiming {
    /// The timing once a scan at `timestamp_ns` is accepted.
    pub fn after_scan(self, timestamp_ns: u64) -> ScanTiming {
        ScanTiming {
            last_ns: Some(timestamp_ns),
            gap_ns: self.last_ns.map(|l| timestamp_ns.saturating_sub(l)),
        }
    }

    /// At `timestamp_ns`, the band of time since the latest scan
    /// ([`SparseScans::band`]) when that scan was sparse (the first scan is: its posterior
    /// holds one scan, as after a sparse one); `None` in a steady stream of scans or before
    /// any scan.
    pub fn sparse_band(&self, timestamp_ns: u64) -> Option<usize> {
        let last = self.last_ns?;
        let sparse = self.gap_ns.map_or(true, |gap| gap as f64 * 1e-9 > SPARSE_SCAN_GAP_S);
        sparse.then(|| SparseScans::band(timestamp_ns.saturating_sub(last) as f64 * 1e-9))
    }
}

/// What an epoch changes besides the filter and the Viterbi window, which keep their own
/// checkpoints: saved before it, so that a panic inside can be undone.
#[derive(Default)]
struct Undo {
    last_epoch_ns: Option<u64>,
    unexplained_run: u32,
    scan_timing: ScanTiming,
    latest: Option<Position>,
    published_track: Vec<TrackPoint>,
    stats: InputStats,
    /// Only for an epoch that takes its motion from the tracker.
    tracker: Option<MotionTracker>,
}

impl Engine {
    /// A session on `site`. Takes the site's walking-distance tables ([`Site::reach_tables`]:
    /// built by the first engine at this radius, shared by the rest): all allocation happens
    /// here.
    /// A site whose transmitter ids are hashed needs its salt in `config.site_salt`.
    pub fn new(site: Arc<Site>, config: EngineConfig) -> Result<Self, Error> {
        config.validate()?;
        let id_hasher = site.scan_hasher(config.site_salt.as_ref())?;
        let n = site.states().len();
        let (reach, map_reach) = site.reach_tables(config.reach_radius_m);
        let rssi_weight = config.floor_rssi_weights(&site);
        let site_rssi_weight = config.rssi_weight_for(&site);
        let scenario_rssi_weight = config.scenario_rssi_weights(&site);
        let accuracy_scale = config.accuracy_scales_for(&site);
        let sparse_scans = config.sparse_scans_for(&site);
        let site_zones = site.zones().len();
        let habits = HabitModel::new(&site);
        let radio_fit_floor = site.calibration().radio_fit_floor.filter(|_| config.site_calibration);
        let unsurveyed = (site.states().iter().enumerate())
            .filter(|(_, s)| s.kind == crate::site::StateKind::Unsurveyed)
            .map(|(i, _)| i)
            .collect();
        Ok(Self {
            tracker: MotionTracker::new(config.motion_for(&site))?,
            viterbi: ViterbiWindow::new(n, config.track_window_epochs),
            site,
            reach,
            map_reach,
            whole_reach: false,
            filter: ForwardFilter::new(n),
            ln_emission: vec![0.0; n],
            scratch: Vec::with_capacity(n),
            last_epoch_ns: None,
            latest: None,
            published_track: Vec::new(),
            listeners: Vec::new(),
            next_subscription: 0,
            stats: InputStats::default(),
            rssi_weight,
            site_rssi_weight,
            scenario_rssi_weight,
            accuracy_scale,
            id_hasher,
            zone_mass: vec![0.0; site_zones],
            history: History::new(config.history_epochs),
            habits,
            habit_prior: HabitPrior::default(),
            radio_fit_floor,
            epoch_radio_fit: None,
            unsurveyed,
            unexplained_run: 0,
            sparse_scans,
            scan_timing: ScanTiming::default(),
            config,
            undo: Undo::default(),
        })
    }

    /// The site.
    pub fn site(&self) -> &Arc<Site> {
        &self.site
    }

    /// The configuration.
    pub fn config(&self) -> &EngineConfig {
        &self.config
    }

    /// The latest position, if any epoch has run.
    pub fn position(&self) -> Option<&Position> {
        self.latest.as_ref()
    }

    /// The posterior over the site's states.
    pub fn posterior(&self) -> &[f64] {
        self.filter.posterior()
    }

    /// Posterior probability of each of the site's zones (the sum of the state posterior over
    /// its states), by zone index; empty for a site without zones. The rest of the mass,
    /// 1 − the sum, is outside every zone.
    pub fn zone_posterior(&self) -> Vec<f64> {
        let mut out = vec![0.0; self.site.zones().len()];
        self.site.zone_mass(self.filter.posterior(), &mut out);
        out
    }

    /// The last epochs (at most `history_epochs`), oldest first, each with the states the user
    /// confirmed at it, if any: input for a later learning pass.
    pub fn history(&self) -> &std::collections::VecDeque<EpochRecord> {
        self.history.records()
    }

    /// Counts of accepted and dropped input.
    pub fn stats(&self) -> &InputStats {
        &self.stats
    }

    /// Counts of inertial samples taken and dropped, and steps.
    pub fn motion_stats(&self) -> &MotionStats {
        self.tracker.stats()
    }

    /// Bytes held by the Viterbi window (bounded by `track_window_epochs`).
    pub fn track_memory_bytes(&self) -> usize {
        self.viterbi.memory_bytes()
    }

    /// The engine's state, for tests (see [`EngineSnapshot`]).
    #[doc(hidden)]
    pub fn snapshot(&self) -> EngineSnapshot {
        EngineSnapshot {
            last_epoch_ns: self.last_epoch_ns,
            position: self.latest.clone(),
            posterior: self.filter.posterior().to_vec(),
            published_track: self.published_track.clone(),
            stats: self.stats.clone(),
            subscriptions: (self.listeners.iter().map(|(id, _)| *id).collect(), self.next_subscription),
            internals: format!(
                "{:?}\n{:?}\n{:?}\n{:?}",
                self.filter, self.viterbi, self.tracker, self.scan_timing
            ),
            history: self.history.records().iter().cloned().collect(),
        }
    }

    /// Calls `listener` with everything published until [`unsubscribe`](Self::unsubscribe).
    pub fn subscribe(&mut self, listener: Box<dyn PositionListener>) -> SubscriptionId {
        let id = SubscriptionId(self.next_subscription);
        self.next_subscription += 1;
        self.listeners.push((id, listener));
        id
    }

    /// Stops a subscription; `false` if it was not active.
    pub fn unsubscribe(&mut self, id: SubscriptionId) -> bool {
        let before = self.listeners.len();
        self.listeners.retain(|(l, _)| *l != id);
        self.listeners.len() != before
    }

    /// The most likely path over the last `track_window_epochs` epochs (HIPE §4.1: Viterbi for
    /// tracking), oldest first.
    pub fn track(&self) -> Vec<TrackPoint> {
        self.viterbi.path().into_iter().map(|(t, s)| self.track_point(t, s)).collect()
    }

    /// The position `fixed_lag_epochs` epochs ago, smoothed by what came after: the current
    /// posterior carried back along the Viterbi back-pointers (each state's mass to the state
    /// its best path passed through then), and Hoang eq. 4 over that, as the live estimate is
    /// over the posterior. The exact fixed-lag smoother sums over every path into each state
    /// rather than following the best; this keeps to what the Viterbi window already holds, in
    /// O(lag × N). `state` is the state holding the most carried mass. Measured on the five
    /// competition floors (`examples/walk_diag.rs` with `FP_RADIUS=8`): 4.61 m mean error
    /// against 4.95 m for the lagged Viterbi state alone and 4.83 m for the live estimate.
    pub fn fixed_lag_position(&self) -> Option<TrackPoint> {
        self.smoothed_position(self.config.fixed_lag_epochs.min(self.viterbi.len().saturating_sub(1)))
    }

    /// [`fixed_lag_position`](Self::fixed_lag_position) at another lag, epochs; `None` when
    /// the track holds fewer than `lag` + 1 epochs.
    pub fn smoothed_position(&self, lag: usize) -> Option<TrackPoint> {
        let (mut carried, mut scratch) = (Vec::new(), Vec::new());
        let timestamp_ns =
            self.viterbi.ancestors(lag, self.filter.posterior(), &mut carried, &mut scratch)?;
        let e = estimate(
            &self.site,
            &carried,
            self.config.estimate_states,
            self.config.accuracy_mass,
            &mut Vec::new(),
        );
        let state = (0..carried.len()).max_by(|&a, &b| carried[a].total_cmp(&carried[b]))? as u32;
        Some(TrackPoint { timestamp_ns, state, floor: e.floor, x: e.position.x, y: e.position.y })
    }

    fn track_point(&self, timestamp_ns: u64, state: u32) -> TrackPoint {
        let s = &self.site.states()[state as usize];
        TrackPoint { timestamp_ns, state, floor: s.floor, x: s.position.x, y: s.position.y }
    }

    /// Learns the user's habits from the [`history`](Self::history) epochs not learned from
    /// yet (Baum-Welch with the feedback they hold, [`crate::habits`]), adds them to the
    /// engine's model and applies it from the next epoch on. Bounded: at most
    /// `history_epochs` epochs, a segment at a time. On an error nothing changes.
    pub fn learn_habits(&mut self) -> Result<HabitReport, HabitError> {
        let records: Vec<EpochRecord> = self.history.records().iter().cloned().collect();
        let mut model = self.habits.clone();
        let report = model.learn(&self.site, &self.reach, &[&records], &self.config.habits)?;
        self.set_habits(model);
        Ok(report)
    }

    /// Learns from epochs recorded elsewhere (other sessions' histories, survey walks), as
    /// [`learn_habits`](Self::learn_habits) does from this engine's own.
    pub fn learn_habits_from(&mut self, sequences: &[&[EpochRecord]]) -> Result<HabitReport, HabitError> {
        let mut model = self.habits.clone();
        let report = model.learn(&self.site, &self.reach, sequences, &self.config.habits)?;
        self.set_habits(model);
        Ok(report)
    }

    /// The learned habits.
    pub fn habits(&self) -> &HabitModel {
        &self.habits
    }

    /// The fix error learned so far (zero bias, unit spread before any fix was learned from).
    pub fn fix_error(&self) -> FixError {
        self.habits.fix_error(&self.config.habits)
    }

    /// The learned habits as JSON, to keep per user ([`HabitModel::to_json`]).
    pub fn export_habits(&self) -> String {
        self.habits.to_json()
    }

    /// Replaces the habits by a model exported on this site; refused (nothing changes) when it
    /// does not parse, is of a newer layout, or was learned on another site.
    pub fn import_habits(&mut self, json: &str) -> Result<(), HabitError> {
        let model = HabitModel::from_json(json, &self.site)?;
        self.set_habits(model);
        Ok(())
    }

    /// Replaces the habits by `model`, which must be of this site.
    pub fn set_habits(&mut self, model: HabitModel) {
        self.habit_prior = HabitPrior::new(&model, &self.reach, self.site.spacing_m());
        self.habits = model;
    }

    /// Forgets every habit.
    pub fn clear_habits(&mut self) {
        self.set_habits(HabitModel::new(&self.site));
    }

    /// Takes a batch of accelerometer samples (m/s², gravity included, phone frame). Samples
    /// with a NaN or infinite value, or not after the previous one, are dropped and counted.
    pub fn push_accelerometer(&mut self, batch: &[SensorSample]) -> BatchReport {
        self.tracker.push_accelerometer(batch)
    }

    /// Takes a batch of gyroscope samples (rad/s, phone frame); bad samples as above.
    pub fn push_gyroscope(&mut self, batch: &[SensorSample]) -> BatchReport {
        self.tracker.push_gyroscope(batch)
    }

    /// Takes a batch of magnetometer samples (µT, phone frame); bad samples as above.
    pub fn push_magnetometer(&mut self, batch: &[SensorSample]) -> BatchReport {
        self.tracker.push_magnetometer(batch)
    }

    /// Takes a WiFi or BLE scan: one epoch of the HMM, with the motion the inertial sensors
    /// measured since the previous epoch (push the inertial batches up to the scan's time
    /// first). A rejected scan leaves the engine as it was and is counted by reason.
    pub fn push_scan(&mut self, scan: &Scan) -> Result<Position, InputError> {
        self.push_scan_from(scan, None)
    }

    /// Takes a scan with motion measured outside Waymark (a platform step detector, a test)
    /// instead of the engine's own inertial tracker. Motion with a non-finite value or a
    /// negative distance or spread rejects the scan.
    pub fn push_scan_with_motion(
        &mut self,
        scan: &Scan,
        motion: &MotionUpdate,
    ) -> Result<Position, InputError> {
        self.push_scan_from(scan, Some(motion))
    }

    fn push_scan_from(&mut self, scan: &Scan, motion: Option<&MotionUpdate>) -> Result<Position, InputError> {
        let result = self.scan_epoch(scan, motion);
        if let Err(e) = &result {
            let counter = match e {
                InputError::OutOfOrder { .. } => &mut self.stats.scans_out_of_order,
                InputError::EmptyScan => &mut self.stats.scans_empty,
                InputError::NonFiniteRssi { .. } => &mut self.stats.scans_non_finite,
                InputError::RssiTooHigh { .. } => &mut self.stats.scans_rssi_too_high,
                InputError::NoKnownTransmitter { .. } => &mut self.stats.scans_no_known_transmitter,
                InputError::InvalidMotion { .. } => &mut self.stats.scans_invalid_motion,
                // Not produced by a scan (fixes and feedback only).
                InputError::UnknownZone { .. }
                | InputError::UnknownFloor { .. }
                | InputError::InvalidValue { .. }
                | InputError::OutsideSite { .. } => &mut self.stats.scans_invalid_motion,
            };
            *counter += 1;
            log::debug!("scan rejected: {e}");
        }
        result
    }

    /// An epoch without radio at `timestamp_ns`, from what the inertial sensors measured
    /// since the previous epoch: call it on a timer when scans are rare (iOS, throttled
    /// Android) to keep the position moving. Scans older than it will then be rejected as out
    /// of order.
    pub fn advance(&mut self, timestamp_ns: u64) -> Result<Position, InputError> {
        self.advance_from(timestamp_ns, None)
    }

    /// [`advance`](Self::advance) with motion measured outside Waymark.
    pub fn advance_with_motion(
        &mut self,
        timestamp_ns: u64,
        motion: &MotionUpdate,
    ) -> Result<Position, InputError> {
        self.advance_from(timestamp_ns, Some(motion))
    }

    fn advance_from(
        &mut self,
        timestamp_ns: u64,
        motion: Option<&MotionUpdate>,
    ) -> Result<Position, InputError> {
        let result = self.motion_epoch(timestamp_ns, motion);
        if let Err(e) = &result {
            self.stats.advances_rejected += 1;
            log::debug!("advance rejected: {e}");
        }
        result
    }

    fn motion_epoch(
        &mut self,
        timestamp_ns: u64,
        motion: Option<&MotionUpdate>,
    ) -> Result<Position, InputError> {
        self.check_time(timestamp_ns)?;
        motion.map_or(Ok(()), check_motion)?;
        Ok(self.atomically(motion.is_none(), |engine| {
            let motion = engine.motion_until(timestamp_ns, motion);
            engine.ln_emission.fill(0.0);
            engine.stats.motion_epochs += 1;
            engine.run_epoch(timestamp_ns, EpochInput::Motion, None, &motion)
        }))
    }

    /// A position from another positioning system (GNSS near an entrance, WiFi RTT, UWB): one
    /// epoch, with the motion the inertial sensors measured since the previous one, whose
    /// observation is the fix, a Gaussian around each state's position (El Gemayel et al.
    /// §II-C/D, eq. 7; σ from `accuracy_m`, see [`fix::sigma_m`]). A precise fix pulls the
    /// estimate to it; a vague one barely moves it. Rejected, changing nothing but
    /// `fixes_rejected`: a timestamp not after the last epoch, a NaN or infinite coordinate, an
    /// accuracy not > 0, an unknown floor, or a fix farther from every state than its own
    /// error allows ([`fix::FIX_GATE_MASS`]).
    pub fn push_fix(&mut self, fix: &PositionFix) -> Result<Position, InputError> {
        let result = self.fix_epoch(fix);
        if let Err(e) = &result {
            self.stats.fixes_rejected += 1;
            log::debug!("position fix rejected: {e}");
        }
        result
    }

    fn fix_epoch(&mut self, fix: &PositionFix) -> Result<Position, InputError> {
        self.check_time(fix.timestamp_ns)?;
        // The learned fix error (§II-C): the bias taken off, the spread widened.
        let error = self.fix_error();
        let corrected = PositionFix {
            x: fix.x - error.bias_m[0],
            y: fix.y - error.bias_m[1],
            accuracy_m: fix.accuracy_m * error.spread,
            ..*fix
        };
        fix::ln_likelihood(&self.site, &corrected, &mut self.ln_emission)?;
        Ok(self.atomically(true, |engine| {
            let motion = engine.motion_until(fix.timestamp_ns, None);
            engine.stats.fixes_accepted += 1;
            engine.run_epoch(fix.timestamp_ns, EpochInput::Fix(*fix), None, &motion)
        }))
    }

    /// User feedback: "I am in this zone" at `timestamp_ns` (El Gemayel et al. §IV-C). The
    /// posterior is zeroed outside the zone's states and renormalised. At the time of the
    /// latest epoch it pins that epoch (the position the user was shown); later, it is an
    /// epoch of its own, with the motion since the previous one. Recorded in the
    /// [`history`](Self::history) for a learning pass. Rejected, changing nothing but
    /// `feedback_rejected`: a time before the latest epoch, or no such zone.
    pub fn confirm_zone(&mut self, timestamp_ns: u64, zone: usize) -> Result<Position, InputError> {
        let states = match self.site.zones().get(zone) {
            Some(z) => Ok(z.states.clone()),
            None => Err(InputError::UnknownZone { zone: format!("#{zone}") }),
        };
        self.feedback(timestamp_ns, states)
    }

    /// [`confirm_zone`](Self::confirm_zone) by the zone's name.
    pub fn confirm_zone_named(&mut self, timestamp_ns: u64, name: &str) -> Result<Position, InputError> {
        let states = match self.site.zone_index(name) {
            Some(z) => Ok(self.site.zones()[z].states.clone()),
            None => Err(InputError::UnknownZone { zone: name.to_owned() }),
        };
        self.feedback(timestamp_ns, states)
    }

    /// User feedback: "I am within `radius_m` of (x, y) on `floor`" (a tap on the map), as
    /// [`confirm_zone`](Self::confirm_zone) with the states within the radius. Also rejected:
    /// an unknown floor, a NaN or infinite coordinate, a radius not > 0, or no state within it.
    pub fn confirm_position(
        &mut self,
        timestamp_ns: u64,
        x: f64,
        y: f64,
        floor: usize,
        radius_m: f64,
    ) -> Result<Position, InputError> {
        let states = fix::states_within(&self.site, x, y, floor, radius_m);
        self.feedback(timestamp_ns, states)
    }

    fn feedback(
        &mut self,
        timestamp_ns: u64,
        states: Result<Vec<u32>, InputError>,
    ) -> Result<Position, InputError> {
        let result = self.feedback_epoch(timestamp_ns, states);
        if let Err(e) = &result {
            self.stats.feedback_rejected += 1;
            log::debug!("feedback rejected: {e}");
        }
        result
    }

    fn feedback_epoch(
        &mut self,
        timestamp_ns: u64,
        states: Result<Vec<u32>, InputError>,
    ) -> Result<Position, InputError> {
        let latest = self.latest.clone().filter(|p| p.timestamp_ns == timestamp_ns);
        if latest.is_none() {
            self.check_time(timestamp_ns)?;
        }
        let states = states?;
        // §IV-C: the forward variable is zeroed outside the known states.
        self.ln_emission.fill(f64::NEG_INFINITY);
        for &s in &states {
            self.ln_emission[s as usize] = 0.0;
        }
        Ok(match latest {
            Some(latest) => self.atomically(false, |engine| {
                engine.stats.feedback_accepted += 1;
                engine.pin_latest(latest, &states)
            }),
            None => self.atomically(true, |engine| {
                let motion = engine.motion_until(timestamp_ns, None);
                engine.stats.feedback_accepted += 1;
                engine.run_epoch(timestamp_ns, EpochInput::Feedback, Some(states), &motion)
            }),
        })
    }

    /// Feedback at the time of the latest epoch: its posterior and Viterbi scores are weighted
    /// by `ln_emission` (no prediction), and its position revised. Feedback that contradicts
    /// earlier feedback at the same epoch wins: the posterior restarts on its states.
    fn pin_latest(&mut self, latest: Position, states: &[u32]) -> Position {
        if self.filter.step(None, &self.ln_emission).is_err() {
            self.restart();
        }
        self.viterbi.pin(&self.ln_emission);
        let position = self.locate(latest);
        self.conclude(position, |history, p| history.pin_latest(states, p.floor, p.x, p.y, p.accuracy_m))
    }

    /// Runs the part of an accepted epoch that changes the engine so that it happens whole or
    /// not at all: a panic inside (a bug) undoes it, leaving the engine exactly as it was before
    /// the call, then goes on unwinding to the caller (the FFI turns it into an error). With
    /// `uses_tracker` the epoch takes its motion from the tracker, which is saved too. What
    /// listeners heard before the panic cannot be taken back: the FFI holds what its own
    /// listener hears until the call has returned, and drops it on a panic.
    ///
    /// The cost, at every epoch: a pointer swap in the filter and in the Viterbi window (the
    /// scores they replace are kept aside, not copied), a copy of the last position, the
    /// published track and the counters, and a clone of the tracker when it is used.
    fn atomically<T>(&mut self, uses_tracker: bool, epoch: impl FnOnce(&mut Self) -> T) -> T {
        self.undo.last_epoch_ns = self.last_epoch_ns;
        self.undo.unexplained_run = self.unexplained_run;
        self.undo.scan_timing = self.scan_timing;
        self.undo.latest.clone_from(&self.latest);
        self.undo.published_track.clone_from(&self.published_track);
        self.undo.stats.clone_from(&self.stats);
        self.undo.tracker = uses_tracker.then(|| self.tracker.clone());
        self.filter.checkpoint();
        self.viterbi.checkpoint();
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| epoch(self))) {
            Ok(result) => {
                self.filter.commit();
                self.viterbi.commit();
                self.undo.tracker = None;
                result
            }
            Err(panic) => {
                self.filter.rollback();
                self.viterbi.rollback();
                self.last_epoch_ns = self.undo.last_epoch_ns;
                self.unexplained_run = self.undo.unexplained_run;
                self.scan_timing = self.undo.scan_timing;
                std::mem::swap(&mut self.latest, &mut self.undo.latest);
                std::mem::swap(&mut self.published_track, &mut self.undo.published_track);
                std::mem::swap(&mut self.stats, &mut self.undo.stats);
                if let Some(tracker) = self.undo.tracker.take() {
                    self.tracker = tracker;
                }
                log::error!("an epoch panicked; the engine is as it was before it");
                std::panic::resume_unwind(panic)
            }
        }
    }

    /// [`Position::beyond_radio_m`] after an epoch whose scan the map did or did not explain
    /// (`unexplained`; `None`: no scan) with `motion` over `dt_s`: back to 0 when the map
    /// explains the scan, growing by the distance walked when it does not, or when there was no
    /// scan since one it did not.
    fn beyond_radio_m(&self, unexplained: Option<bool>, dt_s: Option<f64>, motion: &MotionUpdate) -> f64 {
        let before = self.latest.as_ref().map_or(0.0, |p| p.beyond_radio_m);
        if !unexplained.unwrap_or(before > 0.0) {
            return 0.0;
        }
        let walked = match (motion.distance_m, motion.motion_state) {
            (Some(d), _) => d,
            (None, MotionState::Stationary) => 0.0,
            (None, _) => self.config.hipe.assumed_speed_mps * dt_s.unwrap_or(0.0),
        };
        before + walked
    }

    /// The motion given, or what the tracker measured up to `timestamp_ns`.
    fn motion_until(&mut self, timestamp_ns: u64, given: Option<&MotionUpdate>) -> MotionUpdate {
        match given {
            Some(m) => m.clone(),
            None => self.tracker.update(timestamp_ns),
        }
    }

    fn check_time(&self, timestamp_ns: u64) -> Result<(), InputError> {
        match self.last_epoch_ns {
            Some(last_ns) if timestamp_ns <= last_ns => Err(InputError::OutOfOrder { timestamp_ns, last_ns }),
            _ => Ok(()),
        }
    }

    fn scan_epoch(&mut self, scan: &Scan, motion: Option<&MotionUpdate>) -> Result<Position, InputError> {
        self.check_time(scan.timestamp_ns)?;
        motion.map_or(Ok(()), check_motion)?;
        if scan.readings.is_empty() {
            return Err(InputError::EmptyScan);
        }
        if let Some((index, r)) = scan.readings.iter().enumerate().find(|(_, r)| !plausible_rssi(r.rssi_dbm))
        {
            return Err(InputError::NonFiniteRssi { index, transmitter: r.transmitter.to_string() });
        }
        if let Some((index, r)) = scan.readings.iter().enumerate().find(|(_, r)| r.rssi_dbm > MAX_RSSI_DBM) {
            let transmitter = r.transmitter.to_string();
            return Err(InputError::RssiTooHigh { index, transmitter, rssi_dbm: r.rssi_dbm });
        }
        let max_age_ns = self.config.max_reading_age_ns;
        let resolved = match &mut self.id_hasher {
            Some(hasher) => self.site.radio().resolve(hasher.hash_scan(scan), max_age_ns),
            None => self.site.radio().resolve(scan, max_age_ns),
        };
        if resolved.observations.is_empty() {
            return Err(InputError::NoKnownTransmitter { unknown: resolved.unknown, stale: resolved.stale });
        }
        let ln_unheard = self.site.radio().ln_likelihood(&resolved.observations, &mut self.ln_emission);
        let best = self.ln_emission.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let radio_fit = (best - ln_unheard) / resolved.observations.len() as f64;
        // Only with an estimate to carry on from: the first scan, unexplained or not, is all
        // there is to go on.
        let unexplained =
            self.latest.is_some() && self.radio_fit_floor.is_some_and(|floor| radio_fit < floor);
        let dropped = [resolved.unknown, resolved.duplicates, resolved.stale].map(|n| n as u64);
        // Accepted from here on: the state changes.
        Ok(self.atomically(motion.is_none(), |engine| {
            let motion = engine.motion_until(scan.timestamp_ns, motion);
            engine.scan_timing = engine.scan_timing.after_scan(scan.timestamp_ns);
            if let Some(gamma) = engine.epoch_rssi_weight(scan.timestamp_ns, &motion) {
                for e in engine.ln_emission.iter_mut() {
                    *e *= gamma;
                }
            }
            engine.stats.scans_accepted += 1;
            engine.stats.readings_unknown += dropped[0];
            engine.stats.readings_duplicate += dropped[1];
            engine.stats.readings_stale += dropped[2];
            if unexplained {
                // Beyond the map the fingerprints would pull the estimate to whichever states
                // sound least unlike the scan: the motion alone moves it.
                engine.ln_emission.fill(0.0);
                engine.stats.scans_unexplained += 1;
            }
            engine.epoch_radio_fit = radio_fit.is_finite().then_some((radio_fit, unexplained));
            engine.run_epoch(scan.timestamp_ns, EpochInput::Scan, None, &motion)
        }))
    }

    /// Prediction, update, estimate, publication, history. `ln_emission` holds the observation
    /// (zeros for motion alone); `allowed` is the user's feedback at this epoch.
    fn run_epoch(
        &mut self,
        timestamp_ns: u64,
        input: EpochInput,
        allowed: Option<Vec<u32>>,
        motion: &MotionUpdate,
    ) -> Position {
        let dt_s = self.last_epoch_ns.map(|last| (timestamp_ns - last) as f64 * 1e-9);
        let radio = self.epoch_radio_fit.take().filter(|_| input == EpochInput::Scan);
        let beyond_radio_m = self.beyond_radio_m(radio.map(|r| r.1), dt_s, motion);
        let radio_fit = radio.map(|r| r.0);
        let was_off_map = self.unexplained_run >= UNSURVEYED_AFTER_SCANS;
        if let Some((_, unexplained)) = radio {
            self.unexplained_run = if unexplained { self.unexplained_run.saturating_add(1) } else { 0 };
        }
        let off_map = self.unexplained_run >= UNSURVEYED_AFTER_SCANS;
        // Back from beyond the map, the mass out there needs the whole table to come home.
        self.whole_reach = was_off_map || off_map;
        if !off_map {
            // On the map (as far as the radio says): the unsurveyed states around it are out.
            for &i in &self.unsurveyed {
                self.ln_emission[i] = f64::NEG_INFINITY;
            }
        }
        let evidence = self.forward(timestamp_ns, dt_s, motion);
        self.last_epoch_ns = Some(timestamp_ns);
        let position = self.locate(Position {
            timestamp_ns,
            floor: 0,
            floor_probability: 0.0,
            zone: None,
            zone_probability: 0.0,
            x: 0.0,
            y: 0.0,
            accuracy_m: 0.0,
            accuracy_95_m: 0.0,
            heading_rad: motion.heading_rad,
            heading_accuracy_rad: motion.heading_rad.map(|_| motion.heading_sigma_rad),
            motion_state: motion.motion_state,
            scenario: motion.scenario,
            steps: motion.steps,
            radio_log_evidence: (input == EpochInput::Scan).then_some(evidence),
            radio_fit,
            beyond_radio_m,
        });
        self.conclude(position, |history, p| {
            history.push(EpochRecord {
                timestamp_ns,
                input,
                floor: p.floor,
                x: p.x,
                y: p.y,
                accuracy_m: p.accuracy_m,
                allowed,
            })
        })
    }

    /// `position` with the estimate from the current posterior: floor, (x, y), radii, zone.
    fn locate(&mut self, position: Position) -> Position {
        let e = estimate(
            &self.site,
            self.filter.posterior(),
            self.config.estimate_states,
            self.config.accuracy_mass,
            &mut self.scratch,
        );
        let sparse = self.scan_timing.sparse_band(position.timestamp_ns);
        let scale = sparse
            .and_then(|band| self.sparse_scans.accuracy_scale_by_since[band])
            .unwrap_or(self.accuracy_scale[position.scenario.index()]);
        let (zone, zone_probability) = if self.site.zones().is_empty() {
            (None, 1.0)
        } else {
            let outside = self.site.zone_mass(self.filter.posterior(), &mut self.zone_mass);
            most_likely_zone(&self.zone_mass, outside)
        };
        Position {
            floor: e.floor,
            floor_probability: e.floor_probability,
            zone,
            zone_probability,
            x: e.position.x,
            y: e.position.y,
            accuracy_m: e.accuracy_m * scale[0] + position.beyond_radio_m,
            accuracy_95_m: (e.accuracy_95_m * scale[1]).max(e.accuracy_m * scale[0])
                + position.beyond_radio_m,
            ..position
        }
    }

    /// Publishes `position`, makes it the latest and records it in the history, last: nothing
    /// after a possible panic, so the history needs no undo.
    fn conclude(&mut self, position: Position, record: impl FnOnce(&mut History, &Position)) -> Position {
        self.publish(&position);
        if cfg!(feature = "fault-injection") && position.timestamp_ns == FAULT_INJECTION_MID_EPOCH_NS {
            panic!("fault injected in the middle of the epoch at {}", position.timestamp_ns);
        }
        self.latest = Some(position.clone());
        record(&mut self.history, &position);
        position
    }

    fn publish(&mut self, position: &Position) {
        let mut events = Vec::new();
        if let Some(previous) = &self.latest {
            if previous.scenario != position.scenario {
                events.push(StatusEvent::ScenarioChanged {
                    timestamp_ns: position.timestamp_ns,
                    from: previous.scenario,
                    to: position.scenario,
                });
            }
            if previous.motion_state != position.motion_state {
                events.push(StatusEvent::MotionStateChanged {
                    timestamp_ns: position.timestamp_ns,
                    from: previous.motion_state,
                    to: position.motion_state,
                });
            }
        }
        let revised = self.revise_track();
        for (_, listener) in &mut self.listeners {
            for event in &events {
                listener.on_status(event);
            }
            if !revised.is_empty() {
                listener.on_track_revised(&revised);
            }
            listener.on_position(position);
        }
    }

    /// The points of the Viterbi path, before the newest epoch, that differ from what was last
    /// published.
    fn revise_track(&mut self) -> Vec<TrackPoint> {
        let track = self.track();
        let revised: Vec<TrackPoint> = match track.split_last() {
            Some((_, earlier)) => earlier
                .iter()
                .filter(|p| {
                    self.published_track
                        .iter()
                        .find(|q| q.timestamp_ns == p.timestamp_ns)
                        .is_some_and(|q| q.state != p.state)
                })
                .cloned()
                .collect(),
            None => Vec::new(),
        };
        self.published_track = track;
        revised
    }

    /// Predicts over `dt_s` (none at the first epoch) with the configured model and `motion`,
    /// and updates with `ln_emission`. Returns the log evidence.
    fn forward(&mut self, timestamp_ns: u64, dt_s: Option<f64>, motion: &MotionUpdate) -> f64 {
        let table = prediction_table(&self.reach, self.map_reach.as_deref(), self.whole_reach);
        let Some(dt) = dt_s else {
            self.viterbi.step(
                timestamp_ns,
                &UniformReach { table, rho_m: 0.0, ratio: 1.0 },
                &self.ln_emission,
            );
            return self.update(None);
        };
        let config = &self.config;
        let speed_reach = config.max_speed_mps * dt;
        let table_radius = self.reach.radius_m();
        let hipe_region = hipe_region(config, motion, dt);
        let needed = match config.transition {
            TransitionModel::Reach | TransitionModel::Hoang => speed_reach,
            TransitionModel::Hipe => hipe_region.outer_radius_m(),
        };
        if needed > table_radius {
            return self.bridge_gap(timestamp_ns, speed_reach);
        }
        let ratio_max = config.transition_ratio;
        let reach = UniformReach { table, rho_m: speed_reach, ratio: ratio_max };
        let hipe = HipeTransition {
            site: &self.site,
            table,
            region: hipe_region,
            // Under Hoang's model the regions only stand in for a missing distance or
            // heading, with the same floor K as its other epochs. HIPE's adaptive K reaches
            // down to 200, which on a multi-floor site of thousands of states leaks most of
            // the mass everywhere each epoch (measured: `waymark eval` on the five floors lost
            // the floor in 6-7% of such epochs).
            ratio: match config.transition {
                TransitionModel::Hoang => ratio_max,
                _ => hipe_ratio(config, motion, self.latest.as_ref()),
            },
        };
        let base_variance = config.hoang.movement_variance_m2
            + if config.hoang.quantisation_variance { self.site.spacing_m().powi(2) / 6.0 } else { 0.0 };
        let spread = match (config.hoang.measured_spread, motion.distance_m) {
            (true, Some(d)) => (motion.distance_sigma_m.powi(2), (d * motion.heading_sigma_rad).powi(2)),
            _ => (0.0, 0.0),
        };
        let hoang = HoangTransition {
            site: &self.site,
            table,
            reach_m: speed_reach,
            ratio: ratio_max,
            movement_m: motion.displacement_m,
            walked_m: motion.distance_m.filter(|_| motion.scenario == MdiScenario::Distance),
            variance_m2: base_variance + spread.0,
            across_variance_m2: base_variance + spread.1,
            mahalanobis_cap: config.hoang.mahalanobis_cap,
            exponent: self.epoch_rssi_weight(timestamp_ns, motion).map_or(1.0, |g| 1.0 - g),
        };
        let transition: &dyn Transition = match config.transition {
            TransitionModel::Reach => &reach,
            TransitionModel::Hipe => &hipe,
            // Hoang's Gaussian needs a measured distance (the movement vector, or the distance
            // alone); with only a heading, HIPE's sector still uses what was measured (HIPE
            // Table 1).
            TransitionModel::Hoang
                if motion.displacement_m.is_none() && motion.scenario == MdiScenario::HeadingSpeed =>
            {
                &hipe
            }
            TransitionModel::Hoang => &hoang,
        };
        // Learned habits multiplied in (issue 6: "a prior multiplied into the motion-based
        // transition of each epoch").
        let habitual = Habitual { inner: transition, prior: &self.habit_prior };
        let transition: &dyn Transition = if self.habit_prior.is_empty() { transition } else { &habitual };
        self.viterbi.step(timestamp_ns, transition, &self.ln_emission);
        let result = self.filter.step(Some(transition), &self.ln_emission);
        result.unwrap_or_else(|_| self.restart())
    }

    /// Hoang eq. 14's γ for an epoch at `timestamp_ns` with `motion`, of the floor the engine
    /// is on: that of an epoch with the movement vector's likelihood when its transition has
    /// one, else the γ of the epoch's scenario when the site has one (the distance-only
    /// likelihood, HIPE's sector and the reach alone are different priors to weigh the radio
    /// against), else that of an epoch without a movement likelihood. The first epoch has no
    /// transition at all and a gap longer than the walking-distance table is bridged by the
    /// speed bound alone: both weigh the radio as without a movement likelihood. Measured on the
    /// five competition floors' 112 test walks (`cargo run --release --example walk_diag --
    /// target/ilc/site1/{B1,F1,F2,F3,F4}`): the first epoch at the γ with movement, 0.03, left
    /// the posterior so flat that the floor with the most states took the first estimate; the
    /// first scored scan was on a wrong floor in 4 walks, and in 1 with this rule
    /// (`forward-auto` 5.65 → 5.23 m at the scans).
    fn epoch_rssi_weight(&self, timestamp_ns: u64, motion: &MotionUpdate) -> Option<f64> {
        let [with_movement, without] = self.rssi_weight_now();
        let Some(last) = self.last_epoch_ns else { return without };
        let dt_s = timestamp_ns.saturating_sub(last) as f64 * 1e-9;
        if self.config.max_speed_mps * dt_s > self.reach.radius_m() {
            return without;
        }
        if self.config.transition == TransitionModel::Hoang && motion.displacement_m.is_some() {
            let sparse = self.scan_timing.sparse_band(timestamp_ns).and(self.sparse_scans.rssi_weight);
            sparse.or(with_movement)
        } else {
            self.scenario_rssi_weight[motion.scenario.index()].or(without)
        }
    }

    /// γ (with, without a movement likelihood) for the coming epoch: that of the floor of the
    /// latest estimate, else the site-wide one. One γ for every state of an epoch: ln p(o | s)
    /// is compared across states, and raising one floor's states to a smaller power than
    /// another's favours that floor whatever was heard (`waymark eval` on the five competition
    /// floors with per-state γ found the floor at 21% of epochs).
    fn rssi_weight_now(&self) -> [Option<f64>; 2] {
        self.latest
            .as_ref()
            .and_then(|p| self.rssi_weight.get(p.floor))
            .copied()
            .unwrap_or(self.site_rssi_weight)
    }

    /// A reach beyond the walking-distance table: several passes of the speed bound, or a
    /// restart from the uniform prior when even that is too far.
    fn bridge_gap(&mut self, timestamp_ns: u64, speed_reach: f64) -> f64 {
        let table = prediction_table(&self.reach, self.map_reach.as_deref(), self.whole_reach);
        let table_radius = self.reach.radius_m();
        let passes = (speed_reach / table_radius).ceil().max(1.0);
        let pass = UniformReach { table, rho_m: speed_reach / passes, ratio: self.config.transition_ratio };
        self.viterbi.step(timestamp_ns, &UniformReach { rho_m: table_radius, ..pass }, &self.ln_emission);
        if passes > f64::from(self.config.max_reach_passes) {
            log::debug!("{speed_reach:.0} m of possible walking since the last epoch: restarting");
            self.filter.reset();
            self.stats.filter_restarts += 1;
            return self.update(None);
        }
        for _ in 1..passes as u32 {
            self.filter.predict(&pass);
        }
        let result = self.filter.step(Some(&pass), &self.ln_emission);
        result.unwrap_or_else(|_| self.restart())
    }

    fn update(&mut self, transition: Option<&dyn Transition>) -> f64 {
        match self.filter.step(transition, &self.ln_emission) {
            Ok(evidence) => evidence,
            Err(_) => self.restart(),
        }
    }

    /// The map explains this observation nowhere the motion model allows: start again from the
    /// observation alone.
    fn restart(&mut self) -> f64 {
        self.stats.filter_restarts += 1;
        self.filter.reset();
        self.filter.step(None, &self.ln_emission).unwrap_or(f64::NEG_INFINITY)
    }
}

/// Motion measured outside Waymark must be finite, with distances and spreads not negative:
/// the transitions take it as it is.
fn check_motion(m: &MotionUpdate) -> Result<(), InputError> {
    let fields = [
        ("distance_m", m.distance_m.unwrap_or(0.0), true),
        ("distance_sigma_m", m.distance_sigma_m, true),
        ("heading_rad", m.heading_rad.unwrap_or(0.0), false),
        ("heading_sigma_rad", m.heading_sigma_rad, true),
        ("displacement_m[0]", m.displacement_m.map_or(0.0, |d| d[0]), false),
        ("displacement_m[1]", m.displacement_m.map_or(0.0, |d| d[1]), false),
    ];
    match fields.into_iter().find(|&(_, v, positive)| !v.is_finite() || (positive && v < 0.0)) {
        Some((field, value, _)) => Err(InputError::InvalidMotion { field, value }),
        None => Ok(()),
    }
}

/// Whether an RSSI can be a measurement, as far as its lower end goes: finite and not below
/// -1000 dBm (receivers report about -120 to +20). Below that it is a corrupt producer, as NaN
/// is, and near -1e154 the squared deviation of every fingerprint overflows, so no state could
/// explain the scan. Above [`MAX_RSSI_DBM`] is `RssiTooHigh`.
fn plausible_rssi(rssi_dbm: f64) -> bool {
    rssi_dbm.is_finite() && rssi_dbm >= -1000.0
}

/// Unexplained scans in a row after which the estimate may leave the surveyed map for its
/// unsurveyed states. One is not enough: the site's radio fit floor is the 5th percentile of
/// scans on the map, so one scan in twenty on the map falls below it. Measured on the F2 split
/// with a 10 m margin (`waymark eval target/ilc/site1/F2 --threads 2 --fingerprint-radius-m
/// 8`): `forward-auto` 5.268 m after one, 5.239 m after two, against 5.248 m without
/// unsurveyed states.
const UNSURVEYED_AFTER_SCANS: u32 = 2;

/// The walking-distance table an epoch predicts with: the surveyed map's own (`map`) while the
/// radio explains what it hears, the whole site's (`reach`) beyond the map and on the way back
/// (`whole`).
fn prediction_table<'a>(reach: &'a ReachTable, map: Option<&'a ReachTable>, whole: bool) -> &'a ReachTable {
    match map {
        Some(map) if !whole => map,
        _ => reach,
    }
}

/// HIPE's region for this epoch (HIPE eqs. 7-10, tolerances of Table 4).
fn hipe_region(config: &EngineConfig, motion: &MotionUpdate, dt_s: f64) -> HipeRegion {
    let h = &config.hipe;
    let range_m = h.assumed_speed_mps * dt_s;
    let tolerance = |d: f64| (h.distance_tolerance_fraction * d).max(h.distance_tolerance_min_m);
    match (motion.scenario, motion.distance_m, motion.heading_rad) {
        (MdiScenario::DistanceHeading, Some(d), Some(heading_rad)) if d > 0.0 => HipeRegion::RingSector {
            distance_m: d,
            tolerance_m: tolerance(d),
            heading_rad,
            tolerance_rad: h.heading_tolerance_rad,
        },
        // Standing still, or distance without heading: the ring (a disc of the tolerance when
        // d = 0).
        (MdiScenario::DistanceHeading | MdiScenario::Distance, Some(d), _) => {
            HipeRegion::Ring { distance_m: d, tolerance_m: tolerance(d) }
        }
        (MdiScenario::HeadingSpeed, _, Some(heading_rad)) => {
            HipeRegion::Sector { range_m, heading_rad, tolerance_rad: h.heading_tolerance_rad }
        }
        _ => HipeRegion::Disc { range_m },
    }
}

/// HIPE's adaptive K: log-linear between `hipe.transition_ratio_min` and `transition_ratio`
/// with a reliability r = r_motion · r_estimate in [0, 1]. r_motion is 1 when stationary,
/// else how far the measured spreads stay inside HIPE's tolerances, counting an assumed
/// quantity as unreliable: 0 for assumed speed only, and half the heading's reliability for
/// heading & assumed speed, whose region is measured in angle but assumed in range. Measured
/// with `waymark simulate --runs 100 --seed 1..3` (M = 5 then): with the full heading
/// reliability there, heading & assumed speed was no better than assumed speed alone
/// (1.365 / 1.390 / 1.274 m against 1.365 / 1.354 / 1.234 m); with half, 1.260 / 1.278 /
/// 1.170 m (with M = 3 now: 1.262 / 1.279 / 1.182 against 1.381 / 1.367 / 1.246 m). r_estimate is how
/// far the previous 68% radius is within the least distance tolerance (1.5 m).
fn hipe_ratio(config: &EngineConfig, motion: &MotionUpdate, previous: Option<&Position>) -> f64 {
    let h = &config.hipe;
    let within = |spread: f64, tolerance: f64| (1.0 - spread / tolerance).clamp(0.0, 1.0);
    let distance_tolerance = motion.distance_m.map_or(h.distance_tolerance_min_m, |d| {
        (h.distance_tolerance_fraction * d).max(h.distance_tolerance_min_m)
    });
    let r_distance = within(motion.distance_sigma_m, distance_tolerance);
    let r_heading = within(motion.heading_sigma_rad, h.heading_tolerance_rad);
    let r_motion = match motion.scenario {
        _ if motion.motion_state == MotionState::Stationary => 1.0,
        MdiScenario::DistanceHeading => r_distance * r_heading,
        MdiScenario::Distance => r_distance,
        MdiScenario::HeadingSpeed => 0.5 * r_heading,
        MdiScenario::Speed => 0.0,
    };
    let r_estimate = previous.map_or(0.0, |p| (h.distance_tolerance_min_m / p.accuracy_m).min(1.0));
    let r = r_motion * r_estimate;
    let (lo, hi) = (h.transition_ratio_min.ln(), config.transition_ratio.ln());
    (lo + r * (hi - lo)).exp()
}

#[cfg(test)]
mod tests {
    use super::ScanTiming;

    const SECOND: u64 = 1_000_000_000;

    /// The first scan counts as sparse (its posterior holds one scan); a scan 2 s after the
    /// one before is in a steady stream, one 30 s after is sparse, and the band follows the
    /// time since it.
    #[test]
    fn the_sparse_regime_and_its_band() {
        let none = ScanTiming::default();
        assert_eq!(none.sparse_band(5 * SECOND), None, "no scan yet");
        let first = none.after_scan(10 * SECOND);
        assert_eq!(first.gap_ns, None);
        assert_eq!(first.sparse_band(10 * SECOND), Some(0));
        assert_eq!(first.sparse_band(13 * SECOND), Some(1));
        let steady = first.after_scan(12 * SECOND);
        assert_eq!(steady.gap_ns, Some(2 * SECOND));
        assert_eq!(steady.sparse_band(12 * SECOND), None);
        assert_eq!(steady.sparse_band(40 * SECOND), None, "the regime is the latest scan's");
        let sparse = steady.after_scan(42 * SECOND);
        assert_eq!(
            [42, 44, 47, 55, 70].map(|s| sparse.sparse_band(s * SECOND)),
            [Some(0), Some(1), Some(2), Some(3), Some(4)]
        );
        // Exactly the gap is not beyond it.
        let edge = steady.after_scan(22 * SECOND);
        assert_eq!(edge.sparse_band(22 * SECOND), None);
    }
}
