//! The positioning session: takes scans in time order, runs one HMM epoch per scan, and
//! publishes positions to whoever polls or listens.
//!
//! The engine is single-threaded and deterministic, so a replay is exact; the FFI layer puts
//! it behind a lock.

use crate::config::EngineConfig;
use crate::error::{Error, InputError};
use crate::hmm::{estimate, ForwardFilter, Transition, UniformReach};
use crate::radio::Scan;
use crate::site::{ReachTable, Site};
use std::sync::Arc;

/// Where the phone is, after one epoch.
#[derive(Clone, Debug, PartialEq)]
pub struct Position {
    /// Time of the epoch (the scan's timestamp), ns.
    pub timestamp_ns: u64,
    /// Floor index into the site's floors.
    pub floor: usize,
    /// Posterior probability of that floor.
    pub floor_probability: f64,
    /// East-ish coordinate in the site's metric frame, m.
    pub x: f64,
    /// North-ish coordinate in the site's metric frame, m.
    pub y: f64,
    /// Radius of the circle around (x, y) that holds the true position with probability 0.68
    /// (the configured `accuracy_mass`), m. Always > 0.
    pub accuracy_m: f64,
    /// ln p(scan | earlier scans): how well the site's radio map explains this scan. Very low
    /// values mean the phone hears what the map does not expect.
    pub radio_log_evidence: f64,
}

/// Receives every new position.
pub trait PositionListener: Send {
    /// Called after each epoch, on the thread that pushed the input.
    fn on_position(&mut self, position: &Position);
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
    /// Scans rejected because their timestamp was not after the last accepted one.
    pub scans_out_of_order: u64,
    /// Scans rejected for having no readings.
    pub scans_empty: u64,
    /// Scans rejected for a NaN or infinite RSSI.
    pub scans_non_finite: u64,
    /// Scans rejected because no reading was of a known transmitter.
    pub scans_no_known_transmitter: u64,
    /// Readings of transmitters not in the site (in accepted scans).
    pub readings_unknown: u64,
    /// Repeated readings of one transmitter within a scan (in accepted scans).
    pub readings_duplicate: u64,
    /// Readings older than `max_reading_age_ns` (in accepted scans).
    pub readings_stale: u64,
    /// Times the filter restarted from the uniform prior: after a gap too long to bridge, or
    /// when no state could explain a scan.
    pub filter_restarts: u64,
}

/// A positioning session on one site.
pub struct Engine {
    site: Arc<Site>,
    config: EngineConfig,
    reach: ReachTable,
    filter: ForwardFilter,
    ln_emission: Vec<f64>,
    scratch: Vec<(f64, f64)>,
    last_scan_ns: Option<u64>,
    latest: Option<Position>,
    listeners: Vec<(SubscriptionId, Box<dyn PositionListener>)>,
    next_subscription: u64,
    stats: InputStats,
}

