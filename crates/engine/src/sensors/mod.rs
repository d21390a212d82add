//! Inertial sensors → motion: gravity and step detection (Hoang §4, HIPE §3.1), motion state,
//! heading by Kalman fusion of gyroscope and tilt-compensated compass (Hoang §4), and the
//! `MotionTracker` that turns raw batches into one [`MotionUpdate`] per epoch with the MDI
//! scenario of HIPE Table 1.
//!
//! INTERFACE CONTRACT (used by the engine and the HMM; keep these names and meanings):
//! - [`SensorSample`], [`MotionState`], [`MotionScenario`], [`MotionUpdate`], [`BatchReport`].
//! - `MotionTracker::new(MotionConfig) -> Result<MotionTracker, MotionConfigError>`,
//!   `push_accelerometer / push_gyroscope / push_magnetometer(&mut self, &[SensorSample]) -> BatchReport`,
//!   `update(&mut self, until_ns: u64) -> MotionUpdate`, `stats(&self) -> &MotionStats`.
//!
//! Files: `config.rs` ([`MotionConfig`], every default cited or measured, and
//! [`MotionConfigError`]), `filter.rs` (angle wrapping, a moving average over a duration),
//! `step.rs` (gravity learning, the two detectors, the gait check that keeps shaking out),
//! `heading.rs` (tilt-compensated compass, gyro yaw rate, the 1-D Kalman filter, disturbance
//! detection), `tracker.rs` ([`MotionTracker`]: buffering, time ordering, epochs). Their
//! measured accuracy on simulated phones is in `docs/tuning.md#step-detector` and
//! `#heading-filter`.

mod barometer;
mod clock;
mod config;
mod filter;
mod heading;
mod step;
mod tracker;

pub(crate) use barometer::Barometer;
pub use barometer::{pressure_height_m, PressureSample};
pub(crate) use clock::refuse_ahead;
pub use clock::MAX_TIMESTAMP_NS;
pub use config::{EarthField, MotionConfig, MotionConfigError, StepDetectorKind, StepLengthModel};
pub use filter::wrap_angle;
pub use heading::{compass_azimuth, gyro_yaw_rate};
pub use tracker::{HeadingEstimate, MotionStats, MotionTracker, StepEvent, StreamStats};
pub(crate) use tracker::{ACCEL, GYRO, MAG};

use serde::{Deserialize, Serialize};

/// One sample of a three-axis sensor in the phone's frame (Android's axes: x right, y up the
/// screen, z out of the screen). Units: m/s² (accelerometer, gravity included), rad/s
/// (gyroscope), µT (magnetometer).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SensorSample {
    /// Monotonic time, ns, on the same clock as scans.
    pub timestamp_ns: u64,
    /// x axis.
    pub x: f64,
    /// y axis.
    pub y: f64,
    /// z axis.
    pub z: f64,
}

/// Largest magnitude a sensor value may have in any unit used here (m/s², rad/s, µT).
const ABSURD: f64 = 1e6;

impl SensorSample {
    /// Whether every axis is finite and no larger than any sensor reports (1e6 in m/s², rad/s
    /// or µT): what the motion tracker and the survey recorder take; other samples are dropped
    /// and counted.
    pub fn is_plausible(&self) -> bool {
        [self.x, self.y, self.z].iter().all(|v| v.is_finite() && v.abs() <= ABSURD)
    }
}

/// Whether the person is walking.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MotionState {
    /// No accelerometer data to tell.
    #[default]
    Unknown,
    /// Standing or sitting still (the phone may still be handled).
    Stationary,
    /// Walking: steps are being detected.
    Walking,
}

/// HIPE Table 1: which motion information (MDI) an epoch has.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MotionScenario {
    /// Measured distance (steps × step length) and measured absolute heading.
    DistanceHeading,
    /// Measured distance, heading unknown.
    Distance,
    /// Measured heading, distance from an assumed maximum speed.
    HeadingSpeed,
    /// Neither: an assumed maximum speed only.
    #[default]
    Speed,
}

