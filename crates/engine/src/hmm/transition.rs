//! Sparse transition models. A model gives, for each state i, the weights a_ij of the states j
//! it names explicitly, and one weight shared by every other state (HIPE eq. 11: every
//! a_ij > 0, so the filter can recover from a wrong track). Prediction and the Viterbi step
//! are written once over that shape, in O(explicit entries + N).

use crate::site::{ReachCut, ReachTable};

/// A transition model (or, with Hoang eq. 14, a transition times a movement likelihood).
pub trait Transition {
    /// Writes the explicit entries (j, a_ij) of row `i` into `row` (cleared first by the
    /// caller) and returns the weight of every state not listed. Each j appears at most once.
    fn row(&self, i: usize, row: &mut Vec<(u32, f64)>) -> f64;

    /// [`row`](Self::row) with only the entries whose j has a non-zero `weights[j]` (within
    /// `weights`) written, in the same order, and the same floor weight: what a sum of
    /// `a_ij · weights[j]` over the row needs, as the fixed-lag smoother's step back takes.
    /// A model that can tell an entry's j before its weight overrides it to weigh only those.
    fn row_on(&self, i: usize, weights: &[f64], row: &mut Vec<(u32, f64)>) -> f64 {
        let has_weight = |j: u32| weights.get(j as usize).is_some_and(|&w| w != 0.0);
        let floor = self.row(i, row);
        row.retain(|&(j, _)| has_weight(j));
        floor
    }

    /// What the Viterbi step may know of this epoch's rows without writing them
    /// ([`RowBounds`]); `None` when the model cannot tell it more cheaply than by the rows.
    fn bounds(&self) -> Option<RowBounds<'_>> {
        None
    }

    /// HIPE's K (eq. 11) when every row has its floor weight at 1/K of its explicit ones:
    /// what the prediction prunes rows by (under 1/(K·N) their mass is spread evenly,
    /// docs/tuning.md#engine-speed). `None`: a model with no such floor, whose rows are
    /// pruned only under 1e-15.
    fn floor_ratio(&self) -> Option<f64> {
        self.bounds().map(|b| b.ratio)
    }
}

/// The rows of a model whose row `i` holds `high_i · f_ij` on the states reachable within
/// `rho_m` and `low_i · floor_factor` elsewhere, with `(high_i, low_i)` HIPE eqs. 5-6 for them
/// and every `ln f_ij ≤ ln_most_factor`: the floor weight of a row (exactly what
/// [`Transition::row`] returns) and a bound on its explicit weights, from the row's reachable
/// count alone. The Viterbi step skips a row whose best explicit weight cannot beat the best
/// path through a floor weight (`viterbi_step`).
#[derive(Clone, Copy, Debug)]
pub struct RowBounds<'a> {
    /// Walking-distance table.
    pub table: &'a ReachTable,
    /// The reach of the rows, cut in `table`.
    pub reach: ReachCut,
    /// HIPE's K.
    pub ratio: f64,
    /// What multiplies `low_i` into the floor weight.
    pub floor_factor: f64,
    /// The largest `ln f_ij`.
    pub ln_most_factor: f64,
}

impl RowBounds<'_> {
    fn reachable(&self, i: usize) -> usize {
        self.table.reachable_within(i, self.reach).len()
    }

    /// The floor weight of a row with `reachable` explicit entries.
    pub fn floor_of(&self, reachable: usize) -> f64 {
        hipe_probabilities(reachable, self.table.state_count(), self.ratio).1 * self.floor_factor
    }

    /// The bound on the ln explicit weights of a row with `reachable` explicit entries.
    fn ln_most_of(&self, reachable: usize) -> f64 {
        hipe_probabilities(reachable, self.table.state_count(), self.ratio).0.ln() + self.ln_most_factor
    }

    /// Row `i`'s floor weight.
    pub fn floor(&self, i: usize) -> f64 {
        self.floor_of(self.reachable(i))
    }

    /// An upper bound on the logarithm of row `i`'s explicit weights.
    pub fn ln_most(&self, i: usize) -> f64 {
        self.ln_most_of(self.reachable(i))
    }
}

