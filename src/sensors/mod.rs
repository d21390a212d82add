//! Inertial sensors → motion: gravity and step detection (Hoang §4, HIPE §3.1), motion state,
//! heading by Kalman fusion of gyroscope and tilt-compensated compass (Hoang §4), and the
//! `MotionTracker` that turns raw batches into one [`MotionUpdate`] per epoch with the MDI
//! scenario of HIPE Table 1.
//!
//! INTERFACE CONTRACT (used by the engine and the HMM; keep these names and meanings):
//! - [`SensorSample`], [`MotionState`], [`MdiScenario`], [`MotionUpdate`], [`BatchReport`].
//! - `MotionTracker::new(MotionConfig) -> Result<MotionTracker, crate::Error>`,
//!   `push_accelerometer / push_gyroscope / push_magnetometer(&mut self, &[SensorSample]) -> BatchReport`,
//!   `update(&mut self, until_ns: u64) -> MotionUpdate`, `stats(&self) -> &MotionStats`.
//!
//! Files: `config.rs` ([`MotionConfig`], every default cited or measured), `filter.rs`
//! (angle wrapping, a moving average over a duration), `step.rs` (gravity learning, the two
//! detectors, the gait check that keeps shaking out), `heading.rs` (tilt-compensated compass,
//! gyro yaw rate, the 1-D Kalman filter, disturbance detection), `tracker.rs`
//! ([`MotionTracker`]: buffering, time ordering, epochs). Their measured accuracy on simulated
//! phones is in `docs/tuning.md#step-detector` and `#heading-filter`.

mod config;
mod filter;
mod heading;
mod step;
mod tracker;

pub use config::{EarthField, MotionConfig, StepDetectorKind, StepLengthModel};
pub use filter::wrap_angle;
pub use heading::{compass_azimuth, field_dip, gyro_yaw_rate};
pub use tracker::{HeadingEstimate, MotionStats, MotionTracker, StepEvent, StreamStats};

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
pub enum MdiScenario {
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

impl MdiScenario {
    /// Every scenario, from the most motion information to the least.
    pub const ALL: [MdiScenario; 4] =
        [MdiScenario::DistanceHeading, MdiScenario::Distance, MdiScenario::HeadingSpeed, MdiScenario::Speed];

    /// Its position in [`ALL`](Self::ALL).
    pub fn index(self) -> usize {
        match self {
            MdiScenario::DistanceHeading => 0,
            MdiScenario::Distance => 1,
            MdiScenario::HeadingSpeed => 2,
            MdiScenario::Speed => 3,
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
    pub scenario: MdiScenario,
    /// Whether the compass was judged disturbed during the interval.
    pub compass_disturbed: bool,
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
}
