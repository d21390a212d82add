//! What the survey's calibration measured.

use super::held_out::Tag;
use super::radius::RadiusPoint;
use serde::Serialize;
use waymark_engine::site::{Calibration, FLOOR_BANDS, SPARSE_BANDS};

/// One γ of [`GAMMA_GRID`](super::GAMMA_GRID) on one floor's held-out walks.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct GammaPoint {
    /// γ.
    pub gamma: f64,
    /// Mean held-out error over the floor's epochs, m (floor penalty included).
    pub mean_error_m: f64,
    /// Delete-one-walk jackknife standard error of that mean, m: with S_w and n_w the error
    /// sum and epochs of walk w, θ₋w = (S − S_w) / (N − n_w) and
    /// SE = √((k − 1)/k · Σ (θ₋w − θ̄)²) over the k walks (Efron & Tibshirani 1993, eq. 11.5).
    pub jackknife_se_m: f64,
    /// Walks whose own mean error is least at this γ.
    pub walks_preferring: usize,
}

/// Leave-one-walk-out on one floor: each survey walk replayed on a site surveyed without it.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FloorCalibrationReport {
    /// Floor name.
    pub name: String,
    /// Survey walks held out that scored at least one epoch.
    pub walks: usize,
    /// Held-out epochs scored (with the motion, at each γ).
    pub epochs: usize,
    /// The error curve over γ with the motion as the sensors give it.
    pub gamma: Vec<GammaPoint>,
    /// The curve the floor's own γ is chosen on: its held-out walks that the rest of the survey
    /// covers end to end, replayed as shipped at each γ (`CalibrationReport::gamma_covered_mean_error_m`);
    /// empty when `gamma` decided.
    pub gamma_covered: Vec<GammaPoint>,
    /// The same with the motion withheld.
    pub gamma_without_movement: Vec<GammaPoint>,
    /// The floor's own γ, recorded in the site file: its least mean held-out error on the curve
    /// that decided (`gamma_covered`, else `gamma`), kept only when it beats the site-wide γ
    /// there by more than its standard error (`own_gamma`); `None`: the floor runs at the
    /// site-wide γ.
    pub rssi_weight: Option<f64>,
    /// The same for epochs without a movement likelihood.
    pub rssi_weight_without_movement: Option<f64>,
    /// The γ of least mean held-out error on this floor on the curve that decided, whether kept
    /// or not.
    pub best_rssi_weight: Option<f64>,
    /// Jackknife standard error of the mean error at that γ, m.
    pub jackknife_se_m: Option<f64>,
    /// How much of the floor only one walk surveyed, from the held-out walks replayed as
    /// shipped.
    pub coverage: Coverage,
}

/// A floor's held-out walks replayed with the engine as shipped, split by whether the truth
/// lay on the map the other walks made. An epoch beyond it is on a stretch only the held-out
/// walk surveyed: a phone there is positioned from the neighbours, so a high share says the
/// floor needs more walks (`docs/surveying.md#is-the-survey-enough`).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Coverage {
    /// Held-out epochs scored.
    pub epochs: usize,
    /// Of those, epochs whose truth lay beyond the map the other walks made.
    pub beyond_map: usize,
    /// Mean error of the epochs on that map, m (floor penalty included; NaN, `null` in JSON,
    /// without any).
    pub mean_error_on_map_m: f64,
    /// Mean error of the epochs beyond it, m (the same).
    pub mean_error_beyond_map_m: f64,
    /// Where those epochs were: the stretches to walk again. Not in the JSON report;
    /// [`coverage_geojson`] writes them.
    #[serde(skip)]
    pub beyond_map_points: Vec<CoveragePoint>,
}

/// A held-out epoch beyond the map the other walks made.
#[derive(Clone, Debug, PartialEq)]
pub struct CoveragePoint {
    /// The held-out walk's name.
    pub walk: String,
    /// Its true position in the floor's frame, m.
    pub position_m: [f64; 2],
    /// How far beyond the map, m.
    pub beyond_map_m: f64,
    /// The engine's error there, m (floor penalty included).
    pub error_m: f64,
}

