//! A user's habits, learned in the engine a phone runs: Baum-Welch (El Gemayel et al. §III-A,
//! eqs. 8-10) over the engine's own recorded epochs ([`crate::history`]) with the user's
//! feedback (§IV-C), re-estimating
//!
//! - the **transitions** between the site's states the user actually makes (which corridor
//!   they take, which shop they turn into), over the pairs the engine's walking-distance table
//!   allows (structural zeros: nobody walks through a wall), and
//! - the **error of external position fixes** (§II-C: "a bias ... learned"): one bias vector and
//!   one factor on the fixes' spread.
//!
//! The learned transitions are a prior multiplied into the motion-based transition of every
//! epoch ([`HabitPrior`], [`Habitual`]): each row keeps its total, so habits only redistribute
//! a state's mass among the states the motion already allows. A state never learned keeps its
//! row exactly.
//!
//! # The observations
//!
//! As in the paper, the observation of an epoch is a position estimate: the engine's own
//! estimate after the epoch, a Gaussian around each state with the epoch's 68% radius as its
//! spread ([`fix::sigma_m`]), or, at a fix epoch, the fix itself, through the current fix-error
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

use crate::fix::{self, PositionFix};
use crate::history::{EpochInput, EpochRecord};
use crate::hmm::learn::{expected_counts, Chain, EpochMatrix, LearnError, SparseTransition};
use crate::hmm::Transition;
use crate::site::{ReachTable, Site};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The `format` field of an exported model.
pub const FORMAT: &str = "waymark-habits";

/// The layout version this build writes; it reads this and older ones.
pub const VERSION: u32 = 1;

/// Observations farther than this many σ from a state are taken to say nothing for it:
/// exp(−4²/2) = 3.4e-4 of the Gaussian's peak. Bounds the states a pass considers.
pub const CANDIDATE_SIGMAS: f64 = 4.0;

/// The largest count or strength a model file may hold: 10¹², more moves than a phone makes in
/// a lifetime of 1 s epochs (3·10⁹ in a century). Bounds every sum of counts far from overflow,
/// so no multiplier can be infinite or NaN.
pub const MAX_COUNT: f64 = 1e12;

/// Expected counts below this are not stored: such a count moves a multiplier by under 1e-6 of
/// the pseudo-count.
const NEGLIGIBLE_COUNT: f64 = 1e-6;

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
    /// Most Baum-Welch iterations per pass. Default 10: on the survey walks of the competition
    /// floors (`waymark eval --habits`) passes stopped on the tolerance after 9 (F1), 5 (F2),
    /// 7 (B1) and 7 (all five) iterations, so 10 binds only a pass that has not converged.
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
    /// ([`HabitPrior`]); `None` (default): chosen by each pass on held-out segments
    /// ([`STRENGTHS`]), so habits that do not predict the user's next moves are not applied.
    pub strength: Option<f64>,
}

/// The strengths a pass tries, as pseudo-counts per reachable move: from Laplace's 1 to 1000,
/// where a state needs about a thousand passes through it per reachable neighbour before its
/// habits double a move's weight. A log grid, as for γ.
pub const STRENGTHS: [f64; 7] = [1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0];

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
    /// Checks every field.
    pub fn check(&self) -> Result<(), HabitError> {
        for (name, v) in [
            ("pseudocount", self.pseudocount),
            ("fix_prior_fixes", self.fix_prior_fixes),
            ("tolerance", self.tolerance),
            ("max_gap_s", self.max_gap_s),
            ("strength", self.strength.unwrap_or(1.0)),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(HabitError::Invalid { path: format!("options.{name}"), message: format!("{v}") });
            }
        }
        if self.pseudocount <= 0.0 || self.strength.is_some_and(|k| k <= 0.0) {
            return Err(HabitError::Invalid {
                path: "options.pseudocount / options.strength".into(),
                message: "must be > 0, or an unseen move would become impossible".into(),
            });
        }
        Ok(())
    }
}

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
pub struct FixError {
    /// Mean error of the fixes, m (x, y in the site frame).
    pub bias_m: [f64; 2],
    /// Factor on the fixes' own σ (1: they are as good as they say).
    pub spread: f64,
}

