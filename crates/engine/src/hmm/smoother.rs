//! Exact fixed-lag smoothing: P(s_{t-L} | o_1..t), the forward posterior of L epochs ago
//! corrected by the L epochs since. It is El Gemayel et al.'s eq. 8, γ ∝ αβ, with the
//! backward induction of their §III-A run over the lag only, in the form that needs only what
//! the forward pass computed (the Rauch-Tung-Striebel form):
//!
//! γ_t(i) ∝ α_t(i) · Σ_j a_ij · γ_{t+1}(j) / q_{t+1}(j),   q_{t+1}(j) = Σ_i α_t(i) · a_ij,
//!
//! with α the filtered posterior (Hoang eq. 3), a the step's transition and q its prediction:
//! the induction's p_j(o_{t+1}) · β_j(t+1) is γ_{t+1}(j) / q_{t+1}(j) up to a constant. A step
//! back sums over the states the later γ holds mass on, through the rows of the states α holds
//! mass on.
//!
//! A step keeps α, q and the step's transition model (a few numbers); the rows are written
//! again when smoothing, so memory grows with the posterior's support, not with the rows'.
//! A row that lists no state the later γ holds mass on is not written when the model gives
//! its bounds: it contributes its floor weight alone (docs/tuning.md#fixed-lag).

use super::transition::{prune_mass, Transition};
use std::collections::VecDeque;

/// A state's α below `CUT_MASS / N` is not kept: the mass left out of a step is at most
/// `CUT_MASS`, and so is what the smoothed estimate could have moved there (larger cuts,
/// measured: docs/results.md#the-epoch-as-apps-run-it).
pub const CUT_MASS: f64 = 1e-6;

/// Bytes per state of a step's vectors: (state, α) in single precision, the predicted state
/// and its q in double.
pub const STEP_BYTES_PER_STATE: usize =
    std::mem::size_of::<(u32, f32)>() + std::mem::size_of::<u32>() + std::mem::size_of::<f64>();

/// One forward step as the smoother needs it, with the transition model `M` it stepped with.
#[derive(Clone, Debug)]
struct Step<M> {
    /// The epoch of the prior, ns.
    timestamp_ns: u64,
    model: M,
    /// α_t(i) of the states kept, ascending i (single precision: it only weighs the rows).
    prior: Vec<(u32, f32)>,
    /// The states the next posterior keeps, ascending, and their q_{t+1}(j) (double
    /// precision: a strong scan can leave q of a state it favours below f32's range).
    predicted_at: Vec<u32>,
    predicted: Vec<f64>,
}

/// The last `capacity` forward steps, for [`smooth`](FixedLagSmoother::smooth). `M` is what
/// rebuilds a step's transition (the engine's per-epoch model).
#[derive(Clone, Debug)]
pub struct FixedLagSmoother<M> {
    capacity: usize,
    steps: VecDeque<Step<M>>,
    /// The step [`begin`](Self::begin) started, until [`finish`](Self::finish).
    pending: Option<Step<M>>,
}

/// The states of `posterior` the smoother keeps (at least `CUT_MASS / N`), with their mass.
pub(crate) fn kept(posterior: &[f64]) -> impl Iterator<Item = (u32, f64)> + '_ {
    let cut = CUT_MASS / posterior.len().max(1) as f64;
    posterior.iter().enumerate().filter(move |(_, &p)| p >= cut).map(|(i, &p)| (i as u32, p))
}

impl<M: Clone> FixedLagSmoother<M> {
    /// A smoother over up to `capacity` steps back.
    pub fn new(capacity: usize) -> Self {
        Self { capacity, steps: VecDeque::new(), pending: None }
    }

    /// Forgets every step: the posterior no longer follows from the last by a transition
    /// (a restart, a pinned epoch, a gap bridged, new habits).
    pub fn clear(&mut self) {
        self.steps.clear();
        self.pending = None;
    }

    /// Steps held.
    pub fn len(&self) -> usize {
        self.steps.len()
    }

    /// Whether the next step lets the oldest go.
    pub fn is_full(&self) -> bool {
        self.steps.len() >= self.capacity
    }

    /// The time of the oldest epoch held.
    pub fn oldest_timestamp(&self) -> Option<u64> {
        self.steps.front().map(|s| s.timestamp_ns)
    }

    /// Whether no step is held.
    #[cfg(test)]
    pub fn is_empty(&self) -> bool {
        self.steps.is_empty()
    }

