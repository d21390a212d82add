//! A learning pass: Baum-Welch over segments of the recorded epochs, and the held-out gain
//! that chooses the strength the learned moves are applied with.

use super::prior::Rings;
use super::*;
use crate::fix::{self, PositionFix};
use crate::history::{EpochInput, EpochRecord};
use crate::hmm::learn::{expected_counts, Chain, EpochMatrix, SparseTransition};
use crate::site::{ReachTable, Site};
use std::collections::BTreeMap;

impl HabitModel {
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
                records.iter().filter(|r| after.is_none_or(|a| r.timestamp_ns > a)).collect();
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
            let fix_bias = {
                let mut total = self.fix.clone();
                total.add(&fix_stats);
                total.estimate(options.fix_prior_fixes)
            };
            let mut next: BTreeMap<(u32, u32), f64> = BTreeMap::new();
            let mut next_fix = FixStatistics::default();
            let mut log_likelihood = 0.0;
            for segment in &segments {
                let e = segment.expect(site, self, &learned, fix_bias, options, &mut next, &mut next_fix)?;
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
        report.fix_bias = self.fix_bias(options);
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
            segment.expect(site, &uniform, &none, FixBias::default(), options, &mut own, &mut fix)?;
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
                    let Some((_, d)) =
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
                if o.floor.is_none_or(|f| f == s.floor)
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
                    .filter_map(|(j, _)| local(j))
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
        fix_bias: FixBias,
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
                Some(_) => (fix_bias.bias_m[0], fix_bias.bias_m[1], fix_bias.spread),
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
                let d = [r[0] - fix_bias.bias_m[0], r[1] - fix_bias.bias_m[1]];
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