/// (ln [`RowBounds::floor`], [`RowBounds::ln_most`]) of rows, by their reachable count: rows
/// with one count share their bounds, and a site's rows have a few hundred counts between
/// them, so the Viterbi step takes each logarithm once per count rather than per row. Both
/// are monotone in the count (HIPE eq. 5), so their largest over every row, `most`, is at
/// one of the counts 1 and N: a row whose path falls short even of that needs no lookup.
struct LnBounds<'b> {
    bounds: &'b RowBounds<'b>,
    by_count: Vec<Option<(f64, f64)>>,
    most: (f64, f64),
}

impl<'b> LnBounds<'b> {
    fn new(bounds: &'b RowBounds<'b>) -> Self {
        let [few, all] = [1, bounds.table.state_count().max(1)].map(|count| Self::ln_of(bounds, count));
        Self { bounds, by_count: Vec::new(), most: (few.0.max(all.0), few.1.max(all.1)) }
    }

    fn ln_of(bounds: &RowBounds, count: usize) -> (f64, f64) {
        (bounds.floor_of(count).ln(), bounds.ln_most_of(count))
    }

    /// Row `i`'s (ln floor weight, bound on its ln explicit weights), exactly as
    /// [`RowBounds`] computes them.
    fn of(&mut self, i: usize) -> (f64, f64) {
        let count = self.bounds.reachable(i);
        if count >= self.by_count.len() {
            self.by_count.resize(count + 1, None);
        }
        let bounds = self.bounds;
        *self.by_count[count].get_or_insert_with(|| Self::ln_of(bounds, count))
    }
}

/// Posterior mass below which a state's row is never expanded: its mass is spread evenly
/// instead, as the row's floor weight would spread most of it. Beam pruning as in every
/// large-vocabulary decoder. With at most N such states the mass moved is below N · 1e-15
/// (1e-11 at 10 000 states). Models with HIPE's floor prune more ([`prune_mass`]).
pub const PRUNE_MASS: f64 = 1e-15;

/// The mass below which [`predict`] spreads a row evenly for `transition` over `n` states:
/// 1/(K·N) for a model whose rows keep HIPE's floor at 1/K of their explicit weights
/// (eq. 11), so that the mass moved in one epoch is at most 1/K, the share of a state out of
/// reach against one within it. HIPE's floor leaves about 1e-7 on every state after an epoch
/// without a scan, and expanding those rows was most of a prediction
/// (docs/tuning.md#engine-speed); never below [`PRUNE_MASS`].
pub fn prune_mass(transition: &dyn Transition, n: usize) -> f64 {
    let by_floor = transition.floor_ratio().filter(|k| *k > 0.0).map(|k| 1.0 / (k * n.max(1) as f64));
    by_floor.map_or(PRUNE_MASS, |m| m.max(PRUNE_MASS))
}

/// A Viterbi back-pointer: a state index, stored in 16 bits on a site of at most 65 536 states
/// ([`ViterbiWindow`](super::ViterbiWindow)) and in 32 beyond.
pub trait BackPointer: Copy {
    /// The back-pointer to state `i`, which must fit.
    fn to_state(i: u32) -> Self;
}

impl BackPointer for u16 {
    fn to_state(i: u32) -> Self {
        debug_assert!(i <= u32::from(u16::MAX));
        i as u16
    }
}

impl BackPointer for u32 {
    fn to_state(i: u32) -> Self {
        i
    }
}

/// `out[j] = Σ_i prior[i] · a_ij`, expanding only rows with at least `prune_mass`: 1/(K·N)
/// for a model with HIPE's K ([`Transition::floor_ratio`]), else 1e-15.
pub fn predict(transition: &dyn Transition, prior: &[f64], out: &mut [f64], row: &mut Vec<(u32, f64)>) {
    expand::<u32>(transition, Some((prior, out)), None, row);
}

