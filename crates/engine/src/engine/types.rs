//! What an engine returns and reports: epochs with their positions, status events and track
//! revisions, input counts and snapshots, and the scan timing of the sparse regime.

#[allow(unused_imports)] // doc links
use super::{Engine, MAX_RSSI_DBM};
#[cfg(feature = "fault-injection")]
use crate::history::EpochRecord;
use crate::radio::RadioMap;
use crate::sensors::{MotionScenario, MotionState};
use crate::site::{Site, SparseScans, SPARSE_SCAN_GAP_S};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, Weak};

/// Where the phone is, after one epoch.
#[derive(Clone, Debug, PartialEq)]
pub struct Position {
    /// Time of the epoch (the scan's timestamp), ns.
    pub timestamp_ns: u64,
    /// Floor index into the site's floors.
    pub floor: usize,
    /// Probability that the floor is right: how often it was at this posterior mass on it on
    /// held-out survey walks (docs/accuracy.md#floor-probability), or the posterior's own mass
    /// when the site file has no such calibration.
    pub floor_probability: f64,
    /// A level the site has no floor for, between two levels it has, where the barometer
    /// places the phone (docs/accuracy.md#barometer): the height climbed since the last floor
    /// that explained a height fits it better than `floor`'s level by a Bayes factor above 3.
    /// `None` otherwise, and always without a barometer. The position and the radii still
    /// stand on `floor`'s plan, the nearest the map can place the phone; display the level
    /// ([`Position::level`]) as the floor.
    pub unmapped_level: Option<i32>,
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
    pub scenario: MotionScenario,
    /// Steps detected since the previous epoch.
    pub steps: u32,
    /// ln p(scan | earlier input): how well the radio map explains this scan; `None` for an
    /// epoch without a scan. Very low values mean the phone hears what the map does not expect.
    pub radio_log_evidence: Option<f64>,
    /// How much better, per radio heard (an access point's several networks count once), the
    /// fingerprinted state that best explains this scan does than a state with no fingerprint,
    /// nats (negative when none does better; states that model none of the transmitters heard
    /// do not count); `None` for an epoch without a scan or when no state models a transmitter
    /// heard above the clip level. Below the site's
    /// [`radio_fit_floor`](crate::site::Calibration::radio_fit_floor) the map does not explain
    /// the scan and the engine positions by the motion alone.
    pub radio_fit: Option<f64>,
    /// Distance walked since the radio last explained a scan, m (0 while it does): the phone is
    /// probably beyond the surveyed area, up to this far from the states the estimate stands
    /// on, and both radii include it. The steps' length when measured, else HIPE's assumed
    /// speed (1 m/s) over the time walking or of unknown motion.
    pub beyond_radio_m: f64,
}

impl Position {
    /// The level to show on `site`, the engine's: the [unmapped level](Self::unmapped_level)
    /// where the barometer places the phone, else `floor`'s own level when the site file gives
    /// one ([`Site::floor_level`]).
    pub fn level(&self, site: &Site) -> Option<i32> {
        shown_level(site, self.floor, self.unmapped_level)
    }
}

/// The level an app shows for `floor` with the barometer's `unmapped` level, if any.
fn shown_level(site: &Site, floor: usize, unmapped: Option<i32>) -> Option<i32> {
    unmapped.or(site.floor_level(floor))
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
    /// The level the site has no floor for that the live position of the same epoch reported
    /// ([`Position::unmapped_level`]): the barometer's verdict at that time, which smoothing
    /// does not revise. `None` when the engine's history no longer holds the epoch.
    pub unmapped_level: Option<i32>,
}

impl TrackPoint {
    /// The level to show on `site`, as [`Position::level`]: the epoch's
    /// [unmapped level](Self::unmapped_level), else `floor`'s own level.
    pub fn level(&self, site: &Site) -> Option<i32> {
        shown_level(site, self.floor, self.unmapped_level)
    }
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
        from: MotionScenario,
        /// Now.
        to: MotionScenario,
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
    /// The person entered one of the site's zones: its posterior mass reached
    /// `zone_hysteresis.enter_mass`.
    ZoneEntered {
        /// When, ns.
        timestamp_ns: u64,
        /// Index into the site's zones.
        zone: usize,
        /// The zone's posterior mass then.
        probability: f64,
    },
    /// The person left a zone they had entered: its mass fell below `zone_hysteresis.exit_mass`.
    ZoneExited {
        /// When, ns.
        timestamp_ns: u64,
        /// Index into the site's zones.
        zone: usize,
        /// The zone's posterior mass then.
        probability: f64,
    },
    /// The person entered one of the app's geofences ([`Engine::add_geofence`]).
    GeofenceEntered {
        /// When, ns.
        timestamp_ns: u64,
        /// The geofence's id.
        id: String,
        /// Its posterior mass then.
        probability: f64,
    },
    /// The person left a geofence they had entered.
    GeofenceExited {
        /// When, ns.
        timestamp_ns: u64,
        /// The geofence's id.
        id: String,
        /// Its posterior mass then.
        probability: f64,
    },
}

