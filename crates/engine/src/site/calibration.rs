//! What the survey calibrated for a site (Hoang eq. 14's γ, radius factors, the radio-fit
//! floor, the sparse-scan regime), as the site file carries it, and the radii it scales.

use super::FloorReliability;
use serde::{Deserialize, Serialize};

/// What the survey measured about how this site's radio and walkers behave, applied by
/// engines unless their configuration says otherwise (see
/// [`EngineConfig::site_calibration`](crate::EngineConfig::site_calibration)). Every field is
/// optional: a hand-made site file has none.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// γ of Hoang eq. 14 in epochs with a movement likelihood (steps and heading), chosen by
    /// cross-validation on the survey walks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rssi_weight: Option<f64>,
    /// γ in epochs without one (the radio then only competes with the reachability prior),
    /// chosen the same way with the motion withheld.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rssi_weight_without_movement: Option<f64>,
    /// γ per motion scenario in its epochs without a movement likelihood, before
    /// `rssi_weight_without_movement`: the radio then competes with HIPE's ring (distance
    /// only), sector (heading only) or disc (speed only), each a different prior to balance.
    /// The survey's calibration fits `distance` and `heading_speed` with those sensors alone
    /// (speed's is `rssi_weight_without_movement`).
    #[serde(default, skip_serializing_if = "PerScenario::is_empty")]
    pub rssi_weight_by_scenario: PerScenario<f64>,
    /// Factors on the posterior's 68% and 95% radii so that, on held-out survey walks, the
    /// circles held the truth 68% and 95% of the time.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accuracy_scale: Option<[f64; 2]>,
    /// The same factors per motion scenario (HIPE Table 1), fitted on the held-out epochs the
    /// engine positioned in that scenario: the posterior's spread means something else when
    /// the motion is only a maximum speed than when steps and heading are measured. A scenario
    /// without its own factors uses `accuracy_scale`.
    #[serde(default, skip_serializing_if = "PerScenario::is_empty")]
    pub accuracy_scale_by_scenario: ScenarioScales,
    /// The surveyors' step length model, fitted on the survey walks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step_length: Option<crate::sensors::StepLengthModel>,
    /// The least radio fit ([`Position::radio_fit`](crate::Position::radio_fit)) of a scan
    /// heard on the map, nats per radio heard: below it the map does not explain the scan (the
    /// phone is probably beyond the surveyed area), the engine leans on the motion and its
    /// radii grow with the distance walked. The survey's calibration takes a quantile (5% or 20%,
    /// whichever its held-out walks replayed as shipped err least with) of the fits
    /// over held-out epochs on the map, and 0 when that is below 0
    /// (docs/tuning.md#radio-fit-floor).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radio_fit_floor: Option<f64>,
    /// γ and radius factors for scans far apart, as under Android 9+'s throttling.
    #[serde(default, skip_serializing_if = "SparseScans::is_empty")]
    pub sparse_scans: SparseScans,
    /// M of Hoang eq. 4, the most likely states averaged into the estimate, chosen like γ on
    /// held-out survey walks (docs/tuning.md#mixture-components-m). Since format version 5.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimate_states: Option<u32>,
    /// How often the floor was right on held-out survey epochs, by band of the posterior's
    /// mass on it: the floor probability engines report (docs/accuracy.md#floor-probability).
    /// Since format version 6.
    #[serde(default, skip_serializing_if = "FloorReliability::is_empty")]
    pub floor_reliability: FloorReliability,
    /// How often a walker changes floor, per second: the survey walks' floor changes over their
    /// time, as the posterior mean of a Poisson rate under a flat prior, (changes + 1) / time.
    /// Where the barometer measures the height, the engine moves this much of the mass to the
    /// other floors each second (docs/accuracy.md#barometer); without it, floors exchange mass
    /// only through the floor weight. Since format version 8.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub floor_change_rate_hz: Option<f64>,
}

/// A scan that comes longer than this after the one before it, s, is a sparse scan, and the
/// epochs until the next scan are in the sparse regime ([`SparseScans`]). 10 s lies between
/// an unthrottled phone's scan intervals and Android 9+'s throttling of a foreground app to 4
/// scans in 2 minutes (30 s apart on average) (docs/tuning.md#sparse-scans).
pub const SPARSE_SCAN_GAP_S: f64 = 10.0;

