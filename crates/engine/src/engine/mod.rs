//! The positioning session: takes inertial batches and scans in time order, runs one HMM epoch
//! per scan (or per [`Engine::advance`] without radio), and returns what each epoch produced:
//! the position, status changes and track revisions ([`Epoch`]).
//!
//! The engine is single-threaded and deterministic, so a replay is exact; the FFI layer puts
//! it behind a lock.

mod calibration;
mod epoch;
mod evidence;
mod input;
mod prediction;
mod presence;
mod types;
mod vertical;

use crate::config::EngineConfig;
use crate::error::Error;
use crate::habits::{FixBias, HabitError, HabitModel, HabitPrior, HabitReport};
use crate::history::{EpochRecord, History};
use crate::hmm::{estimate, FixedLagSmoother, ForwardFilter, ViterbiWindow};
use crate::radio::{DeviceOffset, ScanHasher};
use crate::sensors::{Barometer, MotionStats, MotionTracker, MotionUpdate};
use crate::site::{FloorReliability, ReachTable, Site, SparseScans};
use std::sync::Arc;

pub use crate::radio::MAX_RSSI_DBM;
pub use evidence::SessionEvidence;
#[cfg(feature = "fault-injection")]
pub use types::EngineSnapshot;
pub use types::{Epoch, InputStats, Position, ScanTiming, SharedEmissions, StatusEvent, TrackPoint};

/// An epoch (a scan or an advance) at this time panics after it has stepped the filter and
/// the track, moved the clock, raised the counters and worked out its status events, just
/// before it stores the position: as half-done as an epoch gets. The engine must come out of
/// it exactly as it was before the call. It is within the times an engine takes
/// ([`MAX_TIMESTAMP_NS`](crate::sensors::MAX_TIMESTAMP_NS)): `i64::MAX - 8`. It exists only
/// with the `fault-injection` feature, which test builds turn on.
#[cfg(feature = "fault-injection")]
pub const FAULT_INJECTION_MID_EPOCH_NS: u64 = crate::sensors::MAX_TIMESTAMP_NS - 8;

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
    /// `None` when the configuration turns the track off.
    viterbi: Option<ViterbiWindow>,
    /// The filter's last steps, for the fixed-lag estimate.
    smoother: FixedLagSmoother<prediction::StepModel>,
    tracker: MotionTracker,
    ln_emission: Vec<f64>,
    scratch: Vec<(f64, f64)>,
    /// Time of the filter's last step.
    last_epoch_ns: Option<u64>,
    /// The motion-only epochs since the filter's last step, held back from it
    /// ([`EngineConfig::min_motion_step_s`]).
    held: Option<Held>,
    latest: Option<Position>,
    last_track: Vec<TrackPoint>,
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
    /// M of Hoang eq. 4 in effect ([`EngineConfig::estimate_states_for`]).
    estimate_states: usize,
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
    habit_prior: Arc<HabitPrior>,
    /// The site's [`radio_fit_floor`](crate::site::Calibration::radio_fit_floor), when the
    /// configuration takes the site's calibration.
    radio_fit_floor: Option<f64>,
    /// The radio fit of the scan of the running epoch, and whether it is below the floor.
    epoch_radio_fit: Option<(f64, bool)>,
    /// The site's [`StateKind::Unsurveyed`](crate::site::StateKind::Unsurveyed) states: they
    /// hold the estimate only from a scan the map does not explain until one it does.
    unsurveyed: Vec<u32>,
    /// Scans in a row, up to the latest, that the map did not explain.
    unexplained_run: u32,
    /// The site's calibration for scans far apart.
    sparse_scans: SparseScans,
    /// The site's calibration of the floor probability outside the sparse regime.
    floor_reliability: FloorReliability,
    /// Whether the person is in each zone and geofence, and the app's geofences.
    presence: presence::Presence,
    /// When the latest accepted scan came, and how long after the one before.
    scan_timing: ScanTiming,
    /// The phone's RSSI offset against the map, learned from this session's scans
    /// ([`EngineConfig::device_offset`]).
    device_offset: DeviceOffset,
    /// The phone's relative height from its barometer.
    barometer: Barometer,
    /// Where the height last settled, and on which floors ([`vertical`]).
    floor_anchor: Option<vertical::FloorAnchor>,
    /// Each floor's level ([`Site::floor_levels`]).
    levels: Vec<i32>,
    /// The levels between the site's that no floor has ([`Site::unmapped_levels`]).
    unmapped_levels: Vec<i32>,
    /// Where floor changes land ([`Site::landings`]): taken at the barometer's first reading.
    landings: Option<Arc<crate::site::Landings>>,
    /// Scan likelihoods shared with the other engines of an evaluation on this site
    /// ([`Engine::share_emissions`]); `None` in an app.
    shared_emissions: Option<Arc<SharedEmissions>>,
    /// Map evidence being gathered from this session ([`Engine::start_evidence`]).
    gathering: Option<evidence::Gathering>,
}