impl Default for FixError {
    fn default() -> Self {
        Self { bias_m: [0.0, 0.0], spread: 1.0 }
    }
}

impl FixStatistics {
    /// The MAP estimate with `prior_fixes` pseudo-fixes at zero bias and unit spread: each
    /// pseudo-fix weighs as the fixes' average 1/σ².
    pub fn estimate(&self, prior_fixes: f64) -> FixError {
        if self.fixes <= 0.0 {
            return FixError::default();
        }
        let mean_weight = self.weight / self.fixes;
        let w = self.weight + prior_fixes * mean_weight;
        let bias = self.weighted_residual.map(|r| if w > 0.0 { r / w } else { 0.0 });
        let spread = ((self.normalised_square + prior_fixes) / (self.fixes + prior_fixes)).sqrt();
        FixError { bias_m: bias, spread: if spread.is_finite() && spread > 0.0 { spread } else { 1.0 } }
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

/// The JSON form.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelFile {
    format: String,
    version: u32,
    site: SiteKey,
    epochs: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    learned_through_ns: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    strength: Option<f64>,
    transitions: Vec<RowFile>,
    fix: FixStatistics,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RowFile {
    from: u32,
    to: Vec<u32>,
    count: Vec<f64>,
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
pub const SIGNIFICANT_GAIN_ERRORS: f64 = 2.0;

/// The strength to apply, from the held-out gains: the weakest (largest κ) whose gain is within
/// one standard error of the best (the one-standard-error rule of cross-validation: Breiman et
/// al. 1984, §3.4.3; Hastie, Tibshirani & Friedman, *Elements of Statistical Learning* §7.10),
/// and only when that gain is significantly above zero ([`SIGNIFICANT_GAIN_ERRORS`]).
pub fn choose_strength(gains: &[StrengthGain]) -> Option<f64> {
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
    pub fix_error: FixError,
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
    /// pass, e.g. by positioning error on labelled walks (`waymark eval --habits`). Refused,
    /// leaving the model unchanged, unless finite, > 0 and at most [`MAX_COUNT`].
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
    pub fn fix_error(&self, options: &HabitOptions) -> FixError {
        self.fix.estimate(options.fix_prior_fixes)
    }

    /// The model as JSON (`format` [`FORMAT`], `version` [`VERSION`]).
    pub fn to_json(&self) -> String {
        let file = ModelFile {
            format: FORMAT.into(),
            version: VERSION,
            site: self.site.clone(),
            epochs: self.epochs,
            learned_through_ns: self.learned_through_ns,
            strength: self.strength,
            transitions: self
                .rows
                .iter()
                .map(|(&from, row)| RowFile {
                    from,
                    to: row.iter().map(|e| e.0).collect(),
                    count: row.iter().map(|e| e.1).collect(),
                })
                .collect(),
            fix: self.fix.clone(),
        };
        serde_json::to_string(&file).unwrap_or_default()
    }

    /// Reads a model exported by [`to_json`](Self::to_json) for `site`, checking every field.
    pub fn from_json(json: &str, site: &Site) -> Result<Self, HabitError> {
        let value: serde_json::Value =
            serde_json::from_str(json).map_err(|e| HabitError::Json(e.to_string()))?;
        let format = value.get("format").and_then(|f| f.as_str()).unwrap_or_default();
        if format != FORMAT {
            return Err(HabitError::Format(format.to_owned()));
        }
        match value.get("version").and_then(serde_json::Value::as_u64) {
            Some(v) if v <= u64::from(VERSION) => {}
            Some(v) => {
                return Err(HabitError::UnsupportedVersion {
                    found: v.min(u64::from(u32::MAX)) as u32,
                    supported: VERSION,
                })
            }
            None => return Err(HabitError::Json("missing field `version`".into())),
        }
        let file: ModelFile = serde_json::from_value(value).map_err(|e| HabitError::Json(e.to_string()))?;
        let key = SiteKey::of(site);
        if file.site.states != key.states || file.site.digest != key.digest {
            return Err(HabitError::WrongSite(format!(
                "learned on {:?} ({} states, digest {}), this is {:?} ({} states, digest {})",
                file.site.name, file.site.states, file.site.digest, key.name, key.states, key.digest
            )));
        }
        let n = key.states as u64;
        let invalid = |path: String, message: String| HabitError::Invalid { path, message };
        let mut rows = BTreeMap::new();
        for (r, row) in file.transitions.into_iter().enumerate() {
            if u64::from(row.from) >= n {
                return Err(invalid(format!("transitions[{r}].from"), format!("state {} of {n}", row.from)));
            }
            if row.to.len() != row.count.len() {
                return Err(invalid(
                    format!("transitions[{r}].count"),
                    format!("{} counts for {} states", row.count.len(), row.to.len()),
                ));
            }
            for (k, (&j, &c)) in row.to.iter().zip(&row.count).enumerate() {
                if u64::from(j) >= n {
                    return Err(invalid(format!("transitions[{r}].to[{k}]"), format!("state {j} of {n}")));
                }
                if k > 0 && row.to[k - 1] >= j {
                    return Err(invalid(format!("transitions[{r}].to[{k}]"), "states must ascend".into()));
                }
                if !(c.is_finite() && (0.0..=MAX_COUNT).contains(&c)) {
                    return Err(invalid(
                        format!("transitions[{r}].count[{k}]"),
                        format!("{c} is not a count"),
                    ));
                }
            }
            let entries: Vec<(u32, f64)> = row.to.into_iter().zip(row.count).collect();
            if rows.insert(row.from, entries).is_some() {
                return Err(invalid(format!("transitions[{r}].from"), format!("state {} twice", row.from)));
            }
        }
        if let Some(k) = file.strength {
            if !(k.is_finite() && k > 0.0 && k <= MAX_COUNT) {
                return Err(invalid("strength".into(), format!("{k} is not a pseudo-count > 0")));
            }
        }
        let f = &file.fix;
        let fix_values =
            [f.fixes, f.weight, f.normalised_square, f.weighted_residual[0], f.weighted_residual[1]];
        if fix_values.iter().any(|v| !(v.is_finite() && v.abs() <= MAX_COUNT))
            || f.fixes < 0.0
            || f.weight < 0.0
            || f.normalised_square < 0.0
        {
            return Err(invalid("fix".into(), "statistics must be finite and not negative".into()));
        }
        Ok(Self {
            site: file.site,
            rows,
            fix: file.fix,
            epochs: file.epochs,
            learned_through_ns: file.learned_through_ns,
            strength: file.strength,
        })
    }

    /// Learns from `sequences` (each a run of recorded epochs, oldest first; epochs at or before
    /// [`learned_through_ns`](Self::learned_through_ns) are skipped) and adds what it learned.
    /// On an error the model is unchanged.
    pub fn learn(
        &mut self,
        site: &Site,
        reach: &ReachTable,
        sequences: &[&[EpochRecord]],
        options: &HabitOptions,
    ) -> Result<HabitReport, HabitError> {
        options.check()?;
        let key = SiteKey::of(site);
        if key.states != self.site.states || key.digest != self.site.digest {
            return Err(HabitError::WrongSite(format!(
                "the model was made for {:?}, not {:?}",
                self.site.name, key.name
            )));
        }
        let after = self.learned_through_ns;
        let mut report = HabitReport::default();
        let mut segments: Vec<Segment> = Vec::new();
        for records in sequences {
            let fresh: Vec<&EpochRecord> =
                records.iter().filter(|r| after.map_or(true, |a| r.timestamp_ns > a)).collect();
            for run in split(&fresh, options.max_gap_s) {
                if run.len() < 2 {
                    report.segments_skipped += 1;
                    continue;
                }
                match Segment::new(site, reach, &run, options) {
                    Some(s) => segments.push(s),
                    None => report.segments_skipped += 1,
                }
            }
        }
        report.segments = segments.len();
        report.epochs = segments.iter().map(|s| s.epochs.len()).sum();
        report.feedback_epochs = segments.iter().map(|s| s.known.len()).sum();
        report.fix_epochs = segments.iter().flat_map(|s| &s.epochs).filter(|e| e.fix.is_some()).count();
        report.largest_segment_states = segments.iter().map(|s| s.states.len()).max().unwrap_or(0);
        // Epochs of a lone-epoch run at the end stay unlearned: they may start the next pass's
        // segment.
        let newest = segments.iter().map(|s| s.last_ns).max();

        // Baum-Welch: E-step under the current estimate, M-step = prior counts + expected counts.
        let mut learned: BTreeMap<(u32, u32), f64> = BTreeMap::new();
        let mut fix_stats = FixStatistics::default();
        let mut previous: Option<f64> = None;
        for iteration in 0..=options.max_iterations {
            let fix_error = {
                let mut total = self.fix.clone();
                total.add(&fix_stats);
                total.estimate(options.fix_prior_fixes)
            };
            let mut next: BTreeMap<(u32, u32), f64> = BTreeMap::new();
            let mut next_fix = FixStatistics::default();
            let mut log_likelihood = 0.0;
            for segment in &segments {
                let e = segment.expect(site, self, &learned, fix_error, options, &mut next, &mut next_fix)?;
                log_likelihood += e.0;
                if iteration == 0 {
                    report.restarts += e.1;
                }
            }
            report.log_likelihood.push(log_likelihood);
            learned = next;
            fix_stats = next_fix;
            let epochs = report.epochs.max(1) as f64;
            let converged = previous.is_some_and(|p| (log_likelihood - p) / epochs < options.tolerance);
            previous = Some(log_likelihood);
            if converged || iteration == options.max_iterations {
                break;
            }
            report.iterations += 1;
        }
        // How strongly to apply them: chosen on held-out segments (or given).
        let strength = match options.strength {
            Some(k) => Some(k),
            None if segments.len() >= 2 => {
                report.strength_gain = self.strength_gains(site, reach, &segments, options)?;
                choose_strength(&report.strength_gain)
            }
            None => self.strength,
        };
        // Commit.
        self.strength = strength;
        report.strength = strength;
        for ((i, j), c) in learned {
            if c < NEGLIGIBLE_COUNT {
                continue;
            }
            let row = self.rows.entry(i).or_default();
            match row.binary_search_by_key(&j, |e| e.0) {
                Ok(k) => row[k].1 += c,
                Err(k) => row.insert(k, (j, c)),
            }
        }
        self.fix.add(&fix_stats);
        self.epochs += report.epochs as u64;
        if let Some(n) = newest {
            self.learned_through_ns = Some(self.learned_through_ns.map_or(n, |a| a.max(n)));
        }
        report.learned_transitions = self.learned_transitions();
        report.fix_error = self.fix_error(options);
        Ok(report)
    }
}

impl HabitModel {
    /// [`HabitReport::strength_gain`]: each segment's moves as the uniform reachability sees
    /// them (one E-step with no habits, so nothing learned leaks into what is scored), the
    /// even segments' plus the model's counts predicting the odd segments', and the reverse.
    fn strength_gains(
        &self,
        site: &Site,
        reach: &ReachTable,
        segments: &[Segment],
        options: &HabitOptions,
    ) -> Result<Vec<StrengthGain>, HabitError> {
        let uniform = HabitModel::new(site);
        let none = BTreeMap::new();
        // Each segment's moves, and the two halves' summed.
        let mut moves: Vec<BTreeMap<(u32, u32), f64>> = Vec::with_capacity(segments.len());
        let mut halves = [BTreeMap::new(), BTreeMap::new()];
        for (k, segment) in segments.iter().enumerate() {
            let mut fix = FixStatistics::default();
            let mut own = BTreeMap::new();
            segment.expect(site, &uniform, &none, FixError::default(), options, &mut own, &mut fix)?;
            for (&key, &c) in &own {
                *halves[k % 2].entry(key).or_insert(0.0) += c;
            }
            moves.push(own);
        }
        // Per held-out segment and strength: (Σ c, Σ c·v) of the per-move gains v weighted by
        // the expected count c of each move. Moves within a segment are not independent (one
        // walk), so the standard error is taken over segments: the ratio estimator's variance
        // Σ_s (Σ c·v − ḡ Σ c)² / (Σ c)², the delta-method form of a cluster jackknife.
        let mut per_segment = vec![vec![[0.0f64; 2]; STRENGTHS.len()]; segments.len()];
        for half in 0..2 {
            // The other half's counts (with the model's), by row.
            let mut rows: BTreeMap<u32, BTreeMap<u32, f64>> = BTreeMap::new();
            for (&i, row) in &self.rows {
                rows.entry(i).or_default().extend(row.iter().copied());
            }
            for (&(i, j), &c) in &halves[1 - half] {
                *rows.entry(i).or_default().entry(j).or_insert(0.0) += c;
            }
            for (segment, sums) in moves.iter().zip(per_segment.iter_mut()).skip(half).step_by(2) {
                for (&(i, j), &c) in segment {
                    let train_row = rows.get(&i);
                    let count = |k: u32| train_row.and_then(|r| r.get(&k).copied()).unwrap_or(0.0);
                    let rings = Rings::of(reach, i as usize, site.spacing_m(), count);
                    let Some(&(_, d)) =
                        reach.reachable(i as usize, reach.radius_m()).iter().find(|e| e.0 == j)
                    else {
                        continue;
                    };
                    for (sum, &kappa) in sums.iter_mut().zip(&STRENGTHS) {
                        let v = (rings.probability(d, count(j), kappa) * rings.size(d)).ln();
                        sum[0] += c;
                        sum[1] += c * v;
                    }
                }
            }
        }
        Ok(STRENGTHS
            .iter()
            .enumerate()
            .map(|(k, &kappa)| {
                let clusters: Vec<(f64, f64)> = per_segment.iter().map(|s| (s[k][0], s[k][1])).collect();
                let (gain, standard_error) = clustered_ratio(&clusters).unwrap_or((0.0, 0.0));
                StrengthGain { strength: kappa, gain, standard_error }
            })
            .collect())
    }
}

/// The ratio estimate r = Σ y / Σ w over clusters of (w, y), and its standard error
/// √(Σ (y − r w)²) / Σ w, the delta-method form of a cluster jackknife: for means over units
/// that are not independent within a cluster (the moves of one segment, the epochs of one
/// walk). `None` when Σ w ≤ 0.
pub fn clustered_ratio(clusters: &[(f64, f64)]) -> Option<(f64, f64)> {
    let n: f64 = clusters.iter().map(|c| c.0).sum();
    if n.is_nan() || n <= 0.0 {
        return None;
    }
    let ratio = clusters.iter().map(|c| c.1).sum::<f64>() / n;
    let variance = clusters.iter().map(|c| (c.1 - ratio * c.0).powi(2)).sum::<f64>() / (n * n);
    Some((ratio, variance.sqrt()))
}

/// Runs of `records` with no gap over `max_gap_s`.
fn split<'a>(records: &[&'a EpochRecord], max_gap_s: f64) -> Vec<Vec<&'a EpochRecord>> {
    let mut runs: Vec<Vec<&EpochRecord>> = Vec::new();
    for &r in records {
        let new_run = match runs.last().and_then(|run| run.last()) {
            Some(last) => {
                r.timestamp_ns <= last.timestamp_ns
                    || (r.timestamp_ns - last.timestamp_ns) as f64 * 1e-9 > max_gap_s
            }
            None => true,
        };
        if new_run {
            runs.push(Vec::new());
        }
        if let Some(run) = runs.last_mut() {
            run.push(r);
        }
    }
    runs
}

