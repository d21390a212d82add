//! What an engine on a site runs with: each value of its configuration, else the site's
//! calibrated one ([`Calibration`](crate::site::Calibration), with `site_calibration`), else
//! the default.

use crate::config::{EngineConfig, DEFAULT_ESTIMATE_STATES};
use crate::sensors::MotionConfig;

impl EngineConfig {
    /// The motion configuration an engine on `site` runs: `motion` with the site's north (or
    /// the `north` override) applied.
    pub fn motion_for(&self, site: &crate::Site) -> MotionConfig {
        let north = self.north.unwrap_or_else(|| site.north());
        let step_length =
            match (self.step_length_override, self.site_calibration, site.calibration().step_length) {
                (Some(model), _, _) => model,
                (None, true, Some(model)) => model,
                _ => self.motion.step_length,
            };
        MotionConfig {
            declination_rad: north.declination_rad,
            site_rotation_rad: north.site_rotation_rad,
            step_length,
            ..self.motion.clone()
        }
    }

    /// M of Hoang eq. 4 on `site`: `estimate_states`, else the site's calibrated M (with
    /// `site_calibration`), else [`DEFAULT_ESTIMATE_STATES`].
    pub fn estimate_states_for(&self, site: &crate::Site) -> usize {
        let calibrated = site.calibration().estimate_states.filter(|_| self.site_calibration);
        self.estimate_states.or(calibrated.map(|m| m as usize)).unwrap_or(DEFAULT_ESTIMATE_STATES)
    }

    /// γ of Hoang eq. 14 an engine on `site` uses in epochs with a movement likelihood and in
    /// epochs without one: `rssi_weight` for both, else the site's calibrated ones (with
    /// `site_calibration`), else none (eq. 3).
    pub fn rssi_weight_for(&self, site: &crate::Site) -> [Option<f64>; 2] {
        let c = if self.site_calibration { *site.calibration() } else { crate::site::Calibration::default() };
        [
            self.rssi_weight.or(c.rssi_weight),
            self.rssi_weight_without_movement
                .or(self.rssi_weight)
                .or(c.rssi_weight_without_movement)
                .or(c.rssi_weight),
        ]
    }

    /// γ per floor of `site` (index = floor), as in [`rssi_weight_for`](Self::rssi_weight_for)
    /// but with each floor's own calibrated γ ([`Floor::rssi_weight`](crate::site::Floor))
    /// before the site-wide one: an explicit `rssi_weight` still overrides every floor. An
    /// engine runs each epoch at the γ of the floor of its latest estimate.
    pub fn floor_rssi_weights(&self, site: &crate::Site) -> Vec<[Option<f64>; 2]> {
        let c = if self.site_calibration { *site.calibration() } else { crate::site::Calibration::default() };
        site.floors()
            .iter()
            .map(|f| {
                let (with, without) = if self.site_calibration {
                    (f.rssi_weight, f.rssi_weight_without_movement)
                } else {
                    (None, None)
                };
                [
                    self.rssi_weight.or(with).or(c.rssi_weight),
                    self.rssi_weight_without_movement
                        .or(self.rssi_weight)
                        .or(without)
                        .or(c.rssi_weight_without_movement)
                        .or(with)
                        .or(c.rssi_weight),
                ]
            })
            .collect()
    }

    /// Factors on the 68% and 95% radii for `site`, per motion scenario (indexed by
    /// [`MotionScenario::index`](crate::sensors::MotionScenario::index)): the site's calibrated ones, else 1.
    pub fn accuracy_scales_for(&self, site: &crate::Site) -> [[f64; 2]; 4] {
        crate::sensors::MotionScenario::ALL.map(|s| {
            if self.site_calibration {
                site.calibration().accuracy_scale_in(s)
            } else {
                [1.0, 1.0]
            }
        })
    }

    /// The site's calibration of the floor probability outside the sparse regime
    /// ([`Calibration::floor_reliability`](crate::site::Calibration)); none without
    /// `site_calibration` (the posterior's own mass is then reported).
    pub fn floor_reliability_for(&self, site: &crate::Site) -> crate::site::FloorReliability {
        if self.site_calibration {
            site.calibration().floor_reliability
        } else {
            crate::site::FloorReliability::default()
        }
    }

    /// The site's calibration for sparse scans ([`SparseScans`](crate::site::SparseScans)),
    /// without its γ when `rssi_weight` is given (an explicit γ overrides every calibrated
    /// one); none without `site_calibration`.
    pub fn sparse_scans_for(&self, site: &crate::Site) -> crate::site::SparseScans {
        if !self.site_calibration {
            return crate::site::SparseScans::default();
        }
        let mut sparse = site.calibration().sparse_scans;
        if self.rssi_weight.is_some() {
            sparse.rssi_weight = None;
        }
        sparse
    }

