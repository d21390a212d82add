//! The rule by which newer walks replace a labelled fingerprint they contradict
//! (docs/evidence.md#refitting): the radio changed since the survey.

use super::prepare::*;
use super::*;
use serde::Serialize;

/// When newer scans replace a state's labelled fingerprint of one transmitter
/// ([`PreparedSurvey::replace_contradicted`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ReplaceRule {
    /// The newer scans' mean reading (clipped at the clip level, as the fit reads it) must
    /// differ from the labelled scans' by more than this many standard errors of the
    /// difference (Welch's two-sample statistic).
    pub z: f64,
    /// ... and by more than this many of the labelled scans' own standard deviations (at
    /// least the fit's σ floor): a shift the labelled spread explains is not a contradiction.
    pub spreads: f64,
    /// ... with at least this many newer scans at the state.
    pub min_newer_scans: usize,
    /// Where the newer scans do not contradict the labelled ones (or are too few to test),
    /// whether the fit pools both (as [`PreparedSurvey::fit`] does) or keeps the labelled
    /// scans' own: the newer walks' positions are the engine's anchors, less sure than a
    /// surveyor's taps, so a confirmed labelled fingerprint need not take them in.
    pub pool_confirmed: bool,
    /// A transmitter the labelled scans heard in a share p of theirs and none of the n newer
    /// scans heard is dropped from every state when (1 - p)ⁿ, the chance of that silence were
    /// it still there and the newer walks went where the labelled ones did, is below this.
    pub vanished_p: f64,
}

/// z = 3.29: a two-sided test at α = 0.001. A site has some 10⁴-10⁶ (state, transmitter)
/// pairs; at 0.001 an unchanged radio has about one pair in a thousand replaced by chance, and
/// a replaced pair is refitted from the newer scans, not lost. Two labelled standard
/// deviations: the "beyond what its own spread allows" of issue 62, at the usual two-σ band of
/// a Gaussian (95%). Five newer scans: with fewer, the newer scans' variance (4 degrees of
/// freedom at five) is too rough for the normal approximation of the statistic, and a state
/// is trained by about two walking seconds of scans either side (the fingerprint radius), so
/// five is one pass of a walker at a scan a second. The rule's effect is measured on the
/// simulated drift and the real floors in docs/evidence.md#drift.
/// The silence of a vanished transmitter is judged at the same α = 0.001.
pub const REPLACE_RULE: ReplaceRule =
    ReplaceRule { z: 3.29, spreads: 2.0, min_newer_scans: 5, pool_confirmed: true, vanished_p: 0.001 };

/// What [`PreparedSurvey::replace_contradicted`] changed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Replaced {
    /// (state, transmitter) pairs tested: both labelled and newer scans at the state.
    pub tested: usize,
    /// Pairs whose fingerprint the newer scans replaced.
    pub replaced: usize,
    /// Of those, pairs the newer scans never hear: the transmitter is dropped there.
    pub dropped: usize,
    /// Transmitters dropped from every state: the newer scans never hear them anywhere.
    pub vanished: usize,
}

/// Mean and variance (population) of `v`.
fn moments(v: &[f64]) -> (f64, f64) {
    let n = v.len().max(1) as f64;
    let mean = v.iter().sum::<f64>() / n;
    (mean, v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n)
}

impl ReplaceRule {
    /// Whether `newer` readings contradict `labelled` ones, both clipped at the clip level,
    /// `min_std_db` the fit's σ floor.
    pub fn contradicts(&self, labelled: &[f64], newer: &[f64], min_std_db: f64) -> bool {
        if labelled.is_empty() || newer.len() < self.min_newer_scans {
            return false;
        }
        let (m_l, v_l) = moments(labelled);
        let (m_n, v_n) = moments(newer);
        let floor = min_std_db * min_std_db;
        let (v_l, v_n) = (v_l.max(floor), v_n.max(floor));
        // Welch's statistic: the difference of the means over its standard error.
        let se = (v_l / labelled.len() as f64 + v_n / newer.len() as f64).sqrt();
        let d = (m_n - m_l).abs();
        d > self.z * se && d > self.spreads * v_l.sqrt()
    }
}

