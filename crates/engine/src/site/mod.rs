//! The surveyed site: floors, states (the HMM's possible positions), the walkable graph between
//! them, the radio map, and optional zones (rooms, corridors) grouping the states. Loaded from a
//! versioned site file: JSON, or its binary encoding.

mod binary;
pub mod budget;
mod builder;
mod error;
mod file;
mod geo;
mod pseudo;
mod reach;
mod schema;
mod zones;

pub use binary::{LAYOUT_VERSION as BINARY_LAYOUT_VERSION, SIGNATURE as BINARY_SIGNATURE};
pub use builder::fit_columns;
pub use builder::{BuildOptions, SiteBuilder, TrainingScan};
pub use error::SiteError;
pub use file::{IdHashing, MAX_COORDINATE_M};
pub use geo::{Anchor, GeoError, LatLon, MAX_ANCHOR_LATITUDE_DEG};
pub use pseudo::{interpolate as interpolate_pseudo, PSEUDO_SPACING_M};
pub use reach::{Reach, ReachCut, ReachTable};
pub use schema::{FORMAT_VERSION, OLDEST_FORMAT_VERSION};
pub use zones::{most_likely_zone, Zone, ZoneKind, MAX_ZONES};

use crate::radio::RadioMap;
use nalgebra::Point2;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::sync::{Arc, Mutex};

/// A floor of the site.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Floor {
    /// Display name ("B1", "F2", ...).
    pub name: String,
    /// Height of the floor above the site's reference, m.
    pub elevation_m: f64,
    /// The building's own number for the floor (its logical level: -1 for the first
    /// basement), as Core Location's `CLFloor.level`; `None` when the site file gives none.
    pub level: Option<i32>,
    /// Where this floor's frame has its origin in the site frame, m: (0, 0) when every floor is
    /// drawn in the site frame; the plans of a survey that frames each floor on its own box
    /// (the competition's) differ ([`Site::lat_lon`] adds it before the anchor).
    pub origin_m: [f64; 2],
    /// γ of Hoang eq. 14 while the engine is on this floor (its latest estimate's floor), in
    /// epochs with a movement likelihood, chosen by leave-one-walk-out over the floor's survey
    /// walks (Hoang §6.2's jackknife). `None`: the site-wide [`Calibration::rssi_weight`].
    pub rssi_weight: Option<f64>,
    /// The same in epochs without a movement likelihood; `None`: the site-wide
    /// [`Calibration::rssi_weight_without_movement`].
    pub rssi_weight_without_movement: Option<f64>,
}

impl Floor {
    /// The first γ out of (0, 1], as (path, message), the floor being `floors[index]`.
    pub(crate) fn check(&self, index: usize) -> Result<(), (String, String)> {
        if !self.origin_m.iter().all(|v| v.is_finite() && v.abs() <= MAX_COORDINATE_M) {
            return Err((
                format!("floors[{index}].origin_m"),
                format!("must be within ±{MAX_COORDINATE_M} m, got {:?}", self.origin_m),
            ));
        }
        for (name, gamma) in [
            ("rssi_weight", self.rssi_weight),
            ("rssi_weight_without_movement", self.rssi_weight_without_movement),
        ] {
            if let Some(g) = gamma {
                if !(g > 0.0 && g <= 1.0) {
                    return Err((format!("floors[{index}].{name}"), format!("must be in (0, 1], got {g}")));
                }
            }
        }
        Ok(())
    }
}

/// Whether a state was surveyed (has measured fingerprints) or synthesised between surveyed
/// states (Hoang §5).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StateKind {
    /// Fingerprints fitted from training scans taken here.
    #[default]
    Surveyed,
    /// Fingerprints synthesised from neighbouring surveyed states (Hoang eqs. 12-13).
    Pseudo,
    /// No fingerprint: walkable space next to the surveyed area that no survey walk reached.
    /// The radio scores it as a place where no transmitter of the map is modelled, so a scan
    /// the map explains leaves it almost no mass; when the map does not explain a scan the
    /// motion alone can carry the estimate onto it.
    Unsurveyed,
}

/// A possible user position: one hidden state of the HMM.
#[derive(Clone, Debug, PartialEq)]
pub struct State {
    /// The id the site file gives it.
    pub id: u32,
    /// Index into [`Site::floors`].
    pub floor: usize,
    /// Position in the floor's metric frame, m.
    pub position: Point2<f64>,
    /// Surveyed or pseudo.
    pub kind: StateKind,
    /// How many training scans the fingerprint was fitted from.
    pub training_scans: u32,
}

/// How the site's frame sits on the Earth, for turning compass readings into site headings.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct North {
    /// Azimuth of the site's +y axis, radians clockwise from true north.
    #[serde(default)]
    pub site_rotation_rad: f64,
    /// Magnetic declination at the site (true minus magnetic azimuth), rad, east positive.
    #[serde(default)]
    pub declination_rad: f64,
}

/// A walkable connection between two states.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Edge {
    /// State index.
    pub a: u32,
    /// State index.
    pub b: u32,
    /// Walking length, m.
    pub length_m: f64,
}

/// The walkable neighbours of a state with their edge lengths, (state, m), in the order of the
/// site's edges ([`Site::neighbours`]); the default is no neighbour.
#[derive(Clone, Debug, Default)]
pub struct Neighbours<'a> {
    /// The state whose neighbours these are: each is the other end of an edge.
    from: u32,
    edges: &'a [Edge],
    slots: std::slice::Iter<'a, u32>,
}

impl Iterator for Neighbours<'_> {
    type Item = (u32, f64);

    fn next(&mut self) -> Option<(u32, f64)> {
        self.slots.next().map(|&k| {
            let edge = &self.edges[k as usize];
            (if edge.a == self.from { edge.b } else { edge.a }, edge.length_m)
        })
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        self.slots.size_hint()
    }
}