/// [`predict`] and [`viterbi_step`] with one transition, each row written once for both: the
/// two expand overlapping sets of rows (the states near the estimate), and writing a row is
/// most of the cost of each. Both results are exactly those of the two calls.
pub fn predict_and_viterbi_step<B: BackPointer>(
    transition: &dyn Transition,
    (prior, predicted): (&[f64], &mut [f64]),
    (delta, out, back): (&[f64], &mut [f64], &mut [B]),
    row: &mut Vec<(u32, f64)>,
) {
    expand(transition, Some((prior, predicted)), Some((delta, out, back)), row);
}

/// Log-probability below the best partial path at which a path is not extended. A row's
/// explicit weights exceed its floor weight by at most K (HIPE eq. 11; 200 000, 12.2 nats)
/// times Hoang's capped movement factor (½ · 3² = 4.5 nats), and the floors of two rows differ
/// by the ratio of their reachable counts (under 100, 4.6 nats), so a path more than 22 nats
/// behind the best can never beat the best path's floor transition: with the default
/// configuration pruning at 50 changes nothing, and pruned and unpruned steps agree in the
/// tests.
pub const VITERBI_BEAM: f64 = 50.0;

/// Margin, nats, by which a row's bound must fall short of the best floor path before the
/// Viterbi step skips it: covers any rounding of `ln` and `exp` between a weight and its
/// bound (a few ulps, far below this), so a skipped row changes nothing.
const BOUND_MARGIN: f64 = 1e-6;

/// One max-product step in log space: `out[j] = max_i (delta[i] + ln a_ij)` and `back[j]` the
/// maximising i.
///
/// Every j can be reached from the best path through a floor weight, so a row whose best
/// explicit weight cannot beat that path (`delta[i] + ln max_j a_ij` below it) never wins an
/// `out[j]`. When the model gives its rows' bounds ([`RowBounds`]) the floor paths
/// are found first and only rows that can win are written; the result, back-pointers and ties
/// included, is the same as expanding every row of the beam.
pub fn viterbi_step<B: BackPointer>(
    transition: &dyn Transition,
    delta: &[f64],
    out: &mut [f64],
    back: &mut [B],
    row: &mut Vec<(u32, f64)>,
) {
    expand(transition, None, Some((delta, out, back)), row);
}

