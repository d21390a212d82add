//! The forward recursion (Hoang eq. 3) over a normalised posterior, with emissions kept in log
//! space until the update: it cannot underflow over hours of epochs, nor when the likelihoods
//! of a scan with a hundred transmitters sit near -1000 nats and hundreds apart.

use super::transition::{predict, predict_and_viterbi_step, Transition};
use super::viterbi::{BackPointers, ViterbiWindow};

/// Why a step could not be taken; the filter is left as it was.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum FilterError {
    /// The emission vector has the wrong length.
    #[error("emission has {got} states, the filter {expected}")]
    Length {
        /// States in the filter.
        expected: usize,
        /// States in the emission.
        got: usize,
    },
    /// No state can explain the observation (every emission is -inf or NaN).
    #[error("no state has a finite likelihood")]
    Degenerate,
}

/// The posterior P(s_t | observations so far) over N states.
///
/// A new posterior is computed in a scratch buffer and swapped in, so the one it replaces is
/// still there: after [`checkpoint`](Self::checkpoint), [`rollback`](Self::rollback) brings
/// it back at the cost of a pointer swap, not a copy of N values.
#[derive(Clone)]
pub struct ForwardFilter {
    posterior: Vec<f64>,
    predicted: Vec<f64>,
    weights: Vec<f64>,
    row: Vec<(u32, f64)>,
    /// The posterior of the checkpoint, once something replaced it (`Saved::Kept`).
    saved: Vec<f64>,
    checkpoint: Saved,
}

/// Where the checkpoint's posterior is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Saved {
    /// No checkpoint.
    None,
    /// A checkpoint, and the posterior has not changed since.
    Current,
    /// A checkpoint, and its posterior is in `saved`.
    Kept,
}

/// The state only: the scratch buffers hold nothing a later step reads.
impl std::fmt::Debug for ForwardFilter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ForwardFilter").field("posterior", &self.posterior).finish_non_exhaustive()
    }
}

impl ForwardFilter {
    /// A filter over `n` states with the uniform prior.
    pub fn new(n: usize) -> Self {
        let mut filter = Self {
            posterior: vec![0.0; n],
            predicted: vec![0.0; n],
            weights: vec![0.0; n],
            row: Vec::new(),
            saved: vec![0.0; n],
            checkpoint: Saved::None,
        };
        filter.reset();
        filter
    }

    /// Back to the uniform prior.
    pub fn reset(&mut self) {
        if self.checkpoint == Saved::Current {
            std::mem::swap(&mut self.posterior, &mut self.saved);
            self.checkpoint = Saved::Kept;
        }
        let n = self.posterior.len();
        self.posterior.fill(1.0 / n as f64);
    }

    /// Remembers the posterior, so that [`rollback`](Self::rollback) can return to it until
    /// [`commit`](Self::commit).
    pub fn checkpoint(&mut self) {
        self.checkpoint = Saved::Current;
    }

    /// Forgets the checkpoint.
    pub fn commit(&mut self) {
        self.checkpoint = Saved::None;
    }

    /// Back to the posterior of the checkpoint, whatever happened since; nothing without one.
    pub fn rollback(&mut self) {
        if self.checkpoint == Saved::Kept {
            std::mem::swap(&mut self.posterior, &mut self.saved);
        }
        self.checkpoint = Saved::None;
    }

    /// Makes `new` (one of the scratch buffers, holding the new posterior) the posterior. The
    /// old posterior goes to `saved` if it is the checkpoint's, else to `new` as scratch.
    fn replace(posterior: &mut Vec<f64>, new: &mut Vec<f64>, saved: &mut Vec<f64>, checkpoint: &mut Saved) {
        std::mem::swap(posterior, new);
        if *checkpoint == Saved::Current {
            std::mem::swap(new, saved);
            *checkpoint = Saved::Kept;
        }
    }

    /// The prediction of the latest step, before its observation (not normalised).
    pub fn predicted(&self) -> &[f64] {
        &self.predicted
    }

    /// The current posterior; sums to 1.
    pub fn posterior(&self) -> &[f64] {
        &self.posterior
    }

    /// A prediction with no observation: the posterior becomes the predicted distribution.
    pub fn predict(&mut self, transition: &dyn Transition) {
        predict(transition, &self.posterior, &mut self.predicted, &mut self.row);
        let total: f64 = self.predicted.iter().sum();
        for p in self.predicted.iter_mut() {
            *p /= total;
        }
        Self::replace(&mut self.posterior, &mut self.predicted, &mut self.saved, &mut self.checkpoint);
    }

