//! Exact inference on a [`Chain`] given log-emissions: the forward-backward recursion in log
//! space (El Gemayel §III-A.1, eqs. 8-9, normalised per epoch as in Rabiner's tutorial §V-A),
//! the smoothed posteriors, the log-likelihood, and the Viterbi path with its log-probability.

use super::chain::{Chain, SparseTransition};
use super::LearnError;

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
        if !values.len().is_multiple_of(states) {
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

/// Below this, a sum taken in linear space is taken again in log space: its terms
/// exp(ln x − shift) may have lost digits in the subnormal range, or underflowed to zero,
/// which is at most the number of terms times 1e-307 in all, a relative 1e-100 of a sum above
/// this bound.
const SMALL_SUM: f64 = 1e-200;

/// ln Σ exp(x) of the finite and −∞ values given (−∞ for none or all −∞).
fn log_sum_exp(values: impl Iterator<Item = f64> + Clone) -> f64 {
    let max = values.clone().fold(f64::NEG_INFINITY, f64::max);
    if max == f64::NEG_INFINITY {
        return max;
    }
    max + values.map(|v| (v - max).exp()).sum::<f64>().ln()
}

/// The transition matrix by columns: for each state j, its predecessors i and ln a_ij. The
/// forward recursion sums over predecessors; only the epochs it has to redo in log space need
/// them, so they are built on first use.
struct Predecessors {
    start: Vec<usize>,
    from: Vec<u32>,
    log_probability: Vec<f64>,
}

impl Predecessors {
    fn new(transition: &SparseTransition) -> Self {
        let n = transition.states();
        let to = transition.destinations();
        let p = transition.probabilities();
        let mut start = vec![0usize; n + 1];
        for &j in to {
            start[j as usize + 1] += 1;
        }
        for j in 0..n {
            start[j + 1] += start[j];
        }
        let mut next = start.clone();
        let (mut from, mut log_probability) = (vec![0u32; to.len()], vec![0.0; to.len()]);
        for i in 0..n {
            for k in transition.row_range(i) {
                let slot = &mut next[to[k] as usize];
                from[*slot] = i as u32;
                log_probability[*slot] = p[k].ln();
                *slot += 1;
            }
        }
        Self { start, from, log_probability }
    }

    /// ln Σ_i exp(ln α̂(i)) a_ij over the predecessors i of j.
    fn log_predicted(&self, j: usize, log_alpha: &[f64]) -> f64 {
        let range = self.start[j]..self.start[j + 1];
        log_sum_exp(
            self.from[range.clone()]
                .iter()
                .zip(&self.log_probability[range])
                .map(|(&i, &ln_a)| log_alpha[i as usize] + ln_a),
        )
    }
}

/// The forward pass in log space, normalised per epoch (Rabiner §V-A's scaling, in logs):
/// ln α̂_t = ln α_t − ln p(o_1..t), the log filtered posteriors (−∞ where impossible), and
/// ln c_t = ln p(o_t | o_1..t−1), so that ln α̂_t(j) = ln pred_t(j) + ln p_j(o_t) − ln c_t with
/// pred_t = α̂_{t−1} A (π at t = 0).
pub(super) struct Forward {
    pub log_alpha: EpochMatrix,
    pub log_normaliser: Vec<f64>,
    /// ln p(o_1..T) = Σ_t ln c_t.
    pub log_likelihood: f64,
    /// Epochs at which the chain was restarted (see [`forward_into`]), ascending.
    pub restarts: Vec<usize>,
}

/// Scratch buffers reused across sequences.
#[derive(Default)]
pub(super) struct Scratch {
    linear: Vec<f64>,
    sum: Vec<f64>,
    beta: Vec<f64>,
    next_beta: Vec<f64>,
    weight: Vec<f64>,
    gamma: Vec<f64>,
}

/// The forward recursion, `log_alpha` reused when it has the right shape.
///
/// Each state's forward variable is kept as a logarithm, so none is lost however far its
/// emissions lie below the others' (a state thousands of nats behind at one epoch may explain
/// every later one). The prediction α̂_{t−1} A is summed in linear space over the allowed
/// transitions, with exp(ln α̂_{t−1}) ≤ 1; a state whose sum falls below [`SMALL_SUM`], where
/// that may have lost digits, is summed again over its predecessors by log-sum-exp.
///
/// An epoch in `restartable` (ascending) that no reachable state can explain restarts the
/// chain instead of failing: its prediction becomes uniform over the states that can emit
/// there, and the transition into it is cut (the backward pass treats the epoch before as the
/// end of a sequence). Baum-Welch passes the epochs with user feedback: a state the user names
/// but the model rules out would otherwise make α_t zero everywhere, and the paper's pinned
/// forward variable 0 / 0.
pub(super) fn forward_into(
    chain: &Chain,
    emissions: &EpochMatrix,
    sequence: usize,
    scratch: &mut Scratch,
    log_alpha: Option<EpochMatrix>,
    restartable: &[usize],
) -> Result<Forward, LearnError> {
    let n = chain.states();
    check_shape(n, emissions)?;
    let epochs = emissions.epochs();
    let mut log_alpha = match log_alpha {
        Some(a) if a.states == n && a.epochs() == epochs => a,
        _ => EpochMatrix::zeros(n, epochs),
    };
    let mut log_normaliser = Vec::with_capacity(epochs);
    let transition = chain.transition();
    let mut predecessors: Option<Predecessors> = None;
    let Scratch { linear, sum, .. } = scratch;
    let mut log_likelihood = 0.0;
    let mut restarts = Vec::new();
    for t in 0..epochs {
        let e = emissions.row(t);
        // Row t first holds ln pred_t(j) + ln p_j(o_t), the unnormalised ln α̂_t.
        if t == 0 {
            let row = log_alpha.row_mut(0);
            for ((w, &p), &e) in row.iter_mut().zip(chain.initial()).zip(e) {
                *w = p.ln() + e;
            }
        } else {
            let (before, after) = log_alpha.values.split_at_mut(t * n);
            let previous = &before[(t - 1) * n..];
            let row = &mut after[..n];
            linear.clear();
            linear.extend(previous.iter().map(|&l| l.exp()));
            sum.clear();
            sum.resize(n, 0.0);
            for (i, &a) in linear.iter().enumerate() {
                if a == 0.0 {
                    continue;
                }
                let (to, p) = transition.row(i);
                for (&j, &a_ij) in to.iter().zip(p) {
                    sum[j as usize] += a * a_ij;
                }
            }
            for (j, ((w, &s), &e)) in row.iter_mut().zip(sum.iter()).zip(e).enumerate() {
                *w = if e == f64::NEG_INFINITY {
                    f64::NEG_INFINITY
                } else if s >= SMALL_SUM {
                    s.ln() + e
                } else {
                    predecessors
                        .get_or_insert_with(|| Predecessors::new(transition))
                        .log_predicted(j, previous)
                        + e
                };
            }
        }
        let row = log_alpha.row_mut(t);
        let mut log_c = log_sum_exp(row.iter().copied());
        if log_c == f64::NEG_INFINITY {
            let possible = e.iter().filter(|&&v| v > f64::NEG_INFINITY).count();
            if t == 0 || possible == 0 || restartable.binary_search(&t).is_err() {
                return Err(LearnError::Impossible { sequence, epoch: t });
            }
            let uniform = -(possible as f64).ln();
            for (w, &e) in row.iter_mut().zip(e) {
                *w = uniform + e;
            }
            log_c = log_sum_exp(row.iter().copied());
            restarts.push(t);
        }
        for w in row.iter_mut() {
            *w -= log_c;
        }
        log_normaliser.push(log_c);
        log_likelihood += log_c;
    }
    Ok(Forward { log_alpha, log_normaliser, log_likelihood, restarts })
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

/// The backward recursion in log space, from the last epoch to the first. For each epoch t it
/// calls `on_epoch(t, γ_t)` with the smoothed posterior γ_t(i) = α̂_t(i) β̂_t(i) (eq. 8) and,
/// when `counts` is given (one slot per allowed transition), adds Σ_t ξ_t(i, j) (eq. 9) to it,
/// ξ_t(i, j) = α̂_t(i) a_ij p_j(o_t+1) β̂_t+1(j) / c_t+1.
///
/// ln β̂_t(i) = ln Σ_j a_ij exp(v_j), v_j = ln p_j(o_t+1) + ln β̂_t+1(j) − ln c_t+1, β̂_T = 1.
/// The sum is taken in linear space with the weights w_j = exp(v_j − max v) ≤ 1 and, for a row
/// whose sum falls below [`SMALL_SUM`], again by log-sum-exp. It is computed only where
/// α̂_t(i) > 0: elsewhere γ and ξ vanish, and a state with α̂_t > 0 cannot lead to one with
/// α̂_t+1 = 0 through a positive transition and emission, so those β̂ are never needed.
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
    let Scratch { linear, beta, next_beta, weight, gamma, .. } = scratch;
    // A segment's last epoch: β̂ = 1, γ = α̂.
    let end = |log_alpha: &[f64], beta: &mut Vec<f64>, gamma: &mut Vec<f64>| {
        beta.clear();
        beta.extend(log_alpha.iter().map(|&a| if a > f64::NEG_INFINITY { 0.0 } else { f64::NEG_INFINITY }));
        gamma.clear();
        gamma.extend(log_alpha.iter().map(|&a| a.exp()));
    };
    end(forward.log_alpha.row(epochs - 1), beta, gamma);
    on_epoch(epochs - 1, gamma);
    let (to_all, p_all) = (transition.destinations(), transition.probabilities());
    for t in (0..epochs - 1).rev() {
        let log_alpha = forward.log_alpha.row(t);
        if forward.restarts.binary_search(&(t + 1)).is_ok() {
            // The chain restarted at t + 1: epoch t ends a segment, no ξ_t.
            end(log_alpha, beta, gamma);
            on_epoch(t, gamma);
            continue;
        }
        std::mem::swap(beta, next_beta);
        let log_c = forward.log_normaliser[t + 1];
        // v_j, −∞ where α̂_t+1(j) = 0 (β̂_t+1(j) was not computed there).
        weight.clear();
        weight.extend(
            forward
                .log_alpha
                .row(t + 1)
                .iter()
                .zip(emissions.row(t + 1))
                .zip(next_beta.iter())
                .map(|((&a, &e), &b)| if a > f64::NEG_INFINITY { e + b - log_c } else { f64::NEG_INFINITY }),
        );
        let shift = weight.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let shift = if shift > f64::NEG_INFINITY { shift } else { 0.0 };
        linear.clear();
        linear.extend(weight.iter().map(|&v| (v - shift).exp()));
        beta.clear();
        beta.resize(n, f64::NEG_INFINITY);
        gamma.clear();
        gamma.resize(n, 0.0);
        for (i, &a) in log_alpha.iter().enumerate() {
            if a == f64::NEG_INFINITY {
                continue;
            }
            let range = transition.row_range(i);
            let mut s = 0.0;
            for k in range.clone() {
                s += p_all[k] * linear[to_all[k] as usize];
            }
            let linear_sum = s >= SMALL_SUM;
            beta[i] = if linear_sum {
                shift + s.ln()
            } else {
                log_sum_exp(range.clone().map(|k| p_all[k].ln() + weight[to_all[k] as usize]))
            };
            gamma[i] = (a + beta[i]).exp();
            if let Some(counts) = counts.as_deref_mut() {
                if linear_sum {
                    // α̂_t(i) e^shift = γ_t(i) / s ≤ 1 / SMALL_SUM is finite, and each ξ below
                    // is at most γ_t(i).
                    let f = (a + shift).exp();
                    for k in range {
                        counts[k] += f * p_all[k] * linear[to_all[k] as usize];
                    }
                } else {
                    for k in range {
                        counts[k] += (a + p_all[k].ln() + weight[to_all[k] as usize]).exp();
                    }
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
/// Forward and backward variables are kept as logarithms, normalised per epoch (Rabiner
/// §V-A's scaling, in logs), so no state's probability underflows however long the sequence or
/// however far apart the log-emissions; only the posteriors returned are exponentiated (those
/// below ~1e-308 of an epoch's mass come out as 0). A probability is exactly zero only where
/// the chain or the emissions make it so.
pub fn forward_backward(chain: &Chain, log_emission: &EpochMatrix) -> Result<Posterior, LearnError> {
    let mut scratch = Scratch::default();
    let forward = forward_into(chain, log_emission, 0, &mut scratch, None, &[])?;
    let mut smoothed = EpochMatrix::zeros(chain.states(), log_emission.epochs());
    backward(chain, log_emission, &forward, &mut scratch, None, |t, gamma| {
        smoothed.row_mut(t).copy_from_slice(gamma);
    });
    let mut filtered = forward.log_alpha;
    for v in &mut filtered.values {
        *v = v.exp();
    }
    Ok(Posterior { log_likelihood: forward.log_likelihood, filtered, smoothed })
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
        alpha = Some(forward.log_alpha);
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

/// Everything a decode reports.
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
mod tests;
