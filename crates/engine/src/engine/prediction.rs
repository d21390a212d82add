//! The prediction of an epoch: the configured transition model, HIPE's regions and adaptive
//! K, and γ (Hoang eq. 14), the weight of the radio against the motion.

use super::vertical::FloorChanges;
use super::{Engine, Position};
use crate::config::{EngineConfig, TransitionModel};
use crate::habits::{HabitPrior, Habitual};
use crate::hmm::{HipeRegion, MovementVectorTransition, RegionsTransition, Transition, UniformReach};
use crate::sensors::{MotionScenario, MotionState, MotionUpdate};
use crate::site::{Landings, ReachTable, Site};
use std::sync::Arc;

impl Engine {
    /// Predicts over `dt_s` (none at the first epoch) with the configured model and `motion`,
    /// and updates with `ln_emission`. Returns the log evidence.
    pub(super) fn forward(&mut self, timestamp_ns: u64, dt_s: Option<f64>, motion: &MotionUpdate) -> f64 {
        if dt_s.is_none() {
            self.clear_smoother();
        }
        let table = prediction_table(&self.reach, self.map_reach.as_deref(), self.whole_reach);
        let Some(dt) = dt_s else {
            if let Some(viterbi) = &mut self.viterbi {
                viterbi.step(
                    timestamp_ns,
                    &UniformReach { table, rho_m: 0.0, ratio: 1.0 },
                    &self.ln_emission,
                );
            }
            return self.update(None);
        };
        let Some(hipe_region) = self.within_reach(motion, dt) else {
            return self.bridge_gap(timestamp_ns, self.config.max_speed_mps * dt);
        };
        let model = self.step_model(timestamp_ns, motion, dt, hipe_region);
        if let Some(last) = self.last_epoch_ns {
            // The scans whose epoch this step lets go take their posterior first.
            self.settle_evidence(false);
            self.smoother.begin(last, self.filter.posterior(), model);
        }
        let parts = self.transition_parts();
        let (filter, viterbi, ln_emission) = (&mut self.filter, &mut self.viterbi, &self.ln_emission);
        // Each row of the transition written once for the Viterbi step and the prediction.
        let result = parts.with(&model, |transition| match viterbi {
            Some(viterbi) => filter.step_with_viterbi(viterbi, timestamp_ns, transition, ln_emission),
            None => filter.step(Some(transition), ln_emission),
        });
        match result {
            Ok(evidence) => {
                self.smoother.finish(self.filter.predicted(), self.filter.posterior());
                evidence
            }
            Err(_) => self.restart(),
        }
    }

    /// The posterior predicted `dt_s` on by `motion` into `ln_emission`, normalised, the filter
    /// unchanged: where a held epoch is ([`Engine::hold_epoch`]). The posterior itself when
    /// the transition's reach does not cover `dt_s`.
    pub(super) fn predict_held(&mut self, timestamp_ns: u64, dt_s: f64, motion: &MotionUpdate) {
        let Some(region) = self.within_reach(motion, dt_s) else {
            self.ln_emission.copy_from_slice(self.filter.posterior());
            return;
        };
        let model = self.step_model(timestamp_ns, motion, dt_s, region);
        let parts = self.transition_parts();
        let (posterior, predicted) = (self.filter.posterior(), &mut self.ln_emission);
        let mut row = Vec::new();
        parts.with(&model, |t| crate::hmm::predict(t, posterior, predicted, &mut row));
        // As a motion-only step would: on the map, no mass on the unsurveyed states.
        if self.on_map() {
            for &i in &self.unsurveyed {
                self.ln_emission[i as usize] = 0.0;
            }
        }
        let predicted = &mut self.ln_emission;
        let total: f64 = predicted.iter().sum();
        if total > 0.0 && total.is_finite() {
            predicted.iter_mut().for_each(|p| *p /= total);
        } else {
            predicted.copy_from_slice(posterior);
        }
    }