impl ExactSizeIterator for Neighbours<'_> {}

/// What the survey measured about how this site's radio and walkers behave, applied by
/// engines unless their configuration says otherwise (see
/// [`EngineConfig::site_calibration`](crate::EngineConfig::site_calibration)). Every field is
/// optional: a hand-made site file has none.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Calibration {
    /// γ of Hoang eq. 14 in epochs with a movement likelihood (steps and heading), chosen by
    /// cross-validation on the survey walks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rssi_weight: Option<f64>,
    /// γ in epochs without one (the radio then only competes with the reachability prior),
    /// chosen the same way with the motion withheld.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rssi_weight_without_movement: Option<f64>,
    /// γ per motion scenario in its epochs without a movement likelihood, before
    /// `rssi_weight_without_movement`: the radio then competes with HIPE's ring (distance
    /// only), sector (heading only) or disc (speed only), each a different prior to balance.
    /// The survey's calibration fits `distance` and `heading_speed` with those sensors alone
    /// (speed's is `rssi_weight_without_movement`).
    #[serde(default, skip_serializing_if = "PerScenario::is_empty")]
    pub rssi_weight_by_scenario: PerScenario<f64>,
    /// Factors on the posterior's 68% and 95% radii so that, on held-out survey walks, the
    /// circles held the truth 68% and 95% of the time.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accuracy_scale: Option<[f64; 2]>,
    /// The same factors per motion scenario (HIPE Table 1), fitted on the held-out epochs the
    /// engine positioned in that scenario: the posterior's spread means something else when
    /// the motion is only a maximum speed than when steps and heading are measured. A scenario
    /// without its own factors uses `accuracy_scale`.
    #[serde(default, skip_serializing_if = "PerScenario::is_empty")]
    pub accuracy_scale_by_scenario: ScenarioScales,
    /// The surveyors' step length model, fitted on the survey walks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step_length: Option<crate::sensors::StepLengthModel>,
    /// The least radio fit ([`Position::radio_fit`](crate::Position::radio_fit)) of a scan
    /// heard on the map, nats per radio heard: below it the map does not explain the scan (the
    /// phone is probably beyond the surveyed area), the engine leans on the motion and its
    /// radii grow with the distance walked. The survey's calibration takes a quantile (5% or 20%,
    /// whichever its held-out walks replayed as shipped err least with) of the fits
    /// over held-out epochs on the map, and 0 when that is below 0
    /// (docs/tuning.md#radio-fit-floor).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radio_fit_floor: Option<f64>,
    /// γ and radius factors for scans far apart, as under Android 9+'s throttling.
    #[serde(default, skip_serializing_if = "SparseScans::is_empty")]
    pub sparse_scans: SparseScans,
    /// M of Hoang eq. 4, the most likely states averaged into the estimate, chosen like γ on
    /// held-out survey walks (docs/tuning.md#mixture-components-m). Since format version 5.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimate_states: Option<u32>,
    /// How often the floor was right on held-out survey epochs, by band of the posterior's
    /// mass on it: the floor probability engines report (docs/accuracy.md#floor-probability).
    /// Since format version 6.
    #[serde(default, skip_serializing_if = "FloorReliability::is_empty")]
    pub floor_reliability: FloorReliability,
}

/// Edges of the floor probability's bands, as the posterior's mass off the chosen floor: a
/// decade each from an even split down to one in a thousand, the range in which held-out
/// epochs are found wrong (docs/accuracy.md#floor-probability).
pub const FLOOR_MISS_BANDS: [f64; 4] = [0.5, 0.1, 0.01, 0.001];

/// Bands of the posterior's floor mass ([`FLOOR_MISS_BANDS`], the last one open).
pub const FLOOR_BANDS: usize = FLOOR_MISS_BANDS.len() + 1;

/// The share of held-out epochs whose floor was right, per band of the posterior's mass on
/// the floor ([`FloorReliability::band`]); `None`: not fitted. The survey's calibration fits
/// it as it fits the radius factors, so that the floor probability an app reads holds as
/// often as it says, where the posterior's own mass is overconfident because the survey is
/// sparse.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct FloorReliability(pub [Option<f64>; FLOOR_BANDS]);

impl FloorReliability {
    /// Whether no band is fitted.
    pub fn is_empty(&self) -> bool {
        self.0.iter().all(Option::is_none)
    }

    /// The band of a posterior mass `p` on the floor: for how many of [`FLOOR_MISS_BANDS`]
    /// it is above one minus the edge.
    pub fn band(p: f64) -> usize {
        FLOOR_MISS_BANDS.iter().take_while(|&&miss| p > 1.0 - miss).count()
    }

    /// The floor probability to report for a posterior mass `p`: its band's share, else `p`.
    pub fn report(&self, p: f64) -> f64 {
        self.0[Self::band(p)].unwrap_or(p)
    }

    /// The first share out of [0, 1], as (band, share).
    fn invalid(&self) -> Option<(usize, f64)> {
        (self.0.iter().enumerate())
            .find_map(|(band, share)| share.filter(|s| !(0.0..=1.0).contains(s)).map(|s| (band, s)))
    }
}

/// A scan that comes longer than this after the one before it, s, is a sparse scan, and the
/// epochs until the next scan are in the sparse regime ([`SparseScans`]). 10 s lies between
/// an unthrottled phone's scan intervals and Android 9+'s throttling of a foreground app to 4
/// scans in 2 minutes (30 s apart on average) (docs/tuning.md#sparse-scans).
pub const SPARSE_SCAN_GAP_S: f64 = 10.0;

