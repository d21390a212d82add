//! Engine configuration. Every default cites the paper (and equation or table) it comes from,
//! or the docs section (docs/tuning.md) holding the measurement that chose it.

use crate::error::Error;
use crate::habits::HabitOptions;
use crate::sensors::{MotionConfig, StepLengthModel};
use serde::{Deserialize, Serialize};

/// The step lengths an app may give as its user's own (`step_length_override` as a constant,
/// the FFI's `step_length_m`), m: wider than any walking step (about 0.3 m for a small child
/// to about 1 m for a long stride), so only a unit mistake or garbage is refused.
pub const STEP_LENGTH_OVERRIDE_RANGE_M: std::ops::RangeInclusive<f64> = 0.1..=2.5;

/// The largest magnitude of a `north` override's declination, degrees: an angle between two
/// directions is at most half a turn.
pub const MAX_DECLINATION_DEG: f64 = 180.0;

/// The largest magnitude of a `north` override's site rotation, degrees: one turn.
pub const MAX_SITE_ROTATION_DEG: f64 = 360.0;

/// Which transition model the HMM uses.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TransitionModel {
    /// Uniform over the states reachable at `max_speed_mps`, motion ignored (Hoang §6.1,
    /// the "RSSI only" row of Table 1).
    Reach,
    /// High/low probability regions from the measured distance and heading: HIPE's model
    /// (HIPE eqs. 5-11). Written `hipe` in files.
    #[serde(rename = "hipe", alias = "regions")]
    Regions,
    /// Hoang's Gaussian on the movement vector over the reachable states (Hoang eqs. 11, 14)
    /// when distance and heading are both measured; with the distance alone, its along-track
    /// term on the walking distance; with the heading alone, HIPE's sector (which uses it);
    /// with neither, the reachable states.
    /// Written `hoang` in files.
    #[default]
    #[serde(rename = "hoang", alias = "movement_vector")]
    MovementVector,
}

/// The regions model's parameters: HIPE's (HIPE Table 4 unless said otherwise).
#[derive(Clone, Debug, PartialEq)]
pub struct RegionsConfig {
    /// Relative distance tolerance: ±10% of the distance estimate (Table 4).
    pub distance_tolerance_fraction: f64,
    /// Least distance tolerance: 1.5 m, "half the separation distance of most RPs" (§5.2).
    pub distance_tolerance_min_m: f64,
    /// Heading tolerance γ: 55° (Table 4).
    pub heading_tolerance_rad: f64,
    /// Assumed maximum speed for the speed scenarios: 1 m/s (§4.2.2, Table 1).
    pub assumed_speed_mps: f64,
    /// Smallest K: 200 (Table 4). K moves log-linearly between `transition_ratio_min` and
    /// the engine's `transition_ratio` with the reliability of the motion data and of the
    /// previous estimate (§4.2.1: "greater when ... more reliable"; the rule is Waymark's).
    pub transition_ratio_min: f64,
}

impl Default for RegionsConfig {
    fn default() -> Self {
        Self {
            distance_tolerance_fraction: 0.10,
            distance_tolerance_min_m: 1.5,
            heading_tolerance_rad: 55f64.to_radians(),
            assumed_speed_mps: 1.0,
            transition_ratio_min: 200.0,
        }
    }
}

/// The movement-vector model's parameters: Hoang's (Hoang §6.1 unless said otherwise).
#[derive(Clone, Debug, PartialEq)]
pub struct MovementVectorConfig {
    /// Σ_v = variance · I: 0.25 m² (Hoang §6.1, "determined in offline experiments").
    pub movement_variance_m2: f64,
    /// Mahalanobis distance beyond which the movement likelihood stops falling, so that a
    /// miscounted step cannot rule a state out: 3, the usual three-sigma gate. Waymark's
    /// robustness choice, in the spirit of HIPE eq. 11.
    pub mahalanobis_cap: f64,
    /// Whether Σ_v grows by the quantisation of the states: the movement vector is compared
    /// with l_j - l_i, the difference of two cell centres, while the walker is anywhere in
    /// either cell. For cells `s` long (the site's median edge length) each end adds s²/12
    /// per axis, so Σ_v + (s²/6)·I. Hoang's simulated walker stands on the states, where this
    /// is 0; a real one does not. Default on (docs/tuning.md#measured-spread).
    pub quantisation_variance: bool,
    /// Whether Σ_v also grows by the tracker's own spreads of the epoch: the distance's
    /// along the movement and distance × heading spread across it (the error propagation of
    /// v = d·(sin θ, cos θ)). Hoang's simulated walker has a fixed 0.25 m²; a phone's step
    /// count and compass err more on some epochs than on others. Default on: it improves the
    /// Viterbi track on real walks (docs/tuning.md#measured-spread); off reproduces Hoang's
    /// Table 1.
    pub measured_spread: bool,
}

