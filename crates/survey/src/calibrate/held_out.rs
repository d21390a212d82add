//! Held-out replays: each survey walk replayed on a site surveyed without it, its epochs
//! scored and tagged with what the calibration sorts them by.

use crate::io::Trace;
use crate::scoring::{live_estimates, score, Scored};
use waymark::sensors::MdiScenario;
use waymark::site::StateKind;
use waymark::{ScanTiming, Site};

/// Per walk, per γ, per run of the calibration (`survey_calibrated`'s `masks`, then
/// [`THROTTLED`]): the held-out epochs.
pub(super) type HeldOut = Vec<[Vec<Scored>; RUNS]>;

/// Per run of the calibration: each held-out epoch (`Tag`).
pub(super) type Tagged = [Vec<Tag>; RUNS];

/// Runs of each held-out walk at each γ: the four motion masks, then the sensors' motion with
/// throttled scans.
pub(super) const RUNS: usize = 5;

/// The run of the held-out walks with the scans throttled as Android 9+ throttles a foreground
/// app ([`ANDROID_THROTTLE_NS`](crate::replay::ANDROID_THROTTLE_NS)).
pub(super) const THROTTLED: usize = 4;

/// A held-out epoch: its score, how far its truth was beyond the held-out site's map (0 on it,
/// `OnMap`), the scenario the engine positioned it in, the radio fit of its scan and, in the
/// sparse regime, its band of time since the sparse scan ([`ScanTiming::sparse_band`]).
pub(super) type Tag = (Scored, f64, MdiScenario, Option<f64>, Option<usize>);

/// The live positions of a replay of `trace` (on floor `floor`), scored and tagged.
pub(super) fn tag(trace: &Trace, floor: usize, mapped: &OnMap, positions: &[waymark::Position]) -> Vec<Tag> {
    let scored = score(trace, floor, &live_estimates(positions)).0;
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
        .map(|(s, (p, band, truth))| (s, mapped.beyond_m(truth), p.scenario, p.radio_fit, band))
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