/// Upper ends of the bands of time since a sparse scan, s, each with its own radius factors
/// ([`SparseScans::accuracy_scale_by_since`]); the last band is open. After a sparse scan the
/// posterior's own radii first hold too little of the truth, then enough, so the bands are
/// narrow where the fitted factor changes fast, none shorter than the replay's 2 s timer
/// epoch (docs/tuning.md#sparse-scans).
pub const SINCE_SPARSE_SCAN_BANDS_S: [f64; 4] = [2.0, 5.0, 10.0, 20.0];

/// What differs when scans are far apart ([`SPARSE_SCAN_GAP_S`]): the motion has carried
/// the estimate alone for a long while, so the scan that ends it weighs differently against
/// the motion than one of a steady stream, and the posterior after it is not spread as after
/// a stream's. Fitted by the survey's calibration on the held-out walks replayed under
/// throttling (one scan every 30 s reaching the engine).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SparseScans {
    /// γ of every epoch in the sparse regime that has a movement likelihood (in place of
    /// [`Calibration::rssi_weight`] and the floor's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rssi_weight: Option<f64>,
    /// Factors on the 68% and 95% radii in the sparse regime, by band of time since the
    /// sparse scan ([`SINCE_SPARSE_SCAN_BANDS_S`]), in place of the scenario's.
    #[serde(default, skip_serializing_if = "no_scales")]
    pub accuracy_scale_by_since: BandScales,
    /// The floor probability's calibration in the sparse regime, in place of
    /// [`Calibration::floor_reliability`]: long on the motion alone, the posterior's floor
    /// mass means something else. Since format version 6.
    #[serde(default, skip_serializing_if = "FloorReliability::is_empty")]
    pub floor_reliability: FloorReliability,
}

/// Radius factors (68%, 95%) per band of time since a sparse scan; `None`: not fitted.
pub type BandScales = [Option<[f64; 2]>; SPARSE_BANDS];

/// Bands of time since a sparse scan ([`SINCE_SPARSE_SCAN_BANDS_S`], the last one open).
pub const SPARSE_BANDS: usize = SINCE_SPARSE_SCAN_BANDS_S.len() + 1;

fn no_scales(scales: &BandScales) -> bool {
    scales.iter().all(Option::is_none)
}

impl SparseScans {
    /// Whether nothing is calibrated.
    pub fn is_empty(&self) -> bool {
        *self == SparseScans::default()
    }

    /// The band of `since_s` seconds after a sparse scan.
    pub fn band(since_s: f64) -> usize {
        SINCE_SPARSE_SCAN_BANDS_S.iter().take_while(|&&edge| since_s >= edge).count()
    }
}

impl Calibration {
    /// Whether nothing is calibrated.
    pub fn is_empty(&self) -> bool {
        *self == Calibration::default()
    }

    /// The first invalid field, as (path, message).
    pub fn check(&self) -> Result<(), (String, String)> {
        for (name, gamma) in [
            ("rssi_weight", self.rssi_weight),
            ("rssi_weight_without_movement", self.rssi_weight_without_movement),
        ] {
            if let Some(g) = gamma {
                if !(g > 0.0 && g <= 1.0) {
                    return Err((format!("calibration.{name}"), format!("must be in (0, 1], got {g}")));
                }
            }
        }
        for s in crate::sensors::MotionScenario::ALL {
            if let Some(g) = self.rssi_weight_by_scenario.get(s) {
                if !(g > 0.0 && g <= 1.0) {
                    let path = format!("calibration.rssi_weight_by_scenario.{}", ScenarioScales::key(s));
                    return Err((path, format!("must be in (0, 1], got {g}")));
                }
            }
        }
        if let Some(g) = self.sparse_scans.rssi_weight {
            if !(g > 0.0 && g <= 1.0) {
                return Err((
                    "calibration.sparse_scans.rssi_weight".into(),
                    format!("must be in (0, 1], got {g}"),
                ));
            }
        }
        if let Some(f) = self.radio_fit_floor {
            if !f.is_finite() {
                return Err(("calibration.radio_fit_floor".into(), format!("must be finite, got {f}")));
            }
        }
        for (path, reliability) in [
            ("calibration.floor_reliability", &self.floor_reliability),
            ("calibration.sparse_scans.floor_reliability", &self.sparse_scans.floor_reliability),
        ] {
            if let Some((band, share)) = reliability.invalid() {
                return Err((format!("{path}[{band}]"), format!("must be in [0, 1], got {share}")));
            }
        }
        if self.estimate_states == Some(0) {
            return Err(("calibration.estimate_states".into(), "must be at least 1".into()));
        }
        let by_scenario = crate::sensors::MotionScenario::ALL.map(|s| {
            (
                format!("calibration.accuracy_scale_by_scenario.{}", ScenarioScales::key(s)),
                self.accuracy_scale_by_scenario.get(s),
            )
        });
        let by_since = self.sparse_scans.accuracy_scale_by_since.iter().enumerate().map(|(band, &scale)| {
            (format!("calibration.sparse_scans.accuracy_scale_by_since[{band}]"), scale)
        });
        for (path, scale) in std::iter::once(("calibration.accuracy_scale".to_string(), self.accuracy_scale))
            .chain(by_scenario)
            .chain(by_since)
        {
            if let Some(scale) = scale {
                if !scale.iter().all(|s| s.is_finite() && *s > 0.0) {
                    return Err((path, format!("must be finite and > 0, got {scale:?}")));
                }
            }
        }
        Ok(())
    }

    /// The 68% and 95% radius factors of an epoch in `scenario`: its own, else the site's,
    /// else none (1).
    pub fn accuracy_scale_in(&self, scenario: crate::sensors::MotionScenario) -> [f64; 2] {
        self.accuracy_scale_by_scenario.get(scenario).or(self.accuracy_scale).unwrap_or([1.0, 1.0])
    }
}