impl Default for MovementVectorConfig {
    fn default() -> Self {
        Self {
            movement_variance_m2: 0.25,
            mahalanobis_cap: 3.0,
            quantisation_variance: true,
            measured_spread: true,
        }
    }
}

/// How the engine turns scans into positions.
#[derive(Clone, Debug, PartialEq)]
pub struct EngineConfig {
    /// Fastest a person is assumed to move, m/s: bounds the states reachable between two
    /// epochs. Hoang et al. §6.1: "a user cannot move faster than 3 m/s".
    pub max_speed_mps: f64,
    /// The transition model. Default Hoang's movement-vector Gaussian (Hoang eq. 11), which
    /// beats HIPE's regions with full motion (docs/tuning.md#transition-model).
    pub transition: TransitionModel,
    /// How raw inertial samples become steps, distance and heading. `declination_rad` and
    /// `site_rotation_rad` are taken from the site file's `north` when the engine starts,
    /// unless `north` overrides them.
    pub motion: MotionConfig,
    /// The site frame's orientation, when the app knows better than the site file (a fresh
    /// declination from a geomagnetic model, say). `None`: the site file's.
    pub north: Option<crate::site::North>,
    /// The regions model's parameters (HIPE's), for [`TransitionModel::Regions`].
    pub regions: RegionsConfig,
    /// The movement-vector model's parameters (Hoang's), for
    /// [`TransitionModel::MovementVector`].
    pub movement_vector: MovementVectorConfig,
    /// γ of Hoang eq. 14: the radio likelihood is raised to γ and the movement likelihood to
    /// 1 - γ. `None` is eq. 3 (both to the power 1), as in Hoang's simulations (§6.1); the
    /// field-data value is chosen per site by jackknife (Hoang §6.2 found 0.003).
    pub rssi_weight: Option<f64>,
    /// γ in epochs without a movement likelihood (no steps or no heading, or a model other
    /// than Hoang's), where the radio is weighed against the reachability prior alone. `None`:
    /// `rssi_weight`, else the site's calibrated value.
    pub rssi_weight_without_movement: Option<f64>,
    /// Epochs the Viterbi tracker keeps (HIPE §4.1 tracks by Viterbi): 64 epochs, 96 s at
    /// Hoang's 1.5 s epoch, bounding its memory to 64 × 2 bytes per state (4 beyond 65 536
    /// states), and far less where most states share their best predecessor
    /// ([`ViterbiWindow::memory_bound_bytes`](crate::hmm::ViterbiWindow::memory_bound_bytes)).
    pub track_window_epochs: usize,
    /// Run the Viterbi tracker: [`Engine::track`](crate::Engine::track) and the revised track
    /// points each position carries. Off, an epoch skips the Viterbi step and the engine holds
    /// no track window: for callers that read only the live and fixed-lag positions, as the
    /// survey's calibration does (docs/tuning.md#evaluation-speed). The positions are the
    /// same either way.
    pub track: bool,
    /// Lag of the fixed-lag estimate ([`Engine::fixed_lag_position`](crate::Engine::fixed_lag_position)),
    /// epochs: 3 (4.5 s at 1.5 s epochs), where the smoothed error is near its flat optimum
    /// (docs/tuning.md#fixed-lag).
    pub fixed_lag_epochs: usize,
    /// Shortest motion-only epoch the filter steps over, s: an [`advance`](crate::Engine::advance)
    /// sooner than this after the filter's last step is held (its position is the estimate
    /// over the posterior predicted by the motion since, the filter unchanged) and its motion
    /// carried into the next epoch, so that advancing more often does not spread the mass
    /// more: each step adds Σ_v and the grid's quantisation spread whatever its length. 2 s:
    /// the replay's timer, one unthrottled scan interval, the cadence at which the site's γ
    /// and radius factors are calibrated (docs/tuning.md#replay-timer). 0 steps at every
    /// advance.
    pub min_motion_step_s: f64,
    /// Ratio K between the high transition probability (reachable states) and the low one
    /// (everything else), HIPE eqs. 5-6. The low one keeps every a_ij > 0 (HIPE eq. 11) so the
    /// filter can recover from a wrong track. Default: the top of HIPE Table 4's range
    /// [200, 200 000], i.e. the most trust in the reachability model.
    pub transition_ratio: f64,
    /// M, the number of most likely states averaged into the estimate (Hoang eq. 4; the paper
    /// gives no value). `None` (the default): the site's calibrated M (with
    /// `site_calibration`), else [`DEFAULT_ESTIMATE_STATES`].
    pub estimate_states: Option<usize>,
    /// Radius of the precomputed walking-distance table, m. A larger reach (a long gap between
    /// scans) is covered by several passes of the table. Default: the reach of two of Hoang's
    /// 1.5 s epochs at `max_speed_mps` = 3 m/s, so scan jitter up to 2x needs one pass.
    pub reach_radius_m: f64,
    /// Most passes of the reach table one prediction may take; a longer gap restarts the
    /// filter from the uniform prior, since after it the person may be anywhere in
    /// 16 × `reach_radius_m`. 16 bounds the worst epoch to 16 sparse products; it is a cost
    /// bound, not a tuned figure: 16 passes reach 144 m (48 s at 3 m/s), more than most floors.
    pub max_reach_passes: u32,
    /// Readings last measured longer ago than this before their scan are dropped (Android
    /// re-reports cached access points). `None`: the limit the site's survey applied
    /// ([`Site::max_reading_age_ns`](crate::Site::max_reading_age_ns)), so that a scan counts
    /// as it did when the fingerprints and the calibration were made; every reading on a site
    /// that gives none. `Some(u64::MAX)` keeps every reading on any site.
    pub max_reading_age_ns: Option<u64>,
    /// Whether the site file's [`Calibration`](crate::site::Calibration) applies: its γ when
    /// `rssi_weight` is `None`, its surveyors' step length model in place of
    /// `motion.step_length`, and its accuracy scales. Default on: a surveyed site's own
    /// measurements beat generic defaults. A user's own step length goes in
    /// `step_length_override`, which keeps the rest of the calibration.
    pub site_calibration: bool,
    /// Whether the engine learns the phone's RSSI offset against the map from its scans and
    /// corrects readings by it (docs/accuracy.md#device-offset): phone models read the same
    /// signal several dB apart, and a map surveyed with one scores another's scans as if
    /// every transmitter were nearer or farther than it is.
    pub device_offset: bool,
    /// Whether barometer readings ([`Engine::push_pressure`](crate::Engine::push_pressure))
    /// weigh the floors by the height climbed (docs/accuracy.md#barometer).
    pub barometer: bool,
    /// The user's own step length model, used in place of the site's surveyed one and of
    /// `motion.step_length` (an app that knows its user's stride, e.g. from their height).
    /// `None`: the site's, else `motion.step_length`.
    pub step_length_override: Option<StepLengthModel>,
    /// Probability mass inside the reported `accuracy_m` circle: 0.68, as Android's
    /// `Location.getAccuracy()` and iOS's `horizontalAccuracy` define it.
    pub accuracy_mass: f64,
    /// When the person enters and leaves a zone or geofence
    /// ([`StatusEvent::ZoneEntered`](crate::StatusEvent::ZoneEntered) and the rest).
    pub zone_hysteresis: ZoneHysteresis,
    /// The salt the site's transmitter ids were hashed with, for a site file that holds
    /// hashes instead of MAC addresses ([`Site::hashed`](crate::Site::hashed)); scans are
    /// hashed with it before matching. `None` for a site with raw ids. An engine on a hashed
    /// site fails to start without it or with another salt
    /// ([`SiteError::SaltRequired`](crate::SiteError::SaltRequired),
    /// [`SiteError::WrongSalt`](crate::SiteError::WrongSalt)).
    pub site_salt: Option<crate::radio::Salt>,
    /// Epochs kept in the engine's history ([`Engine::history`](crate::Engine::history)) for a
    /// later learning pass, with the user's feedback: 500, the length of the observation
    /// sequences El Gemayel et al. learn from with feedback (§IV-C: "observation sequences of
    /// length 500"). 0 keeps none.
    pub history_epochs: usize,
    /// How [`Engine::learn_habits`](crate::Engine::learn_habits) learns and how the learned
    /// habits are applied ([`crate::habits`]).
    pub habits: HabitOptions,
}