/// One epoch's observation.
struct Observation {
    floor: Option<usize>,
    x: f64,
    y: f64,
    sigma: f64,
    fix: Option<PositionFix>,
}

/// A segment of epochs and the states it involves.
struct Segment {
    /// Time of its last epoch, ns.
    last_ns: u64,
    /// Global state indices, ascending.
    states: Vec<u32>,
    epochs: Vec<Observation>,
    /// (epoch, local states) of the feedback.
    known: Vec<(usize, Vec<u32>)>,
    /// Allowed pairs, local indices, row by row: (local to, global to).
    pairs: Vec<Vec<u32>>,
}

impl Segment {
    fn new(site: &Site, reach: &ReachTable, run: &[&EpochRecord], options: &HabitOptions) -> Option<Self> {
        let spacing = site.spacing_m();
        let epochs: Vec<Observation> = run
            .iter()
            .map(|r| match &r.input {
                EpochInput::Fix(f) => Observation {
                    floor: f.floor,
                    x: f.x,
                    y: f.y,
                    sigma: fix::sigma_m(f.accuracy_m, spacing),
                    fix: Some(*f),
                },
                _ => Observation {
                    floor: Some(r.floor),
                    x: r.x,
                    y: r.y,
                    sigma: fix::sigma_m(r.accuracy_m.max(f64::MIN_POSITIVE), spacing),
                    fix: None,
                },
            })
            .collect();
        let mut wanted = vec![false; site.states().len()];
        for o in &epochs {
            // A fix's σ may be widened by the learned spread: take its candidates generously.
            let reach_m = CANDIDATE_SIGMAS * o.sigma * if o.fix.is_some() { 2.0 } else { 1.0 };
            for (i, s) in site.states().iter().enumerate() {
                if o.floor.map_or(true, |f| f == s.floor)
                    && (s.position.x - o.x).hypot(s.position.y - o.y) <= reach_m
                {
                    wanted[i] = true;
                }
            }
        }
        for r in run {
            for &s in r.allowed.iter().flatten() {
                if let Some(w) = wanted.get_mut(s as usize) {
                    *w = true;
                }
            }
        }
        let states: Vec<u32> = (0..wanted.len() as u32).filter(|&i| wanted[i as usize]).collect();
        if states.is_empty() || states.len() > options.max_segment_states {
            return None;
        }
        let local = |g: u32| states.binary_search(&g).ok().map(|k| k as u32);
        let known = run
            .iter()
            .enumerate()
            .filter_map(|(t, r)| {
                r.allowed.as_ref().map(|a| (t, a.iter().filter_map(|&g| local(g)).collect::<Vec<u32>>()))
            })
            .filter(|(_, a)| !a.is_empty())
            .collect();
        let pairs = states
            .iter()
            .map(|&g| {
                let mut to: Vec<u32> = reach
                    .reachable(g as usize, reach.radius_m())
                    .iter()
                    .filter_map(|&(j, _)| local(j))
                    .collect();
                to.sort_unstable();
                to.dedup();
                to
            })
            .collect();
        let last_ns = run.last().map_or(0, |r| r.timestamp_ns);
        Some(Self { last_ns, states, epochs, known, pairs })
    }

