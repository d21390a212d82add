//! A user's habits, learned in the engine a phone runs: Baum-Welch (El Gemayel et al. §III-A,
//! eqs. 8-10) over the engine's own recorded epochs ([`EpochRecord`](crate::EpochRecord)) with the user's
//! feedback (§IV-C), re-estimating
//!
//! - the **transitions** between the site's states the user actually makes (which corridor
//!   they take, which shop they turn into), over the pairs the engine's walking-distance table
//!   allows (structural zeros: nobody walks through a wall), and
//! - the **error of external position fixes** (§II-C: "a bias ... learned"): one bias vector and
//!   one factor on the fixes' spread.
//!
//! The learned transitions are a prior multiplied into the motion-based transition of every
//! epoch (`HabitPrior`, `Habitual`): each row keeps its total, so habits only redistribute
//! a state's mass among the states the motion already allows. A state never learned keeps its
//! row exactly.
//!
//! # The observations
//!
//! As in the paper, the observation of an epoch is a position estimate: the engine's own
//! estimate after the epoch, a Gaussian around each state with the epoch's 68% radius as its
//! spread (`fix::sigma_m`), or, at a fix epoch, the fix itself, through the current fix-error
//! model. States on another floor than the estimate's cannot explain it. Feedback pins the
//! posterior to the states the user named.
//!
//! # Counts, not probabilities
//!
//! A [`HabitModel`] stores the expected transition counts Σ ξ_t(i, j) summed over everything
//! learned so far, and the fix residuals' sufficient statistics. Each learning pass is a
//! maximum a posteriori Baum-Welch whose Dirichlet prior is the counts already held plus
//! [`HabitOptions::pseudocount`] per allowed transition; at the end its expected counts are
//! added to the model. So a model exported at the end of one session and imported into the
//! next goes on learning, and the same epochs are never counted twice
//! ([`HabitModel::learned_through_ns`]).
//!
//! # Bounds
//!
//! A pass works on one segment of the history at a time (epochs split at gaps the engine itself
//! would not bridge), over the states within 4 σ of that segment's observations: memory
//! O(T · N_seg) for T epochs and N_seg such states (500 epochs of a walk through a few hundred
//! states: a few MB), time O(iterations · T · E_seg) for the E_seg allowed pairs among them.

mod file;
mod learn;
mod options;
mod prior;

use crate::hmm::learn::LearnError;
use crate::site::Site;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

pub use learn::clustered_ratio;
pub use options::HabitOptions;
pub(crate) use prior::HabitPrior;
pub(crate) use prior::Habitual;

/// The `format` field of an exported model.
pub(crate) const FORMAT: &str = "waymark-habits";

/// The layout version this build writes; it reads this and older ones.
pub const VERSION: u32 = 1;

/// Observations farther than this many σ from a state are taken to say nothing for it:
/// exp(−4²/2) = 3.4e-4 of the Gaussian's peak. Bounds the states a pass considers.
pub(crate) const CANDIDATE_SIGMAS: f64 = 4.0;

/// The largest count or strength a model file may hold: 10¹², more moves than a phone makes in
/// a lifetime of 1 s epochs (3·10⁹ in a century). Bounds every sum of counts far from overflow,
/// so no multiplier can be infinite or NaN.
pub(crate) const MAX_COUNT: f64 = 1e12;

/// Expected counts below this are not stored: such a count moves a multiplier by under 1e-6 of
/// the pseudo-count.
const NEGLIGIBLE_COUNT: f64 = 1e-6;

/// The strengths a pass tries, as pseudo-counts per reachable move: from Laplace's 1 to 1000,
/// where a state needs about a thousand passes through it per reachable neighbour before its
/// habits double a move's weight. A log grid, as for γ.
pub const STRENGTHS: [f64; 7] = [1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0];

/// Why habits could not be learned, imported or applied. Nothing changes when one is returned.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum HabitError {
    /// The JSON does not parse, or a field is missing or of the wrong type.
    #[error("habits JSON: {0}")]
    Json(String),
    /// The JSON is not a Waymark habit model.
    #[error("not a Waymark habit model (format {0:?})")]
    Format(String),
    /// A newer layout than this build reads.
    #[error("habit model layout {found} is newer than this build reads ({supported})")]
    UnsupportedVersion {
        /// The file's version.
        found: u32,
        /// The newest this build reads.
        supported: u32,
    },
    /// The model was learned on another site (or another build of the site file).
    #[error("habit model is for another site: {0}")]
    WrongSite(String),
    /// A value is out of range.
    #[error("{path}: {message}")]
    Invalid {
        /// Where, e.g. `transitions[3].count[2]`.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// The learning core refused (a bug if it happens: its input is built here).
    #[error(transparent)]
    Learn(#[from] LearnError),
}

/// The site a model belongs to: its state count and a CRC-32 of every state's floor and
/// position, so that a model learned on one build of a site file is refused by another.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SiteKey {
    /// The site's name (informative).
    pub name: String,
    /// Number of states.
    pub states: usize,
    /// CRC-32 of the states' floors and positions, hex.
    pub digest: String,
}

