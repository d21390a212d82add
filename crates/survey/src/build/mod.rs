//! Survey walks → a site file: reference states on a regular spacing over where the surveyors
//! walked, fingerprints fitted from the scans near each (censored Gaussians, Hoang §3), the
//! walkable graph from the floor plan and from where people actually walked, the site's north
//! and the walkers' step length. When the floor plan names its polygons (shops, rooms), the
//! states inside each named polygon become a zone.
//!
//! States never sit on the labelled waypoints: they are grid points, so a method that snaps to
//! the grid gains nothing from the surveyors' habit of revisiting the same waypoints.

use crate::io::ilc::EventOptions;
use crate::io::{FloorPlan, Trace};
use nalgebra::Point2;
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet, HashMap};
use waymark_engine::radio::{FitOptions, Gaussian, Reading, Scan, TransmitterId};
use waymark_engine::site::{Anchor, BuildOptions, LatLon, North, Site, SiteBuilder, SiteError, Zone};

mod assemble;
mod fit;
mod prepare;
mod radios;
mod refit;
mod replace;
#[cfg(test)]
mod tests;

pub use prepare::{PreparedSurvey, SurveyFits};
pub use refit::MIN_EVIDENCE_SCANS;
pub use replace::{ReplaceRule, Replaced, REPLACE_RULE};

/// How a site is built from survey walks.
#[derive(Clone, Debug, PartialEq)]
pub struct SurveyOptions {
    /// Distance between neighbouring grid states, m. 2 m: WiFi fingerprints of a mall change
    /// over a few metres, and survey scans are 2-3 m apart along a walk
    /// (`scan_interval_median_s`), so a finer grid would have states with no scan of their own.
    pub spacing_m: f64,
    /// A grid point becomes a state when a survey walk passed within this distance, m. One
    /// spacing: the grid then covers a corridor two to three states wide around each walk.
    pub coverage_m: f64,
    /// Grid points within this distance of a surveyed state (and on the floor, when there is a
    /// plan) that no survey walk covered become [`StateKind::Unsurveyed`](waymark_engine::site::StateKind::Unsurveyed) states with no
    /// fingerprint, joined to the grid: where a walker leaves the surveyed area, the motion
    /// can carry the estimate there instead of pinning it to the map's edge. 0: none.
    pub unsurveyed_margin_m: f64,
    /// A survey scan trains every state within this distance of where it was taken, m. The
    /// calibration chooses it per site by cross-validation on the survey walks
    /// ([`FINGERPRINT_RADIUS_GRID`](crate::calibrate::FINGERPRINT_RADIUS_GRID)); this is the
    /// radius without that calibration. 5 m: a state then sees about two walking seconds of
    /// scans either side of it (`docs/tuning.md#fingerprint-radius`).
    pub fingerprint_radius_m: f64,
    /// Whether the floor plan's polygons cut the walkable graph (except where a survey walk
    /// crossed them). Off by default: on the competition's plans, shop and "auxiliary area"
    /// outlines are not where walls are (`docs/tuning.md#walls`). The graph then comes from
    /// where people walked (surveyed states exist only near survey walks, unsurveyed ones
    /// around them). Turn on for plans whose polygons are real walls.
    pub walls: bool,
    /// Readings older than this, ns, were not heard in the scan's own sweep: in training they
    /// count as "not heard" (Android re-reports cached access points for ~30 s). 2 s: one
    /// scan interval, so an entry not refreshed by the latest sweep is out
    /// (`docs/tuning.md#reading-age`). The site keeps it: engines on it drop such readings too.
    pub max_reading_age_ns: u64,
    /// Censored EM or naive fit, clip level, σ floor and cap.
    pub build: BuildOptions,
    /// Whether the clip level c is measured from the survey: one dB below the weakest WiFi
    /// reading any survey phone reported (the receivers' sensitivity, where censoring
    /// happens; Hoang §3 takes c as the phone's reporting floor). Beacons weaker than that
    /// are clipped to it. Off: `build.fit.clip_dbm` as given.
    pub measure_clip: bool,
    /// Which radios to use.
    pub events: EventOptions,
}

impl Default for SurveyOptions {
    fn default() -> Self {
        Self {
            spacing_m: 2.0,
            coverage_m: 2.0,
            unsurveyed_margin_m: UNSURVEYED_MARGIN_M,
            fingerprint_radius_m: 5.0,
            walls: false,
            max_reading_age_ns: 2_000_000_000,
            build: BuildOptions {
                fit: FitOptions { max_std_db: MAX_STD_DB, ..FitOptions::default() },
                ..BuildOptions::default()
            },
            measure_clip: true,
            events: EventOptions::default(),
        }
    }
}

