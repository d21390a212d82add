//! Held-out replays: each survey walk replayed on a site surveyed without it, its epochs
//! scored and tagged with what the calibration sorts them by.

use crate::io::Trace;
use crate::scoring::{live_estimates, quantile, score, Scored};
use waymark_engine::sensors::MotionScenario;
use waymark_engine::site::{
    scaled_radii, Calibration, FloorReliability, StateKind, FLOOR_BANDS, FLOOR_MISS_BANDS,
};
use waymark_engine::{ScanTiming, Site};

/// Per walk, per γ, per run of the calibration (`survey_calibrated`'s `masks`; the as-shipped
/// replays of `shipped` use the first two for steady and throttled scans): the held-out epochs.
pub(super) type HeldOut = Vec<[Vec<Scored>; RUNS]>;

/// One survey walk held out: its replays on the site surveyed without it.
pub(super) struct WalkHeldOut {
    /// Its epochs' scores, per γ and run.
    pub scored: HeldOut,
    /// States the site without it refitted.
    pub refitted: usize,
    /// Its epochs tagged, per γ and run.
    pub tagged: Vec<Tagged>,
    /// Per γ, per M of `ESTIMATE_STATES_GRID`: the epochs of the run with the motion scored
    /// with that M.
    pub by_m: Vec<Vec<Vec<Scored>>>,
}

/// Per run of the calibration: each held-out epoch (`Tag`).
pub(super) type Tagged = [Vec<Tag>; RUNS];

/// Runs of each held-out walk at each γ: the four motion masks.
pub(super) const RUNS: usize = 4;

/// A held-out epoch, with what the calibration sorts it by.
#[derive(Clone, Debug)]
pub(super) struct Tag {
    /// Its score.
    pub scored: Scored,
    /// How far its truth was beyond the held-out site's map, m (0 on it, `OnMap`).
    pub beyond_map_m: f64,
    /// Where the truth was, in its floor's frame, m.
    pub truth: [f64; 2],
    /// The scenario the engine positioned it in.
    pub scenario: MotionScenario,
    /// The radio fit of its scan.
    pub radio_fit: Option<f64>,
    /// In the sparse regime, its band of time since the sparse scan
    /// ([`ScanTiming::sparse_band`]).
    pub band: Option<usize>,
    /// What the engine added to both radii for the walking since the radio last explained a
    /// scan ([`Position::beyond_radio_m`](waymark_engine::Position::beyond_radio_m)), m: not the
    /// posterior's, so no factor applies to it.
    pub beyond_radio_m: f64,
}

/// The live positions of a replay of `trace` (on floor `floor`), scored and tagged.
pub(super) fn tag(
    site: &Site,
    trace: &Trace,
    floor: usize,
    mapped: &OnMap,
    positions: &[waymark_engine::Position],
) -> Vec<Tag> {
    let scored = score(trace, floor, &live_estimates(site, positions)).0;
    // The sparse band of each position, as the engine saw it (its scans are the epochs with
    // radio evidence).
    let mut timing = ScanTiming::default();
    let bands: Vec<Option<usize>> = positions
        .iter()
        .map(|p| {
            if p.radio_log_evidence.is_some() {
                timing = timing.after_scan(p.timestamp_ns);
            }
            timing.sparse_band(p.timestamp_ns)
        })
        .collect();
    // The positions `score` scored, in its order, with their band and the truth's place.
    let scored_positions = positions
        .iter()
        .zip(bands)
        .filter_map(|(p, band)| trace.position_at(p.timestamp_ns).map(|t| (p, band, t)));
    scored
        .into_iter()
        .zip(scored_positions)
        .map(|(scored, (p, band, truth))| Tag {
            scored,
            beyond_map_m: mapped.beyond_m(truth),
            truth: [truth.0, truth.1],
            scenario: p.scenario,
            radio_fit: p.radio_fit,
            band,
            beyond_radio_m: p.beyond_radio_m,
        })
        .collect()
}

/// Fewest held-out epochs a scenario's radius factors are fitted on: the 95th percentile then
/// rests on at least ten epochs beyond it.
pub const MIN_SCENARIO_EPOCHS: usize = 200;