/// The 68% and 95% radii an engine reports, m, from the posterior's own (`posterior`) and the
/// factors in effect (`scale`: the sparse band's, else the scenario's): each radius times its
/// factor, the 95% never inside the 68%, plus `beyond_radio_m`, the walking since the radio
/// last explained a scan, which no factor scales (docs/accuracy.md). The engine reports with
/// it and the survey's calibration scores its held-out epochs with it.
pub fn scaled_radii(posterior: [f64; 2], scale: [f64; 2], beyond_radio_m: f64) -> [f64; 2] {
    let r68 = posterior[0] * scale[0];
    [r68 + beyond_radio_m, (posterior[1] * scale[1]).max(r68) + beyond_radio_m]
}

/// Radius factors (68%, 95%) per motion scenario; `None`: not fitted.
pub type ScenarioScales = PerScenario<[f64; 2]>;

/// A value per motion scenario (HIPE Table 1); `None`: not fitted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PerScenario<T> {
    /// Steps and heading measured.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distance_heading: Option<T>,
    /// Steps measured, heading not.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distance: Option<T>,
    /// Heading measured, distance from the maximum speed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heading_speed: Option<T>,
    /// The maximum speed only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed: Option<T>,
}

impl<T: Clone> PerScenario<T> {
    /// Whether no scenario has a value.
    pub fn is_empty(&self) -> bool {
        crate::sensors::MotionScenario::ALL.iter().all(|&s| self.slot(s).is_none())
    }

    /// The value of `scenario`.
    pub fn get(&self, scenario: crate::sensors::MotionScenario) -> Option<T> {
        self.slot(scenario).clone()
    }

    /// Sets the value of `scenario`.
    pub fn set(&mut self, scenario: crate::sensors::MotionScenario, value: Option<T>) {
        *self.slot_mut(scenario) = value;
    }

    /// Its key in the site file.
    pub fn key(scenario: crate::sensors::MotionScenario) -> &'static str {
        use crate::sensors::MotionScenario::*;
        match scenario {
            DistanceHeading => "distance_heading",
            Distance => "distance",
            HeadingSpeed => "heading_speed",
            Speed => "speed",
        }
    }

    fn slot(&self, scenario: crate::sensors::MotionScenario) -> &Option<T> {
        use crate::sensors::MotionScenario::*;
        match scenario {
            DistanceHeading => &self.distance_heading,
            Distance => &self.distance,
            HeadingSpeed => &self.heading_speed,
            Speed => &self.speed,
        }
    }

    fn slot_mut(&mut self, scenario: crate::sensors::MotionScenario) -> &mut Option<T> {
        use crate::sensors::MotionScenario::*;
        match scenario {
            DistanceHeading => &mut self.distance_heading,
            Distance => &mut self.distance,
            HeadingSpeed => &mut self.heading_speed,
            Speed => &mut self.speed,
        }
    }
}

/// A validated site, ready for engines. Immutable; share it with `Arc`.
#[derive(Clone, Debug)]
pub struct Site {
    name: String,
    floors: Vec<Floor>,
    states: Vec<State>,
    edges: Vec<Edge>,
    /// The edges of state `i` are `adjacency[adjacency_starts[i]..adjacency_starts[i + 1]]`,
    /// as indices into `edges`: the neighbour and the length stay in the edge, so the graph
    /// holds each once (docs/tuning.md#engine-speed). 32 bits, as a site of 2³¹ edges would
    /// take 32 GB.
    adjacency_starts: Vec<u32>,
    adjacency: Vec<u32>,
    /// Shared by the site's copies (the survey's calibration replays each held-out site with
    /// many calibrations, each on a copy): a copy is cheap, and engines on copies with the same
    /// map may share their scan likelihoods
    /// ([`SharedEmissions`](crate::SharedEmissions)).
    radio: Arc<RadioMap>,
    /// The survey's reading-age limit, ns ([`Site::max_reading_age_ns`]).
    max_reading_age_ns: Option<u64>,
    north: North,
    /// Where the site frame sits on the Earth, when the file says.
    anchor: Option<Anchor>,
    spacing_m: f64,
    calibration: Calibration,
    /// Set when the transmitter ids are salted hashes.
    id_hashing: Option<IdHashing>,
    /// Named groups of states (rooms, corridors); may be empty.
    zones: Vec<Zone>,
    /// Each state's zone index, `zones::NO_ZONE` for none; empty when there are no zones.
    zone_of: Vec<u32>,
    /// Walking-distance tables built so far, shared by every engine on this site (and its
    /// clones, whose graph is the same).
    reach_tables: ReachCache,
}

/// The walking-distance tables of a site, per radius: the whole graph's and the surveyed
/// map's ([`ReachTable::build_surveyed`]).
pub type ReachTables = (Arc<ReachTable>, Option<Arc<ReachTable>>);

/// [`Site::reach_tables`]'s memory: the tables of the latest few radii asked for, shared by
/// every engine on the site, since building them is costly (docs/tuning.md#unsurveyed-states).
#[derive(Clone, Default)]
struct ReachCache(Arc<Mutex<Vec<(u64, ReachTables)>>>);

impl std::fmt::Debug for ReachCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let radii = self.0.lock().map_or(0, |c| c.len());
        write!(f, "ReachCache({radii} radii)")
    }
}

/// Radii [`ReachCache`] keeps tables for: an engine's and a habit pass's (the same radius),
/// and one more that a caller tries.
const REACH_CACHE_RADII: usize = 2;