/// [`SurveyOptions::unsurveyed_margin_m`]'s default, m: where held-out survey walks went
/// beyond the map the other walks make, nearly all their epochs were within 10 m of it
/// (`docs/tuning.md#unsurveyed-states`).
pub const UNSURVEYED_MARGIN_M: f64 = 10.0;

/// The largest margin a survey takes, m: a bound on bad input, not a tuned value (ten times
/// the default; the unsurveyed states grow with the square of the margin).
pub const MAX_UNSURVEYED_MARGIN_M: f64 = 100.0;

/// The σ cap of survey fits, dB: the spread of one access point's RSSI at a fixed place
/// over time is a few dB (Hoang §6.1 simulates σ_L = 5 dB); a column of mostly "not heard"
/// scans otherwise fits σ of 20-60 dB (`docs/tuning.md#radio-map`).
pub const MAX_STD_DB: f64 = 8.0;

/// One floor's survey material.
#[derive(Clone, Debug)]
pub struct SurveyFloor<'a> {
    /// The floor's name (`B1`, `F2`...).
    pub name: String,
    /// Its plan, when there is one: with [`SurveyOptions::walls`], its polygons keep the
    /// walkable graph out of shops except where somebody walked in.
    pub plan: Option<&'a FloorPlan>,
    /// Survey walks on this floor.
    pub walks: Vec<&'a Trace>,
    /// Where the floor is on the Earth when its walks' truth is WGS84 rather than a plan's
    /// frame (GetSensorData's `POSI`): used where the plans give no geo-reference.
    pub geo: Option<WalkedGeo>,
}

/// A floor geo-referenced by its walks: the building's anchor, whose frame every floor's walks
/// were placed in, and the floor's level.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WalkedGeo {
    /// The site frame: one for every floor of the building.
    pub anchor: Anchor,
    /// The floor number the walks give (0 ground, negative below).
    pub level: i32,
}

/// What the survey found, per floor.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FloorSurvey {
    /// Floor name.
    pub name: String,
    /// Walks with at least two waypoints.
    pub walks: usize,
    /// Scans positioned between waypoints.
    pub scans: usize,
    /// States placed.
    pub states: usize,
    /// Unsurveyed states placed around them ([`SurveyOptions::unsurveyed_margin_m`]).
    pub unsurveyed_states: usize,
    /// Walkable edges.
    pub edges: usize,
    /// Edges kept only because a survey walk went along them (through a door the plan lacks).
    pub walked_edges: usize,
    /// Grid neighbours split by a wall on the plan.
    pub walled_edges: usize,
    /// Plan polygons survey walks went inside, whose outlines are therefore not walls.
    pub open_rooms: usize,
    /// Zones made from the plan's named polygons that hold at least one state.
    pub zones: usize,
    /// States in those zones.
    pub zoned_states: usize,
    /// Median time between consecutive WiFi scans of a walk, s (the phones' scan interval,
    /// which sets the reading-age limit and the timer epoch's period).
    pub scan_interval_median_s: f64,
    /// 99th percentile of the same, s: how long a replay's beacons wait for the next WiFi
    /// scan, and its timer for one, before an epoch goes without it.
    pub scan_interval_p99_s: f64,
}

/// The survey's outcome.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SurveyReport {
    /// Per floor, in site order.
    pub floors: Vec<FloorSurvey>,
    /// Transmitters in the radio map.
    pub transmitters: usize,
    /// Radios that send two or more of them, each counted once in a scan's likelihood
    /// (docs/tuning.md#shared-radios).
    pub shared_radios: usize,
}

/// A storey's elevation rank from its name: `B2` → −2, `B1` → −1, `F1`/`1F`/`L1` → 0,
/// `F2` → 1; `None` for names without a level number. Used to order floors and set a
/// nominal elevation (rank × [`STOREY_HEIGHT_M`]).
pub fn floor_rank(name: &str) -> Option<i32> {
    let upper = name.trim().to_uppercase();
    let digits: String = upper.chars().filter(char::is_ascii_digit).collect();
    let n: i32 = digits.parse().ok()?;
    if upper.starts_with('B') || upper.ends_with('B') {
        Some(-n)
    } else {
        Some(n - 1)
    }
}

/// Nominal storey height, m, for the floors' `elevation_m` (display and ordering only: no
/// computation uses it). 5 m: a typical shopping-mall storey.
pub const STOREY_HEIGHT_M: f64 = 5.0;

/// A floor's logical level and where its frame's origin is in the site frame, m.
pub type FloorGeo = (Option<i32>, [f64; 2]);

