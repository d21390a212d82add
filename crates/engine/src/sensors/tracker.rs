//! The [`MotionTracker`]: buffers the three sensor streams, processes them in timestamp order,
//! and summarises each epoch as a [`MotionUpdate`] with its HIPE Table 1 scenario.

use super::config::{MotionConfig, MotionConfigError, StepLengthModel};
use super::filter::{s_to_ns, wrap_angle};
use super::heading::HeadingTracker;
use super::step::{GaitStep, GaitValidator, StepDetector};
use super::{refuse_ahead, BatchReport, MotionScenario, MotionState, MotionUpdate, SensorSample};
use nalgebra::Vector3;
use serde::Serialize;
use std::collections::VecDeque;
use std::f64::consts::PI;

/// Counters of one sensor stream.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct StreamStats {
    /// Samples taken into the buffer.
    pub accepted: u64,
    /// Samples dropped for a NaN, infinite or absurd (> 10⁶ in any unit) value.
    pub non_finite: u64,
    /// Samples dropped for a timestamp not after the stream's previous one, or not after the
    /// end of the last update.
    pub out_of_order: u64,
    /// Samples refused for a timestamp too far ahead of the clock ([`BatchReport::ahead`]).
    pub ahead: u64,
    /// Accepted samples dropped, oldest first, because the stream was buffered for longer than
    /// `max_backlog_s` without an update.
    pub overflowed: u64,
    /// Samples processed by an update.
    pub processed: u64,
}

/// Counters of the tracker.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct MotionStats {
    /// The accelerometer stream.
    pub accelerometer: StreamStats,
    /// The gyroscope stream.
    pub gyroscope: StreamStats,
    /// The magnetometer stream.
    pub magnetometer: StreamStats,
    /// Steps counted so far.
    pub steps_total: u64,
    /// Raw detections the gait check did not count (shaking, handling, stray bumps).
    pub rejected_step_candidates: u64,
}

/// One counted step.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct StepEvent {
    /// When the step happened, ns (it is reported once a run of regular steps confirms it,
    /// up to a few steps later).
    pub timestamp_ns: u64,
    /// Its length by the configured model, m.
    pub length_m: f64,
    /// Heading of travel at that step in the site frame, rad clockwise from +y; `None` when
    /// there was no trustworthy absolute heading then.
    pub heading_rad: Option<f64>,
    /// One standard deviation of the heading at that step, rad.
    pub heading_sigma_rad: f64,
    /// The step's period (time since the previous step), s: what the frequency step-length
    /// model uses, and what calibrating it needs.
    pub period_s: f64,
    /// Peak-to-peak gravity-free acceleration norm over the step, m/s²: what the Weinberg
    /// step-length model uses, and what calibrating it needs.
    pub peak_to_peak_mps2: f64,
}

/// The heading filter's current state, trusted or not.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct HeadingEstimate {
    /// Absolute heading in the site frame, rad clockwise from +y, whatever its uncertainty;
    /// `None` before the first compass sample (or without a magnetometer).
    pub heading_rad: Option<f64>,
    /// One standard deviation of `heading_rad`, rad (π when there is none).
    pub sigma_rad: f64,
    /// Whether `sigma_rad` is within `max_heading_sigma_rad` (HIPE Table 4's 55°).
    pub trusted: bool,
    /// Gyroscope-integrated heading, rad, with an arbitrary origin (the heading change since
    /// the first gyroscope sample); `None` without a gyroscope.
    pub relative_rad: Option<f64>,
    /// Whether the compass is judged disturbed now.
    pub compass_disturbed: bool,
}

/// What the raw step carries through the gait check: the heading when it was detected.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct StepTag {
    magnetic: Option<(f64, f64)>,
}

pub(crate) const ACCEL: usize = 0;
pub(crate) const GYRO: usize = 1;
pub(crate) const MAG: usize = 2;