/// Upper ends of the bands of time since a sparse scan, s, each with its own radius factors
/// ([`SparseScans::accuracy_scale_by_since`]); the last band is open. After a sparse scan the
/// posterior's own radii first hold too little of the truth, then enough, so the bands are
/// narrow where the fitted factor changes fast, none shorter than the replay's 2 s timer
/// epoch (docs/tuning.md#sparse-scans).
pub const SINCE_SPARSE_SCAN_BANDS_S: [f64; 4] = [2.0, 5.0, 10.0, 20.0];

/// What differs when scans are far apart (more than 10 s apart): the motion has carried
/// the estimate alone for a long while, so the scan that ends it weighs differently against
/// the motion than one of a steady stream, and the posterior after it is not spread as after
/// a stream's. Fitted by the survey's calibration on the held-out walks replayed under
/// throttling (one scan every 30 s reaching the engine).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SparseScans {
    /// γ of every epoch in the sparse regime that has a movement likelihood (in place of
    /// [`Calibration::rssi_weight`] and the floor's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rssi_weight: Option<f64>,
    /// Factors on the 68% and 95% radii in the sparse regime, by band of time since the
    /// sparse scan ([`SINCE_SPARSE_SCAN_BANDS_S`]), in place of the scenario's.
    #[serde(default, skip_serializing_if = "no_scales")]
    pub accuracy_scale_by_since: BandScales,
    /// The floor probability's calibration in the sparse regime, in place of
    /// [`Calibration::floor_reliability`]: long on the motion alone, the posterior's floor
    /// mass means something else. Since format version 6.
    #[serde(default, skip_serializing_if = "FloorReliability::is_empty")]
    pub floor_reliability: FloorReliability,
}

/// Radius factors (68%, 95%) per band of time since a sparse scan; `None`: not fitted.
pub type BandScales = [Option<[f64; 2]>; SPARSE_BANDS];

/// Bands of time since a sparse scan ([`SINCE_SPARSE_SCAN_BANDS_S`], the last one open).
pub const SPARSE_BANDS: usize = SINCE_SPARSE_SCAN_BANDS_S.len() + 1;

fn no_scales(scales: &BandScales) -> bool {
    scales.iter().all(Option::is_none)
}

impl SparseScans {
    /// Whether nothing is calibrated.
    pub fn is_empty(&self) -> bool {
        *self == SparseScans::default()
    }

    /// The band of `since_s` seconds after a sparse scan.
    pub fn band(since_s: f64) -> usize {
        SINCE_SPARSE_SCAN_BANDS_S.iter().take_while(|&&edge| since_s >= edge).count()
    }
}

impl Calibration {
    /// Whether nothing is calibrated.
    pub fn is_empty(&self) -> bool {
        *self == Calibration::default()
    }

