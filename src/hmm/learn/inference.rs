//! Exact inference on a [`Chain`] given log-emissions: the scaled forward-backward recursion
//! (El Gemayel §III-A.1, eqs. 8-9, with the scaling of Rabiner's tutorial §V-A), the smoothed
//! posteriors, the log-likelihood, and the Viterbi path with its log-probability.

use super::chain::Chain;
use super::LearnError;

/// Probabilities below this are set to zero in the forward variables and in the predicted
/// distribution. It keeps every scaled backward variable below 1/1e-300 (they satisfy
/// α̂_t(i) β̂_t(i) ≤ 1), so nothing overflows, and it moves at most N · 1e-300 of mass.
const NEGLIGIBLE: f64 = 1e-300;

/// Below this normaliser an epoch is rescaled in log space: the observation is explained only by
/// states more than ~460 nats worse than the best-explaining reachable one, and a product of
/// such small numbers would lose precision in the subnormal range.
const SMALL_NORMALISER: f64 = 1e-200;

/// A T × N table of numbers, one row per epoch: log-emissions ln p_i(o_t), or posteriors.
#[derive(Clone, Debug, PartialEq)]
pub struct EpochMatrix {
    states: usize,
    values: Vec<f64>,
}

impl EpochMatrix {
    /// A T × N table from its rows, each of `states` entries. For log-emissions, −∞ means "this
    /// state cannot emit this observation"; NaN and +∞ are refused.
    pub fn from_rows(states: usize, rows: &[Vec<f64>]) -> Result<Self, LearnError> {
        let mut values = Vec::with_capacity(states * rows.len());
        for (t, row) in rows.iter().enumerate() {
            if row.len() != states {
                return Err(LearnError::Dimension {
                    what: format!("log_emission[{t}]"),
                    expected: states,
                    got: row.len(),
                });
            }
            values.extend_from_slice(row);
        }
        Self::new(states, values)
    }

    /// A table from its values, epoch after epoch.
    pub fn new(states: usize, values: Vec<f64>) -> Result<Self, LearnError> {
        if states == 0 {
            return Err(LearnError::Empty("states".into()));
        }
        if values.len() % states != 0 {
            return Err(LearnError::Dimension {
                what: "log-emission table".into(),
                expected: values.len().div_ceil(states) * states,
                got: values.len(),
            });
        }
        if let Some(k) = values.iter().position(|v| v.is_nan() || *v == f64::INFINITY) {
            return Err(LearnError::NonFinite {
                what: format!("log_emission[{}][{}]", k / states, k % states),
                value: values[k],
            });
        }
        Ok(Self { states, values })
    }

    /// A table of zeros (internal: filled in place).
    pub(super) fn zeros(states: usize, epochs: usize) -> Self {
        Self { states, values: vec![0.0; states * epochs] }
    }

    /// N.
    pub fn states(&self) -> usize {
        self.states
    }

    /// T.
    pub fn epochs(&self) -> usize {
        self.values.len() / self.states
    }

    /// Row t.
    pub fn row(&self, t: usize) -> &[f64] {
        &self.values[t * self.states..(t + 1) * self.states]
    }

    pub(super) fn row_mut(&mut self, t: usize) -> &mut [f64] {
        &mut self.values[t * self.states..(t + 1) * self.states]
    }

    /// Every value, epoch after epoch.
    pub fn values(&self) -> &[f64] {
        &self.values
    }

    /// The rows as vectors.
    pub fn to_rows(&self) -> Vec<Vec<f64>> {
        self.values.chunks(self.states).map(<[f64]>::to_vec).collect()
    }