    /// HIPE's regions for `motion` over `dt_s` when the configured transition's reach (the
    /// speed bound's, or the regions' for HIPE) is within the walking-distance table; `None`
    /// when the gap has to be bridged by the speed bound alone.
    pub(super) fn within_reach(&self, motion: &MotionUpdate, dt_s: f64) -> Option<HipeRegion> {
        let config = &self.config;
        let region = hipe_region(config, motion, dt_s);
        let needed = match config.transition {
            TransitionModel::Reach | TransitionModel::MovementVector => config.max_speed_mps * dt_s,
            TransitionModel::Regions => region.outer_radius_m(),
        };
        (needed <= self.reach.radius_m()).then_some(region)
    }

    /// What this epoch's transition is, from the configuration and `motion` over `dt_s`.
    fn step_model(
        &self,
        timestamp_ns: u64,
        motion: &MotionUpdate,
        dt_s: f64,
        region: HipeRegion,
    ) -> StepModel {
        let config = &self.config;
        let reach_m = config.max_speed_mps * dt_s;
        let ratio = config.transition_ratio;
        let kind = match config.transition {
            TransitionModel::Reach => StepKind::Reach,
            TransitionModel::Regions => {
                StepKind::Hipe { region, ratio: hipe_ratio(config, motion, self.step_position()) }
            }
            // Hoang's Gaussian needs a measured distance (the movement vector, or the distance
            // alone); with only a heading, HIPE's sector still uses what was measured (HIPE
            // Table 1).
            // Under Hoang's model the regions only stand in for a missing distance or
            // heading, with the same floor K as its other epochs: HIPE's adaptive K, down to
            // 200, leaks most of the mass of a large multi-floor site each epoch
            // (docs/tuning.md#adaptive-k).
            TransitionModel::MovementVector
                if motion.displacement_m.is_none() && motion.scenario == MotionScenario::HeadingSpeed =>
            {
                StepKind::Hipe { region, ratio }
            }
            TransitionModel::MovementVector => {
                let base_variance = config.movement_vector.movement_variance_m2
                    + if config.movement_vector.quantisation_variance {
                        self.site.spacing_m().powi(2) / 6.0
                    } else {
                        0.0
                    };
                let spread = match (config.movement_vector.measured_spread, motion.distance_m) {
                    (true, Some(d)) => {
                        (motion.distance_sigma_m.powi(2), (d * motion.heading_sigma_rad).powi(2))
                    }
                    _ => (0.0, 0.0),
                };
                StepKind::Hoang {
                    movement_m: motion.displacement_m,
                    walked_m: motion.distance_m.filter(|_| motion.scenario == MotionScenario::Distance),
                    variance_m2: base_variance + spread.0,
                    across_variance_m2: base_variance + spread.1,
                    exponent: self.epoch_rssi_weight(timestamp_ns, motion).map_or(1.0, |g| 1.0 - g),
                }
            }
        };
        StepModel {
            kind,
            reach_m,
            ratio,
            whole_reach: self.whole_reach,
            floor_change: self.floor_change(timestamp_ns, dt_s),
        }
    }

    /// What this engine's transitions are built over. It holds its own references, so the
    /// filter and the track can be stepped while it is in hand.
    fn transition_parts(&self) -> TransitionParts {
        TransitionParts {
            site: Arc::clone(&self.site),
            reach: Arc::clone(&self.reach),
            map_reach: self.map_reach.clone(),
            habits: Arc::clone(&self.habit_prior),
            mahalanobis_cap: self.config.movement_vector.mahalanobis_cap,
            landings: self.landings.clone(),
        }
    }

    /// The fixed-lag posterior `lag` ≥ 1 epochs back ([`FixedLagSmoother`]) into `out`, and
    /// that epoch's time.
    pub(super) fn smoothed_posterior(&self, lag: usize, out: &mut Vec<f64>) -> Option<u64> {
        let parts = self.transition_parts();
        self.smoother.smooth(lag, self.filter.posterior(), out, |model, f| parts.with(model, |t| f(t)))
    }