    /// One E-step over this segment under the prior `model` plus this pass's current `learned`
    /// counts; adds the expected counts to `next` and the fix statistics to `next_fix`.
    /// Returns (ln p(o | θ), restarts).
    #[allow(clippy::too_many_arguments)]
    fn expect(
        &self,
        site: &Site,
        model: &HabitModel,
        learned: &BTreeMap<(u32, u32), f64>,
        fix_error: FixError,
        options: &HabitOptions,
        next: &mut BTreeMap<(u32, u32), f64>,
        next_fix: &mut FixStatistics,
    ) -> Result<(f64, usize), HabitError> {
        let n = self.states.len();
        let rows: Vec<Vec<(u32, f64)>> = self
            .pairs
            .iter()
            .enumerate()
            .map(|(a, to)| {
                let gi = self.states[a];
                let weights: Vec<f64> = to
                    .iter()
                    .map(|&b| {
                        let gj = self.states[b as usize];
                        model.count(gi, gj)
                            + learned.get(&(gi, gj)).copied().unwrap_or(0.0)
                            + options.pseudocount
                    })
                    .collect();
                let total: f64 = weights.iter().sum();
                to.iter().zip(weights).map(|(&b, w)| (b, w / total)).collect()
            })
            .collect();
        let chain = Chain::new(vec![1.0 / n as f64; n], SparseTransition::from_rows(rows)?)?;
        let mut values = Vec::with_capacity(n * self.epochs.len());
        for o in &self.epochs {
            let (bx, by, spread) = match o.fix {
                Some(_) => (fix_error.bias_m[0], fix_error.bias_m[1], fix_error.spread),
                None => (0.0, 0.0, 1.0),
            };
            let sigma = o.sigma * spread;
            for &g in &self.states {
                let s = &site.states()[g as usize];
                values.push(if o.floor.is_some_and(|f| f != s.floor) {
                    f64::NEG_INFINITY
                } else {
                    let (dx, dy) = (o.x - bx - s.position.x, o.y - by - s.position.y);
                    -0.5 * (dx * dx + dy * dy) / (sigma * sigma) - 2.0 * sigma.ln()
                });
            }
        }
        let mut emissions = EpochMatrix::new(n, values)?;
        let known: Vec<crate::hmm::learn::Known> = self
            .known
            .iter()
            .map(|(t, s)| crate::hmm::learn::Known { epoch: *t, states: s.clone() })
            .collect();
        emissions.pin(&known)?;
        // Any epoch may restart the chain: feedback the habits rule out, and an estimate that
        // changed floor away from the stairs (the engine's own floor decision can jump).
        let restartable: Vec<usize> = (1..self.epochs.len()).collect();
        let sequences = [(emissions, restartable)];
        let counts = expected_counts(&chain, &sequences, |_, t, gamma| {
            let o = &self.epochs[t];
            if o.fix.is_none() {
                return;
            }
            let w = 1.0 / (o.sigma * o.sigma);
            let mut residual = [0.0; 2];
            let mut square = 0.0;
            let mut mass = 0.0;
            for (a, &g) in gamma.iter().enumerate() {
                if g == 0.0 {
                    continue;
                }
                let s = &site.states()[self.states[a] as usize];
                let r = [o.x - s.position.x, o.y - s.position.y];
                residual[0] += g * r[0];
                residual[1] += g * r[1];
                let d = [r[0] - fix_error.bias_m[0], r[1] - fix_error.bias_m[1]];
                square += g * (d[0] * d[0] + d[1] * d[1]) * 0.5 * w;
                mass += g;
            }
            if mass > 0.0 {
                next_fix.fixes += mass;
                next_fix.weight += mass * w;
                next_fix.weighted_residual[0] += residual[0] * w;
                next_fix.weighted_residual[1] += residual[1] * w;
                next_fix.normalised_square += square;
            }
        })?;
        let transition = chain.transition();
        for a in 0..n {
            let range = transition.row_range(a);
            let (dest, _) = transition.row(a);
            for (k, &b) in range.zip(dest) {
                let c = counts.transitions[k];
                if c > 0.0 {
                    *next.entry((self.states[a], self.states[b as usize])).or_insert(0.0) += c;
                }
            }
        }
        Ok((counts.log_likelihood, counts.restarts))
    }
}