    /// User feedback (El Gemayel §IV-C): at each known epoch, states outside the known set get
    /// ln p = −∞. The forward variable α_t is then zero outside the set, as the paper pins it,
    /// and the backward pass, the posteriors and Baum-Welch all condition on s_t ∈ set.
    pub fn pin(&mut self, known: &[Known]) -> Result<(), LearnError> {
        let (n, epochs) = (self.states, self.epochs());
        let mut allowed = vec![false; n];
        for (k, fact) in known.iter().enumerate() {
            if fact.epoch >= epochs {
                return Err(LearnError::Dimension {
                    what: format!("known[{k}].epoch {}", fact.epoch),
                    expected: epochs,
                    got: fact.epoch + 1,
                });
            }
            if fact.states.is_empty() {
                return Err(LearnError::Empty(format!("known[{k}].states")));
            }
            allowed.fill(false);
            for &s in &fact.states {
                let s = s as usize;
                if s >= n {
                    return Err(LearnError::StateOutOfRange {
                        what: format!("known[{k}]"),
                        state: s,
                        states: n,
                    });
                }
                allowed[s] = true;
            }
            for (e, &ok) in self.row_mut(fact.epoch).iter_mut().zip(&allowed) {
                if !ok {
                    *e = f64::NEG_INFINITY;
                }
            }
        }
        Ok(())
    }
}

/// User feedback at one epoch (El Gemayel §IV-C): the true state is one of `states` (one state,
/// or every state of the room the user says they are in).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Known {
    /// Epoch index in its sequence.
    pub epoch: usize,
    /// The states it may be in.
    pub states: Vec<u32>,
}

/// The scaled forward pass: α̂_t = α_t / p(o_1..t) (filtered posteriors), and per epoch the shift
/// m_t and the normaliser c_t with which the scaled emission b̃_t(i) = exp(ln p_i(o_t) − m_t)
/// was used: α̂_t(i) = pred_t(i) · b̃_t(i) / c_t, pred_t = α̂_{t−1} A (π at t = 0).
pub(super) struct Forward {
    pub alpha: EpochMatrix,
    pub shift: Vec<f64>,
    pub normaliser: Vec<f64>,
    /// ln p(o_1..T) = Σ_t (m_t + ln c_t).
    pub log_likelihood: f64,
    /// Epochs at which the chain was restarted (see [`forward_into`]), ascending.
    pub restarts: Vec<usize>,
}

/// Scratch buffers reused across sequences.
#[derive(Default)]
pub(super) struct Scratch {
    pred: Vec<f64>,
    beta: Vec<f64>,
    next_beta: Vec<f64>,
    weight: Vec<f64>,
    gamma: Vec<f64>,
}