    /// The posterior of each epoch the fixed-lag smoother holds, smoothed by all the epochs
    /// after it, newest first: the latest epoch's filtered posterior, then up to
    /// `fixed_lag_epochs` epochs back (fewer after a restart, a bridged gap or feedback, as for
    /// [`fixed_lag_position`](Self::fixed_lag_position)), in one backward sweep.
    /// `each(timestamp, γ)` gets the states kept (all but those below 10⁻⁶ of the mass shared
    /// evenly) and their probabilities, which sum to 1. What map evidence weighs a walk's
    /// scans by (docs/evidence.md#from-a-walk).
    pub fn smoothed_posteriors(&self, mut each: impl FnMut(u64, &[(u32, f64)])) {
        let Some(latest) = self.last_epoch_ns else { return };
        let posterior = self.filter.posterior();
        let kept: Vec<(u32, f64)> = crate::hmm::kept(posterior).collect();
        let total: f64 = kept.iter().map(|(_, p)| p).sum();
        if !(total > 0.0 && total.is_finite()) {
            return;
        }
        let kept: Vec<(u32, f64)> = kept.into_iter().map(|(i, p)| (i, p / total)).collect();
        each(latest, &kept);
        let parts = self.transition_parts();
        let _ =
            self.smoother.sweep(self.smoother.len(), posterior, |model, f| parts.with(model, |t| f(t)), each);
    }

    /// Hoang eq. 14's γ for an epoch at `timestamp_ns` with `motion`, of the floor the engine
    /// is on: that of an epoch with the movement vector's likelihood when its transition has
    /// one, else the γ of the epoch's scenario when the site has one (the distance-only
    /// likelihood, HIPE's sector and the reach alone are different priors to weigh the radio
    /// against), else that of an epoch without a movement likelihood. The first epoch has no
    /// transition at all and a gap longer than the walking-distance table is bridged by the
    /// speed bound alone: both weigh the radio as without a movement likelihood, since the γ
    /// with movement leaves the first posterior too flat to choose the floor
    /// (docs/tuning.md#gamma).
    pub(super) fn epoch_rssi_weight(&self, timestamp_ns: u64, motion: &MotionUpdate) -> Option<f64> {
        let [with_movement, without] = self.rssi_weight_now();
        let Some(last) = self.last_epoch_ns else { return without };
        let dt_s = timestamp_ns.saturating_sub(last) as f64 * 1e-9;
        if self.config.max_speed_mps * dt_s > self.reach.radius_m() {
            return without;
        }
        if self.config.transition == TransitionModel::MovementVector && motion.displacement_m.is_some() {
            let sparse = self.scan_timing.sparse_band(timestamp_ns).and(self.sparse_scans.rssi_weight);
            sparse.or(with_movement)
        } else {
            self.scenario_rssi_weight[motion.scenario.index()].or(without)
        }
    }

    /// γ (with, without a movement likelihood) for the coming epoch: that of the floor of the
    /// latest estimate, else the site-wide one. One γ for every state of an epoch: ln p(o | s)
    /// is compared across states, and raising one floor's states to a smaller power than
    /// another's favours that floor whatever was heard (docs/tuning.md#gamma).
    pub(super) fn rssi_weight_now(&self) -> [Option<f64>; 2] {
        self.latest
            .as_ref()
            .and_then(|p| self.rssi_weight.get(p.floor))
            .copied()
            .unwrap_or(self.site_rssi_weight)
    }

    /// A reach beyond the walking-distance table: several passes of the speed bound, or a
    /// restart from the uniform prior when even that is too far.
    pub(super) fn bridge_gap(&mut self, timestamp_ns: u64, speed_reach: f64) -> f64 {
        self.clear_smoother();
        let table = prediction_table(&self.reach, self.map_reach.as_deref(), self.whole_reach);
        let table_radius = self.reach.radius_m();
        let passes = (speed_reach / table_radius).ceil().max(1.0);
        let pass = UniformReach { table, rho_m: speed_reach / passes, ratio: self.config.transition_ratio };
        if let Some(viterbi) = &mut self.viterbi {
            viterbi.step(timestamp_ns, &UniformReach { rho_m: table_radius, ..pass }, &self.ln_emission);
        }
        if passes > f64::from(self.config.max_reach_passes) {
            log::debug!("{speed_reach:.0} m of possible walking since the last epoch: restarting");
            self.filter.reset();
            self.stats.filter_restarts += 1;
            return self.update(None);
        }
        for _ in 1..passes as u32 {
            self.filter.predict(&pass);
        }
        let result = self.filter.step(Some(&pass), &self.ln_emission);
        result.unwrap_or_else(|_| self.restart())
    }

