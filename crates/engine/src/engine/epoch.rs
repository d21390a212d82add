//! One epoch: the scan's emissions, the filter step, the estimate and what it returns.

use super::input::check_motion;
use super::{Engine, Epoch, Position, StatusEvent, TrackPoint};
use crate::error::InputError;
use crate::history::{EpochInput, EpochRecord, History};
use crate::hmm::estimate;
use crate::radio::{check_readings, Scan};
use crate::sensors::MotionUpdate;
use crate::site::{most_likely_zone, scaled_radii};

impl Engine {
    pub(super) fn scan_epoch(
        &mut self,
        scan: &Scan,
        motion: Option<&MotionUpdate>,
    ) -> Result<Epoch, InputError> {
        self.check_time(scan.timestamp_ns)?;
        motion.map_or(Ok(()), check_motion)?;
        check_readings(scan)?;
        let max_age_ns = self.config.max_reading_age_ns.or(self.site.max_reading_age_ns());
        let resolved = match &mut self.id_hasher {
            Some(hasher) => self.site.radio().resolve(hasher.hash_scan(scan), max_age_ns),
            None => self.site.radio().resolve(scan, max_age_ns),
        };
        if resolved.observations.is_empty() {
            return Err(InputError::NoKnownTransmitter { unknown: resolved.unknown, stale: resolved.stale });
        }
        let radio = self.site.radio();
        // The readings as the survey's phones would have read them (docs/accuracy.md#device-offset).
        let corrected: Vec<(u32, f64)>;
        let observations = if self.config.device_offset && self.device_offset.scans() > 0 {
            let offset = self.device_offset;
            corrected = resolved.observations.iter().map(|&(t, rssi)| (t, offset.correct(rssi))).collect();
            &corrected
        } else {
            &resolved.observations
        };
        // The device offset is measured against where the engine believed the phone was before
        // the scan (below); without memoised likelihoods, the walk over the fingerprints that
        // scores the scan also takes what that needs.
        let measures_offset = self.config.device_offset && self.latest.is_some();
        let (ln_unheard, moments) = match &self.shared_emissions {
            Some(shared) => (shared.ln_likelihood(radio, observations, &mut self.ln_emission), None),
            None => {
                let belief = measures_offset.then(|| (&resolved.observations[..], self.filter.posterior()));
                let (ln_unheard, moments) =
                    radio.ln_likelihood_and_moments(observations, belief, &mut self.ln_emission);
                (ln_unheard, belief.map(|_| moments))
            }
        };
        // The fit of the map: the best fingerprinted state against none. Unsurveyed states score
        // the "no fingerprint" baseline itself, so counting them would never let the fit fall
        // below 0, and a site whose held-out fits reach 0 would never find a scan unexplained;
        // a state that models none of the transmitters heard is, for this scan, one with no
        // fingerprint too (docs/accuracy.md#off-the-map).
        let silent: Vec<bool> = radio.silent_states(observations, &self.ln_emission).collect();
        let best = best_fingerprinted(&self.ln_emission, &self.unsurveyed, &silent);
        // Per radio heard: an access point's several networks count once, as they do in the
        // likelihood (docs/tuning.md#shared-radios).
        let radio_fit = (best - ln_unheard) / radio.radios_heard(observations);
        let below_floor = self.radio_fit_floor.is_some_and(|floor| radio_fit < floor);
        // Only with an estimate to carry on from: the first scan, unexplained or not, is all
        // there is to go on, and then only the states whose fingerprints speak to it place the
        // estimate. A state fitted from near-empty survey scans scores about the baseline for
        // any scan, and when nothing on the map explains a scan it would win, wherever it is.
        let unexplained = self.latest.is_some() && below_floor;
        let first_unexplained = self.latest.is_none() && below_floor && silent.contains(&false);
        let dropped = [resolved.unknown, resolved.duplicates, resolved.stale].map(|n| n as u64);
        // The phone's offset as this scan measures it: against where the engine believed the
        // phone was before the scan, so that the scan does not confirm its own reading; not
        // from a scan the map does not explain (docs/accuracy.md#device-offset).
        let offset_db = self.device_offset.mean_db();
        let offset_measurement = (measures_offset && !below_floor)
            .then(|| match &moments {
                Some(moments) => radio.offset_from_moments(&resolved.observations, moments, offset_db),
                None => radio.offset_residual(&resolved.observations, self.filter.posterior(), offset_db),
            })
            .flatten();
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
            if first_unexplained {
                for (e, _) in engine.ln_emission.iter_mut().zip(&silent).filter(|(_, &s)| s) {
                    *e = f64::NEG_INFINITY;
                }
            }
            engine.epoch_radio_fit = radio_fit.is_finite().then_some((radio_fit, unexplained));
            let epoch = engine.run_epoch(scan.timestamp_ns, EpochInput::Scan, None, &motion);
            if let Some((residual, variance)) = offset_measurement {
                engine.device_offset.update(residual, variance);
            }
            epoch
        }))
    }

    /// Prediction, update, estimate, status events, history. `ln_emission` holds the observation
    /// (zeros for motion alone); `allowed` is the user's feedback at this epoch.
    pub(super) fn run_epoch(
        &mut self,
        timestamp_ns: u64,
        input: EpochInput,
        allowed: Option<Vec<u32>>,
        motion: &MotionUpdate,
    ) -> Epoch {
        let (motion, held_record) = match self.step_over_far_held(timestamp_ns, motion) {
            Some((rest, record)) => (std::borrow::Cow::Owned(rest), Some(record)),
            None => (std::borrow::Cow::Borrowed(motion), None),
        };
        let motion = motion.as_ref();
        let dt_s = self.last_epoch_ns.map(|last| (timestamp_ns - last) as f64 * 1e-9);
        let radio = self.epoch_radio_fit.take().filter(|_| input == EpochInput::Scan);
        let before = self.step_position().map_or(0.0, |p| p.beyond_radio_m);
        // The filter steps over the held epochs now: `motion` is theirs and this one's.
        self.held = None;
        let beyond_radio_m = self.beyond_radio_from(before, radio.map(|r| r.1), dt_s, motion);
        let radio_fit = radio.map(|r| r.0);
        let was_off_map = self.unexplained_run >= UNSURVEYED_AFTER_SCANS;
        if let Some((_, unexplained)) = radio {
            self.unexplained_run = if unexplained { self.unexplained_run.saturating_add(1) } else { 0 };
        }
        let off_map = self.unexplained_run >= UNSURVEYED_AFTER_SCANS;
        // Back from beyond the map, the mass out there needs the whole table to come home.
        self.whole_reach = was_off_map || off_map;
        self.rule_out_unsurveyed();
        self.weigh_floors_by_height(timestamp_ns);
        let evidence = self.forward(timestamp_ns, dt_s, motion);
        self.last_epoch_ns = Some(timestamp_ns);
        let mut position = Position::of_motion(timestamp_ns, motion, beyond_radio_m);
        position.radio_log_evidence = (input == EpochInput::Scan).then_some(evidence);
        position.radio_fit = radio_fit;
        let position = self.locate(position);
        let epoch = self.conclude(position, |history, p| {
            if let Some(record) = held_record {
                history.push(record);
            }
            history.push(EpochRecord {
                timestamp_ns,
                input,
                floor: p.floor,
                x: p.x,
                y: p.y,
                unmapped_level: p.unmapped_level,
                accuracy_m: p.accuracy_m,
                allowed,
            })
        });
        self.settle_floor_anchor(timestamp_ns);
        epoch
    }

    /// On the map (as far as the radio says): the unsurveyed states around it are out of
    /// `ln_emission`.
    pub(super) fn rule_out_unsurveyed(&mut self) {
        if self.on_map() {
            for &i in &self.unsurveyed {
                self.ln_emission[i as usize] = f64::NEG_INFINITY;
            }
        }
    }

    /// Whether the radio places the walker on the surveyed map: fewer than
    /// [`UNSURVEYED_AFTER_SCANS`] unexplained scans in a row.
    pub(super) fn on_map(&self) -> bool {
        self.unexplained_run < UNSURVEYED_AFTER_SCANS
    }

    /// When the epoch at `timestamp_ns` with `motion` is farther from the filter's last step
    /// than the walking-distance table reaches, with epochs held since: the filter first steps over
    /// the held motion, a motion-only epoch at the latest held epoch's time, so that the motion
    /// is not lost to a gap bridged by the speed bound alone. An app advancing every 2 s by a
    /// clock slightly behind the engine's holds every other advance. Returns the rest of
    /// `motion` and the held epoch's record for the history.
    fn step_over_far_held(
        &mut self,
        timestamp_ns: u64,
        motion: &MotionUpdate,
    ) -> Option<(MotionUpdate, EpochRecord)> {
        let last = self.last_epoch_ns?;
        let far = self.within_reach(motion, (timestamp_ns - last) as f64 * 1e-9).is_none();
        // The latest position is the latest held epoch's: any other epoch steps.
        let shown = self.latest.clone().filter(|_| far && self.held.is_some())?;
        let held = self.held.take()?;
        let emission = std::mem::take(&mut self.ln_emission);
        self.ln_emission = vec![0.0; emission.len()];
        self.rule_out_unsurveyed();
        let dt_s = (held.timestamp_ns - last) as f64 * 1e-9;
        self.forward(held.timestamp_ns, Some(dt_s), &held.motion);
        self.ln_emission = emission;
        self.last_epoch_ns = Some(held.timestamp_ns);
        let record = EpochRecord {
            timestamp_ns: held.timestamp_ns,
            input: EpochInput::Motion,
            floor: shown.floor,
            x: shown.x,
            y: shown.y,
            unmapped_level: shown.unmapped_level,
            accuracy_m: shown.accuracy_m,
            allowed: None,
        };
        Some((motion.after(&held.motion), record))
    }

    /// `position` with the estimate from the current posterior: floor, (x, y), radii, zone.
    pub(super) fn locate(&mut self, position: Position) -> Position {
        self.locate_over(position, false)
    }

    /// [`locate`](Self::locate) over the posterior, or with `predicted` over the prediction a
    /// held epoch left in `ln_emission` ([`Engine::hold_epoch`]). The zone is always the
    /// posterior's, as [`Engine::zone_posterior`] and the zone events are: they change at the
    /// filter's steps.
    pub(super) fn locate_over(&mut self, position: Position, predicted: bool) -> Position {
        let over = if predicted { &self.ln_emission } else { self.filter.posterior() };
        let e =
            estimate(&self.site, over, self.estimate_states, self.config.accuracy_mass, &mut self.scratch);
        let sparse = self.scan_timing.sparse_band(position.timestamp_ns);
        let scale = sparse
            .and_then(|band| self.sparse_scans.accuracy_scale_by_since[band])
            .unwrap_or(self.accuracy_scale[position.scenario.index()]);
        let radii = scaled_radii([e.accuracy_m, e.accuracy_95_m], scale, position.beyond_radio_m);
        // The floor probability as calibrated on held-out walks (docs/accuracy.md#floor-probability):
        // the sparse regime's table there when the survey fitted one.
        let floor_reliability = match sparse {
            Some(_) if !self.sparse_scans.floor_reliability.is_empty() => {
                &self.sparse_scans.floor_reliability
            }
            _ => &self.floor_reliability,
        };
        let (zone, zone_probability) = if self.site.zones().is_empty() {
            (None, 1.0)
        } else {
            let outside = self.site.zone_mass(self.filter.posterior(), &mut self.zone_mass);
            most_likely_zone(&self.zone_mass, outside)
        };
        Position {
            floor: e.floor,
            floor_probability: floor_reliability.report(e.floor_probability),
            unmapped_level: self.unmapped_level(position.timestamp_ns, e.floor),
            zone,
            zone_probability,
            x: e.position.x,
            y: e.position.y,
            accuracy_m: radii[0],
            accuracy_95_m: radii[1],
            ..position
        }
    }

    /// The epoch of `position`: its status events and track revisions against the latest
    /// position, which it then becomes, and its record in the history, last: nothing after a
    /// possible panic, so the history needs no undo.
    pub(super) fn conclude(
        &mut self,
        position: Position,
        record: impl FnOnce(&mut History, &Position),
    ) -> Epoch {
        let mut status = self.status_changes(&position);
        let (presence, changes) = self.presence.evaluate(
            position.timestamp_ns,
            self.filter.posterior(),
            &self.zone_mass,
            &self.config.zone_hysteresis,
        );
        status.extend(presence);
        let revised_track = self.revise_track();
        #[cfg(feature = "fault-injection")]
        if position.timestamp_ns == super::FAULT_INJECTION_MID_EPOCH_NS {
            panic!("fault injected in the middle of the epoch at {}", position.timestamp_ns);
        }
        self.presence.apply(changes);
        self.latest = Some(position.clone());
        record(&mut self.history, &position);
        Epoch { position, status, revised_track }
    }

    /// What changed about the session between the latest position and `position`.
    fn status_changes(&self, position: &Position) -> Vec<StatusEvent> {
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
        events
    }

    /// The points of the Viterbi path, before the newest epoch, that differ from what the
    /// previous epoch returned.
    pub(super) fn revise_track(&mut self) -> Vec<TrackPoint> {
        let track = self.track();
        let revised: Vec<TrackPoint> = match track.split_last() {
            Some((_, earlier)) => earlier
                .iter()
                .filter(|p| {
                    self.last_track
                        .iter()
                        .find(|q| q.timestamp_ns == p.timestamp_ns)
                        .is_some_and(|q| q.state != p.state)
                })
                .cloned()
                .collect(),
            None => Vec::new(),
        };
        self.last_track = track;
        revised
    }
}