impl Site {
    /// Assembles a site from parts that the caller has checked (indices in range, positive
    /// lengths); the site-file loader and [`SiteBuilder`] are the callers.
    fn from_parts(
        name: String,
        floors: Vec<Floor>,
        states: Vec<State>,
        edges: Vec<Edge>,
        radio: RadioMap,
        north: North,
    ) -> Self {
        let n = states.len();
        // The median first and the lists without a second array of cursors: a transient
        // freed after the long-lived arrays are made can stay resident (docs/tuning.md#engine-speed).
        let spacing_m = median_edge_length(&edges);
        // Where each state's list ends, then filled from the back (edges in reverse order, so
        // each list keeps the edges' order); each end moves down to its list's start.
        let mut adjacency_starts = vec![0u32; n + 1];
        for e in &edges {
            adjacency_starts[e.a as usize] += 1;
            adjacency_starts[e.b as usize] += 1;
        }
        for i in 1..=n {
            adjacency_starts[i] += adjacency_starts[i - 1];
        }
        let mut adjacency = vec![0u32; 2 * edges.len()];
        for (k, e) in edges.iter().enumerate().rev() {
            for end in [e.b, e.a] {
                adjacency_starts[end as usize] -= 1;
                adjacency[adjacency_starts[end as usize] as usize] = k as u32;
            }
        }
        Self {
            name,
            floors,
            states,
            edges,
            adjacency_starts,
            adjacency,
            radio: Arc::new(radio),
            max_reading_age_ns: None,
            north,
            anchor: None,
            spacing_m,
            calibration: Calibration::default(),
            id_hashing: None,
            zones: Vec::new(),
            zone_of: Vec::new(),
            reach_tables: ReachCache::default(),
        }
    }

    /// The walking-distance tables within `radius_m`: the whole graph's and, when the site has
    /// [`StateKind::Unsurveyed`] states, the surveyed map's. Built once per radius and shared.
    /// Refused ([`SiteError::OverLimit`]) when they would pass the site budget
    /// ([`budget::MAX_REACHABLE_STATES`], [`budget::MAX_REACH_ENTRIES`],
    /// [`budget::MAX_REACH_EDGE_VISITS`]): the build stops there, having allocated no more.
    pub fn reach_tables(&self, radius_m: f64) -> Result<ReachTables, SiteError> {
        self.cached_reach_tables(radius_m, || ReachTable::build_both(self, radius_m, None))
    }

    /// [`reach_tables`](Self::reach_tables), taking every row it can from `base`'s tables at
    /// the same radius: `base` is a site surveyed over the same grid, such as the site of every
    /// survey walk for a site surveyed without one of them, which differs from it only around
    /// that walk's path. The tables are the same, entry for entry, as those built from scratch
    /// (docs/tuning.md#evaluation-speed).
    pub fn reach_tables_from(&self, base: &Site, radius_m: f64) -> Result<ReachTables, SiteError> {
        // Before this site's cache is locked: `base` may share it.
        let theirs = base.reach_tables(radius_m)?;
        self.cached_reach_tables(radius_m, || ReachTable::build_both(self, radius_m, Some((base, &theirs))))
    }

    /// The cached tables of `radius_m`, or those `build` makes, cached.
    fn cached_reach_tables(
        &self,
        radius_m: f64,
        build: impl FnOnce() -> Result<(ReachTable, Option<ReachTable>), SiteError>,
    ) -> Result<ReachTables, SiteError> {
        let key = radius_m.to_bits();
        // A panic while building leaves the cache as it was: recover it.
        let mut cache = self.reach_tables.0.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some((_, tables)) = cache.iter().find(|(k, _)| *k == key) {
            return Ok(tables.clone());
        }
        let (whole, surveyed) = build()?;
        let tables = (Arc::new(whole), surveyed.map(Arc::new));
        if cache.len() >= REACH_CACHE_RADII {
            cache.remove(0);
        }
        cache.push((key, tables.clone()));
        Ok(tables)
    }

    /// The site's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The site called `name`.
    pub fn with_name(mut self, name: impl Into<String>) -> Site {
        self.name = name.into();
        self
    }

    /// Floors, by index.
    pub fn floors(&self) -> &[Floor] {
        &self.floors
    }

    /// States, by index.
    pub fn states(&self) -> &[State] {
        &self.states
    }