    /// The site's γ per motion scenario for epochs without a movement likelihood
    /// ([`Calibration::rssi_weight_by_scenario`](crate::site::Calibration)), in
    /// [`MotionScenario::ALL`](crate::sensors::MotionScenario::ALL) order. `None` for every scenario
    /// when `rssi_weight` or `rssi_weight_without_movement` is given (an explicit γ overrides
    /// every calibrated one) or without `site_calibration`; an epoch with `None` takes its
    /// floor's γ without movement ([`floor_rssi_weights`](Self::floor_rssi_weights)).
    pub fn scenario_rssi_weights(&self, site: &crate::Site) -> [Option<f64>; 4] {
        let explicit = self.rssi_weight.is_some() || self.rssi_weight_without_movement.is_some();
        crate::sensors::MotionScenario::ALL.map(|s| {
            if self.site_calibration && !explicit {
                site.calibration().rssi_weight_by_scenario.get(s)
            } else {
                None
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use crate::config::EngineConfig;
    use crate::sensors::StepLengthModel;

    #[test]
    fn a_floors_own_gamma_comes_before_the_sites_and_an_explicit_one_before_both() {
        use crate::site::{BuildOptions, Calibration, SiteBuilder};
        let mut b = SiteBuilder::new("two");
        for f in [b.floor("G", 0.0), b.floor("1", 4.0), b.floor("2", 8.0)] {
            b.state(f, nalgebra::Point2::new(0.0, 0.0), vec![]);
        }
        let site = b
            .build(BuildOptions::default())
            .unwrap()
            .with_calibration(Calibration {
                rssi_weight: Some(0.1),
                rssi_weight_without_movement: Some(0.3),
                ..Calibration::default()
            })
            .unwrap()
            .with_floor_rssi_weights(&[[Some(0.01), None], [None, None], [Some(0.03), Some(1.0)]])
            .unwrap();
        let config = EngineConfig::default();
        assert_eq!(config.rssi_weight_for(&site), [Some(0.1), Some(0.3)]);
        assert_eq!(
            config.floor_rssi_weights(&site),
            vec![[Some(0.01), Some(0.3)], [Some(0.1), Some(0.3)], [Some(0.03), Some(1.0)]]
        );
        let explicit = EngineConfig { rssi_weight: Some(0.5), ..EngineConfig::default() };
        assert_eq!(explicit.floor_rssi_weights(&site), vec![[Some(0.5), Some(0.5)]; 3]);
        let off = EngineConfig { site_calibration: false, ..EngineConfig::default() };
        assert_eq!(off.floor_rssi_weights(&site), vec![[None, None]; 3]);
        // Out of range, or more weights than floors: a typed error naming the floor.
        let bad = site.clone().with_floor_rssi_weights(&[[None, None], [Some(0.0), None]]).unwrap_err();
        assert!(bad.to_string().contains("floors[1].rssi_weight"), "{bad}");
        assert!(site.with_floor_rssi_weights(&[[None, None]; 4]).is_err());
    }

    #[test]
    fn a_users_step_length_beats_the_sites_which_beats_the_default() {
        use crate::site::{BuildOptions, Calibration, SiteBuilder};
        let mut b = SiteBuilder::new("one");
        let f = b.floor("G", 0.0);
        b.state(f, nalgebra::Point2::new(0.0, 0.0), vec![]);
        let plain = b.build(BuildOptions::default()).unwrap();
        let surveyed_model = StepLengthModel::Weinberg { k: 0.48 };
        let surveyed = plain
            .clone()
            .with_calibration(Calibration { step_length: Some(surveyed_model), ..Calibration::default() })
            .unwrap();
        let user = StepLengthModel::Constant { length_m: 0.82 };
        let defaults = EngineConfig::default();
        assert_eq!(defaults.motion_for(&plain).step_length, defaults.motion.step_length);
        assert_eq!(defaults.motion_for(&surveyed).step_length, surveyed_model);
        let mine = EngineConfig { step_length_override: Some(user), ..EngineConfig::default() };
        assert_eq!(mine.motion_for(&surveyed).step_length, user);
        assert_eq!(mine.motion_for(&plain).step_length, user);
        // The override keeps the rest of the site's calibration.
        assert!(mine.site_calibration);
        let bad = EngineConfig {
            step_length_override: Some(StepLengthModel::Constant { length_m: -0.7 }),
            ..EngineConfig::default()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("step_length_override"));
    }
}