/// Unexplained scans in a row after which the estimate may leave the surveyed map for its
/// unsurveyed states. One is not enough: the site's radio fit floor is a low quantile of the
/// fits of scans on the map (5% or 20%, chosen per site), so some scans on the map fall below
/// it (docs/tuning.md#unsurveyed-states).
const UNSURVEYED_AFTER_SCANS: u32 = 2;

/// The largest of `ln_emission` over the states neither in `unsurveyed` (sorted indices) nor
/// `silent`; -∞ when there is none.
fn best_fingerprinted(ln_emission: &[f64], unsurveyed: &[u32], silent: &[bool]) -> f64 {
    let mut skip = unsurveyed.iter().peekable();
    let mut best = f64::NEG_INFINITY;
    for (i, (&e, &quiet)) in ln_emission.iter().zip(silent).enumerate() {
        if skip.next_if(|&&j| j as usize == i).is_none() && !quiet {
            best = best.max(e);
        }
    }
    best
}

impl Position {
    /// What an epoch at `timestamp_ns` with `motion` reports before the estimate is placed:
    /// the motion's heading, state, scenario and steps, and no radio.
    pub(super) fn of_motion(timestamp_ns: u64, motion: &MotionUpdate, beyond_radio_m: f64) -> Position {
        Position {
            timestamp_ns,
            floor: 0,
            floor_probability: 0.0,
            unmapped_level: None,
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
            radio_log_evidence: None,
            radio_fit: None,
            beyond_radio_m,
        }
    }
}