    /// Walkable edges.
    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    /// Walkable neighbours of state `i` with the edge length.
    pub fn neighbours(&self, i: usize) -> Neighbours<'_> {
        Neighbours {
            from: i as u32,
            edges: &self.edges,
            slots: self.adjacency[self.adjacency_starts[i] as usize..self.adjacency_starts[i + 1] as usize]
                .iter(),
        }
    }

    /// The radio map.
    pub fn radio(&self) -> &RadioMap {
        &self.radio
    }

    /// The radio map as its copies share it ([`SharedEmissions`](crate::SharedEmissions)).
    pub(crate) fn shared_radio_map(&self) -> &Arc<RadioMap> {
        &self.radio
    }

    /// Readings last measured longer than this before their scan were left out of the
    /// fingerprints, as not heard (Android re-reports cached access points): engines on the
    /// site leave them out too unless configured otherwise
    /// ([`EngineConfig::max_reading_age_ns`](crate::EngineConfig::max_reading_age_ns)), so a
    /// scan means what it meant to the survey and its calibration. `None`: every reading was
    /// used, or the file does not say (before format version 4).
    pub fn max_reading_age_ns(&self) -> Option<u64> {
        self.max_reading_age_ns
    }

    /// The site with `radios` as the groups of its transmitters (by index) that one radio
    /// sends, each counted once in a scan's likelihood ([`RadioMap::with_shared_radios`]).
    pub fn with_shared_radios(mut self, radios: Vec<Vec<u32>>) -> Result<Site, SiteError> {
        self.radio = Arc::unwrap_or_clone(self.radio)
            .with_shared_radios(radios)
            .map(Arc::new)
            .map_err(|message| SiteError::Invalid { path: "radio.shared_radios".into(), message })?;
        Ok(self)
    }

    /// The site with the survey's reading-age limit ([`max_reading_age_ns`](Self::max_reading_age_ns)).
    /// Site files keep it in whole milliseconds, rounded up.
    pub fn with_max_reading_age_ns(mut self, max_age_ns: Option<u64>) -> Site {
        self.max_reading_age_ns = max_age_ns;
        self
    }

    /// The site frame's orientation on the Earth.
    pub fn north(&self) -> North {
        self.north
    }

    /// What the survey calibrated.
    pub fn calibration(&self) -> &Calibration {
        &self.calibration
    }

    /// How the transmitter ids are hashed; `None` when they are raw MAC addresses and UUIDs.
    pub fn id_hashing(&self) -> Option<&IdHashing> {
        self.id_hashing.as_ref()
    }

    /// The site with `calibration`; `Err((path, message))` if a value is out of range.
    pub fn with_calibration(mut self, calibration: Calibration) -> Result<Site, SiteError> {
        calibration.check().map_err(|(path, message)| SiteError::Invalid { path, message })?;
        self.calibration = calibration;
        Ok(self)
    }

    /// The site with each floor's calibrated γ, `weights[f]` = (with, without a movement
    /// likelihood) for floor `f`; `Err` naming `floors[f].rssi_weight` if one is out of (0, 1]
    /// or there are more entries than floors. Floors past the end keep theirs.
    pub fn with_floor_rssi_weights(mut self, weights: &[[Option<f64>; 2]]) -> Result<Site, SiteError> {
        if weights.len() > self.floors.len() {
            return Err(SiteError::Invalid {
                path: "floors".into(),
                message: format!("{} floor weights for {} floors", weights.len(), self.floors.len()),
            });
        }
        for (f, [with, without]) in weights.iter().enumerate() {
            let floor = Floor {
                rssi_weight: *with,
                rssi_weight_without_movement: *without,
                ..self.floors[f].clone()
            };
            floor.check(f).map_err(|(path, message)| SiteError::Invalid { path, message })?;
            self.floors[f] = floor;
        }
        Ok(self)
    }

    /// The site with `north`.
    pub fn with_north(mut self, north: North) -> Site {
        self.north = north;
        self
    }

    /// Where the site frame sits on the Earth; `None` when the site is not geo-referenced.
    pub fn anchor(&self) -> Option<&Anchor> {
        self.anchor.as_ref()
    }

    /// The site with `anchor` (`None`: not geo-referenced); `Err` naming `anchor.<field>` if a
    /// value is out of range.
    pub fn with_anchor(mut self, anchor: Option<Anchor>) -> Result<Site, SiteError> {
        if let Some(a) = &anchor {
            a.check().map_err(|(field, message)| SiteError::Invalid {
                path: format!("anchor.{field}"),
                message,
            })?;
        }
        self.anchor = anchor;
        Ok(self)
    }

    /// The logical level of floor `floor` (an index into [`floors`](Self::floors)): -1 for
    /// the first basement, as the building numbers it; `None` for an unknown index or a site
    /// file that gives no level.
    pub fn floor_level(&self, floor: usize) -> Option<i32> {
        self.floors.get(floor).and_then(|f| f.level)
    }

    /// The point (x, y), m, of floor `floor`'s frame as latitude/longitude; `None` when the
    /// site has no anchor or the floor index is unknown.
    pub fn lat_lon(&self, floor: usize, x: f64, y: f64) -> Option<LatLon> {
        let (anchor, origin) = (self.anchor.as_ref()?, self.floors.get(floor)?.origin_m);
        Some(anchor.to_lat_lon(x + origin[0], y + origin[1]))
    }

    /// A latitude/longitude as a point of floor `floor`'s frame, m. Without a floor, the
    /// floors must share one frame (the same `origin_m`). Fails when the site has no anchor,
    /// the coordinates are out of range, the floor is unknown, or it is needed and missing.
    pub fn site_point(&self, floor: Option<usize>, at: LatLon) -> Result<Point2<f64>, GeoError> {
        let anchor = self.anchor.as_ref().ok_or(GeoError::NotGeoReferenced)?;
        let at = LatLon::new(at.lat_deg, at.lon_deg)?;
        let origin = match floor {
            Some(f) => {
                let floors = self.floors.len();
                self.floors.get(f).ok_or(GeoError::UnknownFloor { floor: f, floors })?.origin_m
            }
            None => {
                let first = self.floors[0].origin_m;
                if self.floors.iter().any(|f| f.origin_m != first) {
                    return Err(GeoError::FloorRequired);
                }
                first
            }
        };
        let [x, y] = anchor.to_site(at);
        Ok(Point2::new(x - origin[0], y - origin[1]))
    }

    /// The true bearing, degrees clockwise from north, of a heading in radians clockwise from
    /// the site's +y axis (a position's); `None` when the site has no anchor.
    pub fn bearing_deg(&self, heading_rad: f64) -> Option<f64> {
        self.anchor.as_ref().map(|a| a.bearing_deg(heading_rad))
    }

    /// Typical distance between neighbouring states (median edge length), m: the size of the
    /// cell each state stands for.
    pub fn spacing_m(&self) -> f64 {
        self.spacing_m
    }
}

fn median_edge_length(edges: &[Edge]) -> f64 {
    if edges.is_empty() {
        return 0.0;
    }
    let mut lengths: Vec<f64> = edges.iter().map(|e| e.length_m).collect();
    let middle = lengths.len() / 2;
    // In place: a sort would take a buffer as large again.
    *lengths.select_nth_unstable_by(middle, f64::total_cmp).1
}

impl Site {
    /// Loads a site file in either encoding: binary ([`Site::to_binary`]) when the bytes start
    /// with its signature, JSON otherwise. More than [`budget::MAX_SITE_FILE_BYTES`] is
    /// refused unread.
    pub fn from_bytes(bytes: &[u8]) -> Result<Site, SiteError> {
        if bytes.len() as u64 > budget::MAX_SITE_FILE_BYTES {
            return Err(file_too_large(bytes.len() as u64, budget::MAX_SITE_FILE_BYTES));
        }
        if binary::is_binary(bytes) {
            binary::decode(bytes)
        } else {
            Site::from_json(bytes)
        }
    }