/// Turns raw accelerometer, gyroscope and magnetometer batches into one [`MotionUpdate`] per
/// epoch. Streams arrive in separate batches in any interleaving; `update(until_ns)` processes
/// every buffered sample up to `until_ns` in timestamp order. Samples that arrive later with a
/// timestamp at or before an `until_ns` already processed are dropped and counted, so call
/// `update` a little behind real time if the platform delivers sensor batches late.
#[derive(Clone, Debug)]
pub struct MotionTracker {
    config: MotionConfig,
    buffers: [VecDeque<SensorSample>; 3],
    last_pushed_ns: [Option<u64>; 3],
    /// Each stream's last sample refused as ahead of the clock, which the next may confirm.
    refused_ahead_ns: [Option<u64>; 3],
    processed_until_ns: Option<u64>,
    max_backlog_ns: u64,
    max_backlog_samples: usize,
    max_gap_ns: u64,
    stats: MotionStats,
    detector: StepDetector,
    gait: GaitValidator<StepTag>,
    heading: HeadingTracker,
    gait_out: Vec<GaitStep<StepTag>>,
    steps: Vec<StepEvent>,
    last_steps: Vec<StepEvent>,
    interval_start_ns: Option<u64>,
    accel_covered_ns: u64,
    last_accel_ns: Option<u64>,
    interval_disturbed: bool,
}