impl SiteKey {
    /// The key of `site`.
    pub fn of(site: &Site) -> Self {
        let mut hasher = crc32fast::Hasher::new();
        for s in site.states() {
            hasher.update(&(s.floor as u64).to_le_bytes());
            hasher.update(&s.position.x.to_le_bytes());
            hasher.update(&s.position.y.to_le_bytes());
        }
        Self {
            name: site.name().to_owned(),
            states: site.states().len(),
            digest: format!("{:08x}", hasher.finalize()),
        }
    }
}

/// Sufficient statistics of the fix residuals r = fix − true position, each weighted by the
/// posterior of the state it is measured from.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FixStatistics {
    /// Expected number of fixes learned from.
    pub fixes: f64,
    /// Σ r / σ², m⁻¹ per axis.
    pub weighted_residual: [f64; 2],
    /// Σ 1 / σ², m⁻².
    pub weight: f64,
    /// Σ |r − b|² / (2 σ²) around the bias in force when it was measured.
    pub normalised_square: f64,
}

/// A learned fix error: subtract `bias_m` from a fix, then widen its σ by `spread`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FixBias {
    /// Mean error of the fixes, m (x, y in the site frame).
    pub bias_m: [f64; 2],
    /// Factor on the fixes' own σ (1: they are as good as they say).
    pub spread: f64,
}

impl Default for FixBias {
    fn default() -> Self {
        Self { bias_m: [0.0, 0.0], spread: 1.0 }
    }
}

impl FixStatistics {
    /// The MAP estimate with `prior_fixes` pseudo-fixes at zero bias and unit spread: each
    /// pseudo-fix weighs as the fixes' average 1/σ².
    pub fn estimate(&self, prior_fixes: f64) -> FixBias {
        if self.fixes <= 0.0 {
            return FixBias::default();
        }
        let mean_weight = self.weight / self.fixes;
        let w = self.weight + prior_fixes * mean_weight;
        let bias = self.weighted_residual.map(|r| if w > 0.0 { r / w } else { 0.0 });
        let spread = ((self.normalised_square + prior_fixes) / (self.fixes + prior_fixes)).sqrt();
        FixBias { bias_m: bias, spread: if spread.is_finite() && spread > 0.0 { spread } else { 1.0 } }
    }

    fn add(&mut self, other: &FixStatistics) {
        self.fixes += other.fixes;
        self.weight += other.weight;
        self.normalised_square += other.normalised_square;
        for k in 0..2 {
            self.weighted_residual[k] += other.weighted_residual[k];
        }
    }
}

/// Learned habits of one user on one site: expected transition counts and fix statistics.
#[derive(Clone, Debug, PartialEq)]
pub struct HabitModel {
    site: SiteKey,
    /// Learned rows: from-state → (to-state ascending, expected count).
    rows: BTreeMap<u32, Vec<(u32, f64)>>,
    fix: FixStatistics,
    epochs: u64,
    learned_through_ns: Option<u64>,
    /// κ with which the moves are applied; `None`: not applied (not enough evidence yet that
    /// they predict anything).
    strength: Option<f64>,
}

/// How well habits at one strength predicted the held-out moves.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct StrengthGain {
    /// κ.
    pub strength: f64,
    /// Mean gain over the uniform reachability, nats per held-out move.
    pub gain: f64,
    /// Its standard error, over segments (the moves of one walk are not independent).
    pub standard_error: f64,
}

/// Habits are applied only when their held-out gain exceeds this many standard errors: about
/// 97.7% one-sided confidence that they predict the user's moves at all (the usual two-σ level).
pub(crate) const SIGNIFICANT_GAIN_ERRORS: f64 = 2.0;

