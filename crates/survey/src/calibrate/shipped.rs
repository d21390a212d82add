//! Held-out walks replayed with the engine as shipped: the sites they are replayed on, the
//! replays, and γ chosen again on the walks that the rest of the survey covers end to end.

use super::gamma::{gamma_curve, own_gamma};
use super::held_out::{tag, HeldOut, OnMap, Tag, RUNS};
use super::report::GammaPoint;
use super::{held_out_reach, parallel_map_by_cost, replay_cost, CalibrationOptions, FloorData, GAMMA_GRID};
use crate::replay::{replay, ReplayOptions};
use crate::{PreparedSurvey, SurveyFits};
use std::sync::Arc;
use waymark_engine::site::{Calibration, Site};
use waymark_engine::{Engine, SharedEmissions};

/// Walk `w` of floor `f` held out: the site surveyed from every other walk, with its
/// walking-distance tables taken from `whole` where they are the same, the map that says
/// which of the walk's epochs are on it, and the memo its replays share scan likelihoods in.
pub(super) struct HeldOutSite {
    pub site: Site,
    pub mapped: OnMap,
    pub shared: Arc<SharedEmissions>,
    /// States whose fingerprints it fitted afresh.
    pub refitted: usize,
}

impl HeldOutSite {
    /// `None` when the site cannot be built (a floor left without walks).
    pub fn build(
        prepared: &PreparedSurvey,
        full: &SurveyFits,
        whole: &Site,
        options: &CalibrationOptions,
        (f, w): (usize, usize),
    ) -> Option<HeldOutSite> {
        let keep = |ff: usize, ww: usize| !(ff == f && ww == w);
        let fits = prepared.fit(&keep, Some(full), 1);
        let (site, _) = prepared.assemble(&fits).ok()?;
        held_out_reach(&site, whole, options);
        let mapped = OnMap::new(&site, f);
        let shared = SharedEmissions::new(&site);
        Some(HeldOutSite { site, mapped, shared, refitted: fits.refitted() })
    }

    /// The walk `trace` (on floor `f`) replayed on this site with `calibration` and each floor's
    /// own γ (`weights`), its live positions tagged; `None` when the engine refuses them.
    pub fn replay(
        &self,
        calibration: Calibration,
        weights: &[[Option<f64>; 2]],
        options: &CalibrationOptions,
        replay_options: &ReplayOptions,
        trace: &crate::io::Trace,
        f: usize,
    ) -> Option<Vec<Tag>> {
        let site =
            self.site.clone().with_calibration(calibration).and_then(|s| s.with_floor_rssi_weights(weights));
        let site = Arc::new(site.ok()?);
        let mut engine = Engine::new(Arc::clone(&site), options.calibration_engine()).ok()?;
        // Of a copy of this site, with its radio map: cannot fail.
        let _ = engine.share_emissions(Arc::clone(&self.shared));
        Some(tag(&site, trace, f, &self.mapped, &replay(&mut engine, trace, replay_options).positions))
    }
}

/// Whether the rest of the survey covers a held-out walk end to end: it scored epochs and
/// every one of them lay on the map the other walks made (`OnMap`).
pub(super) fn covered(tags: &[Tag]) -> bool {
    !tags.is_empty() && tags.iter().all(|t| t.beyond_map_m == 0.0)
}

/// The run of [`covered_replays`] with every scan.
pub(super) const STEADY: usize = 0;

/// The run of [`covered_replays`] with the scans throttled.
pub(super) const SPARSE: usize = 1;

/// The held-out walks of `jobs` that `covered` marks (each survey walk of `floors` held out
/// from the survey `prepared` fits, `full` being the fit of every walk and `whole` its site)
/// replayed with the engine as shipped (`calibration`, each floor's `weights`) at each γ of
/// [`GAMMA_GRID`], steady ([`STEADY`]) and throttled ([`SPARSE`]): per job, `None` for a walk
/// not covered.
pub(super) fn covered_replays(
    (prepared, full, whole): (&PreparedSurvey, &SurveyFits, &Site),
    (floors, jobs, covered): (&[FloorData], &[(usize, usize)], &[bool]),
    (calibration, weights): (Calibration, &[[Option<f64>; 2]]),
    options: &CalibrationOptions,
    progress: &(dyn Fn() + Sync),
) -> Vec<Option<HeldOut>> {
    let mine: Vec<(usize, (usize, usize))> =
        jobs.iter().copied().enumerate().filter(|&(k, _)| covered[k]).collect();
    let cost = |&(_, (f, w)): &(usize, (usize, usize))| replay_cost(&floors[f].survey[w]);
    let done = parallel_map_by_cost(&mine, options.threads, cost, |&(_, (f, w))| {
        let held = HeldOutSite::build(prepared, full, whole, options, (f, w));
        let trace = &floors[f].survey[w];
        let out = held.and_then(|held| {
            let mut out: HeldOut = vec![Default::default(); GAMMA_GRID.len()];
            for (g, &gamma) in GAMMA_GRID.iter().enumerate() {
                let at = Calibration { rssi_weight: Some(gamma), ..calibration };
                for (run, replay_options) in
                    [(STEADY, options.calibration_replay()), (SPARSE, options.calibration_throttled_replay())]
                {
                    let tags = held.replay(at, weights, options, &replay_options, trace, f)?;
                    out[g][run] = tags.into_iter().map(|t| t.scored).collect();
                }
            }
            Some(out)
        });
        progress();
        out
    });
    let mut per_job: Vec<Option<HeldOut>> = vec![None; jobs.len()];
    for ((k, _), held) in mine.iter().zip(done) {
        per_job[*k] = held;
    }
    per_job
}