impl MotionTracker {
    /// A tracker; fails with [`MotionConfigError`] naming the bad field.
    pub fn new(config: MotionConfig) -> Result<Self, MotionConfigError> {
        config.validate()?;
        let max_backlog_ns = s_to_ns(config.max_backlog_s);
        // At most 1 kHz per stream is kept.
        let max_backlog_samples = (config.max_backlog_s * 1000.0).ceil().max(16.0) as usize;
        Ok(Self {
            max_backlog_ns,
            max_backlog_samples,
            max_gap_ns: s_to_ns(config.max_gap_s),
            buffers: Default::default(),
            last_pushed_ns: [None; 3],
            refused_ahead_ns: [None; 3],
            processed_until_ns: None,
            stats: MotionStats::default(),
            detector: StepDetector::new(&config),
            gait: GaitValidator::new(&config),
            heading: HeadingTracker::new(&config),
            gait_out: Vec::with_capacity(config.confirm_steps + 2),
            steps: Vec::with_capacity(32),
            last_steps: Vec::new(),
            interval_start_ns: None,
            accel_covered_ns: 0,
            last_accel_ns: None,
            interval_disturbed: false,
            config,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &MotionConfig {
        &self.config
    }

    /// Counters of accepted, dropped and processed samples and of steps.
    pub fn stats(&self) -> &MotionStats {
        &self.stats
    }

    /// Accelerometer samples (m/s², gravity included, phone frame).
    pub fn push_accelerometer(&mut self, batch: &[SensorSample]) -> BatchReport {
        self.push(ACCEL, batch, None)
    }

    /// Gyroscope samples (rad/s, phone frame).
    pub fn push_gyroscope(&mut self, batch: &[SensorSample]) -> BatchReport {
        self.push(GYRO, batch, None)
    }

    /// Magnetometer samples (µT, phone frame, calibrated: Android's `TYPE_MAGNETIC_FIELD`).
    pub fn push_magnetometer(&mut self, batch: &[SensorSample]) -> BatchReport {
        self.push(MAG, batch, None)
    }

    fn stream_stats(&mut self, stream: usize) -> &mut StreamStats {
        match stream {
            ACCEL => &mut self.stats.accelerometer,
            GYRO => &mut self.stats.gyroscope,
            _ => &mut self.stats.magnetometer,
        }
    }

    /// Samples of `stream` (`ACCEL`, `GYRO`, `MAG`); `clock_ns`, the time of the latest input
    /// taken outside the tracker (an engine's epochs), joins its own streams' in the clock a
    /// sample may not run ahead of by more than `max_backlog_s`: the tracker holds no more of
    /// a stream than that (docs/errors.md#timestamps-ahead-of-the-clock).
    pub(crate) fn push(
        &mut self,
        stream: usize,
        batch: &[SensorSample],
        clock_ns: Option<u64>,
    ) -> BatchReport {
        let mut report = BatchReport::default();
        let mut clock_ns =
            self.last_pushed_ns.iter().chain([&self.processed_until_ns, &clock_ns]).flatten().max().copied();
        for s in batch {
            if !s.is_plausible() {
                report.non_finite += 1;
                continue;
            }
            let after_previous = self.last_pushed_ns[stream].is_none_or(|p| s.timestamp_ns > p);
            let after_processed = self.processed_until_ns.is_none_or(|p| s.timestamp_ns > p);
            if !(after_previous && after_processed) {
                report.out_of_order += 1;
                continue;
            }
            if refuse_ahead(s.timestamp_ns, clock_ns, self.max_backlog_ns, self.refused_ahead_ns[stream]) {
                self.refused_ahead_ns[stream] = Some(s.timestamp_ns);
                report.ahead += 1;
                continue;
            }
            self.refused_ahead_ns[stream] = None;
            self.last_pushed_ns[stream] = Some(s.timestamp_ns);
            clock_ns = Some(clock_ns.map_or(s.timestamp_ns, |c| c.max(s.timestamp_ns)));
            self.buffers[stream].push_back(*s);
            report.accepted += 1;
        }
        if report.ahead > 0 {
            log::debug!(
                "sensor stream {stream}: {} samples refused, too far ahead of the clock",
                report.ahead
            );
        }
        let mut overflowed = 0;
        let buffer = &mut self.buffers[stream];
        while let (Some(first), Some(last)) = (buffer.front(), buffer.back()) {
            if buffer.len() > self.max_backlog_samples
                || last.timestamp_ns - first.timestamp_ns > self.max_backlog_ns
            {
                buffer.pop_front();
                overflowed += 1;
            } else {
                break;
            }
        }
        if overflowed > 0 {
            log::debug!("sensor stream {stream}: {overflowed} samples dropped, backlog too long");
        }
        let stats = self.stream_stats(stream);
        stats.accepted += report.accepted as u64;
        stats.non_finite += report.non_finite as u64;
        stats.out_of_order += report.out_of_order as u64;
        stats.ahead += report.ahead as u64;
        stats.overflowed += overflowed;
        report
    }

    fn site_heading(&self, magnetic: f64) -> f64 {
        wrap_angle(magnetic + self.config.declination_rad - self.config.site_rotation_rad)
    }

    fn step_length(&self, step: &GaitStep<StepTag>) -> f64 {
        let length = match self.config.step_length {
            StepLengthModel::Constant { length_m } => length_m,
            StepLengthModel::LinearFrequency { intercept_m, slope_m_per_hz } => {
                let f = (1.0 / step.period_s).clamp(self.config.min_cadence_hz, self.config.max_cadence_hz);
                intercept_m + slope_m_per_hz * f
            }
            StepLengthModel::Weinberg { k } => k * step.peak_to_peak.powf(0.25),
        };
        length.clamp(0.05, 2.5)
    }

    fn process(&mut self, stream: usize, s: SensorSample) {
        let t = s.timestamp_ns;
        let v = Vector3::new(s.x, s.y, s.z);
        self.stream_stats(stream).processed += 1;
        match stream {
            ACCEL => {
                let start = self.interval_start_ns.unwrap_or(t);
                if let Some(prev) = self.last_accel_ns {
                    let from = prev.max(start);
                    if t > from && t - prev <= self.max_gap_ns {
                        self.accel_covered_ns += t - from;
                    }
                }
                self.last_accel_ns = Some(t);
                self.heading.on_accelerometer(t, v);
                self.gait.tick(t);
                if let Some(raw) = self.detector.push(t, v.norm()) {
                    let tag = StepTag { magnetic: self.heading.state(t).magnetic };
                    let mut out = std::mem::take(&mut self.gait_out);
                    self.gait.offer(raw, tag, &mut out);
                    for step in out.drain(..) {
                        let length_m = self.step_length(&step);
                        let (heading_rad, heading_sigma_rad) = match step.tag.magnetic {
                            Some((yaw, sigma)) if sigma <= self.config.max_heading_sigma_rad => {
                                (Some(self.site_heading(yaw)), sigma)
                            }
                            Some((_, sigma)) => (None, sigma),
                            None => (None, PI),
                        };
                        self.steps.push(StepEvent {
                            timestamp_ns: step.t_ns,
                            length_m,
                            heading_rad,
                            heading_sigma_rad,
                            period_s: step.period_s,
                            peak_to_peak_mps2: step.peak_to_peak,
                        });
                    }
                    self.gait_out = out;
                }
            }
            GYRO => self.heading.on_gyroscope(t, v),
            _ => {
                if self.heading.on_magnetometer(t, v) {
                    self.interval_disturbed = true;
                }
            }
        }
    }

    /// Processes every buffered sample with a timestamp ≤ `until_ns`, in timestamp order, and
    /// reports what happened since the previous update. An `until_ns` before the previous one
    /// is taken as the previous one (an empty interval).
    pub fn update(&mut self, until_ns: u64) -> MotionUpdate {
        let (start, until) = self.process_until(until_ns);
        let steps = std::mem::take(&mut self.steps);
        let update = self.summarise(start, until, &steps);
        self.stats.steps_total += steps.len() as u64;
        self.last_steps = steps;
        self.steps = Vec::with_capacity(32);
        self.interval_start_ns = Some(until);
        self.accel_covered_ns = 0;
        self.interval_disturbed = false;
        update
    }

    /// What happened since the previous [`update`](Self::update) up to `until_ns`, as
    /// `update` would report it, with the interval left open: the next `update` reports all
    /// of it again, to its own end.
    pub fn peek(&mut self, until_ns: u64) -> MotionUpdate {
        let (start, until) = self.process_until(until_ns);
        let steps = std::mem::take(&mut self.steps);
        let update = self.summarise(start, until, &steps);
        self.steps = steps;
        update
    }

    /// Processes every buffered sample up to `until_ns` (see [`update`](Self::update)):
    /// the interval's start and end.
    fn process_until(&mut self, until_ns: u64) -> (u64, u64) {
        let earliest = self.buffers.iter().filter_map(|b| b.front().map(|s| s.timestamp_ns)).min();
        let start = self
            .interval_start_ns
            .or(self.processed_until_ns)
            .unwrap_or(earliest.unwrap_or(until_ns).min(until_ns));
        self.interval_start_ns = Some(start);
        let until = until_ns.max(start).max(self.processed_until_ns.unwrap_or(0));
        loop {
            let mut best: Option<(usize, u64)> = None;
            for (k, buffer) in self.buffers.iter().enumerate() {
                if let Some(s) = buffer.front() {
                    if s.timestamp_ns <= until && best.is_none_or(|(_, t)| s.timestamp_ns < t) {
                        best = Some((k, s.timestamp_ns));
                    }
                }
            }
            let Some((k, _)) = best else { break };
            if let Some(s) = self.buffers[k].pop_front() {
                self.process(k, s);
            }
        }
        self.gait.tick(until);
        self.processed_until_ns = Some(until);
        (start, until)
    }

    /// The interval from `start` to `end` with its `steps`.
    fn summarise(&mut self, start: u64, end: u64, steps: &[StepEvent]) -> MotionUpdate {
        let c = &self.config;
        // Accelerometer coverage of the interval, counting the tail up to `end`.
        let mut covered = self.accel_covered_ns;
        let accel_alive = self.last_accel_ns.is_some_and(|l| end.saturating_sub(l) <= self.max_gap_ns);
        if let Some(l) = self.last_accel_ns {
            if accel_alive && end > l.max(start) {
                covered += end - l.max(start);
            }
        }
        let covered_enough =
            if end > start { covered as f64 >= 0.5 * (end - start) as f64 } else { accel_alive };
        let distance: f64 = steps.iter().map(|s| s.length_m).sum();
        let distance_m = covered_enough.then_some(distance);
        let walking = self.gait.walking() && !self.detector.gravity().still();
        let motion_state = if self.last_accel_ns.is_none_or_stale(end, 4 * self.max_gap_ns) {
            MotionState::Unknown
        } else if walking {
            MotionState::Walking
        } else {
            MotionState::Stationary
        };
        let nominal = match c.step_length {
            StepLengthModel::Constant { length_m } => length_m,
            _ if !steps.is_empty() => distance / steps.len() as f64,
            _ => 0.7,
        };
        // HIPE Table 3's relative error, plus where within a step each end of the interval
        // falls (uniform over a step: variance L²/12 each) while walking.
        let boundary = if walking || !steps.is_empty() { nominal * nominal / 6.0 } else { 0.0 };
        let distance_sigma_m = if distance_m.is_some() {
            ((c.distance_sigma_fraction * distance).powi(2) + boundary).sqrt()
        } else {
            0.0
        };

        let state = self.heading.state(end);
        let now = state
            .magnetic
            .map(|(yaw, sigma)| (self.site_heading(yaw), sigma))
            .filter(|&(_, sigma)| sigma <= c.max_heading_sigma_rad);
        // Direction of travel: the mean of the steps' headings (weighted by length), which is
        // the direction of the net displacement; without steps, where the phone points.
        let mut heading = now;
        let mut displacement = None;
        if distance_m.is_some() {
            let mut sum = [0.0, 0.0];
            let mut worst = now.map_or(0.0, |h| h.1);
            let mut known = true;
            for s in steps {
                match s.heading_rad.map(|h| (h, s.heading_sigma_rad)).or(now) {
                    Some((h, sigma)) => {
                        sum[0] += s.length_m * h.sin();
                        sum[1] += s.length_m * h.cos();
                        worst = worst.max(sigma);
                    }
                    None => known = false,
                }
            }
            if known && (now.is_some() || !steps.is_empty()) {
                displacement = Some(sum);
                if sum[0].hypot(sum[1]) > 0.5 * distance && distance > 0.0 {
                    heading = Some((sum[0].atan2(sum[1]), worst));
                }
            }
        }
        let (heading_rad, heading_sigma_rad) = match heading {
            Some((h, sigma)) => (Some(h), sigma),
            None => (None, PI),
        };
        let scenario = match (distance_m.is_some(), heading_rad.is_some()) {
            (true, true) => MotionScenario::DistanceHeading,
            (true, false) => MotionScenario::Distance,
            (false, true) => MotionScenario::HeadingSpeed,
            (false, false) => MotionScenario::Speed,
        };
        self.stats.rejected_step_candidates = self.gait.rejected();
        MotionUpdate {
            start_ns: start,
            end_ns: end,
            steps: steps.len() as u32,
            distance_m,
            distance_sigma_m,
            heading_rad,
            heading_sigma_rad,
            displacement_m: if heading_rad.is_some() { displacement } else { None },
            motion_state,
            scenario,
            compass_disturbed: self.interval_disturbed
                || (self.heading.disturbed() && self.heading.compass_alive(end)),
        }
    }

    /// The steps counted by the most recent [`update`](Self::update), with their times.
    pub fn last_steps(&self) -> &[StepEvent] {
        &self.last_steps
    }

    /// The heading filter's state as of the most recent update, trusted or not (for
    /// diagnostics and evaluation; `MotionUpdate` only carries trustworthy headings).
    pub fn heading_estimate(&self) -> HeadingEstimate {
        let t = self.processed_until_ns.unwrap_or(0);
        let state = self.heading.state(t);
        let (heading_rad, sigma_rad) = match state.magnetic {
            Some((yaw, sigma)) => (Some(self.site_heading(yaw)), sigma),
            None => (None, PI),
        };
        HeadingEstimate {
            heading_rad,
            sigma_rad,
            trusted: heading_rad.is_some() && sigma_rad <= self.config.max_heading_sigma_rad,
            relative_rad: state.relative,
            compass_disturbed: self.heading.disturbed() && self.heading.compass_alive(t),
        }
    }

    /// The motion state as of the most recent update.
    pub fn motion_state(&self) -> MotionState {
        let t = self.processed_until_ns.unwrap_or(0);
        if self.last_accel_ns.is_none_or_stale(t, 4 * self.max_gap_ns) {
            MotionState::Unknown
        } else if self.gait.walking() && !self.detector.gravity().still() {
            MotionState::Walking
        } else {
            MotionState::Stationary
        }
    }
}

/// Staleness of an optional timestamp.
trait Staleness {
    fn is_none_or_stale(&self, now: u64, limit: u64) -> bool;
}

impl Staleness for Option<u64> {
    fn is_none_or_stale(&self, now: u64, limit: u64) -> bool {
        self.is_none_or(|t| now.saturating_sub(t) > limit)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t: u64, x: f64, y: f64, z: f64) -> SensorSample {
        SensorSample { timestamp_ns: t, x, y, z }
    }

    #[test]
    fn bad_config_is_rejected_by_name() {
        let e = MotionTracker::new(MotionConfig { max_gap_s: -1.0, ..MotionConfig::default() }).unwrap_err();
        assert!(e.to_string().contains("max_gap_s"));
    }

    #[test]
    fn bad_samples_are_dropped_and_counted() {
        let mut m = MotionTracker::new(MotionConfig::default()).unwrap();
        let r = m.push_accelerometer(&[
            sample(10, 0.0, 0.0, 9.81),
            sample(20, f64::NAN, 0.0, 9.81),
            sample(20, 0.0, f64::INFINITY, 9.81),
            sample(5, 0.0, 0.0, 9.81),
            sample(10, 0.0, 0.0, 9.81),
            sample(30, 0.0, 0.0, 1e300),
            sample(40, 0.0, 0.0, 9.81),
        ]);
        assert_eq!(r, BatchReport { accepted: 2, non_finite: 3, out_of_order: 2, ahead: 0 });
        assert_eq!(m.push_gyroscope(&[]), BatchReport::default());
        let u = m.update(35);
        assert_eq!(u.steps, 0);
        // 40 is still buffered; 30 is now older than what was processed.
        let r = m.push_accelerometer(&[sample(30, 0.0, 0.0, 9.81), sample(50, 0.0, 0.0, 9.81)]);
        assert_eq!(r, BatchReport { accepted: 1, non_finite: 0, out_of_order: 1, ahead: 0 });
        m.update(100);
        assert_eq!(m.stats().accelerometer.processed, 3);
        assert_eq!(m.stats().accelerometer.non_finite, 3);
        assert_eq!(m.stats().accelerometer.out_of_order, 3);
    }

    #[test]
    fn backlog_is_bounded() {
        let config = MotionConfig { max_backlog_s: 1.0, ..MotionConfig::default() };
        let mut m = MotionTracker::new(config).unwrap();
        let batch: Vec<_> = (0..500u64).map(|k| sample(k * 10_000_000, 0.0, 0.0, 9.81)).collect();
        m.push_accelerometer(&batch);
        assert_eq!(m.stats().accelerometer.accepted, 500);
        assert_eq!(m.stats().accelerometer.overflowed, 399);
        m.update(10_000_000_000);
        assert_eq!(m.stats().accelerometer.processed, 101);
    }

    #[test]
    fn streams_interleave_in_time_order_and_later_samples_wait() {
        let mut m = MotionTracker::new(MotionConfig::default()).unwrap();
        let acc: Vec<_> = (1..=300u64).map(|k| sample(k * 10_000_000, 0.0, 0.0, 9.81)).collect();
        let mag: Vec<_> =
            (1..=300u64).map(|k| sample(k * 10_000_000 + 5_000_000, 0.0, 20.0, -45.0)).collect();
        // Magnetometer first, in two batches around the accelerometer.
        m.push_magnetometer(&mag[..150]);
        m.push_accelerometer(&acc);
        m.push_magnetometer(&mag[150..]);
        let u = m.update(1_500_000_000);
        assert_eq!(m.stats().accelerometer.processed, 150);
        assert_eq!(m.stats().magnetometer.processed, 149);
        assert_eq!(u.distance_m, Some(0.0));
        assert_eq!(u.displacement_m, Some([0.0, 0.0]));
        assert_eq!(u.motion_state, MotionState::Stationary);
        assert_eq!(u.scenario, MotionScenario::DistanceHeading);
        // Flat, field to +y: heading north = site +y with zero declination and rotation.
        assert!(u.heading_rad.unwrap().abs() < 1e-6);
        let u = m.update(3_000_000_000);
        assert_eq!(m.stats().accelerometer.processed, 300);
        assert_eq!(u.start_ns, 1_500_000_000);
        // Nothing more: no coverage, no distance.
        let u = m.update(6_000_000_000);
        assert_eq!(u.distance_m, None);
        assert_eq!(u.motion_state, MotionState::Unknown);
        // Time going backwards in update: an empty interval at the last time.
        let u = m.update(1);
        assert_eq!((u.start_ns, u.end_ns), (6_000_000_000, 6_000_000_000));
    }

    #[test]
    fn step_length_models() {
        let step = GaitStep { t_ns: 0, period_s: 0.5, peak_to_peak: 16.0, tag: StepTag::default() };
        let with = |step_length| {
            MotionTracker::new(MotionConfig { step_length, ..MotionConfig::default() }).unwrap()
        };
        assert_eq!(with(StepLengthModel::default()).step_length(&step), 0.7);
        // 0.2 + 0.25 m/Hz × 2 Hz.
        let linear = StepLengthModel::LinearFrequency { intercept_m: 0.2, slope_m_per_hz: 0.25 };
        assert!((with(linear).step_length(&step) - 0.7).abs() < 1e-12);
        // 0.4 × 16^(1/4) = 0.8.
        let weinberg = StepLengthModel::Weinberg { k: 0.4 };
        assert!((with(weinberg).step_length(&step) - 0.8).abs() < 1e-12);
        // A 10 Hz "period" is clamped to the fastest cadence, 2.5 Hz.
        let fast = GaitStep { period_s: 0.1, ..step };
        assert!((with(linear).step_length(&fast) - 0.825).abs() < 1e-12);
    }

    #[test]
    fn declination_and_site_rotation_are_applied() {
        let config = MotionConfig { declination_rad: 0.1, site_rotation_rad: 0.4, ..MotionConfig::default() };
        let mut m = MotionTracker::new(config).unwrap();
        let acc: Vec<_> = (1..=100u64).map(|k| sample(k * 10_000_000, 0.0, 0.0, 9.81)).collect();
        let mag: Vec<_> = (1..=100u64).map(|k| sample(k * 10_000_000, 0.0, 20.0, -45.0)).collect();
        m.push_accelerometer(&acc);
        m.push_magnetometer(&mag);
        let u = m.update(1_000_000_000);
        // Magnetic azimuth 0 → true 0.1 → site 0.1 − 0.4.
        assert!((u.heading_rad.unwrap() - (-0.3)).abs() < 1e-6, "{:?}", u.heading_rad);
    }
}
