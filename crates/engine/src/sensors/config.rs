//! Configuration of the [`MotionTracker`](super::MotionTracker). Every default cites the paper
//! (and equation or table) it comes from, or the docs section holding the measurement that
//! chose it: the tuning sweep on simulated phones (every rate, both detectors, lying still,
//! shaken, walks past steel), one field changed at a time, and real walks, in
//! `docs/tuning.md#step-detector` and `#heading-filter`.

use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Which step detector runs on the smoothed, gravity-free acceleration norm.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StepDetectorKind {
    /// Hoang §4: a step each time the smoothed signal rises above a threshold, re-armed only
    /// after it falls below a lower one (hysteresis), never twice within a minimum interval.
    Threshold,
    /// HIPE §3.1 (peak detection and zero crossing, its refs. 43 and 44): a peak above a threshold
    /// followed by the signal crossing zero downwards; the step is dated at the peak.
    #[default]
    PeakZeroCrossing,
}

/// How long each detected step is.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StepLengthModel {
    /// Every step has the same length (HIPE §3.1, its ref. 45: "an empirically-derived
    /// constant value of the step length (70 cm per step in this paper)").
    Constant {
        /// Step length, m.
        length_m: f64,
    },
    /// Linear in the step frequency f (Hz): `intercept_m + slope_m_per_hz · f`. The frequency
    /// term of Shin et al., "Adaptive step length estimation algorithm using low-cost MEMS
    /// inertial sensors", IEEE SAS 2007 (which adds an acceleration-variance term, dropped
    /// here). Both coefficients are per user: calibrate them on a walk of known length.
    LinearFrequency {
        /// Length at zero frequency, m.
        intercept_m: f64,
        /// Metres per Hz of step frequency.
        slope_m_per_hz: f64,
    },
    /// Weinberg, "Using the ADXL202 in pedometer and personal navigation applications",
    /// Analog Devices AN-602 (2002): `k · (a_max − a_min)^(1/4)` with a the gravity-free
    /// acceleration norm over the step, m/s². `k` is per user.
    Weinberg {
        /// The user's constant, m / (m/s²)^(1/4).
        k: f64,
    },
}

impl Default for StepLengthModel {
    fn default() -> Self {
        StepLengthModel::Constant { length_m: 0.7 }
    }
}

/// The local geomagnetic field, when known (e.g. from the World Magnetic Model for the site).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EarthField {
    /// Total intensity, µT.
    pub magnitude_ut: f64,
    /// Inclination (dip), rad, positive when the field points below the horizon (northern
    /// hemisphere).
    pub dip_rad: f64,
}