impl Engine {
    /// A session on `site`. Precomputes the walking-distance table: all allocation happens here.
    pub fn new(site: Arc<Site>, config: EngineConfig) -> Result<Self, Error> {
        config.validate()?;
        let n = site.states().len();
        let reach = ReachTable::build(&site, config.reach_radius_m);
        Ok(Self {
            site,
            config,
            reach,
            filter: ForwardFilter::new(n),
            ln_emission: vec![0.0; n],
            scratch: Vec::with_capacity(n),
            last_scan_ns: None,
            latest: None,
            listeners: Vec::new(),
            next_subscription: 0,
            stats: InputStats::default(),
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

    /// The latest position, if any scan has been accepted.
    pub fn position(&self) -> Option<&Position> {
        self.latest.as_ref()
    }

    /// The posterior over the site's states.
    pub fn posterior(&self) -> &[f64] {
        self.filter.posterior()
    }

    /// Counts of accepted and dropped input.
    pub fn stats(&self) -> &InputStats {
        &self.stats
    }

    /// Calls `listener` with every new position until [`unsubscribe`](Self::unsubscribe).
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

    /// Takes a WiFi or BLE scan: one epoch of the HMM. A rejected scan leaves the engine as it
    /// was and is counted by reason.
    pub fn push_scan(&mut self, scan: &Scan) -> Result<Position, InputError> {
        let result = self.epoch(scan);
        if let Err(e) = &result {
            let counter = match e {
                InputError::OutOfOrder { .. } => &mut self.stats.scans_out_of_order,
                InputError::EmptyScan => &mut self.stats.scans_empty,
                InputError::NonFiniteRssi { .. } => &mut self.stats.scans_non_finite,
                InputError::NoKnownTransmitter { .. } => &mut self.stats.scans_no_known_transmitter,
            };
            *counter += 1;
            log::debug!("scan rejected: {e}");
        }
        result
    }

    fn epoch(&mut self, scan: &Scan) -> Result<Position, InputError> {
        if let Some(last_ns) = self.last_scan_ns {
            if scan.timestamp_ns <= last_ns {
                return Err(InputError::OutOfOrder { timestamp_ns: scan.timestamp_ns, last_ns });
            }
        }
        if scan.readings.is_empty() {
            return Err(InputError::EmptyScan);
        }
        if let Some((index, r)) = scan.readings.iter().enumerate().find(|(_, r)| !r.rssi_dbm.is_finite()) {
            return Err(InputError::NonFiniteRssi { index, transmitter: r.transmitter.to_string() });
        }
        let resolved = self.site.radio().resolve(scan, self.config.max_reading_age_ns);
        if resolved.observations.is_empty() {
            return Err(InputError::NoKnownTransmitter { unknown: resolved.unknown, stale: resolved.stale });
        }
        self.site.radio().ln_likelihood(&resolved.observations, &mut self.ln_emission);

        // Accepted from here on: the state changes.
        let dt_s = self.last_scan_ns.map(|last| (scan.timestamp_ns - last) as f64 * 1e-9);
        let evidence = self.forward(dt_s);
        self.stats.scans_accepted += 1;
        self.stats.readings_unknown += resolved.unknown as u64;
        self.stats.readings_duplicate += resolved.duplicates as u64;
        self.stats.readings_stale += resolved.stale as u64;
        self.last_scan_ns = Some(scan.timestamp_ns);

        let e = estimate(
            &self.site,
            self.filter.posterior(),
            self.config.estimate_states,
            self.config.accuracy_mass,
            &mut self.scratch,
        );
        let position = Position {
            timestamp_ns: scan.timestamp_ns,
            floor: e.floor,
            floor_probability: e.floor_probability,
            x: e.position.x,
            y: e.position.y,
            accuracy_m: e.accuracy_m,
            radio_log_evidence: evidence,
        };
        for (_, listener) in &mut self.listeners {
            listener.on_position(&position);
        }
        self.latest = Some(position.clone());
        Ok(position)
    }

    /// Predicts over `dt_s` (none at the first epoch) and updates with `ln_emission`.
    /// Returns the radio evidence.
    fn forward(&mut self, dt_s: Option<f64>) -> f64 {
        let ratio = self.config.transition_ratio;
        let (passes, rho_m) = match dt_s {
            None => (0, 0.0),
            Some(dt) => {
                let reach = self.config.max_speed_mps * dt;
                let passes = (reach / self.reach.radius_m()).ceil().max(1.0);
                (passes as u32, reach / passes)
            }
        };
        if passes > self.config.max_reach_passes {
            log::debug!("{:.1} s without a scan: restarting from the uniform prior", dt_s.unwrap_or(0.0));
            self.filter.reset();
            self.stats.filter_restarts += 1;
        }
        let transition = UniformReach { table: &self.reach, rho_m, ratio };
        let passes = if passes > self.config.max_reach_passes { 0 } else { passes };
        // All but the last pass are pure predictions (no observation in between).
        for _ in 1..passes {
            self.filter.predict(&transition);
        }
        let last: Option<&dyn Transition> = if passes >= 1 { Some(&transition) } else { None };
        match self.filter.step(last, &self.ln_emission) {
            Ok(evidence) => evidence,
            Err(_) => {
                // The map explains this scan nowhere the motion model allows: start again from
                // the radio alone.
                self.stats.filter_restarts += 1;
                self.filter.reset();
                self.filter.step(None, &self.ln_emission).unwrap_or(f64::NEG_INFINITY)
            }
        }
    }
}