/// The learned transitions as multipliers, for the engine's reach table. The moves from i are
/// grouped in rings of equal walking distance (one grid spacing wide): how far the user went
/// in an epoch is the motion's to say (Hoang eq. 11), so a habit only says which way. Row i's
/// multiplier for j in ring r is h_ij = n_r (c_ij + κ) / (c_r + n_r κ), the learned
/// probability of j within its ring over the uniform 1/n_r, where n_r is the number of states
/// in the ring and c_r their summed counts; a ring with no count, and a state with no learned
/// count, keep h = 1.
#[derive(Clone, Debug, Default)]
pub struct HabitPrior {
    /// Index into `rows` per state, `u32::MAX` for none.
    row_of: Vec<u32>,
    rows: Vec<PriorRow>,
}

#[derive(Clone, Debug)]
struct PriorRow {
    /// Multiplier of every reachable state without a learned count.
    default: f64,
    /// (j ascending, h_ij).
    entries: Vec<(u32, f64)>,
}

impl HabitPrior {
    /// The multipliers of `model` over `reach`, at the model's strength (none without one).
    pub fn new(model: &HabitModel, reach: &ReachTable, spacing_m: f64) -> Self {
        let n = reach.state_count();
        let mut row_of = vec![u32::MAX; n];
        let mut rows = Vec::new();
        let Some(kappa) = model.strength else { return Self::default() };
        for (&i, learned) in &model.rows {
            let Some(slot) = row_of.get_mut(i as usize) else { continue };
            let count = |j: u32| learned.binary_search_by_key(&j, |e| e.0).map_or(0.0, |k| learned[k].1);
            let rings = Rings::of(reach, i as usize, spacing_m, count);
            if rings.total() <= 0.0 {
                continue;
            }
            let mut entries: Vec<(u32, f64)> = reach
                .reachable(i as usize, reach.radius_m())
                .iter()
                .map(|&(j, d)| (j, rings.probability(d, count(j), kappa) * rings.size(d)))
                .collect();
            entries.sort_unstable_by_key(|e| e.0);
            entries.dedup_by_key(|e| e.0);
            *slot = rows.len() as u32;
            rows.push(PriorRow { default: 1.0, entries });
        }
        Self { row_of, rows }
    }