/// Whether a true position is on a site's map: in a grid cell of one of its states on the
/// floor (within half a cell diagonal, spacing · √2 / 2, of a state). The survey places states
/// wherever a walk passed within `coverage_m`, so every point of a surveyed corridor is on the
/// map; a held-out survey walk that went where no other walk did is not.
///
/// The radius factors are fitted on held-out epochs on the map only. Leaving one walk out
/// takes its stretch of map away where no other walk covered it, so its epochs there are
/// positioned off the map, which the site the engine ships (surveyed from every walk) never
/// asks of the places it was surveyed at; fitted on every held-out epoch, the radii were too
/// wide (`docs/tuning.md#radius-factors`).
pub(super) struct OnMap {
    radius_m: f64,
    states: Vec<(f64, f64)>,
}

impl OnMap {
    pub(super) fn new(site: &Site, floor: usize) -> Self {
        let states = site
            .states()
            .iter()
            .filter(|s| s.floor == floor && s.kind != StateKind::Unsurveyed)
            .map(|s| (s.position.x, s.position.y))
            .collect();
        Self { radius_m: site.spacing_m() * std::f64::consts::FRAC_1_SQRT_2 + 1e-9, states }
    }

    /// How far `(x, y)` is beyond the map: its distance to the nearest cell (within
    /// `radius_m` of a state), 0 on the map.
    pub(super) fn beyond_m(&self, (x, y): (f64, f64)) -> f64 {
        let nearest =
            self.states.iter().map(|&(sx, sy)| (sx - x).hypot(sy - y)).fold(f64::INFINITY, f64::min);
        (nearest - self.radius_m).max(0.0)
    }
}

/// The radius factors (68%, 95%) that make the radii hold their truth at those shares: the
/// 68th percentile of (error − `beyond_radio_m`) ÷ the posterior's 68% radius over the epochs
/// `on_map`, and the 95th of the same over its 95% radius over `every` epoch, on the map and
/// beyond it. A walk left out is off its map far more often than a walker on a surveyed site,
/// so the typical epoch is measured on the map; the 95% radius is about the tail, which is
/// where the engine is lost, so it counts the epochs off the map too
/// (`docs/tuning.md#radius-factors`). `beyond_radio_m` is taken off first because the engine
/// adds it after the factor (`Engine::locate`). `None` without points or with a factor that is
/// not finite and positive.
pub(super) fn radius_factors(on_map: &[&Tag], every: &[&Tag]) -> Option<[f64; 2]> {
    let ratio = |points: &[&Tag], q: f64, radius: fn(&Tag) -> f64| {
        let mut r: Vec<f64> = points
            .iter()
            .map(|t| (t.scored.error_m - t.beyond_radio_m) / (radius(t) - t.beyond_radio_m).max(1e-9))
            .collect();
        r.sort_by(f64::total_cmp);
        quantile(&r, q)
    };
    let scale =
        [ratio(on_map, 0.68, |t| t.scored.accuracy_m), ratio(every, 0.95, |t| t.scored.accuracy_95_m)];
    scale.iter().all(|s| s.is_finite() && *s > 0.0).then_some(scale)
}