/// The site's geo-reference from its floors' plans (docs/site-files.md#geo-reference): the
/// anchor, and each floor's (level, frame origin in the site frame). Each competition plan
/// frames its own longitude/latitude box, so the site frame is the first plan's, anchored at
/// its south-west corner with x east and y north, scaled as that plan stretches its box; every
/// other floor's origin is its box's south-west corner in that frame. No anchor unless every
/// floor has a plan with a box of some extent (a floor without one has no place on the
/// Earth); the levels are the plans' `floor_num` either way.
pub fn geo_reference(plans: &[Option<&FloorPlan>]) -> (Option<Anchor>, Vec<FloorGeo>) {
    geo_reference_or_walked(plans, &vec![None; plans.len()])
}

/// [`geo_reference`] from the plans; where they give no anchor and every floor is
/// geo-referenced by its walks in one frame ([`WalkedGeo`]), that frame, each floor's origin
/// at the site's and its level the walks'.
pub fn geo_reference_or_walked(
    plans: &[Option<&FloorPlan>],
    walked: &[Option<WalkedGeo>],
) -> (Option<Anchor>, Vec<FloorGeo>) {
    let from_plans = plans_geo_reference(plans);
    if from_plans.0.is_some() {
        return from_plans;
    }
    match walked.first() {
        Some(Some(first)) if walked.iter().all(|w| w.is_some_and(|w| w.anchor == first.anchor)) => {
            (Some(first.anchor), walked.iter().flatten().map(|w| (Some(w.level), [0.0, 0.0])).collect())
        }
        _ => from_plans,
    }
}

fn plans_geo_reference(plans: &[Option<&FloorPlan>]) -> (Option<Anchor>, Vec<FloorGeo>) {
    let levels = plans.iter().map(|p| p.and_then(|p| p.level));
    let unanchored = || levels.clone().map(|l| (l, [0.0, 0.0])).collect();
    let Some(Some(first)) = plans.first() else { return (None, unanchored()) };
    if plans.iter().any(Option::is_none) {
        return (None, unanchored());
    }
    let lat_lon = |[lon, lat]: [f64; 2]| LatLon::new(lat, lon);
    let anchor = (|| {
        let [lo, hi] = first.lon_lat_box?;
        let unit = Anchor::at(lat_lon(lo).ok()?);
        let mid = [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0];
        // Ground metres across the box's middle, east-west and south-north.
        let (w, e) =
            (unit.to_site(lat_lon([lo[0], mid[1]]).ok()?), unit.to_site(lat_lon([hi[0], mid[1]]).ok()?));
        let (s, n) =
            (unit.to_site(lat_lon([mid[0], lo[1]]).ok()?), unit.to_site(lat_lon([mid[0], hi[1]]).ok()?));
        let scale = [(e[0] - w[0]) / first.width_m, (n[1] - s[1]) / first.height_m];
        if !scale.iter().all(|s| s.is_finite() && *s > 0.0) {
            return None;
        }
        let anchor = Anchor { scale, ..unit };
        let origins = plans
            .iter()
            .flatten()
            .map(|p| lat_lon(p.lon_lat_box?[0]).ok().map(|sw| anchor.to_site(sw)))
            .collect::<Option<Vec<[f64; 2]>>>()?;
        Some((anchor, origins))
    })();
    match anchor {
        Some((anchor, origins)) => (Some(anchor), levels.zip(origins).collect()),
        None => (None, unanchored()),
    }
}

/// Where a walk went: points every half metre along its waypoint polyline.
pub(super) fn path_points(trace: &Trace) -> Vec<Point2<f64>> {
    let mut points = Vec::new();
    for w in trace.waypoints.windows(2) {
        let (a, b) = (Point2::new(w[0].x, w[0].y), Point2::new(w[1].x, w[1].y));
        let n = ((b - a).norm() / 0.5).ceil().max(1.0) as usize;
        points.extend((0..n).map(|k| a + (b - a) * (k as f64 / n as f64)));
    }
    if let Some(last) = trace.waypoints.last() {
        points.push(Point2::new(last.x, last.y));
    }
    points
}

/// The walk's scans with the position each was taken at (interpolated between waypoints), and
/// readings older than `max_age_ns` removed.
pub fn positioned_scans(trace: &Trace, options: &SurveyOptions) -> Vec<(Point2<f64>, Scan)> {
    trace
        .scans(&options.events)
        .into_iter()
        .filter_map(|scan| {
            let (x, y) = trace.position_at(scan.timestamp_ns)?;
            let readings: Vec<Reading> =
                scan.readings.into_iter().filter(|r| r.age_ns <= options.max_reading_age_ns).collect();
            Some((Point2::new(x, y), Scan { timestamp_ns: scan.timestamp_ns, readings }))
        })
        .collect()
}

/// Builds a site from survey walks, floors in the order given.
pub fn survey(
    name: &str,
    floors: &[SurveyFloor<'_>],
    north: North,
    options: &SurveyOptions,
) -> Result<(Site, SurveyReport), SiteError> {
    PreparedSurvey::new(name, floors, north, options)?.site(&|_, _| true, None)
}