    /// Bytes held by the steps (capacity, not length). Each of a step's three vectors is
    /// reserved for the states it keeps, at most N, so the whole is below
    /// `2 · capacity · N ·` [`STEP_BYTES_PER_STATE`] even where an allocator rounds the
    /// reservation up.
    pub fn memory_bytes(&self) -> usize {
        let bytes = |s: &Step<M>| {
            s.prior.capacity() * std::mem::size_of::<(u32, f32)>()
                + s.predicted_at.capacity() * std::mem::size_of::<u32>()
                + s.predicted.capacity() * std::mem::size_of::<f64>()
        };
        self.steps.iter().map(bytes).sum()
    }

    /// Starts a step from α_t (`posterior`, of the epoch at `timestamp_ns`) with the
    /// transition `model`, before the filter takes it.
    pub fn begin(&mut self, timestamp_ns: u64, posterior: &[f64], model: M) {
        if self.capacity == 0 {
            return;
        }
        let recycled = if self.steps.len() >= self.capacity { self.steps.pop_front() } else { None };
        let (mut prior, mut predicted_at, mut predicted) =
            recycled.map(|s| (s.prior, s.predicted_at, s.predicted)).unwrap_or_default();
        prior.clear();
        predicted_at.clear();
        predicted.clear();
        // Room for exactly the states kept, not doubled: steps after a timer epoch keep every
        // surveyed state (docs/results.md#the-engines-memory-in-use).
        prior.reserve_exact(kept(posterior).count());
        prior.extend(kept(posterior).map(|(i, p)| (i, p as f32)));
        self.pending = Some(Step { timestamp_ns, model, prior, predicted_at, predicted });
    }

    /// Completes the step [`begin`](Self::begin) started, with the filter's prediction and
    /// new posterior.
    pub fn finish(&mut self, predicted: &[f64], posterior: &[f64]) {
        let Some(mut step) = self.pending.take() else { return };
        if predicted.len() != posterior.len() {
            return;
        }
        let count = kept(posterior).count();
        step.predicted_at.reserve_exact(count);
        step.predicted.reserve_exact(count);
        for (j, _) in kept(posterior) {
            step.predicted_at.push(j);
            step.predicted.push(predicted[j as usize]);
        }
        self.steps.push_back(step);
    }

    /// P(s | everything so far) at the epoch `lag` ≥ 1 steps back, into `out` (dense), from
    /// the current `posterior`; `with_transition` hands a step's model's transition to the
    /// closure it is given. Returns that epoch's time, or `None` when fewer than `lag` steps
    /// are held or no state keeps any mass.
    pub fn smooth(
        &self,
        lag: usize,
        posterior: &[f64],
        out: &mut Vec<f64>,
        with_transition: impl Fn(&M, &mut dyn FnMut(&dyn Transition)),
    ) -> Option<u64> {
        let (timestamp_ns, gamma) = self.sweep(lag, posterior, with_transition, |_, _| {})?;
        out.clear();
        out.resize(posterior.len(), 0.0);
        for (i, g) in gamma {
            *out.get_mut(i as usize)? = g;
        }
        Some(timestamp_ns)
    }

    /// The smoothed posterior of each of the `lag` epochs before the current one, newest
    /// first: `each(timestamp, γ)` with γ the states kept and their probabilities, which sum
    /// to one. One backward sweep gives them all, where [`smooth`](Self::smooth) at each lag
    /// would sweep again. Returns the oldest: its time and γ. `None` when `lag` is 0, fewer than
    /// `lag` steps are held or no state keeps any mass (after the epochs given until then).
    pub fn sweep(
        &self,
        lag: usize,
        posterior: &[f64],
        with_transition: impl Fn(&M, &mut dyn FnMut(&dyn Transition)),
        mut each: impl FnMut(u64, &[(u32, f64)]),
    ) -> Option<(u64, Vec<(u32, f64)>)> {
        if lag == 0 || lag > self.steps.len() {
            return None;
        }
        let mut timestamp_ns = 0;
        let n = posterior.len();
        let mut gamma: Vec<(u32, f64)> = kept(posterior).collect();
        let mut ratio = vec![0.0; n];
        let mut row = Vec::new();
        for step in self.steps.iter().rev().take(lag) {
            let mut next = Vec::with_capacity(step.prior.len());
            with_transition(&step.model, &mut |transition| {
                next = back(step, &gamma, transition, &mut ratio, &mut row);
            });
            let sum: f64 = next.iter().map(|(_, g)| g).sum();
            if !(sum > 0.0 && sum.is_finite()) {
                return None;
            }
            for (_, g) in next.iter_mut() {
                *g /= sum;
            }
            gamma = next;
            timestamp_ns = step.timestamp_ns;
            each(timestamp_ns, &gamma);
        }
        Some((timestamp_ns, gamma))
    }
}

