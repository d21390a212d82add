//! The learned transitions applied in the filter: [`HabitPrior`]'s multipliers and the
//! [`Habitual`] transition that multiplies them in.

use super::*;
use crate::hmm::Transition;
use crate::site::ReachTable;
use std::collections::BTreeMap;

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
                .map(|(j, d)| (j, rings.probability(d, count(j), kappa) * rings.size(d)))
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
pub(super) struct Rings {
    spacing_m: f64,
    /// Per ring: (states, summed count).
    rings: BTreeMap<u32, (f64, f64)>,
}

impl Rings {
    pub(super) fn of(reach: &ReachTable, i: usize, spacing_m: f64, count: impl Fn(u32) -> f64) -> Self {
        let mut rings: BTreeMap<u32, (f64, f64)> = BTreeMap::new();
        for (j, d) in reach.reachable(i, reach.radius_m()).iter() {
            let ring = rings.entry(Self::ring(f64::from(d), spacing_m)).or_default();
            ring.0 += 1.0;
            ring.1 += count(j);
        }
        Self { spacing_m, rings }
    }

    pub(super) fn ring(walk_m: f64, spacing_m: f64) -> u32 {
        (walk_m / spacing_m.max(1e-9)).round().clamp(0.0, f64::from(u32::MAX)) as u32
    }

    pub(super) fn get(&self, walk_m: f32) -> (f64, f64) {
        self.rings.get(&Self::ring(f64::from(walk_m), self.spacing_m)).copied().unwrap_or((1.0, 0.0))
    }

    /// States in the ring at `walk_m`.
    pub(super) fn size(&self, walk_m: f32) -> f64 {
        self.get(walk_m).0
    }

    /// The learned probability of a move with count `c` within its ring at strength κ; the
    /// uniform 1/n_r in a ring with no count.
    pub(super) fn probability(&self, walk_m: f32, c: f64, kappa: f64) -> f64 {
        let (n, total) = self.get(walk_m);
        if total <= 0.0 {
            1.0 / n
        } else {
            (c + kappa) / (total + n * kappa)
        }
    }

    /// All counts.
    pub(super) fn total(&self) -> f64 {
        self.rings.values().map(|r| r.1).sum()
    }
}