    /// Whether it changes nothing.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Multiplies row `i`'s explicit entries by h_ij, keeping their sum.
    pub fn apply(&self, i: usize, row: &mut [(u32, f64)]) {
        let Some(prior) = self.row_of.get(i).and_then(|&k| self.rows.get(k as usize)) else { return };
        let before: f64 = row.iter().map(|e| e.1).sum();
        let mut after = 0.0;
        for (j, a) in row.iter_mut() {
            let h =
                prior.entries.binary_search_by_key(j, |e| e.0).map_or(prior.default, |k| prior.entries[k].1);
            // A model's values are bounded (MAX_COUNT), so h is finite; guard anyway.
            *a *= if h.is_finite() { h } else { 1.0 };
            after += *a;
        }
        if after > 0.0 && before > 0.0 {
            let scale = before / after;
            for e in row.iter_mut() {
                e.1 *= scale;
            }
        }
    }
}

/// A transition with the habits multiplied in.
pub struct Habitual<'a> {
    /// The motion-based transition.
    pub inner: &'a dyn Transition,
    /// The learned multipliers.
    pub prior: &'a HabitPrior,
}

impl Transition for Habitual<'_> {
    fn row(&self, i: usize, row: &mut Vec<(u32, f64)>) -> f64 {
        let floor = self.inner.row(i, row);
        self.prior.apply(i, row);
        floor
    }
}