    pub(super) fn update(&mut self, transition: Option<&dyn Transition>) -> f64 {
        match self.filter.step(transition, &self.ln_emission) {
            Ok(evidence) => evidence,
            Err(_) => self.restart(),
        }
    }

    /// The map explains this observation nowhere the motion model allows: start again from the
    /// observation alone.
    pub(super) fn restart(&mut self) -> f64 {
        // A failed step leaves the posterior of the epoch before: the waiting scans settle on it.
        self.clear_smoother();
        self.stats.filter_restarts += 1;
        self.filter.reset();
        self.filter.step(None, &self.ln_emission).unwrap_or(f64::NEG_INFINITY)
    }
}

/// An epoch's transition, as the fixed-lag smoother keeps it to write its rows again.
#[derive(Clone, Copy, Debug)]
pub(super) struct StepModel {
    kind: StepKind,
    /// v_max · Δt, m.
    reach_m: f64,
    /// HIPE's K of the configuration.
    ratio: f64,
    /// Whether the epoch predicted over the whole table ([`prediction_table`]).
    whole_reach: bool,
    /// The probability of a floor change over the epoch ([`FloorChanges`]); 0 for none.
    floor_change: f64,
}

/// The transition model of a [`StepModel`] and what it measured.
#[derive(Clone, Copy, Debug)]
enum StepKind {
    /// Uniform over the reach.
    Reach,
    /// HIPE's region, with its K.
    Hipe { region: HipeRegion, ratio: f64 },
    /// Hoang's movement-vector Gaussian (the fields of [`MovementVectorTransition`]).
    Hoang {
        movement_m: Option<[f64; 2]>,
        walked_m: Option<f64>,
        variance_m2: f64,
        across_variance_m2: f64,
        exponent: f64,
    },
}

/// What a [`StepModel`] becomes a transition over.
struct TransitionParts {
    site: Arc<Site>,
    reach: Arc<ReachTable>,
    map_reach: Option<Arc<ReachTable>>,
    habits: Arc<HabitPrior>,
    mahalanobis_cap: f64,
    /// Where floor changes land, once the barometer has spoken.
    landings: Option<Arc<Landings>>,
}

impl TransitionParts {
    /// Hands `model`'s transition, with the learned habits multiplied in, to `f`.
    fn with<R>(&self, model: &StepModel, f: impl FnOnce(&dyn Transition) -> R) -> R {
        let table = prediction_table(&self.reach, self.map_reach.as_deref(), model.whole_reach);
        let (reach, hipe, hoang, prepared);
        let transition: &dyn Transition = match model.kind {
            StepKind::Reach => {
                reach = UniformReach { table, rho_m: model.reach_m, ratio: model.ratio };
                &reach
            }
            StepKind::Hipe { region, ratio } => {
                hipe = RegionsTransition { site: &self.site, table, region, ratio };
                &hipe
            }
            StepKind::Hoang { movement_m, walked_m, variance_m2, across_variance_m2, exponent } => {
                hoang = MovementVectorTransition {
                    site: &self.site,
                    table,
                    reach: table.cut(model.reach_m),
                    ratio: model.ratio,
                    movement_m,
                    walked_m,
                    variance_m2,
                    across_variance_m2,
                    mahalanobis_cap: self.mahalanobis_cap,
                    exponent,
                };
                prepared = hoang.prepared();
                &prepared
            }
        };
        // Learned habits: a prior multiplied into the motion-based transition of each epoch.
        let habitual;
        let transition: &dyn Transition = if self.habits.is_empty() {
            transition
        } else {
            habitual = Habitual { inner: transition, prior: &self.habits };
            &habitual
        };
        // Floor changes where the barometer measures the height.
        match &self.landings {
            Some(landings) if model.floor_change > 0.0 => {
                f(&FloorChanges { inner: transition, site: &self.site, landings, share: model.floor_change })
            }
            _ => f(transition),
        }
    }
}