/// The floor probability's calibration ([`FloorReliability`]) from held-out epochs, each
/// (the posterior's mass on its floor, whether the floor was right), and the (right, all)
/// epochs of each band.
///
/// A band's share is its right epochs with two pseudo-epochs at what the uncalibrated mass
/// promises at least (the band's lower edge; 1/2 below): a Beta prior of weight 2, as
/// Laplace's rule of succession, so a band with few epochs stays near the posterior's own
/// mass and one with none keeps a value. The shares are then made to rise with the mass by
/// pooling adjacent violators, weighted by epochs (isotonic calibration, Zadrozny & Elkan
/// 2002), so a larger posterior mass never reports a smaller probability.
pub(super) fn floor_reliability(
    points: impl Iterator<Item = (f64, bool)>,
) -> (FloorReliability, [[usize; 2]; FLOOR_BANDS]) {
    let mut counts = [[0usize; 2]; FLOOR_BANDS];
    for (p, right) in points {
        let band = &mut counts[FloorReliability::band(p)];
        band[0] += usize::from(right);
        band[1] += 1;
    }
    // (share, weight, bands) blocks, merged while a block's share is below the one before it.
    let mut blocks: Vec<(f64, f64, usize)> = Vec::with_capacity(FLOOR_BANDS);
    for (band, &[right, all]) in counts.iter().enumerate() {
        let prior = band.checked_sub(1).map_or(0.5, |b| 1.0 - FLOOR_MISS_BANDS[b]);
        let weight = all as f64 + 2.0;
        blocks.push(((right as f64 + 2.0 * prior) / weight, weight, 1));
        while let [.., (a, wa, na), (b, wb, nb)] = blocks[..] {
            if a <= b {
                break;
            }
            blocks.truncate(blocks.len() - 2);
            blocks.push(((a * wa + b * wb) / (wa + wb), wa + wb, na + nb));
        }
    }
    let shares: Vec<f64> = blocks.iter().flat_map(|&(share, _, n)| std::iter::repeat_n(share, n)).collect();
    (FloorReliability(std::array::from_fn(|band| Some(shares[band]))), counts)
}