/// The moves from one state grouped by walking distance: ring k holds the states whose walking
/// distance rounds to k grid spacings.
struct Rings {
    spacing_m: f64,
    /// Per ring: (states, summed count).
    rings: BTreeMap<u32, (f64, f64)>,
}

impl Rings {
    fn of(reach: &ReachTable, i: usize, spacing_m: f64, count: impl Fn(u32) -> f64) -> Self {
        let mut rings: BTreeMap<u32, (f64, f64)> = BTreeMap::new();
        for &(j, d) in reach.reachable(i, reach.radius_m()) {
            let ring = rings.entry(Self::ring(f64::from(d), spacing_m)).or_default();
            ring.0 += 1.0;
            ring.1 += count(j);
        }
        Self { spacing_m, rings }
    }

    fn ring(walk_m: f64, spacing_m: f64) -> u32 {
        (walk_m / spacing_m.max(1e-9)).round().clamp(0.0, f64::from(u32::MAX)) as u32
    }

    fn get(&self, walk_m: f32) -> (f64, f64) {
        self.rings.get(&Self::ring(f64::from(walk_m), self.spacing_m)).copied().unwrap_or((1.0, 0.0))
    }

    /// States in the ring at `walk_m`.
    fn size(&self, walk_m: f32) -> f64 {
        self.get(walk_m).0
    }