/// The forward recursion, `alpha` reused when it has the right shape.
///
/// An epoch in `restartable` (ascending) that no state reachable with probability ≥ 1e-300 can
/// explain restarts the chain instead of failing: its prediction becomes uniform over the
/// states that can emit there, and the transition into it is cut (the backward pass treats
/// the epoch before as the end of a sequence). Baum-Welch passes the epochs with user
/// feedback: a state the user names but the model rules out (its probability underflowed)
/// would otherwise make α_t zero everywhere, and the paper's pinned forward variable 0 / 0.
pub(super) fn forward_into(
    chain: &Chain,
    emissions: &EpochMatrix,
    sequence: usize,
    scratch: &mut Scratch,
    alpha: Option<EpochMatrix>,
    restartable: &[usize],
) -> Result<Forward, LearnError> {
    let n = chain.states();
    check_shape(n, emissions)?;
    let epochs = emissions.epochs();
    let mut alpha = match alpha {
        Some(a) if a.states == n && a.epochs() == epochs => a,
        _ => EpochMatrix::zeros(n, epochs),
    };
    let (mut shift, mut normaliser) = (Vec::with_capacity(epochs), Vec::with_capacity(epochs));
    let transition = chain.transition();
    let pred = &mut scratch.pred;
    let mut log_likelihood = 0.0;
    let mut restarts = Vec::new();
    for t in 0..epochs {
        pred.clear();
        if t == 0 {
            pred.extend_from_slice(chain.initial());
        } else {
            pred.resize(n, 0.0);
            let previous = alpha.row(t - 1);
            for (i, &a) in previous.iter().enumerate() {
                if a == 0.0 {
                    continue;
                }
                let (to, p) = transition.row(i);
                for (&j, &a_ij) in to.iter().zip(p) {
                    pred[j as usize] += a * a_ij;
                }
            }
        }
        for p in pred.iter_mut() {
            if *p < NEGLIGIBLE {
                *p = 0.0;
            }
        }
        let e = emissions.row(t);
        // m_t: the best emission among reachable states, so every b̃ ≤ 1.
        let best = |pred: &[f64]| {
            pred.iter().zip(e).filter(|(&p, _)| p > 0.0).map(|(_, &e)| e).fold(f64::NEG_INFINITY, f64::max)
        };
        let mut m = best(pred);
        if m == f64::NEG_INFINITY {
            let possible = e.iter().filter(|&&v| v > f64::NEG_INFINITY).count();
            if t == 0 || possible == 0 || restartable.binary_search(&t).is_err() {
                return Err(LearnError::Impossible { sequence, epoch: t });
            }
            for (p, &v) in pred.iter_mut().zip(e) {
                *p = if v > f64::NEG_INFINITY { 1.0 / possible as f64 } else { 0.0 };
            }
            m = best(pred);
            restarts.push(t);
        }
        let row = alpha.row_mut(t);
        let mut c = 0.0;
        for ((w, &p), &e) in row.iter_mut().zip(pred.iter()).zip(e) {
            *w = if p > 0.0 { p * (e - m).exp() } else { 0.0 };
            c += *w;
        }
        if c < SMALL_NORMALISER {
            // The best-explaining states are barely reachable: shift by max_i (ln pred_i + e_i)
            // instead, so that c ≥ 1; b̃ ≤ 1 / pred_i ≤ 1e300 cannot overflow.
            m = pred
                .iter()
                .zip(e)
                .filter(|(&p, _)| p > 0.0)
                .map(|(&p, &e)| p.ln() + e)
                .fold(f64::NEG_INFINITY, f64::max);
            c = 0.0;
            for ((w, &p), &e) in row.iter_mut().zip(pred.iter()).zip(e) {
                *w = if p > 0.0 { p * (e - m).exp() } else { 0.0 };
                c += *w;
            }
        }
        for w in row.iter_mut() {
            *w /= c;
            if *w < NEGLIGIBLE {
                *w = 0.0;
            }
        }
        shift.push(m);
        normaliser.push(c);
        log_likelihood += m + c.ln();
    }
    Ok(Forward { alpha, shift, normaliser, log_likelihood, restarts })
}

fn check_shape(n: usize, emissions: &EpochMatrix) -> Result<(), LearnError> {
    if emissions.states() != n {
        return Err(LearnError::Dimension {
            what: "log_emission[0]".into(),
            expected: n,
            got: emissions.states(),
        });
    }
    if emissions.epochs() == 0 {
        return Err(LearnError::Empty("log_emission".into()));
    }
    Ok(())
}