    /// One epoch: predict with `transition` (none at the first epoch, or when no time has
    /// passed), weight by `exp(ln_emission)`, normalise. Returns ln p(o_t | o_1..t-1), the
    /// evidence of this observation given the past.
    pub fn step(
        &mut self,
        transition: Option<&dyn Transition>,
        ln_emission: &[f64],
    ) -> Result<f64, FilterError> {
        let n = self.posterior.len();
        if ln_emission.len() != n {
            return Err(FilterError::Length { expected: n, got: ln_emission.len() });
        }
        match transition {
            Some(t) => predict(t, &self.posterior, &mut self.predicted, &mut self.row),
            None => self.predicted.copy_from_slice(&self.posterior),
        }
        self.update(ln_emission)
    }

    /// [`ViterbiWindow::step`] and then [`step`](Self::step) with the same transition, with
    /// each row of the transition written once for both (`predict_and_viterbi_step`); the
    /// results are exactly those of the two calls.
    pub fn step_with_viterbi(
        &mut self,
        viterbi: &mut ViterbiWindow,
        timestamp_ns: u64,
        transition: &dyn Transition,
        ln_emission: &[f64],
    ) -> Result<f64, FilterError> {
        let n = self.posterior.len();
        if ln_emission.len() != n || viterbi.state_count() != n || viterbi.is_empty() {
            viterbi.step(timestamp_ns, transition, ln_emission);
            return self.step(Some(transition), ln_emission);
        }
        let (posterior, predicted, row) = (&self.posterior, &mut self.predicted, &mut self.row);
        viterbi.step_with(timestamp_ns, ln_emission, |delta, out, back| match back {
            BackPointers::Narrow(back) => {
                predict_and_viterbi_step(transition, (posterior, predicted), (delta, out, back), row)
            }
            BackPointers::Wide(back) => {
                predict_and_viterbi_step(transition, (posterior, predicted), (delta, out, back), row)
            }
        });
        self.update(ln_emission)
    }