impl Tag {
    /// Whether the 68% and 95% radii hold the truth with `calibration`'s factors applied as
    /// the engine applies them (`Engine::locate`) to this epoch's radii, replayed without
    /// factors.
    pub(super) fn holds(&self, calibration: &Calibration) -> [bool; 2] {
        let scale = self
            .band
            .and_then(|band| calibration.sparse_scans.accuracy_scale_by_since[band])
            .unwrap_or(calibration.accuracy_scale_in(self.scenario));
        let posterior = [self.scored.accuracy_m, self.scored.accuracy_95_m].map(|r| r - self.beyond_radio_m);
        scaled_radii(posterior, scale, self.beyond_radio_m).map(|r| self.scored.error_m <= r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tag(error_m: f64, accuracy_m: f64, beyond_radio_m: f64) -> Tag {
        Tag {
            scored: Scored {
                error_m,
                accuracy_m: accuracy_m + beyond_radio_m,
                accuracy_95_m: 2.0 * accuracy_m + beyond_radio_m,
                floor_correct: true,
                zone_correct: None,
                in_zone: None,
                floor_probability: None,
            },
            beyond_map_m: 0.0,
            truth: [error_m, 0.0],
            scenario: MotionScenario::DistanceHeading,
            radio_fit: None,
            band: None,
            beyond_radio_m,
        }
    }

    /// The fitted factors make the radii hold the truth at 68% and 95% of the epochs they were
    /// fitted on, as the engine applies them: on the posterior's radius, `beyond_radio_m` added
    /// after.
    #[test]
    fn fitted_factors_hold_their_shares_with_the_walked_distance_added_after() {
        let tags: Vec<Tag> = (0..100).map(|k| tag(f64::from(k) * 0.1, 2.0, f64::from(k % 3))).collect();
        let points: Vec<&Tag> = tags.iter().collect();
        let scale = radius_factors(&points, &points).unwrap();
        let calibration = Calibration { accuracy_scale: Some(scale), ..Calibration::default() };
        let held = |k: usize| tags.iter().filter(|t| t.holds(&calibration)[k]).count();
        assert!((68..=70).contains(&held(0)), "{scale:?} {}", held(0));
        assert!((95..=97).contains(&held(1)), "{scale:?} {}", held(1));
    }

    /// The 68% factor is measured on the map alone and the 95% factor over every epoch: the
    /// walks' epochs beyond the map widen the 95% radius and leave the 68% one as it was.
    #[test]
    fn the_95_percent_factor_counts_the_epochs_off_the_map() {
        let on: Vec<Tag> = (0..100).map(|k| tag(f64::from(k) * 0.1, 2.0, 0.0)).collect();
        let off: Vec<Tag> = (0..20).map(|_| Tag { beyond_map_m: 5.0, ..tag(40.0, 2.0, 0.0) }).collect();
        let on_map: Vec<&Tag> = on.iter().collect();
        let every: Vec<&Tag> = on.iter().chain(&off).collect();
        let alone = radius_factors(&on_map, &on_map).unwrap();
        let [f68, f95] = radius_factors(&on_map, &every).unwrap();
        assert_eq!(f68, alone[0]);
        // The 114th of 120 ratios is one of the 20 off the map: 40 m over a 4 m 95% radius.
        assert_eq!(f95, 10.0);
        assert!(alone[1] < 2.5, "{alone:?}");
    }

    /// Each band's share is its right epochs with two pseudo-epochs at its lower edge, and
    /// shares that fall as the mass rises are pooled: a larger mass never reports less.
    #[test]
    fn the_floor_calibration_is_smoothed_per_band_and_rises_with_the_mass() {
        let epochs = |p: f64, right: usize, wrong: usize| {
            std::iter::repeat_n((p, true), right).chain(std::iter::repeat_n((p, false), wrong))
        };
        // Band 4 (mass over 0.999): 95 right of 100. Band 3: 9 of 10. Band 2: 1 of 8, below
        // band 1's 3 of 4, so the two are pooled. Band 0: none.
        let points = epochs(0.9999, 95, 5)
            .chain(epochs(0.995, 9, 1))
            .chain(epochs(0.95, 1, 7))
            .chain(epochs(0.7, 3, 1));
        let (table, counts) = floor_reliability(points);
        assert_eq!(counts, [[0, 0], [3, 4], [1, 8], [9, 10], [95, 100]]);
        let t = table.0.map(Option::unwrap);
        assert!((t[4] - (95.0 + 2.0 * 0.999) / 102.0).abs() < 1e-12, "{t:?}");
        assert!((t[3] - (9.0 + 2.0 * 0.99) / 12.0).abs() < 1e-12, "{t:?}");
        // Band 1: (3 + 2·0.5) / 6 = 0.667; band 2: (1 + 2·0.9) / 10 = 0.28: pooled with band
        // 1, then with band 0's prior (0.5, weight 2), which the pool fell below.
        let pooled = (1.0 + 4.0 + 2.8) / (2.0 + 6.0 + 10.0);
        for band in 0..3 {
            assert!((t[band] - pooled).abs() < 1e-12, "{t:?}");
        }
        assert!(t.windows(2).all(|w| w[0] <= w[1]), "{t:?}");
        // No epochs: every band at its prior.
        let (empty, _) = floor_reliability(std::iter::empty());
        assert_eq!(empty.0.map(Option::unwrap), [0.5, 0.5, 0.9, 0.99, 0.999]);
    }

    /// A floor's coverage splits its epochs by the map the other walks made, and a wrong floor
    /// counts its penalty in the mean as the γ search does.
    #[test]
    fn coverage_splits_epochs_on_and_beyond_the_map() {
        let on = [tag(1.0, 2.0, 0.0), tag(3.0, 2.0, 0.0), tag(5.0, 2.0, 0.0)];
        let mut beyond = tag(10.0, 2.0, 0.0);
        beyond.beyond_map_m = 4.0;
        let mut wrong_floor = tag(2.0, 2.0, 0.0);
        wrong_floor.scored.floor_correct = false;
        let tags = on.iter().chain([&beyond, &wrong_floor]).map(|t| ("walk-a", t));
        let c = super::super::Coverage::of(tags);
        assert_eq!((c.epochs, c.beyond_map), (5, 1));
        // The epoch beyond the map is listed where it was, with its walk.
        let [point] = &c.beyond_map_points[..] else { panic!("{c:?}") };
        assert_eq!((point.walk.as_str(), point.position_m), ("walk-a", [10.0, 0.0]));
        assert_eq!((point.beyond_map_m, point.error_m), (4.0, 10.0));
        let penalty = crate::scoring::FLOOR_PENALTY_M;
        assert!((c.mean_error_on_map_m - (1.0 + 3.0 + 5.0 + 2.0 + penalty) / 4.0).abs() < 1e-12, "{c:?}");
        assert_eq!(c.mean_error_beyond_map_m, 10.0);
        assert_eq!(c.beyond_map_share(), 0.2);
        let none = super::super::Coverage::of(std::iter::empty::<(&str, &Tag)>());
        assert!(none.beyond_map_share().is_nan() && none.mean_error_on_map_m.is_nan());
    }
}