    /// The learned probability of a move with count `c` within its ring at strength κ; the
    /// uniform 1/n_r in a ring with no count.
    fn probability(&self, walk_m: f32, c: f64, kappa: f64) -> f64 {
        let (n, total) = self.get(walk_m);
        if total <= 0.0 {
            1.0 / n
        } else {
            (c + kappa) / (total + n * kappa)
        }
    }

    /// All counts.
    fn total(&self) -> f64 {
        self.rings.values().map(|r| r.1).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::clustered_ratio;

    /// By hand: clusters (w, y) = (1, 2) and (3, 2) give r = 4/4 = 1, residuals 2 − 1 = 1 and
    /// 2 − 3 = −1, standard error √2 / 4; no weight gives none.
    #[test]
    fn clustered_ratio_by_hand() {
        let (r, se) = clustered_ratio(&[(1.0, 2.0), (3.0, 2.0)]).unwrap();
        assert!((r - 1.0).abs() < 1e-12 && (se - 2f64.sqrt() / 4.0).abs() < 1e-12, "{r} {se}");
        assert_eq!(clustered_ratio(&[]), None);
        assert_eq!(clustered_ratio(&[(0.0, 5.0)]), None);
        assert_eq!(clustered_ratio(&[(f64::NAN, 1.0)]), None);
    }
}
