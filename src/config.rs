//! Engine configuration. Every default cites the paper (and equation or table) it comes from,
//! or the measurement that chose it.

use crate::error::Error;

/// How the engine turns scans into positions.
#[derive(Clone, Debug, PartialEq)]
pub struct EngineConfig {
    /// Fastest a person is assumed to move, m/s: bounds the states reachable between two
    /// epochs. Hoang et al. §6.1: "a user cannot move faster than 3 m/s".
    pub max_speed_mps: f64,
    /// Ratio K between the high transition probability (reachable states) and the low one
    /// (everything else), HIPE eqs. 5-6. The low one keeps every a_ij > 0 (HIPE eq. 11) so the
    /// filter can recover from a wrong track. Default: the top of HIPE Table 4's range
    /// [200, 200 000], i.e. the most trust in the reachability model.
    pub transition_ratio: f64,
    /// M, the number of most likely states averaged into the estimate (Hoang eq. 4; the paper
    /// gives no value). Default 5, measured with `waymark demo --json --top-m M --seed S` over
    /// seeds 1-5 (not the demo's default seed 0): mean error 1.470 / 1.240 / 1.212 / 1.206 /
    /// 1.206 m for M = 1 / 2 / 3 / 5 / 8. The error stops falling at 3; 5 is as good here and
    /// keeps the average over more than one cell where states are denser (pseudo states).
    pub estimate_states: usize,
    /// Radius of the precomputed walking-distance table, m. A larger reach (a long gap between
    /// scans) is covered by several passes of the table. Default: the reach of two of Hoang's
    /// 1.5 s epochs at `max_speed_mps` = 3 m/s, so scan jitter up to 2x needs one pass.
    pub reach_radius_m: f64,
    /// Most passes of the reach table one prediction may take; a longer gap restarts the
    /// filter from the uniform prior, since after it the person may be anywhere in
    /// 16 × `reach_radius_m`. 16 bounds the worst epoch to 16 sparse products.
    pub max_reach_passes: u32,
    /// Readings last measured longer ago than this before their scan are dropped (Android
    /// re-reports cached access points). `None` keeps every reading: the age limit is chosen
    /// on real traces, not on the simulator, whose readings are all fresh.
    pub max_reading_age_ns: Option<u64>,
    /// Probability mass inside the reported `accuracy_m` circle: 0.68, as Android's
    /// `Location.getAccuracy()` and iOS's `horizontalAccuracy` define it.
    pub accuracy_mass: f64,
}

impl Default for EngineConfig {
    fn default() -> Self {
        Self {
            max_speed_mps: 3.0,
            transition_ratio: 200_000.0,
            estimate_states: 5,
            reach_radius_m: 9.0,
            max_reach_passes: 16,
            max_reading_age_ns: None,
            accuracy_mass: 0.68,
        }
    }
}

impl EngineConfig {
    /// Checks every field; the message names the field and the rule.
    pub fn validate(&self) -> Result<(), Error> {
        let fail = |m: String| Err(Error::InvalidConfig(m));
        if !(self.max_speed_mps.is_finite() && self.max_speed_mps > 0.0) {
            return fail(format!("max_speed_mps must be finite and > 0 (got {})", self.max_speed_mps));
        }
        if !(self.transition_ratio.is_finite() && self.transition_ratio >= 1.0) {
            return fail(format!("transition_ratio must be finite and >= 1 (got {})", self.transition_ratio));
        }
        if self.estimate_states == 0 {
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
}