/// How the motion tracker turns raw inertial samples into steps, distance and heading. In
/// JSON, missing fields take their defaults.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct MotionConfig {
    /// Which step detector to run. Default: HIPE's peak + zero crossing, which dates steps at
    /// the acceleration peak, and detected more steps than the threshold detector
    /// (docs/tuning.md#step-detector).
    pub step_detector: StepDetectorKind,
    /// How long each step is. Default: constant 0.7 m (HIPE §3.1).
    pub step_length: StepLengthModel,
    /// Magnetic declination at the site, rad, positive east: true azimuth = magnetic azimuth +
    /// declination. Default 0 (unknown; e.g. HIPE §5.1 gives 7°43′ for Helsinki, 2012).
    pub declination_rad: f64,
    /// True azimuth of the site's +y axis, rad clockwise from north. Site-frame heading =
    /// magnetic azimuth + `declination_rad` − `site_rotation_rad`. Default 0 (the site's +y
    /// points to true north).
    pub site_rotation_rad: f64,
    /// The local Earth field, if known; otherwise it is learned as the running median of what
    /// the magnetometer reads (most of a walk is in the undisturbed field). Default `None`.
    pub earth_field: Option<EarthField>,
    /// Gravity assumed until it is learned, m/s². Default 9.81: standard gravity 9.80665 m/s²
    /// (3rd CGPM, 1901), rounded as HIPE eq. 1's ĝ starts before anything is learned.
    pub initial_gravity_mps2: f64,
    /// Length of the blocks over which gravity is learned while stationary, s. Default 1 s
    /// (HIPE §3.1: "the average of the acceleration norm for a certain period, e.g., 1 s").
    pub gravity_window_s: f64,
    /// A block is "still" (gravity is learned from it, and the motion state is stationary)
    /// when the standard deviation of the acceleration norm over it is below this, m/s².
    /// Default 0.3: a walking phone's norm varies by 1-2 m/s² (HIPE Fig. 2), sensor noise and
    /// a steady hand by under 0.1 (docs/tuning.md#step-detector).
    pub still_std_mps2: f64,
    /// Length of the moving average that smooths the gravity-free norm, s. Default 0.25 s
    /// (HIPE §3.1: nine samples at 35 Hz, "roughly 0.25 s"); set in seconds so any sampling
    /// rate and irregular sampling give the same filter.
    pub smoothing_window_s: f64,
    /// Threshold detector: a step when the smoothed signal rises above this, m/s². Default 0.5:
    /// under half of the 1.1 m/s² peak to valley that Zhao et al. (see `min_cadence_hz`)
    /// require of a step on the raw norm, of which a 0.25 s average keeps 57-78 % at
    /// 1.5-2.2 Hz (docs/tuning.md#step-detector).
    pub step_threshold_mps2: f64,
    /// Threshold detector: re-armed when the smoothed signal falls below this, m/s² (the
    /// hysteresis). Default 0, the signal's mean once gravity is removed
    /// (docs/tuning.md#step-detector).
    pub step_rearm_mps2: f64,
    /// Peak detector: the peak between two zero crossings must exceed this, m/s². Default 0.5,
    /// as `step_threshold_mps2` (docs/tuning.md#step-detector).
    pub peak_threshold_mps2: f64,
    /// Both detectors: no two raw detections closer than this, s. Default 0.25 s, the
    /// smoothing window: two detections inside one window are one bump. Kept below the
    /// shortest step (1 / `max_cadence_hz`) so that faster rhythms (shaking) reach the gait
    /// check and are rejected there rather than decimated into a walking-like rhythm
    /// (docs/tuning.md#step-detector).
    pub min_step_interval_s: f64,
    /// Slowest step frequency counted as walking, Hz. Default 1.0: the longest step period of
    /// Zhao et al., "An adaptive step detection algorithm based on the state machine" (China
    /// Satellite Navigation Conference 2018): a step takes between 0.41 s and 1 s. It also
    /// bounds one bump of the signal (from peak to zero crossing, or threshold to re-arm) to
    /// 0.6 of this period: a step's bump is a quarter to half of one, while the norm's slow
    /// swells when shaking last longer.
    pub min_cadence_hz: f64,
    /// Fastest step frequency counted as walking, Hz. Default 2.5: Zhao et al.'s shortest step
    /// period 0.41 s; MacDougall & Moore (J. Appl. Physiol. 99, 2005) found everyday walking at
    /// 2 ± 0.13 Hz (Murray et al.: 1.95 ± 0.19 Hz), so 2.5 Hz is about 3 σ above either. Hand
    /// shaking (3-6 Hz) falls above.
    pub max_cadence_hz: f64,
    /// Consecutive regular steps needed before any is counted (and the person is walking);
    /// they are then all counted. Default 4: the "count regulation" of Analog Devices'
    /// pedometer reference design (N. Zhao, Analog Dialogue 44-06, 2010) likewise waits for
    /// several consecutive valid steps; 4 leaves a margin over the fewest that count no
    /// shaking (docs/tuning.md#step-detector).
    pub confirm_steps: usize,
    /// While confirming, each step period may differ from the mean period of the run by at
    /// most this fraction. Default 0.3: normal gait varies by a few per cent from step to step
    /// (stride-time CV 2-4 %, Hausdorff et al., J. Appl. Physiol. 78, 1995), and a step dated
    /// one sample off at 20 Hz moves a 0.45 s period by 11 %. A margin, not the main defence
    /// against shaking (docs/tuning.md#step-detector).
    pub max_interval_change: f64,
    /// A step whose gravity-free acceleration norm exceeds this anywhere between it and the
    /// previous step is rejected as handling, m/s². Default 25 (≈ 2.5 g). Real phones held
    /// flat show sharp heel-strike spikes that the simulator (and HIPE Fig. 2's ±5 m/s²)
    /// lack; 25 keeps nearly all of them on real walks, where a lower cap broke runs of real
    /// steps (docs/tuning.md#step-detector). Vigorous shaking reaches 10-30 m/s²; the cadence,
    /// regularity and roughness checks reject it.
    pub max_step_acceleration_mps2: f64,
    /// A run of steps is confirmed only if, for each, the peak-to-peak of the raw
    /// gravity-free norm is at most this many times that of the smoothed one ("roughness"):
    /// the 0.25 s average passes a walking rhythm (ratio 1.3-2) and removes the 3-6 Hz of
    /// hand shaking. Not applied to steps within a confirmed run. Default 4: between simulated
    /// walking and shaking, and above the heel-strike spikes of real walks, which broke runs of
    /// real steps at 3 (docs/tuning.md#step-detector).
    pub max_step_roughness: f64,
    /// Time constant of the low-pass filter that takes gravity's direction from the
    /// accelerometer (turned by the gyroscope between samples when there is one), s. Default
    /// 1 s (docs/tuning.md#heading-filter).
    pub gravity_lowpass_s: f64,
    /// One standard deviation of the tilt-compensated compass heading in a clean field, rad.
    /// Default 10°: HIPE Table 2, stationary RMSE 9.5° and 12.2°.
    pub compass_sigma_rad: f64,
    /// Correlation time of compass errors, s: successive compass samples closer than this are
    /// not independent, so each sample's variance is scaled by `correlation / dt` and the
    /// filter's trust in the compass does not depend on the sampling rate. Default 1 s
    /// (docs/tuning.md#heading-filter).
    pub compass_correlation_s: f64,
    /// Growth of the heading variance while integrating the gyroscope, rad/√s: gyro noise,
    /// uncorrected bias and the phone turning in the hand, as a random walk. Default 3°/√s
    /// (docs/tuning.md#heading-filter).
    pub gyro_heading_noise: f64,
    /// Growth of the heading variance without a gyroscope (compass-only mode), rad/√s: how fast
    /// a walker may turn unobserved. Default 30°/√s: a larger one errs little less but loses
    /// the heading in more epochs (docs/tuning.md#heading-filter).
    pub free_heading_noise: f64,
    /// Added in quadrature to the filter's heading sigma: the phone is not exactly aligned
    /// with the direction of walking (the simulator holds it up to 4° off), and the compass
    /// has biases the filter cannot see, rad. Default 3°, which leaves the reported sigma
    /// conservative (docs/tuning.md#heading-filter).
    pub heading_sigma_floor_rad: f64,
    /// Headings less certain than this are not reported (the epoch has no measured heading),
    /// rad. Default 55°: HIPE Table 4, tolerated heading error.
    pub max_heading_sigma_rad: f64,
    /// The compass is disturbed when the field's magnitude differs from the Earth's by more
    /// than this, µT. Default 5 µT, about 10 % of the Earth's 22-67 µT; not less, because a
    /// real magnetometer's calibration leaves a few µT of magnitude error as the phone turns,
    /// which the simulator does not model (docs/tuning.md#heading-filter).
    pub field_tolerance_ut: f64,
    /// The compass is disturbed when the field's dip differs from the Earth's by more than
    /// this, rad. Default 5°: a tighter one trips on the dip of a compass without a gyroscope
    /// to steady gravity (docs/tuning.md#heading-filter).
    pub dip_tolerance_rad: f64,
    /// The compass is disturbed when, over one second, its heading changes by this much more
    /// or less than the gyroscope says the phone turned, rad. Default 10°: a margin for
    /// compass errors the other tests miss (docs/tuning.md#heading-filter).
    pub disagreement_rad: f64,
    /// A disturbance is held for this long after the last sample that showed it, s. Default
    /// 2 s, about two metres of walking (steel disturbs the field over a few metres)
    /// (docs/tuning.md#heading-filter).
    pub disturbance_hold_s: f64,
    /// A disturbed compass sample's variance is multiplied by this. Default 10 000 (σ × 100):
    /// the sample is all but ignored, yet the filter still starts from a disturbed compass
    /// rather than having no heading at all (docs/tuning.md#heading-filter).
    pub disturbed_variance_factor: f64,
    /// Relative standard deviation of the distance walked. Default 0.08: HIPE §5.2 / Table 3,
    /// a generic step length errs by about ±8 % for a specific pedestrian.
    pub distance_sigma_fraction: f64,
    /// A stream gap longer than this resets the filters that depend on continuity and does
    /// not count as covered, s. Default 0.5 s: ten periods of a 20 Hz stream, half the longest
    /// step (1 / `min_cadence_hz`) (docs/tuning.md#step-detector). (A gap longer than the
    /// smoothing window restarts the step detector in any case.)
    pub max_gap_s: f64,
    /// A stream buffered for longer than this without `update` loses its oldest samples
    /// (counted in [`MotionStats`](super::MotionStats)), s. Default 10 s: Android batches
    /// sensor events by up to a few seconds; the engine updates every 1.5 s (Hoang §6.1).
    pub max_backlog_s: f64,
}

