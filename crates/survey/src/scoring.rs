//! Scoring a replay against a walk's truth: the errors of its estimates at the walk's WiFi
//! scans and waypoints (truth interpolated between waypoints), with the floor penalty of the
//! Indoor Location Competition 2.0, and the figures over many of them.

use crate::io::Trace;
use nalgebra::Point2;
use serde::Serialize;
use std::collections::HashMap;
use waymark_engine::Site;

/// A wrong floor adds this to the epoch's error, m: the public competition's metric (Indoor
/// Location Competition 2.0 adds 15 × the floor difference).
pub const FLOOR_PENALTY_M: f64 = 15.0;

/// Error figures of one configuration over a set of scored points.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Metrics {
    /// Mean error, m (a wrong floor adds [`FLOOR_PENALTY_M`]).
    pub mean_m: f64,
    /// Root mean square error, m.
    pub rmse_m: f64,
    /// Median error, m.
    pub p50_m: f64,
    /// 75th percentile, m, a wrong floor adding [`FLOOR_PENALTY_M`] as in `mean_m`: the IPIN
    /// competitions' accuracy score, the third quartile of the errors with 15 m per floor of
    /// difference (Potortì et al., "Comparing the performance of indoor localization systems
    /// through the EvAAL framework", Sensors 17(10) 2327, 2017). Here a wrong floor adds
    /// 15 m whatever the difference, which is the same for adjacent floors.
    pub p75_m: f64,
    /// 90th percentile, m.
    pub p90_m: f64,
    /// Largest error, m.
    pub max_m: f64,
    /// Share of points whose horizontal error is within the reported 68% radius.
    pub accuracy_68_hit: f64,
    /// Share within the reported 95% radius.
    pub accuracy_95_hit: f64,
    /// Median reported 68% radius, m.
    pub accuracy_68_median_m: f64,
    /// Share of points on the right floor.
    pub floor_hit: f64,
    /// Room-level accuracy (El Gemayel et al. §II-B): the share of points whose most likely
    /// zone was the true zone, the zone of the state nearest the true position; only for sites
    /// with zones.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zone_hit: Option<f64>,
    /// Share of points whose true position is in a zone (the rest are in none, and a most
    /// likely zone of none is right there): the base rate `zone_hit` should be read against.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub in_zone: Option<f64>,
    /// Mean reported floor probability, over the points that report one (live positions):
    /// read against `floor_hit` (docs/accuracy.md#floor-probability).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub floor_probability_mean: Option<f64>,
    /// Brier score of the reported floor probability over the same points: the mean of
    /// (probability − 1 if the floor was right, else 0)², 0 at best.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub floor_brier: Option<f64>,
    /// Points scored.
    pub epochs: usize,
}

/// One scored estimate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scored {
    /// Horizontal error, m, without the floor penalty.
    pub error_m: f64,
    /// Reported 68% radius, m.
    pub accuracy_m: f64,
    /// Reported 95% radius, m.
    pub accuracy_95_m: f64,
    /// Whether the floor was right.
    pub floor_correct: bool,
    /// Whether the zone was right; `None` when not scored by zone.
    pub zone_correct: Option<bool>,
    /// Whether the true position was in a zone; `None` when not scored by zone.
    pub in_zone: Option<bool>,
    /// The reported floor probability; `None` for estimates that report none.
    pub floor_probability: Option<f64>,
}

impl Scored {
    /// The error with the floor penalty.
    pub fn penalised_m(&self) -> f64 {
        self.error_m + if self.floor_correct { 0.0 } else { FLOOR_PENALTY_M }
    }
}

/// Nearest-rank quantile of sorted values: the smallest value with at least a share `q` of
/// them at or below it; NaN without values.
pub fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let rank = (q * sorted.len() as f64).ceil().max(1.0) as usize;
    sorted[rank.min(sorted.len()) - 1]
}