    /// The update of [`step`](Self::step), with the prediction in `predicted`.
    fn update(&mut self, ln_emission: &[f64]) -> Result<f64, FilterError> {
        // Fast path, in linear space: w_j = pred_j · exp(e_j - max e), one exponential per
        // state. It underflows only when every likely state explains the observation more
        // than ~700 nats worse than the best one; then the log-space path below decides.
        let max_e = ln_emission.iter().copied().filter(|e| !e.is_nan()).fold(f64::NEG_INFINITY, f64::max);
        if max_e.is_finite() {
            let mut total = 0.0;
            for ((w, &p), &e) in self.weights.iter_mut().zip(&self.predicted).zip(ln_emission) {
                // A state the epoch rules out (-inf) weighs 0 without an exponential, and one
                // at the maximum (every state, between scans) its prediction: exp(0) = 1.
                *w = if e.is_nan() || e == f64::NEG_INFINITY {
                    0.0
                } else if e == max_e {
                    p
                } else {
                    p * (e - max_e).exp()
                };
                total += *w;
            }
            if total > 1e-250 {
                for w in self.weights.iter_mut() {
                    *w /= total;
                }
                Self::replace(&mut self.posterior, &mut self.weights, &mut self.saved, &mut self.checkpoint);
                return Ok(max_e + total.ln());
            }
        }
        // w_j = ln pred_j + ln p(o | j); the max is subtracted before exponentiating.
        let mut max = f64::NEG_INFINITY;
        for ((w, &p), &e) in self.weights.iter_mut().zip(&self.predicted).zip(ln_emission) {
            *w = if p > 0.0 && !e.is_nan() { p.ln() + e } else { f64::NEG_INFINITY };
            max = max.max(*w);
        }
        if !max.is_finite() {
            return Err(FilterError::Degenerate);
        }
        let mut total = 0.0;
        for w in self.weights.iter_mut() {
            *w = (*w - max).exp();
            total += *w;
        }
        // total ≥ 1: the maximum contributes exp(0).
        for w in self.weights.iter_mut() {
            *w /= total;
        }
        Self::replace(&mut self.posterior, &mut self.weights, &mut self.saved, &mut self.checkpoint);
        Ok(max + total.ln())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use proptest::prelude::*;

    use crate::hmm::transition::DenseTransition as Dense;

    /// P(s_T = j | o_1..T) by summing over every path: the definition, no recursion.
    fn enumerate(initial: &[f64], a: &[Vec<f64>], emissions: &[Vec<f64>]) -> Vec<f64> {
        let n = initial.len();
        let t_len = emissions.len();
        let mut result = vec![0.0; n];
        let paths = n.pow(t_len as u32);
        for code in 0..paths {
            let path: Vec<usize> = (0..t_len).map(|t| (code / n.pow(t as u32)) % n).collect();
            let mut p = initial[path[0]] * emissions[0][path[0]].exp();
            for t in 1..t_len {
                p *= a[path[t - 1]][path[t]] * emissions[t][path[t]].exp();
            }
            result[path[t_len - 1]] += p;
        }
        let total: f64 = result.iter().sum();
        result.iter().map(|r| r / total).collect()
    }

    #[test]
    fn matches_brute_force_on_a_tiny_hmm() {
        let a = vec![vec![0.7, 0.2, 0.1], vec![0.3, 0.4, 0.3], vec![0.0, 0.5, 0.5]];
        let emissions =
            [vec![-1.0, -2.0, -0.5], vec![-3.0, -0.2, -1.0], vec![-0.1, -4.0, -2.0], vec![-2.0, -2.0, -0.3]];
        let mut filter = ForwardFilter::new(3);
        let dense = Dense(a.clone());
        for (t, e) in emissions.iter().enumerate() {
            let transition: Option<&dyn Transition> = if t == 0 { None } else { Some(&dense) };
            filter.step(transition, e).unwrap();
            let expected = enumerate(&[1.0 / 3.0; 3], &a, &emissions[..=t]);
            for j in 0..3 {
                assert_relative_eq!(filter.posterior()[j], expected[j], epsilon = 1e-12);
            }
        }
    }

    #[test]
    fn survives_likelihoods_hundreds_of_nats_apart_for_hours() {
        let a = vec![vec![0.9, 0.1], vec![0.1, 0.9]];
        let dense = Dense(a);
        let mut filter = ForwardFilter::new(2);
        // 24 h of 1.5 s epochs with 100-transmitter-like log-likelihoods.
        for t in 0..57_600 {
            let e = if t % 2 == 0 { [-1000.0, -1400.0] } else { [-1250.0, -1000.0] };
            let evidence = filter.step(Some(&dense), &e).unwrap();
            assert!(evidence.is_finite());
        }
        let p = filter.posterior();
        assert_relative_eq!(p[0] + p[1], 1.0, epsilon = 1e-12);
        assert!(p.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn degenerate_observation_leaves_the_filter_unchanged() {
        let mut filter = ForwardFilter::new(2);
        filter.step(None, &[-1.0, -2.0]).unwrap();
        let before = filter.posterior().to_vec();
        assert_eq!(filter.step(None, &[f64::NEG_INFINITY, f64::NAN]), Err(FilterError::Degenerate));
        assert_eq!(filter.posterior(), &before[..]);
        assert!(matches!(filter.step(None, &[0.0]), Err(FilterError::Length { .. })));
    }

    #[test]
    fn rollback_returns_to_the_checkpoint_and_commit_keeps_the_step() {
        let dense = Dense(vec![vec![0.9, 0.1], vec![0.2, 0.8]]);
        let mut filter = ForwardFilter::new(2);
        filter.step(None, &[-1.0, -2.0]).unwrap();
        let before = filter.posterior().to_vec();
        // Every way the posterior changes, the log-space path of `step` included.
        filter.checkpoint();
        filter.step(Some(&dense), &[-3.0, -0.5]).unwrap();
        filter.predict(&dense);
        filter.reset();
        filter.step(Some(&dense), &[-800.0, -2000.0]).unwrap();
        assert_ne!(filter.posterior(), &before[..]);
        filter.rollback();
        assert_eq!(filter.posterior(), &before[..]);
        filter.checkpoint();
        filter.reset();
        filter.rollback();
        assert_eq!(filter.posterior(), &before[..]);
        filter.rollback(); // no checkpoint: nothing
        assert_eq!(filter.posterior(), &before[..]);
        // Committed, the step stays, and the filter goes on as one that never saved anything.
        let mut twin = filter.clone();
        filter.checkpoint();
        filter.step(Some(&dense), &[-3.0, -0.5]).unwrap();
        filter.commit();
        filter.rollback();
        twin.step(Some(&dense), &[-3.0, -0.5]).unwrap();
        for e in [[-0.1, -4.0], [-2.0, -1.0]] {
            filter.step(Some(&dense), &e).unwrap();
            twin.step(Some(&dense), &e).unwrap();
        }
        assert_eq!(format!("{filter:?}"), format!("{twin:?}"));
    }

    proptest! {
        #[test]
        fn posterior_is_a_distribution(emissions in proptest::collection::vec(proptest::collection::vec(-2000.0f64..0.0, 4), 1..30)) {
            let a = vec![vec![0.25; 4]; 4];
            let dense = Dense(a);
            let mut filter = ForwardFilter::new(4);
            for e in &emissions {
                filter.step(Some(&dense), e).unwrap();
                let sum: f64 = filter.posterior().iter().sum();
                prop_assert!((sum - 1.0).abs() < 1e-12);
                prop_assert!(filter.posterior().iter().all(|p| p.is_finite() && *p >= 0.0));
            }
        }
    }
}
