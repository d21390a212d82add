//! Walks without labels refit the map (docs/evidence.md#from-a-walk): each walk replayed through
//! the engine gives its epochs the posterior smoothed by the whole walk; where that is sure, the
//! walk is anchored and surveyed like a labelled one, and every scan's posterior is a soft
//! label, map evidence that refits the labelled fingerprints. Repeated, this is EM on the
//! emissions (El Gemayel et al.'s Baum-Welch, eqs. 10-13, with Hoang's censored fit as the
//! M-step).

use super::{
    survey_calibrated, survey_inputs, CalibrationError, CalibrationOptions, CalibrationReport, FloorData,
};
use crate::io::Trace;
use crate::replay::replay;
use crate::{PreparedSurvey, ReplaceRule, SurveyFits, SurveyOptions, SurveyReport, REPLACE_RULE};
use serde::Serialize;
use std::sync::Arc;
use waymark_engine::evidence::{Evidence, EvidenceOptions};
use waymark_engine::site::{Calibration, Site};
use waymark_engine::{Engine, EngineConfig};

/// Epochs a walk's smoother keeps: every epoch of a walk of hours at a scan a second, so that
/// each scan's posterior is smoothed by the whole walk after it.
const WALK_EPOCHS: usize = 1 << 16;

/// What one round of refitting gathered and changed.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct EvidenceRound {
    /// Walks anchored (a round of anchoring) or that gave soft evidence.
    pub walks: u64,
    /// States the soft evidence's scans weigh on (0 in a round of anchoring).
    pub states: usize,
    /// (state, transmitter) entries heard.
    pub entries: usize,
    /// Bytes of the round's merged evidence.
    pub bytes: usize,
    /// States of the refitted site.
    pub site_states: usize,
    /// What the anchored walks replaced of the labelled fingerprints they contradict
    /// ([`UnlabelledOptions::replace`]; zero when off, and in a round of soft
    /// evidence).
    pub replaced: crate::Replaced,
}

/// The engine as `options` ship it after replaying `trace` on `site`, its smoother holding
/// every epoch of the walk ([`Engine::smoothed_posteriors`] then reaches back to the start, or
/// to the filter's last restart). `Err` when the engine refuses the configuration.
fn replayed(site: &Arc<Site>, trace: &Trace, options: &CalibrationOptions) -> Result<Engine, String> {
    let mut engine = walk_engine(site, options)?;
    replay(&mut engine, trace, &options.calibration_replay());
    Ok(engine)
}

/// The engine as `options` ship it, its smoother holding every epoch of a walk.
fn walk_engine(site: &Arc<Site>, options: &CalibrationOptions) -> Result<Engine, String> {
    let config = EngineConfig {
        track: false,
        fixed_lag_epochs: WALK_EPOCHS,
        track_window_epochs: WALK_EPOCHS + 1,
        ..options.engine.clone()
    };
    Engine::new(Arc::clone(site), config).map_err(|e| e.to_string())
}

/// The map evidence of one walk on `site`: the walk replayed through the engine as `options`
/// ship it, gathering evidence as an app's session does ([`Engine::start_evidence_with`],
/// docs/evidence.md#from-a-session) with a smoother that holds the whole walk, so that each
/// scan is weighed by its posterior smoothed by the rest of the walk (or by the epochs up to a
/// restart of the filter), its most probable states up to `options.evidence_mass` of it and
/// `options.evidence_states` of them. The walk's waypoints and floor are not read. `Err` when
/// the engine refuses the configuration.
pub fn walk_evidence(
    site: &Arc<Site>,
    trace: &Trace,
    options: &CalibrationOptions,
) -> Result<Evidence, String> {
    let mut engine = walk_engine(site, options)?;
    engine.start_evidence_with(EvidenceOptions {
        mass: options.evidence_mass,
        states: options.evidence_states,
    });
    replay(&mut engine, trace, &options.calibration_replay());
    let taken = engine.take_evidence().ok_or("the engine stopped gathering evidence")?;
    Ok(taken.evidence)
}