    /// The first invalid field, as (path, message).
    pub fn check(&self) -> Result<(), (String, String)> {
        for (name, gamma) in [
            ("rssi_weight", self.rssi_weight),
            ("rssi_weight_without_movement", self.rssi_weight_without_movement),
        ] {
            if let Some(g) = gamma {
                if !(g > 0.0 && g <= 1.0) {
                    return Err((format!("calibration.{name}"), format!("must be in (0, 1], got {g}")));
                }
            }
        }
        for s in crate::sensors::MotionScenario::ALL {
            if let Some(g) = self.rssi_weight_by_scenario.get(s) {
                if !(g > 0.0 && g <= 1.0) {
                    let path = format!("calibration.rssi_weight_by_scenario.{}", ScenarioScales::key(s));
                    return Err((path, format!("must be in (0, 1], got {g}")));
                }
            }
        }
        if let Some(g) = self.sparse_scans.rssi_weight {
            if !(g > 0.0 && g <= 1.0) {
                return Err((
                    "calibration.sparse_scans.rssi_weight".into(),
                    format!("must be in (0, 1], got {g}"),
                ));
            }
        }
        if let Some(f) = self.radio_fit_floor {
            if !f.is_finite() {
                return Err(("calibration.radio_fit_floor".into(), format!("must be finite, got {f}")));
            }
        }
        for (path, reliability) in [
            ("calibration.floor_reliability", &self.floor_reliability),
            ("calibration.sparse_scans.floor_reliability", &self.sparse_scans.floor_reliability),
        ] {
            if let Some((band, share)) = reliability.invalid() {
                return Err((format!("{path}[{band}]"), format!("must be in [0, 1], got {share}")));
            }
        }
        if let Some(r) = self.floor_change_rate_hz {
            if !(0.0..=1.0).contains(&r) {
                return Err((
                    "calibration.floor_change_rate_hz".into(),
                    format!("must be in [0, 1], got {r}"),
                ));
            }
        }
        if self.estimate_states == Some(0) {
            return Err(("calibration.estimate_states".into(), "must be at least 1".into()));
        }
        let by_scenario = crate::sensors::MotionScenario::ALL.map(|s| {
            (
                format!("calibration.accuracy_scale_by_scenario.{}", ScenarioScales::key(s)),
                self.accuracy_scale_by_scenario.get(s),
            )
        });
        let by_since = self.sparse_scans.accuracy_scale_by_since.iter().enumerate().map(|(band, &scale)| {
            (format!("calibration.sparse_scans.accuracy_scale_by_since[{band}]"), scale)
        });
        for (path, scale) in std::iter::once(("calibration.accuracy_scale".to_string(), self.accuracy_scale))
            .chain(by_scenario)
            .chain(by_since)
        {
            if let Some(scale) = scale {
                if !scale.iter().all(|s| s.is_finite() && *s > 0.0) {
                    return Err((path, format!("must be finite and > 0, got {scale:?}")));
                }
            }
        }
        Ok(())
    }

    /// The 68% and 95% radius factors of an epoch in `scenario`: its own, else the site's,
    /// else none (1).
    pub fn accuracy_scale_in(&self, scenario: crate::sensors::MotionScenario) -> [f64; 2] {
        self.accuracy_scale_by_scenario.get(scenario).or(self.accuracy_scale).unwrap_or([1.0, 1.0])
    }
}

/// The 68% and 95% radii an engine reports, m, from the posterior's own (`posterior`) and the
/// factors in effect (`scale`: the sparse band's, else the scenario's): each radius times its
/// factor, the 95% never inside the 68%, plus `beyond_radio_m`, the walking since the radio
/// last explained a scan, which no factor scales (docs/accuracy.md). The engine reports with
/// it and the survey's calibration scores its held-out epochs with it.
pub fn scaled_radii(posterior: [f64; 2], scale: [f64; 2], beyond_radio_m: f64) -> [f64; 2] {
    let r68 = posterior[0] * scale[0];
    [r68 + beyond_radio_m, (posterior[1] * scale[1]).max(r68) + beyond_radio_m]
}

/// Radius factors (68%, 95%) per motion scenario; `None`: not fitted.
pub type ScenarioScales = PerScenario<[f64; 2]>;

/// A value per motion scenario (HIPE Table 1); `None`: not fitted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PerScenario<T> {
    /// Steps and heading measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distance_heading: Option<T>,
    /// Steps measured, heading not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distance: Option<T>,
    /// Heading measured, distance from the maximum speed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heading_speed: Option<T>,
    /// The maximum speed only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed: Option<T>,
}

impl<T: Clone> PerScenario<T> {
    /// Whether no scenario has a value.
    pub fn is_empty(&self) -> bool {
        crate::sensors::MotionScenario::ALL.iter().all(|&s| self.slot(s).is_none())
    }

    /// The value of `scenario`.
    pub fn get(&self, scenario: crate::sensors::MotionScenario) -> Option<T> {
        self.slot(scenario).clone()
    }

    /// Sets the value of `scenario`.
    pub fn set(&mut self, scenario: crate::sensors::MotionScenario, value: Option<T>) {
        *self.slot_mut(scenario) = value;
    }