impl Default for EngineConfig {
    fn default() -> Self {
        Self {
            max_speed_mps: 3.0,
            transition: TransitionModel::default(),
            motion: MotionConfig::default(),
            north: None,
            regions: RegionsConfig::default(),
            movement_vector: MovementVectorConfig::default(),
            rssi_weight: None,
            rssi_weight_without_movement: None,
            track_window_epochs: 64,
            track: true,
            fixed_lag_epochs: 3,
            min_motion_step_s: 2.0,
            transition_ratio: 200_000.0,
            estimate_states: None,
            reach_radius_m: 9.0,
            max_reach_passes: 16,
            max_reading_age_ns: None,
            accuracy_mass: 0.68,
            zone_hysteresis: ZoneHysteresis::default(),
            site_calibration: true,
            device_offset: true,
            barometer: true,
            step_length_override: None,
            site_salt: None,
            history_epochs: 500,
            habits: HabitOptions::default(),
        }
    }
}

/// The posterior mass of a zone or geofence at which the person is reported to enter it, and
/// below which to leave it; between the two nothing changes, so an estimate that hovers at a
/// boundary does not flap in and out (a Schmitt trigger). The defaults put the band around an
/// even chance at the confidence every radius the engine reports is given at: in once the place
/// holds as much mass as the 68% circle does, out once it holds less than the 32% outside that
/// circle (docs/zones.md#enter-and-exit, where the events are measured on simulated walks).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ZoneHysteresis {
    /// In at this mass or more: 0.68.
    pub enter_mass: f64,
    /// Out below this mass: 0.32.
    pub exit_mass: f64,
}