/// The scaled backward recursion, from the last epoch to the first. For each epoch t it calls
/// `on_epoch(t, γ_t)` with the smoothed posterior γ_t(i) = α̂_t(i) β̂_t(i) (eq. 8) and, when
/// `counts` is given (one slot per allowed transition), adds Σ_t ξ_t(i, j) (eq. 9) to it.
///
/// β̂_t(i) = Σ_j a_ij b̃_{t+1}(j) β̂_{t+1}(j) / c_{t+1}, β̂_T = 1, is computed only where
/// α̂_t(i) > 0: elsewhere γ and ξ vanish, and no state with α̂_t > 0 can lead to a state with
/// α̂_{t+1} = 0 through a positive transition and emission, so those β̂ are never needed.
pub(super) fn backward(
    chain: &Chain,
    emissions: &EpochMatrix,
    forward: &Forward,
    scratch: &mut Scratch,
    mut counts: Option<&mut [f64]>,
    mut on_epoch: impl FnMut(usize, &[f64]),
) {
    let n = chain.states();
    let epochs = emissions.epochs();
    let transition = chain.transition();
    let Scratch { beta, next_beta, weight, gamma, .. } = scratch;
    let last = forward.alpha.row(epochs - 1);
    beta.clear();
    beta.extend(last.iter().map(|&a| if a > 0.0 { 1.0 } else { 0.0 }));
    on_epoch(epochs - 1, last);
    let (to_all, p_all) = (transition.destinations(), transition.probabilities());
    for t in (0..epochs - 1).rev() {
        if forward.restarts.binary_search(&(t + 1)).is_ok() {
            // The chain restarted at t + 1: epoch t ends a segment, β̂_t = 1, no ξ_t.
            let alpha = forward.alpha.row(t);
            beta.clear();
            beta.extend(alpha.iter().map(|&a| if a > 0.0 { 1.0 } else { 0.0 }));
            on_epoch(t, alpha);
            continue;
        }
        std::mem::swap(beta, next_beta);
        // w_j = b̃_{t+1}(j) β̂_{t+1}(j), zero where α̂_{t+1}(j) = 0.
        let (m, c) = (forward.shift[t + 1], forward.normaliser[t + 1]);
        weight.clear();
        weight.extend(
            forward
                .alpha
                .row(t + 1)
                .iter()
                .zip(emissions.row(t + 1))
                .zip(next_beta.iter())
                .map(|((&a, &e), &b)| if a > 0.0 { (e - m).exp() * b } else { 0.0 }),
        );
        let alpha = forward.alpha.row(t);
        beta.clear();
        beta.resize(n, 0.0);
        gamma.clear();
        gamma.resize(n, 0.0);
        for (i, &a) in alpha.iter().enumerate() {
            if a == 0.0 {
                continue;
            }
            let range = transition.row_range(i);
            let mut s = 0.0;
            for k in range.clone() {
                s += p_all[k] * weight[to_all[k] as usize];
            }
            beta[i] = s / c;
            gamma[i] = a * beta[i];
            if let Some(counts) = counts.as_deref_mut() {
                let f = a / c;
                for k in range {
                    counts[k] += f * p_all[k] * weight[to_all[k] as usize];
                }
            }
        }
        on_epoch(t, gamma);
    }
}

/// The result of [`forward_backward`].
#[derive(Clone, Debug, PartialEq)]
pub struct Posterior {
    /// ln p(o_1..T) (the paper's p(o | θ) = Σ_i α_i(T), in logs).
    pub log_likelihood: f64,
    /// P(s_t = i | o_1..t): the forward algorithm's output (§III-B).
    pub filtered: EpochMatrix,
    /// P(s_t = i | o_1..T): eq. 8.
    pub smoothed: EpochMatrix,
}

/// Filtered and smoothed posteriors and the log-likelihood of one sequence. Feedback, if any,
/// is applied to the emissions first with [`EpochMatrix::pin`].
///
/// Probabilities are scaled per epoch (Rabiner §V-A), in linear space with each epoch's
/// emissions shifted by their largest reachable value, so nothing underflows however long the
/// sequence or however far apart the log-emissions; probabilities below 1e-300 are dropped.
pub fn forward_backward(chain: &Chain, log_emission: &EpochMatrix) -> Result<Posterior, LearnError> {
    let mut scratch = Scratch::default();
    let forward = forward_into(chain, log_emission, 0, &mut scratch, None, &[])?;
    let mut smoothed = EpochMatrix::zeros(chain.states(), log_emission.epochs());
    backward(chain, log_emission, &forward, &mut scratch, None, |t, gamma| {
        smoothed.row_mut(t).copy_from_slice(gamma);
    });
    Ok(Posterior { log_likelihood: forward.log_likelihood, filtered: forward.alpha, smoothed })
}

/// What [`expected_counts`] summed over its sequences.
#[derive(Clone, Debug, PartialEq)]
pub struct ExpectedCounts {
    /// ln p(o | θ) summed over the sequences.
    pub log_likelihood: f64,
    /// Σ_t ξ_t(i, j) (eq. 9) per allowed transition, in the order of
    /// [`SparseTransition::probabilities`](super::SparseTransition::probabilities).
    pub transitions: Vec<f64>,
    /// Expected sequence starts per state (γ_1).
    pub initial: Vec<f64>,
    /// Epochs at which a sequence was restarted on feedback the model ruled out.
    pub restarts: usize,
}