/// What the covered walks replayed as shipped choose.
#[derive(Clone, Debug, Default, PartialEq)]
pub(super) struct CoveredGamma {
    /// Pooled, steady: the curve over γ and its least.
    pub curve: Vec<GammaPoint>,
    pub best: Option<f64>,
    /// Pooled, throttled, and the position of its least.
    pub sparse_curve: Vec<GammaPoint>,
    pub sparse_best: Option<usize>,
    /// Per floor, steady.
    pub floors: Vec<(Vec<GammaPoint>, Option<usize>)>,
    /// Walks and their steady epochs at a candidate.
    pub walks: usize,
    pub epochs: usize,
}

impl CoveredGamma {
    /// The curves of `replays` (per job, [`covered_replays`]), with `jobs` giving each job's
    /// floor among `floor_count`.
    pub fn of(replays: &[Option<HeldOut>], jobs: &[(usize, usize)], floor_count: usize) -> Self {
        let walks: Vec<&HeldOut> = replays.iter().flatten().collect();
        let (curve, best) = gamma_curve(&walks, STEADY);
        let (sparse_curve, sparse_best) = gamma_curve(&walks, SPARSE);
        let floors = (0..floor_count)
            .map(|floor| {
                let mine: Vec<&HeldOut> = jobs
                    .iter()
                    .zip(replays)
                    .filter(|((f, _), _)| *f == floor)
                    .filter_map(|(_, h)| h.as_ref())
                    .collect();
                gamma_curve(&mine, STEADY)
            })
            .collect();
        let epochs = walks.iter().map(|w| w.iter().map(|m| m[STEADY].len()).max().unwrap_or(0)).sum();
        CoveredGamma {
            best: best.map(|k| curve[k].gamma),
            curve,
            sparse_curve,
            sparse_best,
            floors,
            walks: walks.len(),
            epochs,
        }
    }

    /// The sparse regime's own γ against the site-wide `gamma`: its least on the throttled
    /// curve, when it beats `gamma` there by more than its standard error.
    pub fn sparse_gamma(&self, gamma: Option<f64>) -> Option<f64> {
        own_gamma(&self.sparse_curve, self.sparse_best, gamma)
    }
}

const _: () = assert!(RUNS > SPARSE);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::gamma::tests::scored;
    use waymark_engine::sensors::MotionScenario;

    fn tag(beyond_map_m: f64) -> Tag {
        Tag {
            scored: scored(1.0),
            beyond_map_m,
            truth: [0.0, 0.0],
            scenario: MotionScenario::DistanceHeading,
            radio_fit: None,
            band: None,
            beyond_radio_m: 0.0,
        }
    }

    #[test]
    fn a_walk_is_covered_when_every_epoch_is_on_the_map() {
        assert!(covered(&[tag(0.0), tag(0.0)]));
        assert!(!covered(&[tag(0.0), tag(0.5)]), "one epoch beyond the map");
        assert!(!covered(&[]), "no epochs: nothing says it was covered");
    }

    /// A covered walk replayed steady and throttled at the candidates: `errors[k]` = (steady,
    /// throttled) error of each of its `n` epochs at candidate `k`.
    fn walk(candidates: &[usize], errors: &[(f64, f64)], n: usize) -> HeldOut {
        let mut h: HeldOut = vec![Default::default(); GAMMA_GRID.len()];
        for (&g, &(steady, sparse)) in candidates.iter().zip(errors) {
            h[g][STEADY] = vec![scored(steady); n];
            h[g][SPARSE] = vec![scored(sparse); n];
        }
        h
    }

    #[test]
    fn covered_walks_choose_gamma_pooled_and_per_floor_and_the_sparse_gamma_beyond_its_error() {
        let at = |g: f64| GAMMA_GRID.iter().position(|&x| x == g).unwrap();
        let c = [at(0.03), at(0.1), at(0.3)];
        // Two floors: floor 0's walks are best at 0.03, floor 1's at 0.3; pooled, 0.03.
        let replays = vec![
            Some(walk(&c, &[(2.0, 5.0), (3.0, 4.0), (4.0, 4.5)], 10)),
            None,
            Some(walk(&c, &[(2.2, 5.2), (3.1, 4.1), (4.2, 4.4)], 10)),
            Some(walk(&c, &[(5.0, 6.0), (4.5, 5.0), (4.0, 5.5)], 10)),
        ];
        let jobs = [(0, 0), (0, 1), (0, 2), (1, 0)];
        let chosen = CoveredGamma::of(&replays, &jobs, 2);
        assert_eq!((chosen.walks, chosen.epochs), (3, 30));
        assert_eq!(chosen.curve.iter().map(|p| p.gamma).collect::<Vec<_>>(), [0.03, 0.1, 0.3]);
        assert_eq!(chosen.best, Some(0.03));
        assert!((chosen.curve[0].mean_error_m - 9.2 / 3.0).abs() < 1e-12, "{:?}", chosen.curve);
        let floor_best = |f: usize| chosen.floors[f].1.map(|k| chosen.floors[f].0[k].gamma);
        assert_eq!((floor_best(0), floor_best(1)), (Some(0.03), Some(0.3)));
        // Throttled, 0.1 is least: 4.37 m against 5.4 m at the site-wide 0.03, beyond its
        // jackknife error (0.32 m over the three walks), so the sparse regime gets its own γ;
        // where 0.1 is the site-wide γ, none.
        assert!((chosen.sparse_curve[1].jackknife_se_m - 0.31798).abs() < 1e-4, "{:?}", chosen.sparse_curve);
        assert_eq!(chosen.sparse_gamma(Some(0.03)), Some(0.1));
        assert_eq!(chosen.sparse_gamma(Some(0.1)), None);
    }
}