impl Default for ZoneHysteresis {
    fn default() -> Self {
        Self { enter_mass: 0.68, exit_mass: 0.32 }
    }
}

/// M of Hoang eq. 4 (the paper gives no value) on a site without a calibrated one: 3, the best
/// fused on the pseudo-state grid and within 4 mm of the best radio only
/// (docs/tuning.md#mixture-components-m).
pub const DEFAULT_ESTIMATE_STATES: usize = 3;

impl EngineConfig {
    /// Checks every field; the message names the field and the rule.
    pub fn validate(&self) -> Result<(), Error> {
        let fail = |m: String| Err(Error::InvalidConfig(m));
        if let Some((path, message)) = self.habits.invalid_field() {
            return fail(format!("{path}: {message}"));
        }
        if !(self.max_speed_mps.is_finite() && self.max_speed_mps > 0.0) {
            return fail(format!("max_speed_mps must be finite and > 0 (got {})", self.max_speed_mps));
        }
        if !(self.transition_ratio.is_finite() && self.transition_ratio >= 1.0) {
            return fail(format!("transition_ratio must be finite and >= 1 (got {})", self.transition_ratio));
        }
        self.motion.validate()?;
        if let Some(model) = self.step_length_override {
            MotionConfig { step_length: model, ..self.motion.clone() }
                .validate()
                .map_err(|e| Error::InvalidConfig(format!("step_length_override: {e}")))?;
            if let StepLengthModel::Constant { length_m } = model {
                if !STEP_LENGTH_OVERRIDE_RANGE_M.contains(&length_m) {
                    let range = &STEP_LENGTH_OVERRIDE_RANGE_M;
                    return fail(format!(
                        "step_length_override: a step length must be in [{}, {}] m (got {length_m})",
                        range.start(),
                        range.end()
                    ));
                }
            }
        }
        if let Some(n) = self.north {
            if !(n.declination_rad.is_finite() && n.site_rotation_rad.is_finite()) {
                return fail("north: angles must be finite".into());
            }
            let (declination_deg, rotation_deg) =
                (n.declination_rad.to_degrees(), n.site_rotation_rad.to_degrees());
            if declination_deg.abs() > MAX_DECLINATION_DEG {
                return fail(format!(
                    "north: declination must be within ±{MAX_DECLINATION_DEG}° (got {declination_deg}°)"
                ));
            }
            if rotation_deg.abs() > MAX_SITE_ROTATION_DEG {
                return fail(format!(
                    "north: site rotation must be within ±{MAX_SITE_ROTATION_DEG}° (got {rotation_deg}°)"
                ));
            }
        }
        let h = &self.regions;
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let tolerances_ok = h.distance_tolerance_fraction.is_finite()
            && h.distance_tolerance_fraction >= 0.0
            && positive(h.distance_tolerance_min_m)
            && positive(h.heading_tolerance_rad)
            && positive(h.assumed_speed_mps);
        if !tolerances_ok {
            return fail("hipe: tolerances and assumed_speed_mps must be finite and positive".into());
        }
        if !(h.transition_ratio_min >= 1.0 && h.transition_ratio_min <= self.transition_ratio) {
            return fail(format!(
                "hipe.transition_ratio_min must be in [1, transition_ratio] (got {})",
                h.transition_ratio_min
            ));
        }
        if !positive(self.movement_vector.movement_variance_m2)
            || !positive(self.movement_vector.mahalanobis_cap)
        {
            return fail("hoang: movement_variance_m2 and mahalanobis_cap must be finite and > 0".into());
        }
        if let Some(g) = self.rssi_weight {
            if !(g > 0.0 && g <= 1.0) {
                return fail(format!("rssi_weight must be in (0, 1] (got {g})"));
            }
        }
        if !(self.min_motion_step_s.is_finite() && self.min_motion_step_s >= 0.0) {
            return fail(format!(
                "min_motion_step_s must be finite and >= 0 (got {})",
                self.min_motion_step_s
            ));
        }
        if self.track_window_epochs == 0 || self.fixed_lag_epochs >= self.track_window_epochs {
            return fail("track_window_epochs must be > fixed_lag_epochs".into());
        }
        if self.estimate_states == Some(0) {
            return fail("estimate_states must be at least 1".into());
        }
        if !(self.reach_radius_m.is_finite() && self.reach_radius_m > 0.0) {
            return fail(format!("reach_radius_m must be finite and > 0 (got {})", self.reach_radius_m));
        }
        if self.max_reach_passes == 0 {
            return fail("max_reach_passes must be at least 1".into());
        }
        if !(self.accuracy_mass > 0.0 && self.accuracy_mass < 1.0) {
            return fail(format!("accuracy_mass must be in (0, 1) (got {})", self.accuracy_mass));
        }
        let ZoneHysteresis { enter_mass, exit_mass } = self.zone_hysteresis;
        if !(0.0 < exit_mass && exit_mass <= enter_mass && enter_mass <= 1.0) {
            return fail(format!(
                "zone_hysteresis needs 0 < exit_mass <= enter_mass <= 1 (got exit {exit_mass}, enter {enter_mass})"
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_is_valid_and_bad_fields_are_named() {
        EngineConfig::default().validate().unwrap();
        let bad = EngineConfig { max_speed_mps: f64::NAN, ..EngineConfig::default() };
        assert!(bad.validate().unwrap_err().to_string().contains("max_speed_mps"));
        let bad = EngineConfig { accuracy_mass: 1.0, ..EngineConfig::default() };
        assert!(bad.validate().unwrap_err().to_string().contains("accuracy_mass"));
    }

    /// A step length or north override far out of any plausible range (1e300, a unit mistake)
    /// is an invalid config, not an engine that walks to another continent.
    #[test]
    fn implausible_overrides_are_refused() {
        let step = |length_m| EngineConfig {
            step_length_override: Some(StepLengthModel::Constant { length_m }),
            ..EngineConfig::default()
        };
        for ok in [0.1, 0.7, 2.5] {
            assert!(step(ok).validate().is_ok(), "{ok} m");
        }
        for bad in [1e300, 70.0, 0.05] {
            let e = step(bad).validate().unwrap_err().to_string();
            assert!(e.contains("step_length_override") && e.contains("2.5"), "{bad} m: {e}");
        }
        let north = |declination_deg: f64, rotation_deg: f64| EngineConfig {
            north: Some(crate::site::North {
                declination_rad: declination_deg.to_radians(),
                site_rotation_rad: rotation_deg.to_radians(),
            }),
            ..EngineConfig::default()
        };
        assert!(north(-180.0, 360.0).validate().is_ok());
        assert!(north(12.5, -90.0).validate().is_ok());
        for (d, r) in [(1e300, 0.0), (181.0, 0.0), (0.0, 1e300), (0.0, -361.0)] {
            let e = north(d, r).validate().unwrap_err().to_string();
            assert!(e.contains("north:"), "{d}, {r}: {e}");
        }
    }
}