/// The E-step of Baum-Welch for any emission model: each sequence is given by its
/// log-emissions (feedback already applied with [`EpochMatrix::pin`]) and the epochs at which
/// the chain may restart when the model rules the observation out (see
/// [`FitOptions::restart_on_contradicted_feedback`](super::FitOptions); pass the feedback
/// epochs, or none). `on_epoch(sequence, t, γ_t)` sees every smoothed posterior, for the
/// caller's own emission statistics. [`fit`](super::fit) runs the same recursions for its
/// Gaussian mixtures; the live engine's habit learning (`crate::habits`) uses this with
/// emissions that change from epoch to epoch.
pub fn expected_counts(
    chain: &Chain,
    sequences: &[(EpochMatrix, Vec<usize>)],
    mut on_epoch: impl FnMut(usize, usize, &[f64]),
) -> Result<ExpectedCounts, LearnError> {
    let mut scratch = Scratch::default();
    let mut counts = ExpectedCounts {
        log_likelihood: 0.0,
        transitions: vec![0.0; chain.transition().allowed()],
        initial: vec![0.0; chain.states()],
        restarts: 0,
    };
    let mut alpha = None;
    for (s, (emissions, restartable)) in sequences.iter().enumerate() {
        let forward = forward_into(chain, emissions, s, &mut scratch, alpha.take(), restartable)?;
        counts.log_likelihood += forward.log_likelihood;
        counts.restarts += forward.restarts.len();
        let initial = &mut counts.initial;
        backward(chain, emissions, &forward, &mut scratch, Some(&mut counts.transitions), |t, gamma| {
            if t == 0 {
                for (p, &g) in initial.iter_mut().zip(gamma) {
                    *p += g;
                }
            }
            on_epoch(s, t, gamma);
        });
        alpha = Some(forward.alpha);
    }
    Ok(counts)
}

/// The most likely state sequence and its log-probability ln p(s_1..T, o_1..T), by max-product
/// in log space over the allowed transitions. Ties go to the lowest state index.
pub fn viterbi(chain: &Chain, log_emission: &EpochMatrix) -> Result<(Vec<u32>, f64), LearnError> {
    let n = chain.states();
    check_shape(n, log_emission)?;
    let epochs = log_emission.epochs();
    let transition = chain.transition();
    let ln_a: Vec<f64> = transition.probabilities().iter().map(|p| p.ln()).collect();
    let to = transition.destinations();
    let mut delta: Vec<f64> =
        chain.initial().iter().zip(log_emission.row(0)).map(|(p, e)| p.ln() + e).collect();
    let mut next = vec![f64::NEG_INFINITY; n];
    let mut back = vec![0u32; n * epochs];
    let alive = |d: &[f64]| d.iter().any(|&v| v > f64::NEG_INFINITY);
    if !alive(&delta) {
        return Err(LearnError::Impossible { sequence: 0, epoch: 0 });
    }
    for t in 1..epochs {
        next.fill(f64::NEG_INFINITY);
        let back_t = &mut back[t * n..(t + 1) * n];
        for (i, &d) in delta.iter().enumerate() {
            if d == f64::NEG_INFINITY {
                continue;
            }
            for k in transition.row_range(i) {
                let j = to[k] as usize;
                let v = d + ln_a[k];
                if v > next[j] {
                    next[j] = v;
                    back_t[j] = i as u32;
                }
            }
        }
        for (v, &e) in next.iter_mut().zip(log_emission.row(t)) {
            *v += e;
        }
        if !alive(&next) {
            return Err(LearnError::Impossible { sequence: 0, epoch: t });
        }
        std::mem::swap(&mut delta, &mut next);
    }
    let (mut state, mut best) = (0, f64::NEG_INFINITY);
    for (i, &d) in delta.iter().enumerate() {
        if d > best {
            (state, best) = (i, d);
        }
    }
    let mut path = vec![0u32; epochs];
    for t in (0..epochs).rev() {
        path[t] = state as u32;
        if t > 0 {
            state = back[t * n + state] as usize;
        }
    }
    Ok((path, best))
}