/// The prediction (`forward`: prior, out) and the Viterbi step (`viterbi`: delta, out, back),
/// either or both, in one pass over the rows in state order, so each sum and maximum is taken
/// in the same order whichever of the two run.
#[allow(clippy::type_complexity)]
fn expand<B: BackPointer>(
    transition: &dyn Transition,
    forward: Option<(&[f64], &mut [f64])>,
    viterbi: Option<(&[f64], &mut [f64], &mut [B])>,
    row: &mut Vec<(u32, f64)>,
) {
    let (prior, predicted) = match forward {
        Some((prior, out)) => (prior, Some(out)),
        None => (&[][..], None),
    };
    let (delta, mut scores, mut back) = match viterbi {
        Some((delta, out, back)) => (delta, Some(out), Some(back)),
        None => (&[][..], None, None),
    };
    let n = prior.len().max(delta.len());
    // Prediction: the mass that rows below `prune_mass` and every row's floor spread evenly.
    let prune = prune_mass(transition, prior.len());
    let mut shared = 0.0;
    let uniform = 1.0 / prior.len().max(1) as f64;
    let mut predicted = predicted;
    if let Some(out) = predicted.as_deref_mut() {
        out.fill(0.0);
    }
    // Viterbi: the best predecessor through the shared (floor) weight, valid for every j.
    let (mut floor_best, mut floor_arg) = (f64::NEG_INFINITY, 0u32);
    let best = delta.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let in_beam = |d: f64| d != f64::NEG_INFINITY && d >= best - VITERBI_BEAM;
    if let Some(out) = scores.as_deref_mut() {
        out.fill(f64::NEG_INFINITY);
    }
    let bounds = if delta.is_empty() { None } else { transition.bounds() };
    let bounded = bounds.is_some();
    let mut ln_bounds = bounds.as_ref().map(LnBounds::new);
    if let Some(ln_bounds) = &mut ln_bounds {
        for (i, &d) in delta.iter().enumerate() {
            // Short of the best floor path even through the largest floor weight (BOUND_MARGIN
            // covers the rounding of the logarithms): this row's cannot beat it.
            if !in_beam(d) || d + ln_bounds.most.0 + BOUND_MARGIN < floor_best {
                continue;
            }
            let via_floor = d + ln_bounds.of(i).0;
            if via_floor > floor_best {
                floor_best = via_floor;
                floor_arg = i as u32;
            }
        }
    }
    for i in 0..n {
        let mass = predicted.as_ref().and_then(|_| prior.get(i).copied());
        let expand_mass = match mass {
            Some(p) if p < prune => {
                shared += p * uniform;
                false
            }
            Some(_) => true,
            None => false,
        };
        let d = delta.get(i).copied().filter(|&d| in_beam(d));
        // Skipped only when provably beaten (a NaN bound skips nothing).
        // Beaten by the largest bound of any row with a margin to spare, or else by its own.
        let beaten = |d: f64, b: &mut LnBounds| {
            d + b.most.1 + 2.0 * BOUND_MARGIN < floor_best || d + b.of(i).1 + BOUND_MARGIN < floor_best
        };
        let expand_path = d.is_some_and(|d| !ln_bounds.as_mut().is_some_and(|b| beaten(d, b)));
        if !expand_mass && !expand_path {
            continue;
        }
        row.clear();
        let floor = transition.row(i, row);
        if let (true, Some(p), Some(out)) = (expand_mass, mass, predicted.as_deref_mut()) {
            shared += p * floor;
            for &(j, a) in row.iter() {
                out[j as usize] += p * (a - floor);
            }
        }
        if let (true, Some(d), Some(out), Some(back)) =
            (expand_path, d, scores.as_deref_mut(), back.as_deref_mut())
        {
            if !bounded {
                let via_floor = d + floor.ln();
                if via_floor > floor_best {
                    floor_best = via_floor;
                    floor_arg = i as u32;
                }
            }
            for &(j, a) in row.iter() {
                let v = d + a.ln();
                if v > out[j as usize] {
                    out[j as usize] = v;
                    back[j as usize] = B::to_state(i as u32);
                }
            }
        }
    }
    if let Some(out) = predicted {
        for v in out.iter_mut() {
            *v += shared;
        }
    }
    if let (Some(out), Some(back)) = (scores, back) {
        for (o, b) in out.iter_mut().zip(back.iter_mut()) {
            if floor_best > *o {
                *o = floor_best;
                *b = B::to_state(floor_arg);
            }
        }
    }
}

/// Uniform 1/U over the U states reachable from state i within `rho_m` walking distance
/// (Hoang §6.1), with every other state at 1/K of that (HIPE eqs. 5-6, 11):
/// a_h = K / (U·K + N - U), a_l = a_h / K, so that each row sums to 1.
#[derive(Clone, Copy, Debug)]
pub struct UniformReach<'a> {
    /// Walking-distance table.
    pub table: &'a ReachTable,
    /// Reach this epoch, m (at most the table's radius).
    pub rho_m: f64,
    /// HIPE's K.
    pub ratio: f64,
}

/// HIPE eqs. 5-6: the high and low probabilities of a row with `high_count` of `n` states in
/// the high set and ratio `k`.
pub fn hipe_probabilities(high_count: usize, n: usize, k: f64) -> (f64, f64) {
    let (i, n) = (high_count as f64, n as f64);
    let high = k / (i * k + n - i);
    (high, high / k)
}

impl Transition for UniformReach<'_> {
    fn row(&self, i: usize, row: &mut Vec<(u32, f64)>) -> f64 {
        let reach = self.table.reachable(i, self.rho_m);
        let (high, low) = hipe_probabilities(reach.len(), self.table.state_count(), self.ratio);
        row.extend(reach.iter().map(|(j, _)| (j, high)));
        low
    }

    fn bounds(&self) -> Option<RowBounds<'_>> {
        let (table, ratio) = (self.table, self.ratio);
        Some(RowBounds { table, reach: table.cut(self.rho_m), ratio, floor_factor: 1.0, ln_most_factor: 0.0 })
    }
}