/// Motion-only epochs the filter has not stepped over yet: they came sooner than
/// [`EngineConfig::min_motion_step_s`] after its last step.
#[derive(Clone, Debug)]
struct Held {
    /// The latest held epoch.
    timestamp_ns: u64,
    /// The motion since the filter's last step.
    motion: MotionUpdate,
    /// The position of the filter's last step.
    step: Position,
}

/// What an epoch changes besides the filter and the Viterbi window, which keep their own
/// checkpoints: saved before it, so that a panic inside can be undone.
#[derive(Default)]
struct Undo {
    last_epoch_ns: Option<u64>,
    held: Option<Held>,
    unexplained_run: u32,
    scan_timing: ScanTiming,
    latest: Option<Position>,
    last_track: Vec<TrackPoint>,
    stats: InputStats,
    /// Only for an epoch that takes its motion from the tracker.
    tracker: Option<MotionTracker>,
}

impl Engine {
    /// A session on `site`. Takes the site's walking-distance tables ([`Site::reach_tables`]:
    /// built by the first engine at this radius, shared by the rest): all allocation happens
    /// here, but for where floor changes land (computed once per site and shared), taken at
    /// the first pressure reading on a site with a floor-change rate.
    /// A site whose transmitter ids are hashed needs its salt in `config.site_salt`. A site
    /// whose tables would pass the site budget is refused
    /// ([`SiteError::OverLimit`](crate::SiteError::OverLimit),
    /// docs/errors.md#site-limits).
    pub fn new(site: Arc<Site>, config: EngineConfig) -> Result<Self, Error> {
        config.validate()?;
        let id_hasher = site.scan_hasher(config.site_salt.as_ref())?;
        let n = site.states().len();
        let (reach, map_reach) = site.reach_tables(config.reach_radius_m)?;
        let rssi_weight = config.floor_rssi_weights(&site);
        let site_rssi_weight = config.rssi_weight_for(&site);
        let scenario_rssi_weight = config.scenario_rssi_weights(&site);
        let accuracy_scale = config.accuracy_scales_for(&site);
        let estimate_states = config.estimate_states_for(&site);
        let sparse_scans = config.sparse_scans_for(&site);
        let floor_reliability = config.floor_reliability_for(&site);
        let site_zones = site.zones().len();
        let habits = HabitModel::new(&site);
        let radio_fit_floor = site.calibration().radio_fit_floor.filter(|_| config.site_calibration);
        let unsurveyed = (site.states().iter().enumerate())
            .filter(|(_, s)| s.kind == crate::site::StateKind::Unsurveyed)
            .map(|(i, _)| i as u32)
            .collect();
        let levels = site.floor_levels();
        let unmapped_levels = site.unmapped_levels();
        Ok(Self {
            tracker: MotionTracker::new(config.motion_for(&site))?,
            viterbi: config.track.then(|| ViterbiWindow::new(n, config.track_window_epochs)),
            site,
            reach,
            map_reach,
            whole_reach: false,
            filter: ForwardFilter::new(n),
            smoother: FixedLagSmoother::new(config.fixed_lag_epochs),
            ln_emission: vec![0.0; n],
            scratch: Vec::with_capacity(n),
            last_epoch_ns: None,
            held: None,
            latest: None,
            last_track: Vec::new(),
            stats: InputStats::default(),
            rssi_weight,
            site_rssi_weight,
            scenario_rssi_weight,
            accuracy_scale,
            estimate_states,
            id_hasher,
            zone_mass: vec![0.0; site_zones],
            history: History::new(config.history_epochs),
            habits,
            habit_prior: Arc::default(),
            radio_fit_floor,
            epoch_radio_fit: None,
            unsurveyed,
            unexplained_run: 0,
            sparse_scans,
            floor_reliability,
            presence: presence::Presence::new(site_zones),
            scan_timing: ScanTiming::default(),
            device_offset: DeviceOffset::default(),
            barometer: Barometer::default(),
            floor_anchor: None,
            levels,
            unmapped_levels,
            landings: None,
            shared_emissions: None,
            gathering: None,
            config,
            undo: Undo::default(),
        })
    }