/// The strength to apply, from the held-out gains: the weakest (largest κ) whose gain is within
/// one standard error of the best (the one-standard-error rule of cross-validation: Breiman et
/// al. 1984, §3.4.3; Hastie, Tibshirani & Friedman, *Elements of Statistical Learning* §7.10),
/// and only when that gain is significantly above zero ([`SIGNIFICANT_GAIN_ERRORS`]).
pub(crate) fn choose_strength(gains: &[StrengthGain]) -> Option<f64> {
    let best = gains.iter().max_by(|a, b| a.gain.total_cmp(&b.gain))?;
    let chosen = gains
        .iter()
        .filter(|g| g.gain >= best.gain - best.standard_error)
        .max_by(|a, b| a.strength.total_cmp(&b.strength))?;
    (chosen.gain > SIGNIFICANT_GAIN_ERRORS * chosen.standard_error && chosen.gain > 0.0)
        .then_some(chosen.strength)
}

/// What a learning pass did.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct HabitReport {
    /// Epochs learned from.
    pub epochs: usize,
    /// Segments (runs of epochs without a long gap) learned from.
    pub segments: usize,
    /// Segments skipped: a single epoch, or over `max_segment_states` states.
    pub segments_skipped: usize,
    /// Epochs with feedback.
    pub feedback_epochs: usize,
    /// Fix epochs.
    pub fix_epochs: usize,
    /// Baum-Welch iterations run.
    pub iterations: usize,
    /// ln p(o | θ) before each iteration and for the learned model, summed over segments.
    pub log_likelihood: Vec<f64>,
    /// Feedback epochs the model ruled out, at which a segment restarted.
    pub restarts: usize,
    /// The most states one segment involved.
    pub largest_segment_states: usize,
    /// Transitions with a learned count, after the pass.
    pub learned_transitions: usize,
    /// The fix error after the pass.
    pub fix_bias: FixBias,
    /// Per strength of [`STRENGTHS`]: ln p of the held-out segments' moves under the other
    /// half's habits, minus ln p under the uniform reachability, nats per move (the first
    /// half predicting the second and the reverse). Empty with fewer than two segments.
    pub strength_gain: Vec<StrengthGain>,
    /// The strength chosen (`None`: habits not applied).
    pub strength: Option<f64>,
}

impl HabitModel {
    /// An empty model for `site`: applying it changes nothing.
    pub fn new(site: &Site) -> Self {
        Self {
            site: SiteKey::of(site),
            rows: BTreeMap::new(),
            fix: FixStatistics::default(),
            epochs: 0,
            learned_through_ns: None,
            strength: None,
        }
    }

    /// Whether nothing has been learned.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty() && self.fix.fixes == 0.0
    }

    /// The site it belongs to.
    pub fn site(&self) -> &SiteKey {
        &self.site
    }

    /// Epochs learned from, over all passes.
    pub fn epochs(&self) -> u64 {
        self.epochs
    }

    /// The newest epoch learned from; a later pass starts after it.
    pub fn learned_through_ns(&self) -> Option<u64> {
        self.learned_through_ns
    }

    /// Transitions with a learned count.
    pub fn learned_transitions(&self) -> usize {
        self.rows.values().map(Vec::len).sum()
    }

    /// The expected count of the move i → j.
    pub fn count(&self, i: u32, j: u32) -> f64 {
        self.rows
            .get(&i)
            .and_then(|r| r.binary_search_by_key(&j, |e| e.0).ok().map(|k| r[k].1))
            .unwrap_or(0.0)
    }

    /// κ with which the learned moves are applied; `None`: they are not.
    pub fn strength(&self) -> Option<f64> {
        self.strength
    }

    /// Sets κ (`None`: the learned moves are not applied), for a strength chosen outside the
    /// pass, e.g. by positioning error on labelled walks (docs/tuning.md#habit-strength). Refused,
    /// leaving the model unchanged, unless finite, > 0 and at most 10¹².
    pub fn set_strength(&mut self, strength: Option<f64>) -> Result<(), HabitError> {
        if let Some(k) = strength {
            if !(k.is_finite() && k > 0.0 && k <= MAX_COUNT) {
                return Err(HabitError::Invalid {
                    path: "strength".into(),
                    message: format!("{k} is not a pseudo-count > 0"),
                });
            }
        }
        self.strength = strength;
        Ok(())
    }

    /// The fix statistics.
    pub fn fix_statistics(&self) -> &FixStatistics {
        &self.fix
    }

    /// The learned fix error, with `options`' prior.
    pub fn fix_bias(&self, options: &HabitOptions) -> FixBias {
        self.fix.estimate(options.fix_prior_fixes)
    }
}