impl Default for MotionConfig {
    fn default() -> Self {
        let deg = PI / 180.0;
        Self {
            step_detector: StepDetectorKind::PeakZeroCrossing,
            step_length: StepLengthModel::default(),
            declination_rad: 0.0,
            site_rotation_rad: 0.0,
            earth_field: None,
            initial_gravity_mps2: 9.81,
            gravity_window_s: 1.0,
            still_std_mps2: 0.3,
            smoothing_window_s: 0.25,
            step_threshold_mps2: 0.5,
            step_rearm_mps2: 0.0,
            peak_threshold_mps2: 0.5,
            min_step_interval_s: 0.25,
            min_cadence_hz: 1.0,
            max_cadence_hz: 2.5,
            confirm_steps: 4,
            max_interval_change: 0.3,
            max_step_acceleration_mps2: 25.0,
            max_step_roughness: 4.0,
            gravity_lowpass_s: 1.0,
            compass_sigma_rad: 10.0 * deg,
            compass_correlation_s: 1.0,
            gyro_heading_noise: 3.0 * deg,
            free_heading_noise: 30.0 * deg,
            heading_sigma_floor_rad: 3.0 * deg,
            max_heading_sigma_rad: 55.0 * deg,
            field_tolerance_ut: 5.0,
            dip_tolerance_rad: 5.0 * deg,
            disagreement_rad: 10.0 * deg,
            disturbance_hold_s: 2.0,
            disturbed_variance_factor: 10_000.0,
            distance_sigma_fraction: 0.08,
            max_gap_s: 0.5,
            max_backlog_s: 10.0,
        }
    }
}