/// Where a walk without labels was at each epoch its posterior is sure of: the walk with
/// those places as its waypoints, and the floor most of them are on. An epoch is sure when its
/// posterior, smoothed by the whole walk, holds `floor_mass` or more on one floor and spreads
/// no more than `spread_m` (the mass-weighted RMS distance from its mean there); the survey
/// then places the scans between two such epochs as it places them between a surveyor's taps
/// (by time, `Trace::position_at`), which is how a walk reaches states the site lacks (Zee,
/// Rai et al. 2012, places crowdsourced scans by the walker's motion between anchors). `None`
/// with fewer than two sure epochs on that floor.
pub fn anchored_walk(
    site: &Arc<Site>,
    trace: &Trace,
    options: &CalibrationOptions,
    spread_m: f64,
    floor_mass: f64,
) -> Result<Option<(usize, Trace)>, String> {
    let engine = replayed(site, trace, options)?;
    let states = site.states();
    let mut anchors: Vec<(u64, usize, f64, f64)> = Vec::new();
    engine.smoothed_posteriors(|timestamp_ns, posterior| {
        let mut by_floor = vec![0.0; site.floors().len()];
        for &(i, p) in posterior {
            by_floor[states[i as usize].floor] += p;
        }
        let Some((floor, &mass)) = by_floor.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)) else {
            return;
        };
        if mass < floor_mass {
            return;
        }
        let on = || posterior.iter().filter(|(i, _)| states[*i as usize].floor == floor);
        let (mut x, mut y) = (0.0, 0.0);
        for &(i, p) in on() {
            x += p * states[i as usize].position.x;
            y += p * states[i as usize].position.y;
        }
        (x, y) = (x / mass, y / mass);
        let spread2: f64 = on()
            .map(|&(i, p)| {
                let d = states[i as usize].position - nalgebra::Point2::new(x, y);
                p * d.norm_squared()
            })
            .sum::<f64>()
            / mass;
        if spread2.sqrt() <= spread_m {
            anchors.push((timestamp_ns, floor, x, y));
        }
    });
    anchors.sort_by_key(|a| a.0);
    let mut count = vec![0usize; site.floors().len()];
    for a in &anchors {
        count[a.1] += 1;
    }
    let Some((floor, &n)) = count.iter().enumerate().max_by_key(|c| *c.1) else { return Ok(None) };
    if n < 2 {
        return Ok(None);
    }
    let waypoints = anchors
        .iter()
        .filter(|a| a.1 == floor)
        .map(|&(timestamp_ns, _, x, y)| crate::io::Waypoint { timestamp_ns, x, y, floor: None })
        .collect();
    Ok(Some((floor, Trace { waypoints, ..trace.clone() })))
}

/// An anchor's floor mass: the posterior holds at least this on one floor. An anchor on the
/// wrong floor writes one floor's radio into another's fingerprints, the worst a walk can add;
/// 0.99 lets at most one in a hundred of the epochs it admits be wrong where the posterior's
/// floor mass is calibrated (docs/accuracy.md#floor-probability).
pub const ANCHOR_FLOOR_MASS: f64 = 0.99;

/// How walks without labels refit the site ([`survey_with_unlabelled`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnlabelledOptions {
    /// Rounds of anchoring: each walk anchored where the site of the round before is sure of it
    /// ([`anchored_walk`]) and surveyed with the labelled walks.
    pub anchor_rounds: usize,
    /// Rounds of refitting with every scan's soft label after those ([`walk_evidence`],
    /// [`PreparedSurvey::refit`]).
    pub evidence_rounds: usize,
    /// The rule by which the anchored walks replace the labelled fingerprints they contradict
    /// ([`PreparedSurvey::replace_contradicted`], shipped as [`REPLACE_RULE`]): the radio
    /// changed after the survey. `None`: they only pool with them.
    pub replace: Option<ReplaceRule>,
}

impl Default for UnlabelledOptions {
    /// One round of anchoring, none of soft evidence (docs/evidence.md#measured), contradicted
    /// fingerprints replaced by [`REPLACE_RULE`] (it does not hurt the real floors and follows
    /// a radio that changed, docs/evidence.md#drift).
    fn default() -> Self {
        UnlabelledOptions { anchor_rounds: 1, evidence_rounds: 0, replace: Some(REPLACE_RULE) }
    }
}

