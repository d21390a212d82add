//! How a learning pass runs: its options and their checks.

use super::HabitError;

/// How a learning pass runs.
#[derive(Clone, Debug, PartialEq)]
pub struct HabitOptions {
    /// Dirichlet pseudo-count added to every allowed transition. Default 1 (Laplace's rule of
    /// succession): a state's habits outweigh the uniform reachability only once it has been
    /// passed through about as many times as it has reachable neighbours, so a single walk
    /// barely moves them, and the prior never makes an allowed move impossible.
    pub pseudocount: f64,
    /// Pseudo-fixes at zero bias and unit spread factor behind the fix-error estimate. Default
    /// 5, Waymark's choice, not a paper's or a measurement (no data here has external fixes):
    /// one fix, or a few, cannot shift every later fix; twenty agreeing fixes carry 80% of the
    /// weight.
    pub fix_prior_fixes: f64,
    /// Most Baum-Welch iterations per pass. Default 10: above the iterations the passes on the
    /// competition floors' survey walks took to reach the tolerance
    /// (docs/tuning.md#habit-strength), so it binds only a pass that has not converged.
    pub max_iterations: usize,
    /// Stop when an iteration improves ln p(o | θ) by less than this many nats per epoch.
    /// Default 1e-3, the tolerance of [`FitOptions::default`](crate::hmm::learn::FitOptions).
    pub tolerance: f64,
    /// A gap between two epochs longer than this starts a new segment, s. Default 48: the
    /// longest gap the engine still predicts across rather than restarting
    /// (`max_reach_passes` 16 × `reach_radius_m` 9 m ÷ `max_speed_mps` 3 m/s).
    pub max_gap_s: f64,
    /// Most states one segment may involve; a segment over more is skipped and counted.
    /// Default 20 000: with 500 epochs, 80 MB for the forward variables in the worst case.
    pub max_segment_states: usize,
    /// The strength κ with which the learned moves are applied in the filter
    /// (the habit prior); `None` (default): chosen by each pass on held-out segments (among
    /// `habits::STRENGTHS`), so habits that do not predict the user's next moves are not
    /// applied.
    pub strength: Option<f64>,
}

impl Default for HabitOptions {
    fn default() -> Self {
        Self {
            pseudocount: 1.0,
            fix_prior_fixes: 5.0,
            max_iterations: 10,
            tolerance: 1e-3,
            max_gap_s: 48.0,
            max_segment_states: 20_000,
            strength: None,
        }
    }
}

impl HabitOptions {
    /// The first field out of range, as its path (`options.<field>`) and what is wrong.
    pub(crate) fn invalid_field(&self) -> Option<(String, String)> {
        for (name, v) in [
            ("pseudocount", self.pseudocount),
            ("fix_prior_fixes", self.fix_prior_fixes),
            ("tolerance", self.tolerance),
            ("max_gap_s", self.max_gap_s),
            ("strength", self.strength.unwrap_or(1.0)),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Some((format!("options.{name}"), format!("{v}")));
            }
        }
        if self.pseudocount <= 0.0 || self.strength.is_some_and(|k| k <= 0.0) {
            return Some((
                "options.pseudocount / options.strength".into(),
                "must be > 0, or an unseen move would become impossible".into(),
            ));
        }
        None
    }

    /// Checks every field.
    pub fn check(&self) -> Result<(), HabitError> {
        match self.invalid_field() {
            Some((path, message)) => Err(HabitError::Invalid { path, message }),
            None => Ok(()),
        }
    }
}