/// A [`MotionConfig`] field out of range; the message names the field and the rule. The
/// engine reports it as [`Error::InvalidConfig`](crate::Error::InvalidConfig).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("invalid configuration: {0}")]
pub struct MotionConfigError(pub String);

impl MotionConfig {
    /// Checks every field; the message names the field and the rule.
    pub fn validate(&self) -> Result<(), MotionConfigError> {
        fn positive(name: &str, v: f64) -> Result<(), MotionConfigError> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(MotionConfigError(format!("{name} must be finite and > 0 (got {v})")))
            }
        }
        fn finite(name: &str, v: f64) -> Result<(), MotionConfigError> {
            if v.is_finite() {
                Ok(())
            } else {
                Err(MotionConfigError(format!("{name} must be finite (got {v})")))
            }
        }
        match self.step_length {
            StepLengthModel::Constant { length_m } => positive("step_length.length_m", length_m)?,
            StepLengthModel::LinearFrequency { intercept_m, slope_m_per_hz } => {
                finite("step_length.intercept_m", intercept_m)?;
                finite("step_length.slope_m_per_hz", slope_m_per_hz)?;
            }
            StepLengthModel::Weinberg { k } => positive("step_length.k", k)?,
        }
        finite("declination_rad", self.declination_rad)?;
        finite("site_rotation_rad", self.site_rotation_rad)?;
        if let Some(field) = self.earth_field {
            positive("earth_field.magnitude_ut", field.magnitude_ut)?;
            if !(field.dip_rad.is_finite() && field.dip_rad.abs() <= PI / 2.0) {
                return Err(MotionConfigError(format!(
                    "earth_field.dip_rad must be within ±π/2 (got {})",
                    field.dip_rad
                )));
            }
        }
        positive("initial_gravity_mps2", self.initial_gravity_mps2)?;
        positive("gravity_window_s", self.gravity_window_s)?;
        positive("still_std_mps2", self.still_std_mps2)?;
        positive("smoothing_window_s", self.smoothing_window_s)?;
        positive("step_threshold_mps2", self.step_threshold_mps2)?;
        finite("step_rearm_mps2", self.step_rearm_mps2)?;
        if self.step_rearm_mps2 >= self.step_threshold_mps2 {
            return Err(MotionConfigError(format!(
                "step_rearm_mps2 ({}) must be below step_threshold_mps2 ({})",
                self.step_rearm_mps2, self.step_threshold_mps2
            )));
        }
        positive("peak_threshold_mps2", self.peak_threshold_mps2)?;
        positive("min_step_interval_s", self.min_step_interval_s)?;
        positive("min_cadence_hz", self.min_cadence_hz)?;
        positive("max_cadence_hz", self.max_cadence_hz)?;
        if self.min_cadence_hz >= self.max_cadence_hz {
            return Err(MotionConfigError(format!(
                "min_cadence_hz ({}) must be below max_cadence_hz ({})",
                self.min_cadence_hz, self.max_cadence_hz
            )));
        }
        if !(1..=64).contains(&self.confirm_steps) {
            return Err(MotionConfigError(format!(
                "confirm_steps must be within 1..=64 (got {})",
                self.confirm_steps
            )));
        }
        positive("max_interval_change", self.max_interval_change)?;
        positive("max_step_acceleration_mps2", self.max_step_acceleration_mps2)?;
        positive("max_step_roughness", self.max_step_roughness)?;
        positive("gravity_lowpass_s", self.gravity_lowpass_s)?;
        positive("compass_sigma_rad", self.compass_sigma_rad)?;
        positive("compass_correlation_s", self.compass_correlation_s)?;
        positive("gyro_heading_noise", self.gyro_heading_noise)?;
        positive("free_heading_noise", self.free_heading_noise)?;
        if !(self.heading_sigma_floor_rad.is_finite() && self.heading_sigma_floor_rad >= 0.0) {
            return Err(MotionConfigError(format!(
                "heading_sigma_floor_rad must be finite and >= 0 (got {})",
                self.heading_sigma_floor_rad
            )));
        }
        positive("max_heading_sigma_rad", self.max_heading_sigma_rad)?;
        positive("field_tolerance_ut", self.field_tolerance_ut)?;
        positive("dip_tolerance_rad", self.dip_tolerance_rad)?;
        positive("disagreement_rad", self.disagreement_rad)?;
        if !(self.disturbance_hold_s.is_finite() && self.disturbance_hold_s >= 0.0) {
            return Err(MotionConfigError(format!(
                "disturbance_hold_s must be finite and >= 0 (got {})",
                self.disturbance_hold_s
            )));
        }
        if !(self.disturbed_variance_factor.is_finite() && self.disturbed_variance_factor >= 1.0) {
            return Err(MotionConfigError(format!(
                "disturbed_variance_factor must be finite and >= 1 (got {})",
                self.disturbed_variance_factor
            )));
        }
        if !(self.distance_sigma_fraction.is_finite() && self.distance_sigma_fraction >= 0.0) {
            return Err(MotionConfigError(format!(
                "distance_sigma_fraction must be finite and >= 0 (got {})",
                self.distance_sigma_fraction
            )));
        }
        positive("max_gap_s", self.max_gap_s)?;
        positive("max_backlog_s", self.max_backlog_s)?;
        if self.max_backlog_s > 3600.0 {
            return Err(MotionConfigError(format!(
                "max_backlog_s must be at most 3600 (got {})",
                self.max_backlog_s
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_is_valid_and_bad_fields_are_named() {
        MotionConfig::default().validate().unwrap();
        let bad = MotionConfig { smoothing_window_s: 0.0, ..MotionConfig::default() };
        assert!(bad.validate().unwrap_err().to_string().contains("smoothing_window_s"));
        let bad = MotionConfig {
            step_length: StepLengthModel::Constant { length_m: f64::NAN },
            ..MotionConfig::default()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("step_length.length_m"));
        let bad = MotionConfig { min_cadence_hz: 3.0, ..MotionConfig::default() };
        assert!(bad.validate().unwrap_err().to_string().contains("min_cadence_hz"));
        let bad = MotionConfig { step_rearm_mps2: 1.0, ..MotionConfig::default() };
        assert!(bad.validate().unwrap_err().to_string().contains("step_rearm_mps2"));
        let bad = MotionConfig {
            earth_field: Some(EarthField { magnitude_ut: 50.0, dip_rad: 2.0 }),
            ..MotionConfig::default()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("earth_field.dip_rad"));
        let bad = MotionConfig { confirm_steps: 0, ..MotionConfig::default() };
        assert!(bad.validate().unwrap_err().to_string().contains("confirm_steps"));
    }
}