/// The site calibrated from `floors`' survey walks, then refitted with `unlabelled` walks
/// (docs/evidence.md#refitting): first each walk is anchored where the site of the round before
/// is sure of it, the anchors within half the calibrated fingerprint radius (so that a scan an
/// anchor places stays within the radius of the cells its true position trains) and
/// [`ANCHOR_FLOOR_MASS`], and the anchored walks are surveyed with the labelled ones; then the
/// labelled survey's fits are refitted with the soft evidence of every walk. The calibration
/// (γ, radius factors, radio fit floor) stays the labelled survey's. Returns the site, the
/// labelled survey's reports and each round's.
pub fn survey_with_unlabelled(
    floors: &[FloorData],
    unlabelled: &[Trace],
    options: &CalibrationOptions,
    rounds: UnlabelledOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<(Site, SurveyReport, CalibrationReport, Vec<EvidenceRound>), CalibrationError> {
    let (labelled, survey, report) = survey_calibrated(floors, options, progress)?;
    let refit = Refit::of(&labelled, &report, options);
    let mut site = Arc::new(labelled);
    let mut history = Vec::new();
    let mut surveyed: Vec<FloorData> = floors.to_vec();
    let spread_m = report.fingerprint_radius_m / 2.0;
    for _ in 0..rounds.anchor_rounds {
        let anchored: Vec<Result<Option<(usize, Trace)>, String>> =
            super::parallel_map_by_cost(unlabelled, options.threads, super::replay_cost, |trace| {
                anchored_walk(&site, trace, options, spread_m, ANCHOR_FLOOR_MASS)
            });
        surveyed = floors.to_vec();
        let mut added = 0;
        for walk in anchored {
            if let Some((floor, trace)) = walk.map_err(CalibrationError::Evidence)? {
                surveyed[floor].survey.push(trace);
                added += 1;
            }
        }
        let inputs = survey_inputs(&surveyed);
        let prepared = PreparedSurvey::new("eval", &inputs, site.north(), &refit.survey_options)?;
        let fits = prepared.fit(&|_, _| true, None, options.threads);
        // The anchored walks follow each floor's labelled ones (`surveyed` above).
        let newer = |f: usize, w: usize| w >= floors[f].survey.len();
        let (fits, replaced) = match &rounds.replace {
            Some(rule) => prepared.replace_contradicted(&fits, &newer, rule),
            None => (fits, crate::Replaced::default()),
        };
        let (next, _) = prepared.assemble(&fits)?;
        let next = refit.finish(next)?;
        history.push(EvidenceRound {
            walks: added as u64,
            site_states: next.states().len(),
            replaced,
            ..EvidenceRound::default()
        });
        site = Arc::new(next);
    }
    if rounds.evidence_rounds > 0 {
        let inputs = survey_inputs(&surveyed);
        let prepared = PreparedSurvey::new("eval", &inputs, site.north(), &refit.survey_options)?;
        let fits = prepared.fit(&|_, _| true, None, options.threads);
        for _ in 0..rounds.evidence_rounds {
            let walks: Vec<Result<Evidence, String>> =
                super::parallel_map_by_cost(unlabelled, options.threads, super::replay_cost, |trace| {
                    walk_evidence(&site, trace, options)
                });
            let mut evidence = Evidence::new(&site);
            for walk in walks {
                let walk = walk.map_err(CalibrationError::Evidence)?;
                evidence.merge(&walk).map_err(|e| CalibrationError::Evidence(e.to_string()))?;
            }
            let (next, round) = refit.round(&prepared, &fits, &site, &evidence)?;
            history.push(round);
            site = Arc::new(next);
        }
    }
    let site = Arc::try_unwrap(site).unwrap_or_else(|shared| (*shared).clone());
    Ok((site, survey, report, history))
}

/// The site calibrated from `floors`' survey walks and refitted once with `evidence` gathered
/// on it ([`walk_evidence`] per walk, merged): the distributed form of
/// [`survey_with_unlabelled`] with no round of anchoring and one of soft evidence, which gives
/// the same site when `evidence` is the merge of its walks' evidence (docs/evidence.md#at-scale).
/// `Err` when the evidence is of another site. Returns the site, the labelled survey's reports
/// and the round's.
pub fn survey_with_evidence(
    floors: &[FloorData],
    evidence: &Evidence,
    options: &CalibrationOptions,
    progress: &(dyn Fn() + Sync),
) -> Result<(Site, SurveyReport, CalibrationReport, EvidenceRound), CalibrationError> {
    let (labelled, survey, report) = survey_calibrated(floors, options, progress)?;
    let refit = Refit::of(&labelled, &report, options);
    let inputs = survey_inputs(floors);
    let prepared = PreparedSurvey::new("eval", &inputs, labelled.north(), &refit.survey_options)?;
    let fits = prepared.fit(&|_, _| true, None, options.threads);
    let (site, round) = refit.round(&prepared, &fits, &labelled, evidence)?;
    Ok((site, survey, report, round))
}

/// What every site refitted from a labelled survey keeps of it: the survey at its calibrated
/// fingerprint radius, and its calibration (γ, radius factors, radio fit floor) and floors' γ.
struct Refit {
    survey_options: SurveyOptions,
    weights: Vec<[Option<f64>; 2]>,
    calibration: Calibration,
}

impl Refit {
    fn of(labelled: &Site, report: &CalibrationReport, options: &CalibrationOptions) -> Refit {
        Refit {
            survey_options: SurveyOptions {
                fingerprint_radius_m: report.fingerprint_radius_m,
                ..options.survey.clone()
            },
            weights: labelled
                .floors()
                .iter()
                .map(|f| [f.rssi_weight, f.rssi_weight_without_movement])
                .collect(),
            calibration: *labelled.calibration(),
        }
    }

    /// `site` with the labelled survey's calibration.
    fn finish(&self, site: Site) -> Result<Site, CalibrationError> {
        Ok(site.with_calibration(self.calibration)?.with_floor_rssi_weights(&self.weights)?)
    }

    /// One round of soft evidence: `fits` refitted with `evidence` gathered on `site`
    /// ([`PreparedSurvey::refit`]), assembled and calibrated, and what the round gathered.
    fn round(
        &self,
        prepared: &PreparedSurvey,
        fits: &SurveyFits,
        site: &Site,
        evidence: &Evidence,
    ) -> Result<(Site, EvidenceRound), CalibrationError> {
        let refitted = prepared.refit(fits, site, evidence).map_err(CalibrationError::Evidence)?;
        let (next, _) = prepared.assemble(&refitted)?;
        let next = self.finish(next)?;
        let round = EvidenceRound {
            walks: evidence.walks(),
            states: evidence.states_scanned(),
            entries: evidence.heard_entries(),
            bytes: evidence.to_bytes().len(),
            site_states: next.states().len(),
            replaced: crate::Replaced::default(),
        };
        Ok((next, round))
    }
}