/// A dense transition matrix, as the reference the sparse code is tested against.
#[cfg(test)]
pub(crate) struct DenseTransition(pub Vec<Vec<f64>>);

#[cfg(test)]
impl Transition for DenseTransition {
    fn row(&self, i: usize, row: &mut Vec<(u32, f64)>) -> f64 {
        row.extend(self.0[i].iter().enumerate().map(|(j, &a)| (j as u32, a)));
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::site::{BuildOptions, Site, SiteBuilder, TrainingScan};
    use approx::assert_relative_eq;
    use nalgebra::Point2;

    /// Six states on a corridor, 2 m apart.
    fn corridor() -> Site {
        let mut b = SiteBuilder::new("corridor");
        let f = b.floor("G", 0.0);
        let ids: Vec<u32> = (0..6)
            .map(|k| b.state(f, Point2::new(2.0 * k as f64, 0.0), Vec::<TrainingScan>::new()))
            .collect();
        for w in ids.windows(2) {
            b.edge(w[0], w[1], None);
        }
        b.build(BuildOptions::default()).unwrap()
    }

    #[test]
    fn rows_follow_hipe_eqs_5_and_6() {
        let site = corridor();
        let table = ReachTable::build(&site, 9.0);
        let ratio = 1000.0;
        let t = UniformReach { table: &table, rho_m: 3.0, ratio };
        // Row of state 2: itself, 1 and 3 reachable (U = 3), the other three low.
        let mut prior = vec![0.0; 6];
        prior[2] = 1.0;
        let mut out = vec![0.0; 6];
        predict(&t, &prior, &mut out, &mut Vec::new());
        let high = ratio / (3.0 * ratio + 3.0);
        for (j, &p) in out.iter().enumerate() {
            let expected = if (1..=3).contains(&j) { high } else { high / ratio };
            assert_relative_eq!(p, expected, epsilon = 1e-15);
        }
        assert_relative_eq!(out.iter().sum::<f64>(), 1.0, epsilon = 1e-15);
    }

    /// a_ij by definition on the corridor: walking distance |i - j| · 2 m.
    fn dense(t: &UniformReach, i: usize, j: usize) -> f64 {
        let reachable = |k: usize| (k as f64 - i as f64).abs() * 2.0 <= t.rho_m || k.abs_diff(i) == 1;
        let u = (0..6).filter(|&k| reachable(k)).count();
        let (high, low) = hipe_probabilities(u, 6, t.ratio);
        if reachable(j) {
            high
        } else {
            low
        }
    }

    #[test]
    fn sparse_prediction_equals_the_dense_matrix() {
        let site = corridor();
        let table = ReachTable::build(&site, 9.0);
        let t = UniformReach { table: &table, rho_m: 4.5, ratio: 200_000.0 };
        let prior = [0.1, 0.3, 0.0, 0.2, 0.15, 0.25];
        let mut sparse = vec![0.0; 6];
        predict(&t, &prior, &mut sparse, &mut Vec::new());
        for (j, &p) in sparse.iter().enumerate() {
            let expected: f64 = (0..6).map(|i| prior[i] * dense(&t, i, j)).sum();
            assert_relative_eq!(p, expected, epsilon = 1e-15);
        }
    }

    #[test]
    fn sparse_viterbi_step_equals_the_dense_maximum() {
        let site = corridor();
        let table = ReachTable::build(&site, 9.0);
        let t = UniformReach { table: &table, rho_m: 2.0, ratio: 50.0 };
        let delta = [-3.0, -1.0, f64::NEG_INFINITY, -2.5, -7.0, -0.5];
        let (mut out, mut back) = (vec![0.0; 6], vec![0u32; 6]);
        viterbi_step(&t, &delta, &mut out, &mut back, &mut Vec::new());
        for j in 0..6 {
            let (best_i, best) = (0..6)
                .map(|i| (i, delta[i] + dense(&t, i, j).ln()))
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .unwrap();
            assert_relative_eq!(out[j], best, epsilon = 1e-12);
            assert_eq!(back[j] as usize, best_i);
        }
    }
}
