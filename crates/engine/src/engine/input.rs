//! The inputs an engine takes: inertial batches, scans, advances without radio, position
//! fixes and user feedback, each epoch run atomically.

use super::{Engine, Epoch, Held, InputStats, Position};
use crate::error::InputError;
use crate::fix::{self, PositionFix};
use crate::history::EpochInput;
use crate::radio::Scan;
use crate::sensors::{
    BatchReport, MotionState, MotionUpdate, SensorSample, ACCEL, GYRO, MAG, MAX_TIMESTAMP_NS,
};

impl Engine {
    /// Takes a batch of accelerometer samples (m/s², gravity included, phone frame). Samples
    /// with a NaN or infinite value, or not after the previous one, are dropped and counted;
    /// samples too far ahead of the engine's clock are refused and counted in
    /// [`InputStats::timestamps_ahead`](super::InputStats::timestamps_ahead)
    /// (docs/errors.md#timestamps-ahead-of-the-clock).
    pub fn push_accelerometer(&mut self, batch: &[SensorSample]) -> BatchReport {
        self.push_samples(ACCEL, batch)
    }

    /// Takes a batch of gyroscope samples (rad/s, phone frame); bad samples as above.
    pub fn push_gyroscope(&mut self, batch: &[SensorSample]) -> BatchReport {
        self.push_samples(GYRO, batch)
    }

    /// Takes a batch of magnetometer samples (µT, phone frame); bad samples as above.
    pub fn push_magnetometer(&mut self, batch: &[SensorSample]) -> BatchReport {
        self.push_samples(MAG, batch)
    }

    /// The engine's clock is the latest time it took: its epochs' and its sensor streams'.
    fn push_samples(&mut self, stream: usize, batch: &[SensorSample]) -> BatchReport {
        let epoch_ns = self.held.as_ref().map(|h| h.timestamp_ns).or(self.last_epoch_ns);
        let report = self.tracker.push(stream, batch, epoch_ns);
        self.stats.timestamps_ahead += report.ahead as u64;
        report
    }

    /// Takes a WiFi or BLE scan: one epoch of the HMM, with the motion the inertial sensors
    /// measured since the previous epoch (push the inertial batches up to the scan's time
    /// first). A rejected scan leaves the engine as it was and is counted by reason.
    pub fn push_scan(&mut self, scan: &Scan) -> Result<Epoch, InputError> {
        self.push_scan_from(scan, None)
    }

    /// Takes a scan with motion measured outside Waymark (a platform step detector, a test)
    /// instead of the engine's own inertial tracker. Motion with a non-finite value or a
    /// negative distance or spread rejects the scan.
    pub fn push_scan_with_motion(&mut self, scan: &Scan, motion: &MotionUpdate) -> Result<Epoch, InputError> {
        self.push_scan_from(scan, Some(motion))
    }