impl Metrics {
    /// Figures over `points`.
    pub fn new(points: &[Scored]) -> Metrics {
        let n = points.len();
        if n == 0 {
            return Metrics::default();
        }
        let mut errors: Vec<f64> = points.iter().map(Scored::penalised_m).collect();
        errors.sort_by(f64::total_cmp);
        let share = |f: &dyn Fn(&Scored) -> bool| points.iter().filter(|p| f(p)).count() as f64 / n as f64;
        let mut radii: Vec<f64> = points.iter().map(|p| p.accuracy_m).collect();
        radii.sort_by(f64::total_cmp);
        Metrics {
            mean_m: errors.iter().sum::<f64>() / n as f64,
            rmse_m: (errors.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt(),
            p50_m: quantile(&errors, 0.5),
            p75_m: quantile(&errors, 0.75),
            p90_m: quantile(&errors, 0.9),
            max_m: errors[n - 1],
            accuracy_68_hit: share(&|p| p.error_m <= p.accuracy_m),
            accuracy_95_hit: share(&|p| p.error_m <= p.accuracy_95_m),
            accuracy_68_median_m: quantile(&radii, 0.5),
            floor_hit: share(&|p| p.floor_correct),
            zone_hit: crate::metrics::zone_hit(points.iter().map(|p| p.zone_correct)),
            in_zone: crate::metrics::zone_hit(points.iter().map(|p| p.in_zone)),
            floor_probability_mean: mean(points.iter().filter_map(|p| p.floor_probability)),
            floor_brier: mean(points.iter().filter_map(|p| {
                p.floor_probability.map(|q| (q - if p.floor_correct { 1.0 } else { 0.0 }).powi(2))
            })),
            epochs: n,
        }
    }
}

/// The mean of `values`; `None` without any.
fn mean(values: impl Iterator<Item = f64>) -> Option<f64> {
    let (sum, n) = values.fold((0.0, 0usize), |(sum, n), v| (sum + v, n + 1));
    (n > 0).then(|| sum / n as f64)
}

/// An estimate in time, for scoring.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// When, ns.
    pub timestamp_ns: u64,
    /// Floor index in the site.
    pub floor: usize,
    /// Position, m.
    pub x: f64,
    /// Position, m.
    pub y: f64,
    /// 68% radius, m.
    pub accuracy_m: f64,
    /// 95% radius, m.
    pub accuracy_95_m: f64,
    /// The most likely zone, by index into the site's zones.
    pub zone: Option<usize>,
    /// The reported floor probability; `None` for estimates that report none (smoothed
    /// points, single-scan baselines).
    pub floor_probability: Option<f64>,
}

/// The true zone of a position: the zone of the site's state nearest to it on its floor (a
/// zone is a set of states, each standing for the cell around it).
pub struct ZoneTruth {
    /// Per floor: (position, zone) of its states.
    floors: Vec<Vec<(Point2<f64>, Option<usize>)>>,
}

impl ZoneTruth {
    /// For `site`; `None` when it has no zones.
    pub fn new(site: &Site) -> Option<ZoneTruth> {
        if site.zones().is_empty() {
            return None;
        }
        let mut floors = vec![Vec::new(); site.floors().len()];
        for (i, s) in site.states().iter().enumerate() {
            floors[s.floor].push((s.position, site.zone_of(i)));
        }
        Some(ZoneTruth { floors })
    }

    /// The zone of the state nearest (x, y) on `floor`.
    pub fn zone_at(&self, floor: usize, x: f64, y: f64) -> Option<usize> {
        let at = Point2::new(x, y);
        self.floors
            .get(floor)?
            .iter()
            .min_by(|a, b| nalgebra::distance(&a.0, &at).total_cmp(&nalgebra::distance(&b.0, &at)))
            .and_then(|s| s.1)
    }
}

/// Scores a walk's estimates at each estimate's own time (within the waypoints' span), and
/// at each waypoint with the latest estimate at or before it. Returns (epochs, waypoints).
/// Calibration uses the epochs: every position the engine reports is one a radius must hold.
pub fn score(trace: &Trace, floor: usize, estimates: &[Estimate]) -> (Vec<Scored>, Vec<Scored>) {
    let scored = scorer(floor, None);
    let epochs = estimates
        .iter()
        .filter_map(|e| {
            trace.position_at(e.timestamp_ns).map(|p| scored(e, p, trace.floor_at(e.timestamp_ns)))
        })
        .collect();
    (epochs, score_waypoints(trace, estimates, &scored))
}

