//! The fingerprint radius, chosen per site by cross-validation on the survey walks.

use super::gamma::GAMMA_GRID;
use super::{
    parallel_map_by_cost, replay_cost, survey_inputs, CalibrationError, CalibrationOptions, FloorData,
};
use crate::replay::replay;
use crate::scoring::{live_estimates, score_scans, Scored};
use crate::{PreparedSurvey, SurveyOptions};
use std::collections::BTreeMap;
use std::sync::Arc;
use waymark_engine::site::{Calibration, North};
use waymark_engine::{Engine, EngineConfig, SharedEmissions};

/// One radius of the fingerprint radius's search: (radius m, held-out mean error m, scans).
pub type RadiusPoint = (f64, f64, usize);

/// Fingerprint radii the survey's calibration tries, m: 4 m · √2^k, k = 0..4, a factor of two
/// in spread either side of 8 m. A radius trades the noise of fits from few scans (small)
/// against smearing fingerprints over places that sound different (large); where the balance
/// lies depends on how densely a site was walked, which varies between sites, so it is
/// measured per site rather than fixed ([`CalibrationReport::fingerprint_radius_mean_error_m`](super::CalibrationReport::fingerprint_radius_mean_error_m),
/// `docs/tuning.md#fingerprint-radius`).
pub const FINGERPRINT_RADIUS_GRID: [f64; 5] = [4.0, 5.657, 8.0, 11.314, 16.0];

/// Folds of the fingerprint radius's cross-validation: each floor's survey walks go to fold
/// `walk % 5`. Five, not one per walk, because every radius refits nearly every state of each
/// fold's site; with a fifth of the walks held out, each held-out walk is judged by a site a
/// little sparser than the whole survey, so the choice leans, if anything, to a wider radius.
/// A cost bound, not a tuned figure (`docs/tuning.md#fingerprint-radius`).
pub const FINGERPRINT_RADIUS_FOLDS: usize = 5;

/// The fingerprint radius of least held-out error of the engine as shipped: for each radius of
/// [`FINGERPRINT_RADIUS_GRID`] and each fold, the site from the other folds' walks (with the
/// survey's step length, `calibration`) replays each of the fold's walks at every γ of
/// [`GAMMA_GRID`], scored at its WiFi scans (floor penalty included); a radius scores its
/// best γ, since γ is calibrated afterwards on the chosen radius. The fingerprints are judged
/// by what uses them, the engine, not the single-scan MLE, whose error is flat over radii
/// that change the engine's (`docs/tuning.md#fingerprint-radius`). Radii are tried from the
/// grid's middle outward (a local search). Returns the radius and the curve over the radii tried (radius, mean error m,
/// scans); `None` when no held-out scan was scored.
pub(super) fn calibrate_fingerprint_radius(
    floors: &[FloorData],
    north: North,
    calibration: Calibration,
    options: &CalibrationOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<(Option<f64>, Vec<RadiusPoint>), CalibrationError> {
    let inputs = survey_inputs(floors);
    let held: Vec<(usize, usize)> = floors
        .iter()
        .enumerate()
        .flat_map(|(f, floor)| (0..floor.survey.len()).map(move |w| (f, w)))
        .collect();
    let held_out_error = |radius: f64| -> Result<Option<(f64, usize)>, CalibrationError> {
        let survey = SurveyOptions { fingerprint_radius_m: radius, ..options.survey.clone() };
        let prepared = PreparedSurvey::new("eval", &inputs, north, &survey)?;
        // The states of every walk, for each fold to reuse where none of its walks trained
        // them: the same scans fit the same fingerprints.
        let all = prepared.fit(&|_, _| true, None, options.threads);
        // Per γ: (Σ error, scans).
        let mut sums = vec![(0.0, 0usize); GAMMA_GRID.len()];
        for fold in 0..FINGERPRINT_RADIUS_FOLDS {
            let keep = |_: usize, w: usize| w % FINGERPRINT_RADIUS_FOLDS != fold;
            let fits = prepared.fit(&keep, Some(&all), options.threads);
            // A fold that leaves a floor without states is skipped: it cannot be scored.
            let site = prepared.assemble(&fits).ok().and_then(|(s, _)| s.with_calibration(calibration).ok());
            let Some(site) = site.map(Arc::new) else {
                progress();
                continue;
            };
            let jobs: Vec<(usize, usize)> = held.iter().copied().filter(|&(f, w)| !keep(f, w)).collect();
            let cost = |&(f, w): &(usize, usize)| replay_cost(&floors[f].survey[w]);
            let walks = parallel_map_by_cost(&jobs, options.threads, cost, |&(f, w)| {
                let trace = &floors[f].survey[w];
                // The walk's scan likelihoods on the fold's site, computed at the first γ.
                let shared = SharedEmissions::new(&site);
                GAMMA_GRID.map(|gamma| {
                    let config = EngineConfig { rssi_weight: Some(gamma), ..options.calibration_engine() };
                    let Ok(mut engine) = Engine::new(Arc::clone(&site), config) else { return (0.0, 0) };
                    // Of this very site: cannot fail.
                    let _ = engine.share_emissions(Arc::clone(&shared));
                    let r = replay(&mut engine, trace, &options.calibration_replay());
                    let scored = score_scans(trace, f, &live_estimates(&site, &r.positions), None).0;
                    (scored.iter().map(Scored::penalised_m).sum::<f64>(), scored.len())
                })
            });
            for walk in walks {
                for (sum, (s, n)) in sums.iter_mut().zip(walk) {
                    sum.0 += s;
                    sum.1 += n;
                }
            }
            progress();
        }
        Ok(sums
            .iter()
            .filter(|s| s.1 > 0)
            .map(|s| (s.0 / s.1 as f64, s.1))
            .min_by(|a, b| a.0.total_cmp(&b.0)))
    };
    // A local search on the grid from its middle: the middle and its neighbours, then outward
    // while an end of what was tried is the least. The error curve over a radius is a bias
    // against a variance, one valley; the search tries three or four radii, not five.
    let mut tried: BTreeMap<usize, Option<(f64, usize)>> = BTreeMap::new();
    let middle = FINGERPRINT_RADIUS_GRID.len() / 2;
    let mut next: Vec<usize> = vec![middle - 1, middle, middle + 1];
    while !next.is_empty() {
        for k in next.drain(..) {
            tried.insert(k, held_out_error(FINGERPRINT_RADIUS_GRID[k])?);
        }
        let least = tried
            .iter()
            .filter_map(|(&k, e)| e.map(|e| (k, e.0)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(k, _)| k);
        let (&low, &high) = (tried.keys().next().unwrap_or(&0), tried.keys().next_back().unwrap_or(&0));
        match least {
            Some(k) if k == low && k > 0 => next.push(k - 1),
            Some(k) if k == high && k + 1 < FINGERPRINT_RADIUS_GRID.len() => next.push(k + 1),
            _ => {}
        }
    }
    let curve: Vec<RadiusPoint> = tried
        .into_iter()
        .filter_map(|(k, e)| e.map(|(mean, n)| (FINGERPRINT_RADIUS_GRID[k], mean, n)))
        .collect();
    let best = curve.iter().min_by(|a, b| a.1.total_cmp(&b.1)).map(|c| c.0);
    Ok((best, curve))
}