    /// Takes each scan's likelihoods (Hoang eqs. 9-10) from `shared`, which the other engines
    /// on this site's radio map fill, instead of computing them again ([`SharedEmissions`]):
    /// for tools that replay many walks on one site, such as the survey's calibration and the
    /// evaluation (docs/tuning.md#evaluation-speed). An app runs one engine per site and has no
    /// use for it. The positions are the same to the bit. `Err` when `shared` is of another
    /// radio map (another allocation, even if equal: a site and its copies share theirs).
    pub fn share_emissions(&mut self, shared: Arc<SharedEmissions>) -> Result<(), Error> {
        if !shared.is_of(&self.site) {
            return Err(Error::InvalidConfig("scan likelihoods shared from another site".into()));
        }
        self.shared_emissions = Some(shared);
        Ok(())
    }

    /// Loads `site` in place of the session's own, a site refitted from evidence
    /// (docs/evidence.md#loading-a-refitted-site): the session goes on with the new radio map
    /// and calibration. A site with the same states (floors and positions, in order) and zones
    /// carries over everything the session knows: the posterior, the fixed-lag steps, the
    /// track, the history, the habits and the zone presence. Another site starts the estimate
    /// afresh and keeps what is not of the site's states: the motion tracker, the phone's RSSI
    /// offset, the barometer, the counters and the app's geofences (placed again on the new
    /// states; one that holds none of them is dropped). Returns the evidence gathered on the
    /// old site and not yet taken, which is of that site; gathering, if on, goes on on the
    /// new one. Refused, changing nothing, with the errors of [`Engine::new`].
    pub fn replace_site(&mut self, site: Arc<Site>) -> Result<Option<SessionEvidence>, Error> {
        let mut next = Engine::new(site, self.config.clone())?;
        let taken = self.take_evidence();
        next.gathering = self.gathering.as_ref().map(|g| g.restarted(&next.site));
        let same_states = crate::evidence::Evidence::site_key(&self.site)
            == crate::evidence::Evidence::site_key(&next.site)
            && self.site.zones().len() == next.site.zones().len();
        if same_states {
            next.set_habits(std::mem::replace(&mut self.habits, HabitModel::new(&self.site)));
            std::mem::swap(&mut next.filter, &mut self.filter);
            std::mem::swap(&mut next.viterbi, &mut self.viterbi);
            std::mem::swap(&mut next.smoother, &mut self.smoother);
            std::mem::swap(&mut next.history, &mut self.history);
            std::mem::swap(&mut next.presence, &mut self.presence);
            std::mem::swap(&mut next.zone_mass, &mut self.zone_mass);
            next.last_epoch_ns = self.last_epoch_ns;
            next.held = self.held.take();
            next.latest = self.latest.take();
            next.last_track = std::mem::take(&mut self.last_track);
            next.whole_reach = self.whole_reach;
            next.unexplained_run = self.unexplained_run;
            next.scan_timing = self.scan_timing;
            next.floor_anchor = self.floor_anchor.take();
        } else {
            for fence in self.geofences() {
                if let Err(e) = next.add_geofence(fence.clone()) {
                    log::debug!("geofence {} dropped with the old site: {e}", fence.id);
                }
            }
        }
        std::mem::swap(&mut next.tracker, &mut self.tracker);
        next.device_offset = self.device_offset;
        std::mem::swap(&mut next.barometer, &mut self.barometer);
        if self.landings.is_some() {
            next.landings = Some(next.site.landings());
        }
        std::mem::swap(&mut next.stats, &mut self.stats);
        *self = next;
        Ok(taken)
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

    /// The current estimate's (x, y) with each M of Hoang eq. 4 in `grid` in place of the
    /// engine's, on the same floor: for choosing M on held-out walks.
    pub fn positions_by_states(&self, grid: &[usize]) -> Vec<[f64; 2]> {
        crate::hmm::positions_by_states(&self.site, self.filter.posterior(), grid)
            .into_iter()
            .map(|p| [p.x, p.y])
            .collect()
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

    /// The last epochs the filter stepped over (at most `history_epochs`), oldest first, each
    /// with the states the user confirmed at it, if any: input for a later learning pass. A held
    /// advance ([`EngineConfig::min_motion_step_s`]) is not among them until an epoch beyond
    /// the walking-distance table's reach steps over it.
    pub fn history(&self) -> &std::collections::VecDeque<EpochRecord> {
        self.history.records()
    }

    /// The phone's RSSI offset against the site's map as this session has learned it
    /// (docs/accuracy.md#device-offset): dB the phone reads above the survey's phones, with
    /// its standard deviation. `None` before a scan has measured it, or with
    /// [`EngineConfig::device_offset`] off.
    pub fn device_offset(&self) -> Option<(f64, f64)> {
        let offset = &self.device_offset;
        (self.config.device_offset && offset.scans() > 0).then(|| (offset.mean_db(), offset.std_db()))
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
        self.viterbi.as_ref().map_or(0, ViterbiWindow::memory_bytes)
    }

    /// Bytes held by the fixed-lag smoother: at most `fixed_lag_epochs` steps, each with the
    /// posterior and prediction over the states holding mass (bounded by every state).
    pub fn fixed_lag_memory_bytes(&self) -> usize {
        self.smoother.memory_bytes()
    }

    /// Everything the engine holds that decides its later answers ([`EngineSnapshot`]), for
    /// tests that check a rejected or panicking call left it as it was. Only with the
    /// `fault-injection` feature, which test builds turn on.
    #[cfg(feature = "fault-injection")]
    pub fn snapshot(&self) -> EngineSnapshot {
        EngineSnapshot {
            last_epoch_ns: self.held.as_ref().map(|h| h.timestamp_ns).or(self.last_epoch_ns),
            position: self.latest.clone(),
            posterior: self.filter.posterior().to_vec(),
            last_track: self.last_track.clone(),
            stats: self.stats.clone(),
            internals: format!(
                "{:?}\n{:?}\n{:?}\n{:?}\n{:?}\n{:?}",
                self.held,
                self.filter,
                self.viterbi,
                self.tracker,
                self.scan_timing,
                self.presence.flags()
            ),
            history: self.history.records().iter().cloned().collect(),
        }
    }

    /// The most likely path over the last `track_window_epochs` epochs (HIPE §4.1: Viterbi for
    /// tracking), oldest first.
    pub fn track(&self) -> Vec<TrackPoint> {
        let path = self.viterbi.as_ref().map(ViterbiWindow::path).unwrap_or_default();
        path.into_iter().map(|(t, s)| self.track_point(t, s)).collect()
    }

    /// The position `fixed_lag_epochs` epochs ago, smoothed by what came after: the exact
    /// fixed-lag posterior P(s | o_1..t) of that epoch (the backward pass of the
    /// forward-backward recursion over the lag, `FixedLagSmoother`), and Hoang eq. 4 over it,
    /// as the live estimate is over the filtered posterior. Fewer epochs back when the filter
    /// restarted, bridged a gap or was pinned by feedback since, as the filter's history
    /// begins there. `state` is the state of most smoothed mass. The lag:
    /// `docs/tuning.md#fixed-lag`.
    pub fn fixed_lag_position(&self) -> Option<TrackPoint> {
        self.smoothed_position(self.config.fixed_lag_epochs.min(self.smoother.len()))
    }

    /// [`fixed_lag_position`](Self::fixed_lag_position) at another lag, epochs (0: the
    /// filtered posterior of the latest epoch); `None` before the first epoch, beyond
    /// `fixed_lag_epochs`, or beyond the filter's history.
    pub fn smoothed_position(&self, lag: usize) -> Option<TrackPoint> {
        let mut smoothed = Vec::new();
        let timestamp_ns = match lag {
            0 => {
                smoothed.extend_from_slice(self.filter.posterior());
                self.last_epoch_ns?
            }
            lag => self.smoothed_posterior(lag, &mut smoothed)?,
        };
        let e =
            estimate(&self.site, &smoothed, self.estimate_states, self.config.accuracy_mass, &mut Vec::new());
        let state = (0..smoothed.len()).max_by(|&a, &b| smoothed[a].total_cmp(&smoothed[b]))? as u32;
        let unmapped_level = self.unmapped_level_at(timestamp_ns);
        Some(TrackPoint {
            timestamp_ns,
            state,
            floor: e.floor,
            x: e.position.x,
            y: e.position.y,
            unmapped_level,
        })
    }

    fn track_point(&self, timestamp_ns: u64, state: u32) -> TrackPoint {
        let s = &self.site.states()[state as usize];
        let unmapped_level = self.unmapped_level_at(timestamp_ns);
        TrackPoint { timestamp_ns, state, floor: s.floor, x: s.position.x, y: s.position.y, unmapped_level }
    }

    /// The unmapped level the epoch at `timestamp_ns` reported, as the history holds it.
    fn unmapped_level_at(&self, timestamp_ns: u64) -> Option<i32> {
        self.history.at(timestamp_ns).and_then(|r| r.unmapped_level)
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
    pub fn fix_bias(&self) -> FixBias {
        self.habits.fix_bias(&self.config.habits)
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
        // The steps the smoother holds were taken with the old habits.
        self.clear_smoother();
        self.habit_prior = Arc::new(HabitPrior::new(&model, &self.reach, self.site.spacing_m()));
        self.habits = model;
    }

    /// Forgets every habit.
    pub fn clear_habits(&mut self) {
        self.set_habits(HabitModel::new(&self.site));
    }
}