impl Coverage {
    /// The coverage of a floor from its held-out epochs, each with its walk's name.
    pub(super) fn of<'a>(tags: impl IntoIterator<Item = (&'a str, &'a Tag)>) -> Self {
        let (mut on, mut beyond) = ((0usize, 0.0), (0usize, 0.0));
        let mut beyond_map_points = Vec::new();
        for (walk, t) in tags {
            let error_m = t.scored.penalised_m();
            let side = if t.beyond_map_m > 0.0 {
                beyond_map_points.push(CoveragePoint {
                    walk: walk.to_string(),
                    position_m: t.truth,
                    beyond_map_m: t.beyond_map_m,
                    error_m,
                });
                &mut beyond
            } else {
                &mut on
            };
            side.0 += 1;
            side.1 += error_m;
        }
        let mean = |(n, sum): (usize, f64)| if n > 0 { sum / n as f64 } else { f64::NAN };
        Coverage {
            epochs: on.0 + beyond.0,
            beyond_map: beyond.0,
            mean_error_on_map_m: mean(on),
            mean_error_beyond_map_m: mean(beyond),
            beyond_map_points,
        }
    }

    /// The share of epochs beyond the map (NaN without epochs).
    pub fn beyond_map_share(&self) -> f64 {
        if self.epochs > 0 {
            self.beyond_map as f64 / self.epochs as f64
        } else {
            f64::NAN
        }
    }
}

/// What the survey's calibration measured.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct CalibrationReport {
    /// All floors pooled: mean held-out error at each γ of [`GAMMA_GRID`](super::GAMMA_GRID), m (floor penalty
    /// included).
    pub gamma_mean_error_m: Vec<(f64, f64)>,
    /// The same with the motion withheld.
    pub gamma_without_movement_mean_error_m: Vec<(f64, f64)>,
    /// All floors pooled, at the site-wide γ with the motion: mean held-out error with each M
    /// of [`ESTIMATE_STATES_GRID`](super::ESTIMATE_STATES_GRID), m (floor penalty included);
    /// empty when the configuration sets M.
    pub estimate_states_mean_error_m: Vec<(usize, f64)>,
    /// The M of least error there (Hoang eq. 4).
    pub estimate_states: Option<u32>,
    /// Held-out walks that the rest of the survey covers end to end (each of their epochs on
    /// the map the other walks made), and their epochs: what γ is chosen on again.
    pub covered_walks: usize,
    /// See `covered_walks`.
    pub covered_epochs: usize,
    /// Those walks replayed with the engine as shipped at each γ of the grid: mean error at
    /// each, m (floor penalty included). Its least
    /// is the site-wide γ when the walks have at least
    /// [`MIN_SCENARIO_EPOCHS`](super::MIN_SCENARIO_EPOCHS) epochs (`docs/tuning.md#gamma`).
    pub gamma_covered_mean_error_m: Vec<(f64, f64)>,
    /// The site-wide γ, for floors without their own: the least of
    /// `gamma_covered_mean_error_m`, or of `gamma_mean_error_m` where too few walks are covered.
    pub rssi_weight: Option<f64>,
    /// The same for epochs without a movement likelihood.
    pub rssi_weight_without_movement: Option<f64>,
    /// How often the survey's walkers changed floor, per second
    /// ([`Calibration::floor_change_rate_hz`](waymark_engine::site::Calibration::floor_change_rate_hz)).
    pub floor_change_rate_hz: Option<f64>,
    /// All floors pooled, with only the distance and with only the heading: the curve each
    /// scenario's own γ is chosen on (`rssi_weight_by_scenario`).
    pub gamma_by_scenario: waymark_engine::site::PerScenario<Vec<GammaPoint>>,
    /// The γ of those scenarios, when their own beat `rssi_weight_without_movement` on their
    /// curve by more than its standard error.
    pub rssi_weight_by_scenario: waymark_engine::site::PerScenario<f64>,
    /// Per floor, in site order: the γ each floor gets.
    pub floors: Vec<FloorCalibrationReport>,
    /// The radius factors chosen (68%, 95%), over the held-out walks replayed with the engine
    /// as shipped (every calibrated value but the factors, the motion as the sensors give it):
    /// the 68% over their epochs on the map (`OnMap`), the 95% over all of them
    /// (`docs/tuning.md#radius-factors`). The fallback for a scenario without its own.
    pub accuracy_scale: Option<[f64; 2]>,
    /// The factors per motion scenario, over the held-out epochs the engine positioned in that
    /// scenario (the 68% over those on the map, as above): from the replays with the engine as shipped when they have
    /// at least [`MIN_SCENARIO_EPOCHS`](super::MIN_SCENARIO_EPOCHS) in it, else from the
    /// calibration's replays with the motion as the sensors give it, withheld, distance only
    /// and heading only, at each floor's γ; a scenario with fewer than that in both has none.
    pub accuracy_scale_by_scenario: waymark_engine::site::ScenarioScales,
    /// Those epochs per scenario ([`MotionScenario::ALL`](waymark_engine::sensors::MotionScenario::ALL) order).
    pub scenario_epochs: [usize; 4],
    /// Held-out epochs on the map replayed with the engine as shipped: what
    /// `accuracy_scale`'s 68% factor was fitted on.
    pub epochs: usize,
    /// Held-out epochs left out of the 68% radius factors (the 95% ones count them): their
    /// truth was off the held-out site's map (`OnMap`).
    pub epochs_off_map: usize,
    /// How the engine did on those epochs as shipped (every calibrated value, the radio fit
    /// floor included, radii with the chosen factors): what a walk that leaves the surveyed
    /// area gets.
    pub off_map: OffMapReport,
    /// The same from the calibration's own replays, without the radio fit floor (radii with
    /// the chosen factors).
    pub off_map_without_floor: OffMapReport,
    /// The held-out epochs on the map, replayed with the engine as shipped, as one band: by
    /// construction their radii hold the truth at about 68% and 95%.
    pub on_map: OffMapReport,
    /// The radio fit floor chosen ([`Calibration::radio_fit_floor`]), nats per radio heard: none
    /// from fewer than [`MIN_SCENARIO_EPOCHS`](super::MIN_SCENARIO_EPOCHS) scans (a 5% percentile then rests on ten below).
    pub radio_fit_floor: Option<f64>,
    /// The share of the held-out scans on the map whose fit quantile that floor is.
    pub radio_fit_floor_share: Option<f64>,
    /// Each candidate floor: (share, floor in nats per radio heard, mean error of the steady
    /// held-out epochs replayed as shipped with it, m, floor penalty included).
    pub radio_fit_floor_mean_error_m: Vec<(f64, f64, f64)>,
    /// Held-out scans on the map the floor was chosen from.
    pub radio_fit_scans: usize,
    /// Sites surveyed for the leave-one-walk-out (one per survey walk).
    pub sites: usize,
    /// Mean share of states whose fingerprints those sites fitted afresh (the rest were
    /// reused from the site of all walks, their training scans being the same).
    pub refitted_share: f64,
    /// The step length and north fitted on the survey walks.
    pub motion: Option<MotionSummary>,
    /// The fingerprint radius the site was surveyed with, m: the calibrated one, or the
    /// survey options' when not calibrated.
    pub fingerprint_radius_m: f64,
    /// Held-out error of the engine per radius of [`FINGERPRINT_RADIUS_GRID`](super::FINGERPRINT_RADIUS_GRID) tried, at its
    /// best γ: (radius m, mean error m at the WiFi scans with the floor penalty, scans); empty
    /// when the radius was given.
    pub fingerprint_radius_mean_error_m: Vec<RadiusPoint>,
    /// The held-out walks replayed with throttled scans, and what they calibrated.
    pub sparse_scans: SparseScansReport,
    /// The floor probability's calibration outside the sparse regime.
    pub floor_reliability: FloorReliabilityReport,
}