/// One step back: γ_t (not normalised) from γ_{t+1}, over the states `step` kept. `ratio` is
/// dense scratch, zero on entry and on return.
fn back<M>(
    step: &Step<M>,
    gamma: &[(u32, f64)],
    transition: &dyn Transition,
    ratio: &mut [f64],
    row: &mut Vec<(u32, f64)>,
) -> Vec<(u32, f64)> {
    // r(j) = γ_{t+1}(j) / q_{t+1}(j); both lists ascend in j.
    let mut total = 0.0;
    let mut predicted = step.predicted_at.iter().zip(&step.predicted).peekable();
    for &(j, g) in gamma {
        while predicted.next_if(|&(&k, _)| k < j).is_some() {}
        let p = predicted.peek().filter(|&&(&k, _)| k == j).map_or(0.0, |&(_, &p)| p);
        if p > 0.0 && (j as usize) < ratio.len() {
            ratio[j as usize] = g / p;
            total += g / p;
        }
    }
    // A row the prediction spread evenly (under `prune_mass`) is 1/N on every j, as the
    // filter stepped with it.
    let (n, prune) = (ratio.len(), prune_mass(transition, ratio.len()));
    // A row none of whose entries holds later mass is its floor weight times the total: its
    // entries need not be weighed. With the model's bounds, the reach lists the row's states
    // and gives its floor weight exactly as the row would, so the result is the same.
    let bounds = transition.bounds();
    let out = step
        .prior
        .iter()
        .map(|&(i, alpha)| {
            let alpha = f64::from(alpha);
            if alpha < prune {
                return (i, alpha * total.max(0.0) / n as f64);
            }
            if let Some(bounds) = &bounds {
                let reach = bounds.table.reachable_within(i as usize, bounds.reach);
                if reach.iter().all(|(j, _)| ratio.get(j as usize).is_none_or(|&r| r == 0.0)) {
                    return (i, alpha * (0.0 + bounds.floor_of(reach.len()) * total.max(0.0)));
                }
            }
            // Σ_j a_ij r(j) over the entries with later mass (`row_on`): an entry without adds
            // exactly nothing to either sum.
            row.clear();
            let floor = transition.row_on(i as usize, ratio, row);
            // The listed entries, and the floor weight on every other j.
            let (mut explicit, mut listed) = (0.0, 0.0);
            for &(j, a) in row.iter() {
                let r = ratio.get(j as usize).copied().unwrap_or(0.0);
                explicit += a * r;
                listed += r;
            }
            (i, alpha * (explicit + floor * (total - listed).max(0.0)))
        })
        .collect();
    for &(j, _) in gamma {
        if let Some(r) = ratio.get_mut(j as usize) {
            *r = 0.0;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hmm::ForwardFilter;
    use approx::assert_relative_eq;

    /// Row i lists itself (`stay`) and the next state round a ring (`on`); every other state
    /// takes the floor weight. `stay` is the step's model, so each step's own rows are tested.
    struct Ring {
        n: usize,
        stay: f64,
    }

    const ON: f64 = 0.3;
    const FLOOR: f64 = 0.02;

    impl Ring {
        fn a(&self, i: usize, j: usize) -> f64 {
            match j {
                _ if j == i => self.stay,
                _ if j == (i + 1) % self.n => ON,
                _ => FLOOR,
            }
        }
    }

    impl Transition for Ring {
        fn row(&self, i: usize, row: &mut Vec<(u32, f64)>) -> f64 {
            row.push((i as u32, self.stay));
            row.push((((i + 1) % self.n) as u32, ON));
            FLOOR
        }
    }

    /// P(s_at | every emission), by summing over every path from the uniform prior.
    fn by_every_path(n: usize, stays: &[f64], emissions: &[Vec<f64>], at: usize) -> Vec<f64> {
        let len = emissions.len();
        let mut marginal = vec![0.0; n];
        for code in 0..n.pow(len as u32) {
            let path: Vec<usize> = (0..len).map(|t| (code / n.pow(t as u32)) % n).collect();
            let mut p = emissions[0][path[0]].exp();
            for t in 1..len {
                p *= Ring { n, stay: stays[t - 1] }.a(path[t - 1], path[t]) * emissions[t][path[t]].exp();
            }
            marginal[path[at]] += p;
        }
        let total: f64 = marginal.iter().sum();
        marginal.iter().map(|m| m / total).collect()
    }

    fn emissions() -> Vec<Vec<f64>> {
        vec![
            vec![-0.2, -1.5, -2.5, -1.0],
            vec![-1.4, -0.3, -2.0, -2.2],
            vec![-2.0, -1.9, -0.3, -0.8],
            vec![-0.9, -2.5, -0.4, -1.7],
            vec![-2.2, -0.6, -1.1, -0.2],
            vec![-0.5, -1.2, -2.9, -0.4],
        ]
    }

    /// Runs the filter over `emissions` with step `t` taking `stays[t - 1]`, the smoother
    /// beside it.
    fn run(stays: &[f64], emissions: &[Vec<f64>], capacity: usize) -> (ForwardFilter, FixedLagSmoother<f64>) {
        let n = emissions[0].len();
        let mut filter = ForwardFilter::new(n);
        let mut smoother = FixedLagSmoother::new(capacity);
        filter.step(None, &emissions[0]).unwrap();
        for (t, e) in emissions.iter().enumerate().skip(1) {
            let stay = stays[t - 1];
            smoother.begin(10 * (t as u64 - 1), filter.posterior(), stay);
            filter.step(Some(&Ring { n, stay }), e).unwrap();
            smoother.finish(filter.predicted(), filter.posterior());
        }
        (filter, smoother)
    }

    #[test]
    fn smoothing_is_the_forward_backward_marginal() {
        let (emissions, stays) = (emissions(), [0.5, 0.1, 0.9, 0.4, 0.6]);
        let last = emissions.len() - 1;
        let (filter, smoother) = run(&stays, &emissions, last);
        assert_eq!(smoother.len(), last);
        let mut out = Vec::new();
        for lag in 1..=last {
            let at = smoother.smooth(lag, filter.posterior(), &mut out, |&stay, f| f(&Ring { n: 4, stay }));
            assert_eq!(at, Some(10 * (last - lag) as u64), "lag {lag}");
            let expected = by_every_path(4, &stays, &emissions, last - lag);
            for (got, want) in out.iter().zip(&expected) {
                assert_relative_eq!(got, want, max_relative = 1e-6);
            }
        }
        // The filtered posterior is the marginal of the newest epoch.
        for (got, want) in filter.posterior().iter().zip(by_every_path(4, &stays, &emissions, last)) {
            assert_relative_eq!(*got, want, max_relative = 1e-6);
        }
        let none = |lag| {
            smoother.smooth(lag, filter.posterior(), &mut out.clone(), |&stay, f| f(&Ring { n: 4, stay }))
        };
        assert_eq!((none(0), none(last + 1)), (None, None));
    }

    #[test]
    fn one_sweep_gives_every_epochs_marginal() {
        let (emissions, stays) = (emissions(), [0.5, 0.1, 0.9, 0.4, 0.6]);
        let last = emissions.len() - 1;
        let (filter, smoother) = run(&stays, &emissions, last);
        let mut seen = Vec::new();
        let oldest = smoother.sweep(
            last,
            filter.posterior(),
            |&stay, f| f(&Ring { n: 4, stay }),
            |t, gamma| {
                seen.push((t, gamma.to_vec()));
            },
        );
        assert_eq!(oldest.map(|o| o.0), Some(0));
        // Newest first: epoch last - 1 down to 0, each the marginal given every emission.
        assert_eq!(seen.len(), last);
        for (k, (t, gamma)) in seen.iter().enumerate() {
            let at = last - 1 - k;
            assert_eq!(*t, 10 * at as u64);
            let expected = by_every_path(4, &stays, &emissions, at);
            let mut dense = [0.0; 4];
            for &(i, g) in gamma {
                dense[i as usize] = g;
            }
            for (got, want) in dense.iter().zip(&expected) {
                assert_relative_eq!(got, want, max_relative = 1e-6);
            }
        }
    }

    #[test]
    fn keeps_the_newest_steps_up_to_its_capacity_and_clear_forgets_them() {
        let (emissions, stays) = (emissions(), [0.5, 0.1, 0.9, 0.4, 0.6]);
        let (filter, mut smoother) = run(&stays, &emissions, 2);
        assert_eq!(smoother.len(), 2);
        assert!(smoother.memory_bytes() > 0);
        assert!(smoother.memory_bytes() <= 2 * 2 * 4 * STEP_BYTES_PER_STATE);
        let mut out = Vec::new();
        let at = smoother.smooth(2, filter.posterior(), &mut out, |&stay, f| f(&Ring { n: 4, stay }));
        assert_eq!(at, Some(30));
        for (got, want) in out.iter().zip(by_every_path(4, &stays, &emissions, 3)) {
            assert_relative_eq!(*got, want, max_relative = 1e-6);
        }
        assert_eq!(
            smoother.smooth(3, filter.posterior(), &mut out, |&stay, f| f(&Ring { n: 4, stay })),
            None
        );
        smoother.clear();
        assert!(smoother.is_empty());
        assert_eq!(
            smoother.smooth(1, filter.posterior(), &mut out, |&stay, f| f(&Ring { n: 4, stay })),
            None
        );
        // A step begun and not finished (the filter refused the observation) is not kept.
        smoother.begin(50, filter.posterior(), 0.5);
        assert!(smoother.is_empty());
        // Nor anything without capacity.
        let (_, none) = run(&stays, &emissions, 0);
        assert!(none.is_empty());
    }
}