    /// Its key in the site file.
    pub fn key(scenario: crate::sensors::MotionScenario) -> &'static str {
        use crate::sensors::MotionScenario::*;
        match scenario {
            DistanceHeading => "distance_heading",
            Distance => "distance",
            HeadingSpeed => "heading_speed",
            Speed => "speed",
        }
    }

    fn slot(&self, scenario: crate::sensors::MotionScenario) -> &Option<T> {
        use crate::sensors::MotionScenario::*;
        match scenario {
            DistanceHeading => &self.distance_heading,
            Distance => &self.distance,
            HeadingSpeed => &self.heading_speed,
            Speed => &self.speed,
        }
    }

    fn slot_mut(&mut self, scenario: crate::sensors::MotionScenario) -> &mut Option<T> {
        use crate::sensors::MotionScenario::*;
        match scenario {
            DistanceHeading => &mut self.distance_heading,
            Distance => &mut self.distance,
            HeadingSpeed => &mut self.heading_speed,
            Speed => &mut self.speed,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sparse_bands_start_at_their_edges() {
        assert_eq!(
            [0.0, 1.99, 2.0, 4.9, 5.0, 9.9, 10.0, 19.9, 20.0, 1e6].map(SparseScans::band),
            [0, 0, 1, 1, 2, 2, 3, 3, 4, 4]
        );
    }

    /// The site file carries the sparse calibration, and nothing of it when there is none.
    #[test]
    fn sparse_calibration_round_trips() {
        let mut accuracy_scale_by_since = [None; SPARSE_BANDS];
        accuracy_scale_by_since[1] = Some([1.5, 1.25]);
        let calibration = Calibration {
            sparse_scans: SparseScans {
                rssi_weight: Some(0.1),
                accuracy_scale_by_since,
                floor_reliability: FloorReliability::default(),
            },
            ..Calibration::default()
        };
        let json = serde_json::to_string(&calibration).unwrap();
        assert_eq!(serde_json::from_str::<Calibration>(&json).unwrap(), calibration, "{json}");
        let empty = serde_json::to_string(&Calibration::default()).unwrap();
        assert!(!empty.contains("sparse"), "{empty}");
        let scales_only = Calibration {
            sparse_scans: SparseScans { rssi_weight: None, ..calibration.sparse_scans },
            ..Calibration::default()
        };
        let json = serde_json::to_string(&scales_only).unwrap();
        assert!(json.contains("\"accuracy_scale_by_since\":[null,[1.5,1.25],null,null,null]"), "{json}");
    }

    /// A sparse γ out of (0, 1] or a bad factor is refused with its path.
    #[test]
    fn sparse_calibration_is_checked() {
        let gamma = Calibration {
            sparse_scans: SparseScans { rssi_weight: Some(1.5), ..SparseScans::default() },
            ..Calibration::default()
        };
        assert_eq!(gamma.check().unwrap_err().0, "calibration.sparse_scans.rssi_weight");
        let mut accuracy_scale_by_since = [None; SPARSE_BANDS];
        accuracy_scale_by_since[2] = Some([1.0, -1.0]);
        let scale = Calibration {
            sparse_scans: SparseScans { accuracy_scale_by_since, ..SparseScans::default() },
            ..Calibration::default()
        };
        assert_eq!(scale.check().unwrap_err().0, "calibration.sparse_scans.accuracy_scale_by_since[2]");
        assert!(Calibration::default().check().is_ok());
    }

    /// The floor calibration round-trips as a plain array, is left out when empty and is
    /// refused with its path when a share is not a probability.
    #[test]
    fn floor_reliability_round_trips_and_is_checked() {
        let calibration = Calibration {
            floor_reliability: FloorReliability([None, Some(0.5), Some(0.75), Some(0.9), Some(0.99)]),
            ..Calibration::default()
        };
        let json = serde_json::to_string(&calibration).unwrap();
        assert!(json.contains("\"floor_reliability\":[null,0.5,0.75,0.9,0.99]"), "{json}");
        assert_eq!(serde_json::from_str::<Calibration>(&json).unwrap(), calibration);
        assert!(!serde_json::to_string(&Calibration::default()).unwrap().contains("floor"));
        let mut bad = calibration;
        bad.floor_reliability.0[3] = Some(1.5);
        assert_eq!(bad.check().unwrap_err().0, "calibration.floor_reliability[3]");
        let mut bad = Calibration::default();
        bad.sparse_scans.floor_reliability.0[0] = Some(f64::NAN);
        assert_eq!(bad.check().unwrap_err().0, "calibration.sparse_scans.floor_reliability[0]");
    }
}