    /// Loads a site file from disk. It reads no more than [`budget::MAX_SITE_FILE_BYTES`],
    /// and stops after the first block when that does not begin like a site file in either
    /// encoding (`/dev/zero`, an image).
    pub fn load(path: impl AsRef<Path>) -> Result<Site, SiteError> {
        let path = path.as_ref();
        Site::from_bytes(&read_site_file(path)?)
    }
}

fn file_too_large(bytes: u64, limit: u64) -> SiteError {
    let size = if bytes > limit { "larger".to_owned() } else { format!("{bytes} bytes") };
    budget::over("MAX_SITE_FILE_BYTES", limit, format!("the site file is {size}"))
}

/// Bytes read before the start of a file is checked ([`read_bounded`]).
const FIRST_BLOCK_BYTES: u64 = 64 * 1024;

/// A site file's bytes ([`read_bounded`] up to [`budget::MAX_SITE_FILE_BYTES`]).
fn read_site_file(path: &Path) -> Result<Vec<u8>, SiteError> {
    let io = |e: std::io::Error| SiteError::Io { path: path.display().to_string(), message: e.to_string() };
    let file = std::fs::File::open(path).map_err(io)?;
    // The size the file says it has, to allocate once: only a hint (a device, a pipe or a
    // file that grows says otherwise), so the reading is bounded as well.
    let hint = file.metadata().map_or(0, |m| m.len());
    read_bounded(file, hint, budget::MAX_SITE_FILE_BYTES, io)
}

/// Reads a site file of at most `limit` bytes, said to be `hint` bytes long: refused unread
/// when the hint is over the limit, as soon as the reading passes it, or after the first block
/// when that shows it is no site file ([`not_a_site_file`]). `io` names a failed read.
fn read_bounded(
    reader: impl std::io::Read,
    hint: u64,
    limit: u64,
    io: impl Fn(std::io::Error) -> SiteError,
) -> Result<Vec<u8>, SiteError> {
    use std::io::Read;
    if hint > limit {
        return Err(file_too_large(hint, limit));
    }
    let mut limited = reader.take(limit + 1);
    let mut bytes = Vec::with_capacity(FIRST_BLOCK_BYTES.min(hint + 1) as usize);
    (&mut limited).take(FIRST_BLOCK_BYTES).read_to_end(&mut bytes).map_err(&io)?;
    if let Some(e) = not_a_site_file(&bytes) {
        return Err(e);
    }
    bytes.reserve((hint as usize + 1).saturating_sub(bytes.len()));
    limited.read_to_end(&mut bytes).map_err(io)?;
    if bytes.len() as u64 > limit {
        return Err(file_too_large(bytes.len() as u64, limit));
    }
    Ok(bytes)
}