/// Everything `waymark hmm decode` prints.
#[derive(Clone, Debug, PartialEq)]
pub struct Decoded {
    /// The forward-backward result.
    pub posterior: Posterior,
    /// The Viterbi path.
    pub viterbi: Vec<u32>,
    /// ln p(path, o_1..T).
    pub viterbi_log_prob: f64,
}

/// [`forward_backward`] and [`viterbi`] on one sequence.
pub fn decode(chain: &Chain, log_emission: &EpochMatrix) -> Result<Decoded, LearnError> {
    let posterior = forward_backward(chain, log_emission)?;
    let (viterbi, viterbi_log_prob) = viterbi(chain, log_emission)?;
    Ok(Decoded { posterior, viterbi, viterbi_log_prob })
}

#[cfg(test)]
mod tests {
    use super::super::chain::SparseTransition;
    use super::*;
    use approx::assert_relative_eq;

    fn chain(initial: Vec<f64>, a: &[Vec<f64>]) -> Chain {
        Chain::new(initial, SparseTransition::from_dense(a).unwrap()).unwrap()
    }

    /// Every path enumerated: p(o), P(s_t | o_1..t), P(s_t | o_1..T), best path.
    #[allow(clippy::type_complexity)]
    fn enumerate(
        initial: &[f64],
        a: &[Vec<f64>],
        e: &[Vec<f64>],
    ) -> (f64, Vec<Vec<f64>>, Vec<Vec<f64>>, Vec<u32>) {
        let (n, t_len) = (initial.len(), e.len());
        let mut smoothed = vec![vec![0.0; n]; t_len];
        let mut prefix = vec![vec![0.0; n]; t_len];
        let (mut total, mut best) = (0.0, (f64::NEG_INFINITY, vec![]));
        for code in 0..n.pow(t_len as u32) {
            let path: Vec<usize> = (0..t_len).map(|t| (code / n.pow(t as u32)) % n).collect();
            let mut p = initial[path[0]] * e[0][path[0]].exp();
            // P(s_1..t, o_1..t) summed over the continuations weighs each prefix once per
            // completion; divide by the number of completions.
            let mut prefix_p = vec![p];
            for t in 1..t_len {
                p *= a[path[t - 1]][path[t]] * e[t][path[t]].exp();
                prefix_p.push(p);
            }
            for t in 0..t_len {
                smoothed[t][path[t]] += p;
                if path[t + 1..].iter().all(|&s| s == 0) {
                    prefix[t][path[t]] += prefix_p[t];
                }
            }
            total += p;
            if p.ln() > best.0 {
                best = (p.ln(), path.iter().map(|&s| s as u32).collect());
            }
        }
        let norm = |rows: Vec<Vec<f64>>| {
            rows.into_iter().map(|r| {
                let s: f64 = r.iter().sum();
                r.into_iter().map(|v| v / s).collect()
            })
        };
        (total.ln(), norm(prefix).collect(), norm(smoothed).collect(), best.1)
    }

    #[test]
    fn matches_enumeration_with_structural_zeros() {
        let initial = vec![0.5, 0.3, 0.2];
        let a = vec![vec![0.7, 0.3, 0.0], vec![0.0, 0.4, 0.6], vec![0.5, 0.0, 0.5]];
        let e = vec![
            vec![-1.0, -2.0, -0.5],
            vec![-3.0, -0.2, -1.0],
            vec![-0.1, -4.0, -2.0],
            vec![-2.0, -2.0, -0.3],
        ];
        let (ll, filtered, smoothed, path) = enumerate(&initial, &a, &e);
        let decoded = decode(&chain(initial, &a), &EpochMatrix::from_rows(3, &e).unwrap()).unwrap();
        assert_relative_eq!(decoded.posterior.log_likelihood, ll, max_relative = 1e-13);
        for t in 0..4 {
            for i in 0..3 {
                assert_relative_eq!(decoded.posterior.filtered.row(t)[i], filtered[t][i], epsilon = 1e-14);
                assert_relative_eq!(decoded.posterior.smoothed.row(t)[i], smoothed[t][i], epsilon = 1e-14);
            }
        }
        assert_eq!(decoded.viterbi, path);
    }