impl PreparedSurvey<'_> {
    /// `fits` with each state's fingerprint of a transmitter refitted from the `newer` walks'
    /// scans alone where they contradict its labelled scans by `rule`
    /// ([`ReplaceRule::contradicts`]): the radio there changed after the survey. A state's
    /// fingerprint pools the labelled and newer scans in its radius otherwise (what
    /// [`PreparedSurvey::fit`] gave). A transmitter the labelled scans heard and the newer ones
    /// never hear loses its fingerprint there; one that only the newer scans hear is fitted
    /// from them alone. `newer(floor, walk)` says which walks are newer than the survey.
    pub fn replace_contradicted(
        &self,
        fits: &SurveyFits,
        newer: &dyn Fn(usize, usize) -> bool,
        rule: &ReplaceRule,
    ) -> (SurveyFits, Replaced) {
        let clip = fits.clip_dbm;
        let build = BuildOptions {
            fit: FitOptions { clip_dbm: clip, ..self.options.build.fit },
            ..self.options.build
        };
        let fit = build.stored_fit();
        let mut out = fits.clone();
        let mut counts = Replaced::default();
        // Transmitters the newer walks never hear, against how often the labelled ones did.
        let (mut old_scans, mut new_scans) = (0usize, 0usize);
        let mut old_heard: BTreeMap<u32, usize> = BTreeMap::new();
        let mut new_heard: BTreeSet<u32> = BTreeSet::new();
        for (f, floor) in self.floors.iter().enumerate() {
            for (w, walk) in floor.walks.iter().enumerate().filter(|(w, _)| fits.kept[f][*w]) {
                let recent = newer(f, w);
                for scan in &walk.scans {
                    if recent {
                        new_scans += 1;
                        new_heard.extend(scan.iter().filter(|r| r.1 > clip).map(|r| r.0));
                    } else {
                        old_scans += 1;
                        let mut heard: Vec<u32> = scan.iter().filter(|r| r.1 > clip).map(|r| r.0).collect();
                        heard.sort_unstable();
                        heard.dedup();
                        for t in heard {
                            *old_heard.entry(t).or_default() += 1;
                        }
                    }
                }
            }
        }
        let vanished: BTreeSet<u32> = old_heard
            .iter()
            .filter(|(t, &n)| {
                let p = n as f64 / old_scans.max(1) as f64;
                !new_heard.contains(t) && (1.0 - p).powf(new_scans as f64) < rule.vanished_p
            })
            .map(|(&t, _)| t)
            .collect();
        counts.vanished = vanished.len();
        if !vanished.is_empty() {
            for cell_fit in out.floors.iter_mut().flat_map(|f| f.values_mut()) {
                cell_fit.models.retain(|m| !vanished.contains(&m.0));
            }
        }
        for (f, floor) in self.floors.iter().enumerate() {
            for (c, cell_fit) in out.floors[f].iter_mut() {
                let Some(candidate) = floor.cells.get(c) else { continue };
                let training: Training =
                    candidate.training.iter().copied().filter(|&(w, _)| fits.kept[f][w as usize]).collect();
                let (new, old): (Training, Training) =
                    training.iter().partition(|&&(w, _)| newer(f, w as usize));
                if old.is_empty()
                    || new.is_empty()
                    || (rule.pool_confirmed && new.len() < rule.min_newer_scans)
                {
                    continue;
                }
                // Per transmitter, each scan's reading clipped at the clip level, as
                // `fit_columns` reads it (the stronger of two).
                let columns = |scans: &[(u32, u32)]| {
                    let mut columns: BTreeMap<u32, Vec<f64>> = BTreeMap::new();
                    for (k, &(w, scan)) in scans.iter().enumerate() {
                        for &(t, rssi) in &floor.walks[w as usize].scans[scan as usize] {
                            if rssi.is_finite() {
                                let column = columns.entry(t).or_insert_with(|| vec![clip; scans.len()]);
                                column[k] = column[k].max(rssi.max(clip));
                            }
                        }
                    }
                    columns
                };
                let (old_columns, new_columns) = (columns(&old), columns(&new));
                let never = |n: usize| vec![clip; n];
                let mut heard: Vec<u32> = old_columns.keys().chain(new_columns.keys()).copied().collect();
                heard.sort_unstable();
                heard.dedup();
                for t in heard {
                    if vanished.contains(&t) {
                        continue;
                    }
                    let labelled = old_columns.get(&t).cloned().unwrap_or_else(|| never(old.len()));
                    let recent = new_columns.get(&t).cloned().unwrap_or_else(|| never(new.len()));
                    counts.tested += usize::from(new.len() >= rule.min_newer_scans);
                    let model = if rule.contradicts(&labelled, &recent, fit.min_std_db) {
                        counts.replaced += 1;
                        counts.dropped += usize::from(!new_columns.contains_key(&t));
                        // Never heard by the newer scans: no fingerprint here (the state is
                        // one of its "not heard" states).
                        if new_columns.contains_key(&t) {
                            build.model.fit(&recent, &fit)
                        } else {
                            None
                        }
                    } else if rule.pool_confirmed {
                        continue;
                    } else if old_columns.contains_key(&t) {
                        build.model.fit(&labelled, &fit)
                    } else {
                        None
                    };
                    let at = cell_fit.models.binary_search_by_key(&t, |m| m.0);
                    match (model, at) {
                        (Some(g), Ok(i)) => cell_fit.models[i].1 = g,
                        (Some(g), Err(i)) => cell_fit.models.insert(i, (t, g)),
                        (None, Ok(i)) => {
                            cell_fit.models.remove(i);
                        }
                        (None, Err(_)) => {}
                    }
                }
            }
        }
        (out, counts)
    }
}