    pub(super) fn push_scan_from(
        &mut self,
        scan: &Scan,
        motion: Option<&MotionUpdate>,
    ) -> Result<Epoch, InputError> {
        let result = self.scan_epoch(scan, motion);
        if result.is_ok() {
            self.keep_scan_for_evidence(scan);
        }
        if let Err(e) = &result {
            let counter = match e {
                InputError::TimeAhead { .. } => &mut self.stats.timestamps_ahead,
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
    /// of order. Sooner than [`min_motion_step_s`](crate::EngineConfig::min_motion_step_s)
    /// after the filter's last step it is held: the position is the estimate over the
    /// posterior predicted by the motion since, and the filter steps over all of it at the
    /// next epoch.
    pub fn advance(&mut self, timestamp_ns: u64) -> Result<Epoch, InputError> {
        self.advance_from(timestamp_ns, None)
    }

    /// [`advance`](Self::advance) with motion measured outside Waymark.
    pub fn advance_with_motion(
        &mut self,
        timestamp_ns: u64,
        motion: &MotionUpdate,
    ) -> Result<Epoch, InputError> {
        self.advance_from(timestamp_ns, Some(motion))
    }

    pub(super) fn advance_from(
        &mut self,
        timestamp_ns: u64,
        motion: Option<&MotionUpdate>,
    ) -> Result<Epoch, InputError> {
        let result = self.motion_epoch(timestamp_ns, motion);
        if let Err(e) = &result {
            self.count_rejected(e, |stats| &mut stats.advances_rejected);
            log::debug!("advance rejected: {e}");
        }
        result
    }

    pub(super) fn motion_epoch(
        &mut self,
        timestamp_ns: u64,
        motion: Option<&MotionUpdate>,
    ) -> Result<Epoch, InputError> {
        self.check_time(timestamp_ns)?;
        motion.map_or(Ok(()), check_motion)?;
        let min_step_ns = (self.config.min_motion_step_s * 1e9) as u64;
        let soon = self.last_epoch_ns.is_some_and(|last| timestamp_ns - last < min_step_ns);
        // Held from the position of the filter's last step.
        let hold_from = self.step_position().filter(|_| soon).cloned();
        Ok(self.atomically(motion.is_none(), |engine| {
            engine.stats.motion_epochs += 1;
            if let Some(step) = hold_from {
                // The tracker's own interval stays open, so that the step reports all of it
                // as one; motion given is added to what was held.
                let motion = match motion {
                    None => engine.tracker.peek(timestamp_ns),
                    Some(_) => engine.motion_until(timestamp_ns, motion),
                };
                return engine.hold_epoch(timestamp_ns, motion, step);
            }
            let motion = engine.motion_until(timestamp_ns, motion);
            engine.ln_emission.fill(0.0);
            engine.run_epoch(timestamp_ns, EpochInput::Motion, None, &motion)
        }))
    }

    /// A motion-only epoch the filter does not step over ([`Held`]): the estimate over the
    /// prediction from the filter's last step (at `step`) by `motion`, all there has been since it, into
    /// `ln_emission` (scratch between epochs); the posterior, and with it the zone, stays as
    /// it was. Not in the history, which holds the filter's steps.
    fn hold_epoch(&mut self, timestamp_ns: u64, motion: MotionUpdate, step: Position) -> Epoch {
        let dt_s = self.last_epoch_ns.map_or(0.0, |last| (timestamp_ns - last) as f64 * 1e-9);
        let beyond_radio_m = self.beyond_radio_from(step.beyond_radio_m, None, Some(dt_s), &motion);
        self.predict_held(timestamp_ns, dt_s, &motion);
        let position = self.locate_over(Position::of_motion(timestamp_ns, &motion, beyond_radio_m), true);
        self.held = Some(Held { timestamp_ns, motion, step });
        self.conclude(position, |_, _| {})
    }

    /// The position of the filter's last step: the latest but for held epochs.
    pub(super) fn step_position(&self) -> Option<&Position> {
        self.held.as_ref().map(|h| &h.step).or(self.latest.as_ref())
    }

    /// A position from another positioning system (GNSS near an entrance, WiFi RTT, UWB): one
    /// epoch, with the motion the inertial sensors measured since the previous one, whose
    /// observation is the fix, a Gaussian around each state's position (El Gemayel et al.
    /// §II-C/D, eq. 7; σ from `accuracy_m`, see `fix::sigma_m`). A precise fix pulls the
    /// estimate to it; a vague one barely moves it. Rejected, changing nothing but
    /// `fixes_rejected`: a timestamp not after the last epoch, a NaN or infinite coordinate, an
    /// accuracy not > 0, an unknown floor, or a fix farther from every state than its own
    /// error allows (`fix::FIX_GATE_MASS`).
    pub fn push_fix(&mut self, fix: &PositionFix) -> Result<Epoch, InputError> {
        let result = self.fix_epoch(fix);
        if let Err(e) = &result {
            self.count_rejected(e, |stats| &mut stats.fixes_rejected);
            log::debug!("position fix rejected: {e}");
        }
        result
    }

    pub(super) fn fix_epoch(&mut self, fix: &PositionFix) -> Result<Epoch, InputError> {
        self.check_time(fix.timestamp_ns)?;
        // The learned fix error (§II-C): the bias taken off, the spread widened.
        let error = self.fix_bias();
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
    pub fn confirm_zone(&mut self, timestamp_ns: u64, zone: usize) -> Result<Epoch, InputError> {
        let states = match self.site.zones().get(zone) {
            Some(z) => Ok(z.states.clone()),
            None => Err(InputError::UnknownZone { zone: format!("#{zone}") }),
        };
        self.feedback(timestamp_ns, states)
    }

    /// [`confirm_zone`](Self::confirm_zone) by the zone's name.
    pub fn confirm_zone_named(&mut self, timestamp_ns: u64, name: &str) -> Result<Epoch, InputError> {
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
    ) -> Result<Epoch, InputError> {
        let states = fix::states_within(&self.site, x, y, floor, radius_m);
        self.feedback(timestamp_ns, states)
    }

    pub(super) fn feedback(
        &mut self,
        timestamp_ns: u64,
        states: Result<Vec<u32>, InputError>,
    ) -> Result<Epoch, InputError> {
        let result = self.feedback_epoch(timestamp_ns, states);
        if let Err(e) = &result {
            self.count_rejected(e, |stats| &mut stats.feedback_rejected);
            log::debug!("feedback rejected: {e}");
        }
        result
    }

    pub(super) fn feedback_epoch(
        &mut self,
        timestamp_ns: u64,
        states: Result<Vec<u32>, InputError>,
    ) -> Result<Epoch, InputError> {
        let at_latest = self.latest.as_ref().is_some_and(|p| p.timestamp_ns == timestamp_ns);
        if !at_latest {
            self.check_time(timestamp_ns)?;
        }
        // A held epoch was not a step of the filter: the feedback at it is a step of its own,
        // over the motion held.
        let latest = self.latest.clone().filter(|_| at_latest && self.held.is_none());
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
    pub(super) fn pin_latest(&mut self, latest: Position, states: &[u32]) -> Epoch {
        // Feedback is an observation without a step: the smoother's history ends here.
        self.clear_smoother();
        if self.filter.step(None, &self.ln_emission).is_err() {
            self.restart();
        }
        if let Some(viterbi) = &mut self.viterbi {
            viterbi.pin(&self.ln_emission);
        }
        let position = self.locate(latest);
        self.conclude(position, |history, p| history.pin_latest(states, p.floor, p.x, p.y, p.accuracy_m))
    }

    /// Runs the part of an accepted epoch that changes the engine so that it happens whole or
    /// not at all: a panic inside (a bug) undoes it, leaving the engine exactly as it was before
    /// the call, then goes on unwinding to the caller (the FFI turns it into an error). With
    /// `uses_tracker` the epoch takes its motion from the tracker, which is saved too.
    ///
    /// The cost, at every epoch: a pointer swap in the filter and in the Viterbi window (the
    /// scores they replace are kept aside, not copied), a copy of the last position, the
    /// returned track and the counters, and a clone of the tracker when it is used.
    pub(super) fn atomically<T>(&mut self, uses_tracker: bool, epoch: impl FnOnce(&mut Self) -> T) -> T {
        self.undo.last_epoch_ns = self.last_epoch_ns;
        self.undo.held.clone_from(&self.held);
        self.undo.unexplained_run = self.unexplained_run;
        self.undo.scan_timing = self.scan_timing;
        self.undo.latest.clone_from(&self.latest);
        self.undo.last_track.clone_from(&self.last_track);
        self.undo.stats.clone_from(&self.stats);
        self.undo.tracker = uses_tracker.then(|| self.tracker.clone());
        self.filter.checkpoint();
        if let Some(viterbi) = &mut self.viterbi {
            viterbi.checkpoint();
        }
        match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| epoch(self))) {
            Ok(result) => {
                self.filter.commit();
                if let Some(viterbi) = &mut self.viterbi {
                    viterbi.commit();
                }
                self.undo.tracker = None;
                result
            }
            Err(panic) => {
                self.filter.rollback();
                if let Some(viterbi) = &mut self.viterbi {
                    viterbi.rollback();
                }
                // The smoother's history may hold the undone step.
                self.smoother.clear();
                self.last_epoch_ns = self.undo.last_epoch_ns;
                std::mem::swap(&mut self.held, &mut self.undo.held);
                self.unexplained_run = self.undo.unexplained_run;
                self.scan_timing = self.undo.scan_timing;
                std::mem::swap(&mut self.latest, &mut self.undo.latest);
                std::mem::swap(&mut self.last_track, &mut self.undo.last_track);
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
    /// `before` is its value at the filter's last step.
    pub(super) fn beyond_radio_from(
        &self,
        before: f64,
        unexplained: Option<bool>,
        dt_s: Option<f64>,
        motion: &MotionUpdate,
    ) -> f64 {
        if !unexplained.unwrap_or(before > 0.0) {
            return 0.0;
        }
        let walked = match (motion.distance_m, motion.motion_state) {
            (Some(d), _) => d,
            (None, MotionState::Stationary) => 0.0,
            (None, _) => self.config.regions.assumed_speed_mps * dt_s.unwrap_or(0.0),
        };
        before + walked
    }

    /// What the tracker measured up to `timestamp_ns` since its previous update, which spans
    /// the epochs held since (they only peek); or the motion given, after that of the held
    /// epochs.
    pub(super) fn motion_until(&mut self, timestamp_ns: u64, given: Option<&MotionUpdate>) -> MotionUpdate {
        match (given, &self.held) {
            (None, _) => self.tracker.update(timestamp_ns),
            (Some(m), Some(held)) => held.motion.then(m),
            (Some(m), None) => m.clone(),
        }
    }

    /// Counts a refused input once: in `timestamps_ahead` for a time too far ahead, else in
    /// its own counter.
    fn count_rejected(&mut self, e: &InputError, counter: impl FnOnce(&mut InputStats) -> &mut u64) {
        *match e {
            InputError::TimeAhead { .. } => &mut self.stats.timestamps_ahead,
            _ => counter(&mut self.stats),
        } += 1;
    }

    /// Input must come after the latest epoch, held or not, and by a time a phone's clock can
    /// show: epochs may be minutes apart (sparse scans), so only a time past
    /// [`MAX_TIMESTAMP_NS`] is too far ahead (docs/errors.md#timestamps-ahead-of-the-clock).
    pub(super) fn check_time(&self, timestamp_ns: u64) -> Result<(), InputError> {
        if timestamp_ns > MAX_TIMESTAMP_NS {
            return Err(InputError::TimeAhead { timestamp_ns });
        }
        match self.held.as_ref().map(|h| h.timestamp_ns).or(self.last_epoch_ns) {
            Some(last_ns) if timestamp_ns <= last_ns => Err(InputError::OutOfOrder { timestamp_ns, last_ns }),
            _ => Ok(()),
        }
    }
}

/// Motion measured outside Waymark must be finite, with distances and spreads not negative:
/// the transitions take it as it is.
pub(super) fn check_motion(m: &MotionUpdate) -> Result<(), InputError> {
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