/// The calibration for sparse scans ([`SparseScans`](waymark_engine::site::SparseScans)): every
/// held-out walk replayed again at each γ with one scan every 30 s reaching the engine.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct SparseScansReport {
    /// All floors pooled: held-out error per γ of the walks covered end to end, replayed as
    /// shipped with one scan every 30 s (`CalibrationReport::gamma_covered_mean_error_m`'s
    /// replays, throttled).
    pub gamma: Vec<GammaPoint>,
    /// Held-out epochs on the map in the sparse regime at the γ they get, per band of time
    /// since the sparse scan (`SINCE_SPARSE_SCAN_BANDS_S`): the radius factors of a band with
    /// fewer than [`MIN_SCENARIO_EPOCHS`](super::MIN_SCENARIO_EPOCHS) are not fitted.
    pub epochs_by_since: [usize; SPARSE_BANDS],
    /// The floor probability's calibration in the sparse regime.
    pub floor_reliability: FloorReliabilityReport,
    /// What was chosen.
    pub calibration: waymark_engine::site::SparseScans,
}

/// The floor probability's calibration ([`FloorReliability`](waymark_engine::site::FloorReliability))
/// and the held-out epochs on the map it rests on; empty on a site of one floor.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct FloorReliabilityReport {
    /// Per band of the posterior's mass on the floor (`FLOOR_MISS_BANDS`): (epochs whose floor
    /// was right, epochs). Fewer than [`MIN_SCENARIO_EPOCHS`](super::MIN_SCENARIO_EPOCHS) in
    /// all: no calibration.
    pub epochs_right_by_band: [[usize; 2]; FLOOR_BANDS],
    /// What was chosen.
    pub calibration: waymark_engine::site::FloorReliability,
}