/// What one epoch produced: the position, and what else changed with it. Every input that
/// makes an epoch (a scan, an advance, a fix, feedback) returns one; there is no other channel.
#[derive(Clone, Debug, PartialEq)]
pub struct Epoch {
    /// Where the phone is now.
    pub position: Position,
    /// What changed about the session at this epoch, in the order it happened.
    pub status: Vec<StatusEvent>,
    /// The points of the most likely track, before this epoch, that a later observation moved
    /// to another state since the previous epoch, oldest first; empty when none did.
    pub revised_track: Vec<TrackPoint>,
}

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
    /// Readings older than the reading-age limit (in accepted scans): the configuration's
    /// `max_reading_age_ns`, else the site's.
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
    /// Inputs refused for a timestamp too far ahead of the engine's clock: sensor samples more
    /// than `max_backlog_s` ahead of the latest input taken (unless the stream's next sample
    /// confirms the jump), and any input past [`MAX_TIMESTAMP_NS`](crate::sensors::MAX_TIMESTAMP_NS)
    /// (docs/errors.md#timestamps-ahead-of-the-clock). Each refused input is counted here
    /// only, not also in its kind's counter.
    pub timestamps_ahead: u64,
    /// Barometer readings dropped: not finite, not a pressure, or not after the previous
    /// ([`Engine::push_pressure`](super::Engine::push_pressure)).
    pub pressure_dropped: u64,
}

/// Everything an engine holds that decides its later answers, for tests that check a call
/// changed nothing (a rejected scan must leave the engine as it was). Not a stable API: the
/// internals are compared through their `Debug` renderings, which show every field. Built
/// with the `fault-injection` feature only, as [`Engine::snapshot`](super::Engine::snapshot) is.
#[cfg(feature = "fault-injection")]
#[derive(Clone, Debug, PartialEq)]
pub struct EngineSnapshot {
    /// Time of the last epoch.
    pub last_epoch_ns: Option<u64>,
    /// The latest position.
    pub position: Option<Position>,
    /// The posterior over the site's states.
    pub posterior: Vec<f64>,
    /// The track as last returned ([`Epoch::revised_track`] is the change from it).
    pub last_track: Vec<TrackPoint>,
    /// Counts of accepted and dropped input (a test decides whether these count as state).
    pub stats: InputStats,
    /// `Debug` of the forward filter, the Viterbi window and the motion tracker.
    pub internals: String,
    /// The epoch history with its feedback.
    pub history: Vec<EpochRecord>,
}

/// When the latest scan an engine accepted came and how long after the one before it: whether
/// the engine is in the sparse regime (more than 10 s apart) and how long since its scan.
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
        let sparse = self.gap_ns.is_none_or(|gap| gap as f64 * 1e-9 > SPARSE_SCAN_GAP_S);
        sparse.then(|| SparseScans::band(timestamp_ns.saturating_sub(last) as f64 * 1e-9))
    }
}

/// Scan likelihoods shared by the engines an evaluation runs on one site and its copies: the
/// survey's calibration replays each held-out walk at every γ and motion mask
/// (`waymark-survey`, `calibrate`), and ln p(o | s) of a scan (Hoang eqs. 9-10) depends on the
/// radio map and the resolved scan only, so the engines of one map compute it once per scan
/// and copy it thereafter (`docs/tuning.md#evaluation-speed`). Not for apps: an app runs one
/// engine per site, which never sees a scan twice. Hand it to engines with
/// [`Engine::share_emissions`]; it holds every distinct scan's likelihoods (8 bytes per state
/// each) until dropped.
#[derive(Debug)]
pub struct SharedEmissions {
    /// The radio map the likelihoods are of, held weakly so that its address names it: a site
    /// and its copies with another calibration share it.
    radio: Weak<RadioMap>,
    /// Per resolved scan (its observations, RSSI as bits): ln p(o | s) per state and the
    /// likelihood of hearing nothing, as `RadioMap::ln_likelihood` returned them.
    memo: Mutex<HashMap<Vec<(u32, u64)>, ScanLikelihoods>>,
}

/// One scan's ln p(o | s) per state and its likelihood of hearing nothing.
type ScanLikelihoods = Arc<(Box<[f64]>, f64)>;

impl SharedEmissions {
    /// An empty memo for the engines on `site`.
    pub fn new(site: &Site) -> Arc<Self> {
        Arc::new(Self { radio: Arc::downgrade(site.shared_radio_map()), memo: Mutex::default() })
    }

    /// Whether these are the likelihoods of `site`'s radio map (the same allocation, which its
    /// copies share, not an equal map).
    pub(super) fn is_of(&self, site: &Site) -> bool {
        std::ptr::eq(self.radio.as_ptr(), Arc::as_ptr(site.shared_radio_map()))
    }

    /// ln p(o | s) of `observations` into `out`, and the likelihood of hearing nothing: from the
    /// memo when a scan with the same observations was seen, else from `radio` and memoised.
    pub(super) fn ln_likelihood(
        &self,
        radio: &RadioMap,
        observations: &[(u32, f64)],
        out: &mut [f64],
    ) -> f64 {
        let key: Vec<(u32, u64)> = observations.iter().map(|&(t, rssi)| (t, rssi.to_bits())).collect();
        let seen = self.memo.lock().ok().and_then(|memo| memo.get(&key).cloned());
        if let Some(seen) = seen {
            out.copy_from_slice(&seen.0);
            return seen.1;
        }
        let ln_unheard = radio.ln_likelihood(observations, out);
        if let Ok(mut memo) = self.memo.lock() {
            memo.insert(key, Arc::new((out.into(), ln_unheard)));
        }
        ln_unheard
    }
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