/// A walk scored as evaluations report it: the latest estimate at or before each of the walk's
/// WiFi scans within the waypoints' span (truth interpolated), and at or before each waypoint,
/// by zone against `zones` when given. Returns (scans, waypoints). Every configuration is
/// scored at the same instants, every scan time: scoring each estimate at its
/// own time would weigh an engine with more epochs (motion-only timer epochs, beacon-only
/// scans) on other points than k-NN's one estimate a scan.
pub fn score_scans(
    trace: &Trace,
    floor: usize,
    estimates: &[Estimate],
    zones: Option<&ZoneTruth>,
) -> (Vec<Scored>, Vec<Scored>) {
    let scored = scorer(floor, zones);
    let scans = trace
        .wifi_scans
        .iter()
        .filter_map(|s| {
            let truth = trace.position_at(s.timestamp_ns)?;
            Some(scored(latest_at(estimates, s.timestamp_ns)?, truth, trace.floor_at(s.timestamp_ns)))
        })
        .collect();
    (scans, score_waypoints(trace, estimates, &scored))
}

/// The latest of `estimates` (in time order) at or before `timestamp_ns`.
fn latest_at(estimates: &[Estimate], timestamp_ns: u64) -> Option<&Estimate> {
    let k = estimates.partition_point(|e| e.timestamp_ns <= timestamp_ns);
    k.checked_sub(1).map(|k| &estimates[k])
}

fn score_waypoints(
    trace: &Trace,
    estimates: &[Estimate],
    scored: &impl Fn(&Estimate, (f64, f64), Option<usize>) -> Scored,
) -> Vec<Scored> {
    trace
        .waypoints
        .iter()
        .filter_map(|w| latest_at(estimates, w.timestamp_ns).map(|e| scored(e, (w.x, w.y), w.floor)))
        .collect()
}

/// An estimate against the truth (x, y) on the floor the walk's truth gives there, else on
/// `floor`, the walk's own ([`Trace::floor_at`]).
fn scorer(
    floor: usize,
    zones: Option<&ZoneTruth>,
) -> impl Fn(&Estimate, (f64, f64), Option<usize>) -> Scored + '_ {
    move |e: &Estimate, (x, y): (f64, f64), at: Option<usize>| {
        let floor = at.unwrap_or(floor);
        let truth = zones.map(|z| z.zone_at(floor, x, y));
        Scored {
            error_m: (e.x - x).hypot(e.y - y),
            accuracy_m: e.accuracy_m,
            accuracy_95_m: e.accuracy_95_m,
            floor_correct: e.floor == floor,
            zone_correct: truth.map(|t| e.floor == floor && e.zone == t),
            in_zone: truth.map(|t| t.is_some()),
            floor_probability: e.floor_probability,
        }
    }
}

/// A replay's three estimates: the live positions, the fixed-lag estimates and the Viterbi
/// track (the last two need a track window as long as the walk). Smoothed points carry the
/// live radius of their epoch; the replay smooths the last `lag` epochs by what there is when
/// the walk ends, and any epoch after the last smoothed one takes its state on the final track.
pub fn decoded(site: &Site, r: &crate::replay::Replay) -> [Vec<Estimate>; 3] {
    let live = live_estimates(site, &r.positions);
    let levels = scoring_levels(&site.floor_levels());
    let radius: HashMap<u64, (f64, f64)> =
        live.iter().map(|e| (e.timestamp_ns, (e.accuracy_m, e.accuracy_95_m))).collect();
    let smoothed = |points: &mut dyn Iterator<Item = &waymark_engine::TrackPoint>| -> Vec<Estimate> {
        points
            .map(|p| {
                let (a68, a95) = radius.get(&p.timestamp_ns).copied().unwrap_or((f64::NAN, f64::NAN));
                Estimate {
                    timestamp_ns: p.timestamp_ns,
                    floor: scored_floor(&levels, p.floor, p.unmapped_level),
                    x: p.x,
                    y: p.y,
                    accuracy_m: a68,
                    accuracy_95_m: a95,
                    zone: site.zone_of(p.state as usize),
                    floor_probability: None,
                }
            })
            .collect()
    };
    let mut lagged = smoothed(&mut r.fixed_lag.iter());
    let last = lagged.last().map(|e| e.timestamp_ns);
    lagged.extend(smoothed(&mut r.track.iter().filter(|p| last.is_none_or(|l| p.timestamp_ns > l))));
    lagged.dedup_by_key(|e| e.timestamp_ns);
    let viterbi = smoothed(&mut r.track.iter());
    [live, lagged, viterbi]
}