impl MotionScenario {
    /// Every scenario, from the most motion information to the least.
    pub const ALL: [MotionScenario; 4] = [
        MotionScenario::DistanceHeading,
        MotionScenario::Distance,
        MotionScenario::HeadingSpeed,
        MotionScenario::Speed,
    ];

    /// Its position in [`ALL`](Self::ALL).
    pub fn index(self) -> usize {
        match self {
            MotionScenario::DistanceHeading => 0,
            MotionScenario::Distance => 1,
            MotionScenario::HeadingSpeed => 2,
            MotionScenario::Speed => 3,
        }
    }
}

/// What the inertial sensors say happened between two epochs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MotionUpdate {
    /// Start of the interval (the previous update), ns.
    pub start_ns: u64,
    /// End of the interval, ns.
    pub end_ns: u64,
    /// Steps detected in the interval.
    pub steps: u32,
    /// Path length walked (sum of step lengths), m; `None` without accelerometer coverage.
    pub distance_m: Option<f64>,
    /// One standard deviation of `distance_m`, m.
    pub distance_sigma_m: f64,
    /// Absolute heading of travel in the site frame, radians clockwise from the site's +y axis
    /// (declination and site rotation applied); `None` when no trustworthy absolute heading.
    pub heading_rad: Option<f64>,
    /// One standard deviation of `heading_rad`, rad.
    pub heading_sigma_rad: f64,
    /// Net displacement (Δx, Δy) in the site frame, m: the movement vector of Hoang eq. 11;
    /// `None` unless both distance and heading are known.
    pub displacement_m: Option<[f64; 2]>,
    /// Motion state at the end of the interval.
    pub motion_state: MotionState,
    /// The HIPE scenario this interval supports.
    pub scenario: MotionScenario,
    /// Whether the compass was judged disturbed during the interval.
    pub compass_disturbed: bool,
}

impl MotionUpdate {
    /// The motion of this interval and of `next`, the one right after it, as one interval:
    /// how an engine carries a motion-only epoch it holds back into the next one
    /// ([`EngineConfig::min_motion_step_s`](crate::EngineConfig::min_motion_step_s)).
    /// Steps, distances and displacements add up, the distance spreads in quadrature (the
    /// parts' errors taken as independent), and the heading is the summed displacement's
    /// direction when the path was straight enough to have one (the tracker's rule: net
    /// displacement over half the distance), else the latest heading, with the larger spread
    /// of the parts. A distance is known when the parts that know it span at least half of
    /// the interval; a part with none walked adds no displacement.
    pub fn then(&self, next: &MotionUpdate) -> MotionUpdate {
        let parts = [self, next];
        let span = |m: &MotionUpdate| m.end_ns.saturating_sub(m.start_ns) as f64;
        let known: Vec<&MotionUpdate> = parts.into_iter().filter(|m| m.distance_m.is_some()).collect();
        let known_span: f64 = known.iter().map(|m| span(m)).sum();
        let distance_m = (!known.is_empty() && 2.0 * known_span >= span(self) + span(next))
            .then(|| known.iter().filter_map(|m| m.distance_m).sum::<f64>());
        let distance_sigma_m = known.iter().map(|m| m.distance_sigma_m.powi(2)).sum::<f64>().sqrt();
        // A part without a displacement only counts as none moved if it walked nothing.
        let moved = |m: &MotionUpdate| m.displacement_m.or((m.distance_m == Some(0.0)).then_some([0.0, 0.0]));
        let displacement = match (moved(self), moved(next)) {
            (Some(a), Some(b)) if self.displacement_m.is_some() || next.displacement_m.is_some() => {
                Some([a[0] + b[0], a[1] + b[1]])
            }
            _ => None,
        };
        let latest = next.heading_rad.map(|h| (h, next.heading_sigma_rad));
        let latest = latest.or(self.heading_rad.map(|h| (h, self.heading_sigma_rad)));
        let widest =
            parts.iter().filter(|m| m.heading_rad.is_some()).map(|m| m.heading_sigma_rad).fold(0.0, f64::max);
        let heading = match (displacement, distance_m) {
            (Some(d), Some(walked)) if walked > 0.0 && d[0].hypot(d[1]) > 0.5 * walked => {
                Some((d[0].atan2(d[1]), widest))
            }
            _ => latest,
        };
        let scenario = match (distance_m.is_some(), heading.is_some()) {
            (true, true) => MotionScenario::DistanceHeading,
            (true, false) => MotionScenario::Distance,
            (false, true) => MotionScenario::HeadingSpeed,
            (false, false) => MotionScenario::Speed,
        };
        MotionUpdate {
            start_ns: self.start_ns,
            end_ns: next.end_ns,
            steps: self.steps.saturating_add(next.steps),
            distance_m,
            distance_sigma_m: if distance_m.is_some() { distance_sigma_m } else { 0.0 },
            heading_rad: heading.map(|h| h.0),
            heading_sigma_rad: heading.map_or(std::f64::consts::PI, |h| h.1),
            displacement_m: displacement.filter(|_| heading.is_some() && distance_m.is_some()),
            motion_state: next.motion_state,
            scenario,
            compass_disturbed: self.compass_disturbed || next.compass_disturbed,
        }
    }
}