/// The walking-distance table an epoch predicts with: the surveyed map's own (`map`) while the
/// radio explains what it hears, the whole site's (`reach`) beyond the map and on the way back
/// (`whole`).
pub(super) fn prediction_table<'a>(
    reach: &'a ReachTable,
    map: Option<&'a ReachTable>,
    whole: bool,
) -> &'a ReachTable {
    match map {
        Some(map) if !whole => map,
        _ => reach,
    }
}

/// HIPE's region for this epoch (HIPE eqs. 7-10, tolerances of Table 4).
pub(super) fn hipe_region(config: &EngineConfig, motion: &MotionUpdate, dt_s: f64) -> HipeRegion {
    let h = &config.regions;
    let range_m = h.assumed_speed_mps * dt_s;
    let tolerance = |d: f64| (h.distance_tolerance_fraction * d).max(h.distance_tolerance_min_m);
    match (motion.scenario, motion.distance_m, motion.heading_rad) {
        (MotionScenario::DistanceHeading, Some(d), Some(heading_rad)) if d > 0.0 => HipeRegion::RingSector {
            distance_m: d,
            tolerance_m: tolerance(d),
            heading_rad,
            tolerance_rad: h.heading_tolerance_rad,
        },
        // Standing still, or distance without heading: the ring (a disc of the tolerance when
        // d = 0).
        (MotionScenario::DistanceHeading | MotionScenario::Distance, Some(d), _) => {
            HipeRegion::Ring { distance_m: d, tolerance_m: tolerance(d) }
        }
        (MotionScenario::HeadingSpeed, _, Some(heading_rad)) => {
            HipeRegion::Sector { range_m, heading_rad, tolerance_rad: h.heading_tolerance_rad }
        }
        _ => HipeRegion::Disc { range_m },
    }
}

/// HIPE's adaptive K: log-linear between `hipe.transition_ratio_min` and `transition_ratio`
/// with a reliability r = r_motion · r_estimate in [0, 1]. r_motion is 1 when stationary,
/// else how far the measured spreads stay inside HIPE's tolerances, counting an assumed
/// quantity as unreliable: 0 for assumed speed only, and half the heading's reliability for
/// heading & assumed speed, whose region is measured in angle but assumed in range
/// (docs/tuning.md#adaptive-k). r_estimate is how far the previous 68% radius is within the
/// least distance tolerance (1.5 m).
pub(super) fn hipe_ratio(config: &EngineConfig, motion: &MotionUpdate, previous: Option<&Position>) -> f64 {
    let h = &config.regions;
    let within = |spread: f64, tolerance: f64| (1.0 - spread / tolerance).clamp(0.0, 1.0);
    let distance_tolerance = motion.distance_m.map_or(h.distance_tolerance_min_m, |d| {
        (h.distance_tolerance_fraction * d).max(h.distance_tolerance_min_m)
    });
    let r_distance = within(motion.distance_sigma_m, distance_tolerance);
    let r_heading = within(motion.heading_sigma_rad, h.heading_tolerance_rad);
    let r_motion = match motion.scenario {
        _ if motion.motion_state == MotionState::Stationary => 1.0,
        MotionScenario::DistanceHeading => r_distance * r_heading,
        MotionScenario::Distance => r_distance,
        MotionScenario::HeadingSpeed => 0.5 * r_heading,
        MotionScenario::Speed => 0.0,
    };
    let r_estimate = previous.map_or(0.0, |p| (h.distance_tolerance_min_m / p.accuracy_m).min(1.0));
    let r = r_motion * r_estimate;
    let (lo, hi) = (h.transition_ratio_min.ln(), config.transition_ratio.ln());
    (lo + r * (hi - lo)).exp()
}