/// The floor index a level has in scoring: its floor's index in `site`, else, for one of the
/// site's unmapped levels ([`Site::unmapped_levels`]), the site's floor count plus its rank
/// among them; any other level is past those. Ground truth ([`crate::io::GsdWalk::trace`])
/// and reported [unmapped levels](waymark_engine::Position::unmapped_level) share it.
pub fn scoring_levels(site_levels: &[i32]) -> Vec<Option<i32>> {
    let between = waymark_engine::site::levels_between(site_levels);
    site_levels.iter().chain(&between).copied().map(Some).collect()
}

/// The floor index an estimate on `floor` scores as, with the unmapped level it reported:
/// that level's index in `levels` ([`scoring_levels`]).
fn scored_floor(levels: &[Option<i32>], floor: usize, unmapped_level: Option<i32>) -> usize {
    unmapped_level.and_then(|l| levels.iter().position(|&k| k == Some(l))).unwrap_or(floor)
}

/// The engine's live positions as estimates: a reported unmapped level scores as its index
/// in [`scoring_levels`].
pub fn live_estimates(site: &Site, positions: &[waymark_engine::Position]) -> Vec<Estimate> {
    let levels = scoring_levels(&site.floor_levels());
    positions
        .iter()
        .map(|p| Estimate {
            timestamp_ns: p.timestamp_ns,
            floor: scored_floor(&levels, p.floor, p.unmapped_level),
            x: p.x,
            y: p.y,
            accuracy_m: p.accuracy_m,
            accuracy_95_m: p.accuracy_95_m,
            zone: p.zone,
            floor_probability: Some(p.floor_probability),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_reported_unmapped_level_scores_as_the_truth_on_that_level_does() {
        // Levels −2 and 0 surveyed: −1 is scored as a floor of its own, after the site's.
        let levels = scoring_levels(&[-2, 0]);
        assert_eq!(levels, [Some(-2), Some(0), Some(-1)]);
        assert_eq!(scored_floor(&levels, 1, Some(-1)), 2);
        assert_eq!(scored_floor(&levels, 1, None), 1);
        assert_eq!(scored_floor(&levels, 0, Some(5)), 0, "a level scoring does not know");
    }

    fn point(floor_correct: bool, floor_probability: Option<f64>) -> Scored {
        Scored {
            error_m: 1.0,
            accuracy_m: 2.0,
            accuracy_95_m: 3.0,
            floor_correct,
            zone_correct: None,
            in_zone: None,
            floor_probability,
        }
    }

    /// The floor probability's mean and Brier score are over the points that report one.
    #[test]
    fn the_floor_probability_is_scored_where_reported() {
        let points = [point(true, Some(0.9)), point(false, Some(0.6)), point(false, None)];
        let m = Metrics::new(&points);
        assert!((m.floor_probability_mean.unwrap() - 0.75).abs() < 1e-12, "{m:?}");
        assert!((m.floor_brier.unwrap() - (0.01 + 0.36) / 2.0).abs() < 1e-12, "{m:?}");
        assert!((m.floor_hit - 1.0 / 3.0).abs() < 1e-12);
        let none = Metrics::new(&[point(true, None)]);
        assert_eq!((none.floor_probability_mean, none.floor_brier), (None, None));
    }

    /// IPIN's score is the nearest-rank third quartile of the errors, a wrong floor counting
    /// 15 m more.
    #[test]
    fn the_ipin_score_is_the_third_quartile_with_the_floor_penalty() {
        let at = |error_m: f64, floor_correct: bool| Scored { error_m, ..point(floor_correct, None) };
        let right: Vec<Scored> = [4.0, 1.0, 3.0, 2.0].iter().map(|&e| at(e, true)).collect();
        assert_eq!(Metrics::new(&right).p75_m, 3.0);
        // 1 m on the wrong floor is 16 m, now the largest: the quartile moves to 4 m.
        let wrong = [at(1.0, false), at(2.0, true), at(3.0, true), at(4.0, true)];
        assert_eq!(Metrics::new(&wrong).p75_m, 4.0);
        let worse = [at(1.0, false), at(2.0, false), at(3.0, true), at(4.0, true)];
        assert_eq!(Metrics::new(&worse).p75_m, 16.0);
    }
}