/// What happened to one pushed batch.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BatchReport {
    /// Samples taken.
    pub accepted: usize,
    /// Samples dropped for a NaN or infinite value.
    pub non_finite: usize,
    /// Samples dropped for a timestamp not after the stream's previous sample, or older than
    /// what the tracker has already processed.
    pub out_of_order: usize,
    /// Samples refused for a timestamp too far ahead of the clock: past
    /// [`MAX_TIMESTAMP_NS`], or more than `max_backlog_s` after the latest input taken, unless
    /// the stream's next sample confirms the jump (docs/errors.md#timestamps-ahead-of-the-clock).
    pub ahead: usize,
}

impl MotionUpdate {
    /// What is left of this motion after `earlier`, which begins where it does and ends
    /// before it ([`then`](Self::then) undone): steps, distance and displacement less
    /// `earlier`'s, the distance spread less `earlier`'s in quadrature, and the heading the
    /// remaining displacement's when the path left was straight enough to have one, else this
    /// motion's.
    pub fn after(&self, earlier: &MotionUpdate) -> MotionUpdate {
        let distance_m = match (self.distance_m, earlier.distance_m) {
            (Some(all), Some(before)) => Some((all - before).max(0.0)),
            (all, _) => all,
        };
        let displacement = match (self.displacement_m, earlier.displacement_m) {
            (Some(all), Some(before)) => Some([all[0] - before[0], all[1] - before[1]]),
            (all, _) => all,
        };
        let heading = match (displacement, distance_m) {
            (Some(d), Some(walked)) if walked > 0.0 && d[0].hypot(d[1]) > 0.5 * walked => {
                Some(d[0].atan2(d[1]))
            }
            _ => self.heading_rad,
        };
        MotionUpdate {
            start_ns: earlier.end_ns,
            steps: self.steps.saturating_sub(earlier.steps),
            distance_m,
            distance_sigma_m: (self.distance_sigma_m.powi(2) - earlier.distance_sigma_m.powi(2))
                .max(0.0)
                .sqrt(),
            heading_rad: heading,
            displacement_m: displacement.filter(|_| heading.is_some()),
            ..self.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

    fn part(start_s: u64, distance_m: Option<f64>, heading_rad: f64) -> MotionUpdate {
        let d = distance_m.unwrap_or(0.0);
        MotionUpdate {
            start_ns: start_s * 1_000_000_000,
            end_ns: (start_s + 1) * 1_000_000_000,
            steps: 2,
            distance_m,
            distance_sigma_m: if distance_m.is_some() { 0.3 } else { 0.0 },
            heading_rad: Some(heading_rad),
            heading_sigma_rad: 0.1 + heading_rad.abs() / 10.0,
            displacement_m: distance_m.map(|_| [d * heading_rad.sin(), d * heading_rad.cos()]),
            motion_state: MotionState::Walking,
            scenario: if distance_m.is_some() {
                MotionScenario::DistanceHeading
            } else {
                MotionScenario::HeadingSpeed
            },
            compass_disturbed: false,
        }
    }

    /// Two legs at right angles: the distance is both, the heading the net displacement's,
    /// with the wider spread; the distance spreads add in quadrature.
    #[test]
    fn consecutive_motion_adds_up() {
        let (north, east) = (part(0, Some(3.0), 0.0), part(1, Some(3.0), FRAC_PI_2));
        let both = north.then(&east);
        assert_eq!((both.start_ns, both.end_ns, both.steps), (0, 2_000_000_000, 4));
        assert_eq!(both.distance_m, Some(6.0));
        assert!((both.distance_sigma_m - 0.3 * 2f64.sqrt()).abs() < 1e-12);
        let d = both.displacement_m.unwrap();
        assert!((d[0] - 3.0).abs() < 1e-12 && (d[1] - 3.0).abs() < 1e-12, "{d:?}");
        assert!((both.heading_rad.unwrap() - FRAC_PI_4).abs() < 1e-12);
        assert!((both.heading_sigma_rad - (0.1 + FRAC_PI_2 / 10.0)).abs() < 1e-12);
        assert_eq!(both.scenario, MotionScenario::DistanceHeading);
        // Out and back: no direction of travel, so the latest heading.
        let back = north.then(&part(1, Some(3.0), PI));
        assert!(back.displacement_m.unwrap()[1].abs() < 1e-12);
        assert_eq!(back.heading_rad, Some(PI));
    }

    /// A distance is known over the whole when it is known over at least half of it; then
    /// there is no displacement for the part that did not measure one.
    #[test]
    fn a_part_without_a_distance_is_counted_by_its_span() {
        let known = part(0, Some(2.0), 0.0);
        let unknown = part(1, None, 0.0);
        let half = known.then(&unknown);
        assert_eq!((half.distance_m, half.displacement_m), (Some(2.0), None));
        assert_eq!(half.scenario, MotionScenario::DistanceHeading);
        let longer = MotionUpdate { end_ns: 4_000_000_000, ..unknown.clone() };
        let mostly_unknown = known.then(&longer);
        assert_eq!((mostly_unknown.distance_m, mostly_unknown.distance_sigma_m), (None, 0.0));
        assert_eq!(mostly_unknown.scenario, MotionScenario::HeadingSpeed);
        // Standing still measures no displacement without a heading, and moves nothing.
        let still =
            MotionUpdate { distance_m: Some(0.0), heading_rad: None, displacement_m: None, ..known.clone() };
        assert_eq!(still.then(&known).displacement_m, known.displacement_m);
    }

    /// `after` undoes `then`: the part after the first leg is the second leg.
    #[test]
    fn after_undoes_then() {
        let (north, east) = (part(0, Some(3.0), 0.0), part(1, Some(3.0), FRAC_PI_2));
        let rest = north.then(&east).after(&north);
        assert_eq!((rest.start_ns, rest.end_ns, rest.steps), (east.start_ns, east.end_ns, 2));
        assert_eq!(rest.distance_m, Some(3.0));
        let d = rest.displacement_m.unwrap();
        assert!((d[0] - 3.0).abs() < 1e-12 && d[1].abs() < 1e-12, "{d:?}");
        assert!((rest.heading_rad.unwrap() - FRAC_PI_2).abs() < 1e-12);
        assert!((rest.distance_sigma_m - 0.3).abs() < 1e-12);
    }
}