    #[test]
    fn emissions_thousands_of_nats_apart_stay_finite() {
        // The best-explaining state is reachable only with probability 1e-250 each time.
        let a = vec![vec![1.0 - 1e-250, 1e-250], vec![0.5, 0.5]];
        let rows: Vec<Vec<f64>> =
            (0..200).map(|t| if t % 2 == 0 { vec![-5000.0, 0.0] } else { vec![0.0, -3000.0] }).collect();
        let chain = chain(vec![1.0, 0.0], &a);
        let e = EpochMatrix::from_rows(2, &rows).unwrap();
        let p = forward_backward(&chain, &e).unwrap();
        assert!(p.log_likelihood.is_finite());
        for t in 0..200 {
            for m in [&p.filtered, &p.smoothed] {
                let s: f64 = m.row(t).iter().sum();
                assert_relative_eq!(s, 1.0, epsilon = 1e-12);
                assert!(m.row(t).iter().all(|v| v.is_finite() && *v >= 0.0));
            }
        }
        let (path, lp) = viterbi(&chain, &e).unwrap();
        assert!(lp.is_finite());
        assert_eq!(path.len(), 200);
    }

    #[test]
    fn pinned_epochs_condition_the_posterior() {
        let initial = vec![1.0 / 3.0; 3];
        let a = vec![vec![0.8, 0.1, 0.1], vec![0.1, 0.8, 0.1], vec![0.1, 0.1, 0.8]];
        let rows = vec![vec![-1.0, -1.2, -3.0], vec![-2.0, -0.5, -1.0], vec![-1.0, -1.0, -1.0]];
        let mut e = EpochMatrix::from_rows(3, &rows).unwrap();
        e.pin(&[Known { epoch: 1, states: vec![0, 2] }]).unwrap();
        let p = forward_backward(&chain(initial.clone(), &a), &e).unwrap();
        assert_eq!(p.filtered.row(1)[1], 0.0);
        assert_eq!(p.smoothed.row(1)[1], 0.0);
        // The same as enumerating with state 1 impossible at epoch 1.
        let mut masked = rows.clone();
        masked[1][1] = -1e4;
        let (ll, _, smoothed, _) = enumerate(&initial, &a, &masked);
        assert_relative_eq!(p.log_likelihood, ll, max_relative = 1e-12);
        assert_relative_eq!(p.smoothed.row(0)[2], smoothed[0][2], epsilon = 1e-14);
        let bad = |k: Known| e.clone().pin(&[k]).unwrap_err();
        assert!(matches!(bad(Known { epoch: 3, states: vec![0] }), LearnError::Dimension { .. }));
        assert!(matches!(bad(Known { epoch: 0, states: vec![5] }), LearnError::StateOutOfRange { .. }));
        assert!(matches!(bad(Known { epoch: 0, states: vec![] }), LearnError::Empty(_)));
    }

    #[test]
    fn impossible_sequences_are_errors_not_nans() {
        let c = chain(vec![1.0, 0.0], &[vec![1.0, 0.0], vec![0.0, 1.0]]);
        let e = EpochMatrix::from_rows(2, &[vec![0.0, 0.0], vec![f64::NEG_INFINITY, 0.0]]).unwrap();
        assert_eq!(forward_backward(&c, &e).unwrap_err(), LearnError::Impossible { sequence: 0, epoch: 1 });
        assert_eq!(viterbi(&c, &e).unwrap_err(), LearnError::Impossible { sequence: 0, epoch: 1 });
        assert!(matches!(
            EpochMatrix::from_rows(2, &[vec![f64::NAN, 0.0]]),
            Err(LearnError::NonFinite { .. })
        ));
        assert!(matches!(EpochMatrix::from_rows(2, &[vec![0.0]]), Err(LearnError::Dimension { .. })));
        let e3 = EpochMatrix::from_rows(3, &[vec![0.0; 3]]).unwrap();
        assert!(matches!(forward_backward(&c, &e3), Err(LearnError::Dimension { .. })));
    }
}