/// The held-out epochs whose truth was off the held-out site's map, with the motion as the
/// sensors give it at each floor's γ, by how far beyond the map the truth was.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct OffMapReport {
    /// Per band of distance beyond the map (bands without epochs left out).
    pub bands: Vec<OffMapBand>,
}

/// One band of [`OffMapReport`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct OffMapBand {
    /// Distance beyond the map, m: from (exclusive; 0 with `to_m` 0: on the map).
    pub from_m: f64,
    /// To (inclusive; infinite, `null` in JSON, for the last band).
    pub to_m: f64,
    /// Epochs.
    pub epochs: usize,
    /// Mean horizontal error, m (no floor penalty).
    pub mean_error_m: f64,
    /// Share whose 68% radius holds the truth: the replay's own radius with the chosen factors
    /// applied as the engine applies them.
    pub accuracy_68_hit: f64,
    /// The same for the 95% radius.
    pub accuracy_95_hit: f64,
}

/// Bands of distance beyond the map, m, for the report only: within one grid spacing (2 m,
/// `SurveyOptions::spacing_m`) of the map's cells, then about 2-5, 5-10 and over 10 s of
/// walking at HIPE's 1 m/s.
const OFF_MAP_BANDS: [f64; 5] = [0.0, 2.0, 5.0, 10.0, f64::INFINITY];

impl OffMapReport {
    /// Epochs on the map as one band from 0 to 0 m, their radii with `calibration`'s factors.
    pub(super) fn of_on_map(points: &[&Tag], calibration: &Calibration) -> Self {
        Self { bands: OffMapBand::of(0.0, 0.0, points, calibration).into_iter().collect() }
    }

    /// Epochs beyond the map by band, their radii with `calibration`'s factors.
    pub(super) fn of(points: &[&Tag], calibration: &Calibration) -> Self {
        let bands = OFF_MAP_BANDS
            .windows(2)
            .filter_map(|w| {
                let inside: Vec<&Tag> = points
                    .iter()
                    .copied()
                    .filter(|t| t.beyond_map_m > w[0] && t.beyond_map_m <= w[1])
                    .collect();
                OffMapBand::of(w[0], w[1], &inside, calibration)
            })
            .collect();
        Self { bands }
    }
}

impl OffMapBand {
    /// The band of `points`, their radii with `calibration`'s factors; `None` without points.
    fn of(from_m: f64, to_m: f64, points: &[&Tag], calibration: &Calibration) -> Option<Self> {
        let n = points.len();
        let holds: Vec<[bool; 2]> = points.iter().map(|t| t.holds(calibration)).collect();
        let share = |k: usize| holds.iter().filter(|h| h[k]).count() as f64 / n as f64;
        (n > 0).then(|| OffMapBand {
            from_m,
            to_m,
            epochs: n,
            mean_error_m: points.iter().map(|t| t.scored.error_m).sum::<f64>() / n as f64,
            accuracy_68_hit: share(0),
            accuracy_95_hit: share(1),
        })
    }
}

/// The motion calibration, for reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MotionSummary {
    /// The chosen step length model.
    pub step_length: waymark_engine::sensors::StepLengthModel,
    /// Site heading = magnetic azimuth + this, degrees.
    pub heading_offset_deg: f64,
    /// Walks used.
    pub walks: usize,
}

/// The held-out epochs beyond the map of every floor of `report`, as a GeoJSON (RFC 7946)
/// FeatureCollection of points in WGS84 longitude/latitude, each with its floor's name and
/// level, its walk, how far beyond the map it was and the error there: where a survey of
/// `site` needs more walks (`docs/surveying.md#is-the-survey-enough`). `None` when `site` is
/// not geo-referenced, since GeoJSON has no other frame.
pub fn coverage_geojson(
    site: &waymark_engine::Site,
    report: &CalibrationReport,
) -> Option<geojson::FeatureCollection> {
    site.anchor()?;
    let mut features = Vec::new();
    for (f, floor) in report.floors.iter().enumerate() {
        for p in &floor.coverage.beyond_map_points {
            let at = site.lat_lon(f, p.position_m[0], p.position_m[1])?;
            let properties = serde_json::json!({
                "floor": floor.name,
                "level": site.floor_level(f),
                "walk": p.walk,
                "beyond_map_m": p.beyond_map_m,
                "error_m": p.error_m,
            });
            features.push(geojson::Feature {
                geometry: Some(geojson::Geometry::new(geojson::Value::Point(vec![at.lon_deg, at.lat_deg]))),
                properties: properties.as_object().cloned(),
                ..geojson::Feature::default()
            });
        }
    }
    Some(geojson::FeatureCollection { bbox: None, features, foreign_members: None })
}