/// Why a file that begins with `start` cannot be a site file, if it cannot: neither the binary
/// signature nor, after an optional byte order mark and white space, the `{` (or `[`) a JSON
/// site file begins with. The error is the one the JSON reader gives at that byte.
fn not_a_site_file(start: &[u8]) -> Option<SiteError> {
    let signature = &binary::SIGNATURE[..start.len().min(binary::SIGNATURE.len())];
    if start.starts_with(signature) {
        return None;
    }
    let json = start.strip_prefix(schema::UTF8_BOM).unwrap_or(start);
    match json.iter().find(|b| !b" \t\r\n".contains(b)) {
        None | Some(b'{' | b'[') => None,
        Some(_) => Site::from_json(start).err(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The reading stops at the limit, whatever the file said its size was, and after the
    /// first block when that is no site file: `/dev/zero` made `Site::load` read about 0.5 GB
    /// before it failed (issue 60, item 10).
    #[test]
    fn site_files_are_read_no_further_than_needed() {
        let io = |e: std::io::Error| SiteError::Io { path: "test".into(), message: e.to_string() };
        let read = |bytes: &[u8], hint: u64, limit: u64| read_bounded(bytes, hint, limit, io);
        let json = [&b"{"[..], &[b' '; 200]].concat();
        assert_eq!(read(&json, 0, 201).unwrap(), json, "a file that says it is empty (a pipe)");
        for hint in [0, 10, 200] {
            match read(&json, hint, 200) {
                Err(SiteError::OverLimit { name: "MAX_SITE_FILE_BYTES", limit: 200, what }) => {
                    assert_eq!(what, "the site file is larger")
                }
                other => panic!("{other:?}"),
            }
        }
        assert!(matches!(read(&json, 500, 201), Err(SiteError::OverLimit { .. })), "refused unread");
        // Never more than the first block of an endless stream that is no site file.
        let mut counted = CountingReader { inner: std::io::repeat(0), read: 0 };
        match read_bounded(&mut counted, 0, budget::MAX_SITE_FILE_BYTES, io) {
            Err(SiteError::Syntax { line: 1, column: 1, .. }) => {}
            other => panic!("{other:?}"),
        }
        assert_eq!(counted.read, FIRST_BLOCK_BYTES);
        // What may still be a site file is read on: either encoding's start, after white
        // space and a byte order mark.
        for start in [&binary::SIGNATURE[..3], &binary::SIGNATURE[..], b"\xEF\xBB\xBF \n{", b"", b"\t\r\n "] {
            assert!(not_a_site_file(start).is_none(), "{start:?}");
        }
        assert!(not_a_site_file(b"\x89PNG\r\n").is_some());
    }

    /// Counts the bytes read through it.
    struct CountingReader<R> {
        inner: R,
        read: u64,
    }

    impl<R: std::io::Read> std::io::Read for CountingReader<R> {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = self.inner.read(buf)?;
            self.read += n as u64;
            Ok(n)
        }
    }

    /// Each state's neighbours are the other ends of its edges, in the order of the site's
    /// edges, whichever end of an edge the state is.
    #[test]
    fn neighbours_are_the_other_ends_of_the_edges() {
        let mut b = SiteBuilder::new("triangle");
        let f = b.floor("G", 0.0);
        let ids: Vec<u32> = [(0.0, 0.0), (1.0, 0.0), (0.0, 2.0)]
            .iter()
            .map(|&(x, y)| b.state(f, Point2::new(x, y), Vec::<TrainingScan>::new()))
            .collect();
        b.edge(ids[0], ids[1], Some(1.0));
        b.edge(ids[1], ids[2], Some(2.0));
        b.edge(ids[2], ids[0], Some(3.0));
        let site = b.build(Default::default()).unwrap();
        let of = |i: usize| site.neighbours(i).collect::<Vec<_>>();
        assert_eq!(of(0), [(1, 1.0), (2, 3.0)]);
        assert_eq!(of(1), [(0, 1.0), (2, 2.0)]);
        assert_eq!(of(2), [(1, 2.0), (0, 3.0)]);
        assert_eq!(site.neighbours(2).len(), 2);
    }

    #[test]
    fn sparse_bands_start_at_their_edges() {
        assert_eq!(
            [0.0, 1.99, 2.0, 4.9, 5.0, 9.9, 10.0, 19.9, 20.0, 1e6].map(SparseScans::band),
            [0, 0, 1, 1, 2, 2, 3, 3, 4, 4]
        );
    }

    /// The site file carries the sparse calibration, and nothing of it when there is none.
    #[test]
    fn sparse_calibration_round_trips() {
        let mut accuracy_scale_by_since = [None; SPARSE_BANDS];
        accuracy_scale_by_since[1] = Some([1.5, 1.25]);
        let calibration = Calibration {
            sparse_scans: SparseScans {
                rssi_weight: Some(0.1),
                accuracy_scale_by_since,
                floor_reliability: FloorReliability::default(),
            },
            ..Calibration::default()
        };
        let json = serde_json::to_string(&calibration).unwrap();
        assert_eq!(serde_json::from_str::<Calibration>(&json).unwrap(), calibration, "{json}");
        let empty = serde_json::to_string(&Calibration::default()).unwrap();
        assert!(!empty.contains("sparse"), "{empty}");
        let scales_only = Calibration {
            sparse_scans: SparseScans { rssi_weight: None, ..calibration.sparse_scans },
            ..Calibration::default()
        };
        let json = serde_json::to_string(&scales_only).unwrap();
        assert!(json.contains("\"accuracy_scale_by_since\":[null,[1.5,1.25],null,null,null]"), "{json}");
    }

    /// A sparse γ out of (0, 1] or a bad factor is refused with its path.
    #[test]
    fn sparse_calibration_is_checked() {
        let gamma = Calibration {
            sparse_scans: SparseScans { rssi_weight: Some(1.5), ..SparseScans::default() },
            ..Calibration::default()
        };
        assert_eq!(gamma.check().unwrap_err().0, "calibration.sparse_scans.rssi_weight");
        let mut accuracy_scale_by_since = [None; SPARSE_BANDS];
        accuracy_scale_by_since[2] = Some([1.0, -1.0]);
        let scale = Calibration {
            sparse_scans: SparseScans { accuracy_scale_by_since, ..SparseScans::default() },
            ..Calibration::default()
        };
        assert_eq!(scale.check().unwrap_err().0, "calibration.sparse_scans.accuracy_scale_by_since[2]");
        assert!(Calibration::default().check().is_ok());
    }

    /// The bands are decades of the mass off the floor, each closed at its upper end of mass.
    #[test]
    fn floor_bands_are_decades_of_the_mass_off_the_floor() {
        assert_eq!(
            [0.0, 0.5, 0.51, 0.9, 0.91, 0.99, 0.995, 0.999, 0.9995, 1.0].map(FloorReliability::band),
            [0, 0, 1, 1, 2, 2, 3, 3, 4, 4]
        );
        let table = FloorReliability([None, Some(0.6), Some(0.8), Some(0.9), Some(0.97)]);
        assert_eq!(table.report(0.3), 0.3, "an unfitted band reports the posterior's mass");
        assert_eq!(table.report(0.95), 0.8);
        assert_eq!(table.report(1.0), 0.97);
        assert_eq!(FloorReliability::default().report(0.95), 0.95);
    }

    /// The floor calibration round-trips as a plain array, is left out when empty and is
    /// refused with its path when a share is not a probability.
    #[test]
    fn floor_reliability_round_trips_and_is_checked() {
        let calibration = Calibration {
            floor_reliability: FloorReliability([None, Some(0.5), Some(0.75), Some(0.9), Some(0.99)]),
            ..Calibration::default()
        };
        let json = serde_json::to_string(&calibration).unwrap();
        assert!(json.contains("\"floor_reliability\":[null,0.5,0.75,0.9,0.99]"), "{json}");
        assert_eq!(serde_json::from_str::<Calibration>(&json).unwrap(), calibration);
        assert!(!serde_json::to_string(&Calibration::default()).unwrap().contains("floor"));
        let mut bad = calibration;
        bad.floor_reliability.0[3] = Some(1.5);
        assert_eq!(bad.check().unwrap_err().0, "calibration.floor_reliability[3]");
        let mut bad = Calibration::default();
        bad.sparse_scans.floor_reliability.0[0] = Some(f64::NAN);
        assert_eq!(bad.check().unwrap_err().0, "calibration.sparse_scans.floor_reliability[0]");
    }
}
