//! The accuracy benchmark over buildings (`docs/benchmark.md`): a list of rows, each a building,
//! a split of its walks into survey and test walks, and the share of survey walks kept; each
//! row surveyed, calibrated and evaluated as `waymark eval` does it
//! ([`survey_calibrated`], then [`evaluate_on`]); the figures of each configuration with the
//! walk-bootstrap standard error of its mean; the mean over buildings; and the rule a change to
//! the engine is judged by against a baseline run ([`compare`]).

use crate::real::{
    evaluate_crowd, evaluate_on, split_without_labels, EvalError, EvalOptions, WalkResult, WithoutLabels,
};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};
use statrs::statistics::Statistics;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;
use waymark_survey::calibrate::{
    load_gsd_building, survey_calibrated, survey_with_unlabelled, CalibrationError, FloorData,
    UnlabelledOptions, WalkSplit,
};
use waymark_survey::io::Trace;
use waymark_survey::scoring::{Metrics, Scored};

mod compare;

pub use compare::{compare, Change, Comparison, Verdict};

/// Where the rows' data is read from.
#[derive(Clone, Debug)]
pub struct DataSource {
    /// The checkout: data unpacked under its `target/`, or found as [`crate::data`] says.
    pub workspace: PathBuf,
    /// Only the first N walk files of each floor (a quick look, not the benchmark).
    pub max_walks: Option<usize>,
}

/// Why a row's data could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// The data is not on this machine: the row is skipped.
    #[error("{0}")]
    Absent(String),
    /// The data is there but could not be read.
    #[error(transparent)]
    Calibration(#[from] CalibrationError),
}

/// Reads a row's floors, split into survey and test walks (one multi-floor site).
pub type Loader = fn(&DataSource) -> Result<Vec<FloorData>, LoadError>;

/// One row of the benchmark: a building, a split of its walks, and the share of each floor's
/// survey walks the site is surveyed from. A value, so that a building's rows are a few lines
/// of [`ROWS`].
#[derive(Clone, Copy, Debug)]
pub struct Row {
    /// The building, as the data names it (`ilc20-site1`); the mean over buildings groups by it.
    pub building: &'static str,
    /// The split, unique within the building (`F=1`).
    pub split: &'static str,
    /// The share F (0 < F ≤ 1) of each floor's survey walks kept
    /// ([`FloorData::keep_survey_fraction`]), as `waymark eval --survey-fraction`.
    pub survey_fraction: f64,
    /// Reads the row's floors.
    pub load: Loader,
    /// What the survey is given besides its labelled walks.
    pub protocol: Protocol,
}

/// How a row's site is made from its walks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Protocol {
    /// From the labelled survey walks alone: the rows every accuracy change is judged on.
    Labelled,
    /// The labelled survey walks and the walks [`WithoutLabels`] names (a map learned from
    /// use, docs/evidence.md); a row of [`LEARNING_ROWS`].
    WithoutLabels {
        /// The survey walks the fraction leaves out, given back without labels.
        rest: bool,
        /// Test walks of these repetitions given without labels.
        test_unlabelled: &'static [u32],
        /// Test walks of these repetitions surveyed with labels.
        test_labelled: &'static [u32],
    },
    /// The crowd protocol with this many folds ([`evaluate_crowd`]); a row of [`LEARNING_ROWS`].
    Crowd(usize),
}

impl Protocol {
    fn without_labels(&self) -> WithoutLabels<'static> {
        match *self {
            Protocol::WithoutLabels { rest, test_unlabelled, test_labelled } => {
                WithoutLabels { rest, test_unlabelled, test_labelled }
            }
            Protocol::Labelled | Protocol::Crowd(_) => WithoutLabels::default(),
        }
    }
}

impl Row {
    /// `building/split`, as `--rows` names it.
    pub fn name(&self) -> String {
        format!("{}/{}", self.building, self.split)
    }

    /// The row's floors, its survey fraction applied, and the walks its protocol gives the
    /// survey without labels ([`split_without_labels`]).
    pub fn floors(&self, source: &DataSource) -> Result<(Vec<FloorData>, Vec<Trace>), LoadError> {
        let floors = (self.load)(source)?;
        Ok(split_without_labels(floors, self.survey_fraction, self.protocol.without_labels()))
    }

    /// Whether the row is one of [`LEARNING_ROWS`]: not in the mean over buildings.
    pub fn learning(&self) -> bool {
        self.protocol != Protocol::Labelled
    }
}

pub use crate::data::SITE1_FLOORS;

/// Site 1's five floors ([`SITE1_FLOORS`]), split as `waymark eval` splits them (file i of a
/// floor is a test walk when i % 5 == 4).
pub fn ilc20_site1(source: &DataSource) -> Result<Vec<FloorData>, LoadError> {
    SITE1_FLOORS
        .iter()
        .map(|floor| {
            let dir = crate::data::site1_floor(&source.workspace, floor)
                .ok_or_else(|| LoadError::Absent(format!("ilc20-site1/{floor} not found")))?;
            Ok(FloorData::load(&dir, source.max_walks)?)
        })
        .collect()
}

/// The IPIN 2023 museum's logfiles split by `split` ([`load_gsd_building`]).
fn ipin2023_t3(source: &DataSource, split: WalkSplit) -> Result<Vec<FloorData>, LoadError> {
    let dir = crate::data::ipin2023_t3(&source.workspace)
        .ok_or_else(|| LoadError::Absent("ipin2023-t3 not found".into()))?;
    Ok(load_gsd_building(&dir, &split, source.max_walks)?)
}

/// The museum surveyed with the SM-A520F and tested with the SM-G930F.
pub fn ipin2023_t3_a520f(source: &DataSource) -> Result<Vec<FloorData>, LoadError> {
    ipin2023_t3(source, WalkSplit::Phone("SM-A520F".into()))
}

/// The museum surveyed with the SM-G930F and tested with the SM-A520F.
pub fn ipin2023_t3_g930f(source: &DataSource) -> Result<Vec<FloorData>, LoadError> {
    ipin2023_t3(source, WalkSplit::Phone("SM-G930F".into()))
}

/// The museum surveyed from repetitions 1 and 3 of every route and tested on 2 and 4: both
/// phones on both sides (the data's README).
pub fn ipin2023_t3_both(source: &DataSource) -> Result<Vec<FloorData>, LoadError> {
    ipin2023_t3(source, WalkSplit::Repetitions(vec![1, 3]))
}

/// Every row of the benchmark, in the order it runs them: the five floors surveyed from all
/// their survey walks and from half of them, and the museum surveyed with each phone and tested
/// with the other, and with both phones on both sides (`docs/benchmark.md#rows`).
pub const ROWS: [Row; 5] = [
    Row {
        building: "ilc20-site1",
        split: "F=1",
        survey_fraction: 1.0,
        load: ilc20_site1,
        protocol: LABELLED,
    },
    Row {
        building: "ilc20-site1",
        split: "F=0.5",
        survey_fraction: 0.5,
        load: ilc20_site1,
        protocol: LABELLED,
    },
    Row {
        building: "ipin2023-t3",
        split: "A520F-surveys",
        survey_fraction: 1.0,
        load: ipin2023_t3_a520f,
        protocol: LABELLED,
    },
    Row {
        building: "ipin2023-t3",
        split: "G930F-surveys",
        survey_fraction: 1.0,
        load: ipin2023_t3_g930f,
        protocol: LABELLED,
    },
    Row {
        building: "ipin2023-t3",
        split: "both-phones",
        survey_fraction: 1.0,
        load: ipin2023_t3_both,
        protocol: LABELLED,
    },
];

const LABELLED: Protocol = Protocol::Labelled;

/// The survey walks the fraction leaves out, given back without labels.
const REST_UNLABELLED: Protocol =
    Protocol::WithoutLabels { rest: true, test_unlabelled: &[], test_labelled: &[] };

/// The rows of a map learned from use (`waymark benchmark --learning`, docs/evidence.md#measured),
/// after [`ROWS`] and not in the mean over buildings: the five floors with the survey walks
/// F = 0.5 and 0.25 leave out given back without labels, and with the crowd protocol at F = 1;
/// the museum surveyed with the SM-A520F and the SM-G930F's repetition 3 given without labels,
/// and with labels (the baseline on the same test walks: the G930F's other walks).
pub const LEARNING_ROWS: [Row; 5] = [
    Row {
        building: "ilc20-site1",
        split: "F=0.5+rest-unlabelled",
        survey_fraction: 0.5,
        load: ilc20_site1,
        protocol: REST_UNLABELLED,
    },
    Row {
        building: "ilc20-site1",
        split: "F=0.25+rest-unlabelled",
        survey_fraction: 0.25,
        load: ilc20_site1,
        protocol: REST_UNLABELLED,
    },
    Row {
        building: "ilc20-site1",
        split: "F=1-crowd-2",
        survey_fraction: 1.0,
        load: ilc20_site1,
        protocol: Protocol::Crowd(2),
    },
    Row {
        building: "ipin2023-t3",
        split: "A520F-surveys+G930F-rep3-unlabelled",
        survey_fraction: 1.0,
        load: ipin2023_t3_a520f,
        protocol: Protocol::WithoutLabels { rest: false, test_unlabelled: &[3], test_labelled: &[] },
    },
    Row {
        building: "ipin2023-t3",
        split: "A520F-surveys+G930F-rep3-labelled",
        survey_fraction: 1.0,
        load: ipin2023_t3_a520f,
        protocol: Protocol::WithoutLabels { rest: false, test_unlabelled: &[], test_labelled: &[3] },
    },
];

/// Resamples of the walk bootstrap. An SE needs a few hundred (Efron & Tibshirani, *An
/// Introduction to the Bootstrap*, 1993, §6.4: seldom more than 200); 1000 keeps the SE's own
/// resampling error near 2% (about 1/√(2B) for a statistic near normal).
pub const BOOTSTRAP_RESAMPLES: usize = 1000;

/// Seed of the walk bootstrap: fixed, so a run's SE does not move when nothing else does, and
/// the same for every configuration of a row, which then resample the same walks.
pub const BOOTSTRAP_SEED: u64 = 59;

/// The walk-bootstrap standard error of a pooled mean: `walks` holds each walk's (Σ penalised
/// error, points); the walks are drawn with replacement as many times as there are, the pooled
/// mean Σ errors / Σ points recomputed, `resamples` times, and the standard deviation of those
/// means returned (Efron & Tibshirani 1993, eq. 6.6). Walks, not points, are resampled: the
/// errors along one walk are not independent. Walks without points take no part (they add
/// nothing to the pooled mean). `None` without any walk with points, or under 2 resamples.
pub fn bootstrap_se(walks: &[(f64, usize)], resamples: usize, seed: u64) -> Option<f64> {
    let walks: Vec<(f64, usize)> = walks.iter().copied().filter(|w| w.1 > 0).collect();
    if walks.is_empty() || resamples < 2 {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let means: Vec<f64> = (0..resamples)
        .map(|_| {
            let (sum, points) = (0..walks.len()).fold((0.0, 0usize), |(sum, points), _| {
                let (s, n) = walks[rng.random_range(0..walks.len())];
                (sum + s, points + n)
            });
            sum / points as f64
        })
        .collect();
    // Identical walks give identical means, whose spread is 0 exactly.
    if means.iter().all(|&m| m == means[0]) {
        return Some(0.0);
    }
    Some(means.iter().std_dev())
}

/// One configuration's figures in one row.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Figures {
    /// Mean error, m, a wrong floor adding 15 m ([`Metrics::mean_m`]).
    pub mean_m: f64,
    /// 90th percentile, m.
    pub p90_m: f64,
    /// IPIN's score: the 75th percentile, m ([`Metrics::p75_m`]).
    pub p75_m: f64,
    /// Share of points within the reported 68% radius.
    pub accuracy_68_hit: f64,
    /// Share within the reported 95% radius.
    pub accuracy_95_hit: f64,
    /// Share on the right floor.
    pub floor_hit: f64,
    /// Walk-bootstrap standard error of `mean_m`, m ([`bootstrap_se`]); `null` without walks.
    pub mean_se_m: Option<f64>,
    /// Points scored.
    pub epochs: usize,
}

impl Figures {
    /// From the pooled metrics and each test walk's scored points.
    pub fn new(pooled: &Metrics, walks: &[&[Scored]]) -> Figures {
        let sums: Vec<(f64, usize)> =
            walks.iter().map(|w| (w.iter().map(Scored::penalised_m).sum(), w.len())).collect();
        Figures {
            mean_m: pooled.mean_m,
            p90_m: pooled.p90_m,
            p75_m: pooled.p75_m,
            accuracy_68_hit: pooled.accuracy_68_hit,
            accuracy_95_hit: pooled.accuracy_95_hit,
            floor_hit: pooled.floor_hit,
            mean_se_m: bootstrap_se(&sums, BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED),
            epochs: pooled.epochs,
        }
    }
}

/// One row's outcome.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RowReport {
    /// [`Row::building`].
    pub building: String,
    /// [`Row::split`].
    pub split: String,
    /// [`Row::survey_fraction`].
    pub survey_fraction: f64,
    /// A row of a map learned from use ([`LEARNING_ROWS`]): not in the mean over buildings.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub learning: bool,
    /// Why the row was not evaluated (its data is absent); absent when it was.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub skipped: Option<String>,
    /// Test walks replayed.
    #[serde(default)]
    pub test_walks: usize,
    /// Wall-clock time of the row (reading, survey and calibration, replays), s.
    #[serde(default)]
    pub seconds: f64,
    /// Per configuration key.
    #[serde(default)]
    pub configurations: BTreeMap<String, Figures>,
    /// Each test walk's figures, to find which walks a change moved.
    #[serde(default)]
    pub walks: Vec<WalkFigures>,
}

/// One test walk's figures in a row.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WalkFigures {
    /// The walk's name (its file's).
    pub name: String,
    /// Per configuration key: (mean error with the floor penalty, m; share on the right floor;
    /// points scored).
    pub configurations: BTreeMap<String, (f64, f64, usize)>,
}

impl WalkFigures {
    fn new(walk: &WalkResult) -> WalkFigures {
        let configurations = walk
            .scored
            .iter()
            .filter(|(_, points)| !points.is_empty())
            .map(|(key, points)| {
                let n = points.len();
                let mean = points.iter().map(Scored::penalised_m).sum::<f64>() / n as f64;
                let floor = points.iter().filter(|p| p.floor_correct).count() as f64 / n as f64;
                (key.clone(), (mean, floor, n))
            })
            .collect();
        WalkFigures { name: walk.name.clone(), configurations }
    }
}

impl RowReport {
    /// `row` not evaluated, for `reason`.
    pub fn skipped(row: &Row, reason: String) -> RowReport {
        RowReport {
            building: row.building.into(),
            split: row.split.into(),
            survey_fraction: row.survey_fraction,
            learning: row.learning(),
            skipped: Some(reason),
            test_walks: 0,
            seconds: 0.0,
            configurations: BTreeMap::new(),
            walks: Vec::new(),
        }
    }

    /// `building/split`.
    pub fn name(&self) -> String {
        format!("{}/{}", self.building, self.split)
    }
}

/// Surveys and calibrates a site from the survey walks of `floors` and replays their test
/// walks, as `waymark eval` does: [`survey_calibrated`], then [`evaluate_on`] with the options
/// the survey made the site with. `calibrating` ticks once per calibration step
/// ([`calibration_steps`](waymark_survey::calibrate::calibration_steps)), `replaying` once per
/// test walk. `started` is when the row began (its reading counts in [`RowReport::seconds`]).
#[allow(clippy::too_many_arguments)]
pub fn evaluate_row(
    row: &Row,
    floors: &[FloorData],
    unlabelled: &[Trace],
    options: &EvalOptions,
    started: Instant,
    calibrating: &(dyn Fn() + Sync),
    replaying: &(dyn Fn() + Sync),
) -> Result<RowReport, EvalError> {
    let (configurations, walks) = match row.protocol {
        Protocol::Crowd(folds) => {
            let crowd = evaluate_crowd(floors, options, folds, UnlabelledOptions::default(), calibrating)?;
            (crowd.configurations, crowd.walks)
        }
        Protocol::WithoutLabels { .. } if !unlabelled.is_empty() => {
            let (site, _, calibration, _) = survey_with_unlabelled(
                floors,
                unlabelled,
                &options.calibration,
                UnlabelledOptions::default(),
                calibrating,
            )?;
            evaluate_on(&Arc::new(site), floors, &options.surveyed_with(&calibration), replaying)?
        }
        _ => {
            let (site, _, calibration) = survey_calibrated(floors, &options.calibration, calibrating)?;
            evaluate_on(&Arc::new(site), floors, &options.surveyed_with(&calibration), replaying)?
        }
    };
    let configurations = configurations
        .iter()
        .map(|(key, report)| {
            let scored: Vec<&[Scored]> =
                walks.iter().filter_map(|w| w.scored.get(key).map(Vec::as_slice)).collect();
            (key.clone(), Figures::new(&report.pooled, &scored))
        })
        .collect();
    Ok(RowReport {
        building: row.building.into(),
        split: row.split.into(),
        survey_fraction: row.survey_fraction,
        learning: row.learning(),
        skipped: None,
        test_walks: walks.len(),
        seconds: started.elapsed().as_secs_f64(),
        configurations,
        walks: walks.iter().map(WalkFigures::new).collect(),
    })
}

/// One configuration's figures averaged over buildings ([`building_mean`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MeanFigures {
    /// Mean error, m.
    pub mean_m: f64,
    /// IPIN's score, m.
    pub p75_m: f64,
    /// Share within the reported 68% radius.
    pub accuracy_68_hit: f64,
    /// Share within the reported 95% radius.
    pub accuracy_95_hit: f64,
    /// Share on the right floor.
    pub floor_hit: f64,
}

impl MeanFigures {
    fn of(f: &Figures) -> MeanFigures {
        MeanFigures {
            mean_m: f.mean_m,
            p75_m: f.p75_m,
            accuracy_68_hit: f.accuracy_68_hit,
            accuracy_95_hit: f.accuracy_95_hit,
            floor_hit: f.floor_hit,
        }
    }

    /// The plain average of `figures`, each field on its own.
    fn average(figures: &[MeanFigures]) -> MeanFigures {
        let n = figures.len() as f64;
        let mean = |field: fn(&MeanFigures) -> f64| figures.iter().map(field).sum::<f64>() / n;
        MeanFigures {
            mean_m: mean(|f| f.mean_m),
            p75_m: mean(|f| f.p75_m),
            accuracy_68_hit: mean(|f| f.accuracy_68_hit),
            accuracy_95_hit: mean(|f| f.accuracy_95_hit),
            floor_hit: mean(|f| f.floor_hit),
        }
    }
}

/// The evaluated rows of `rows` (not skipped) by building, in name order.
fn by_building(rows: &[RowReport]) -> BTreeMap<&str, Vec<&RowReport>> {
    let mut buildings: BTreeMap<&str, Vec<&RowReport>> = BTreeMap::new();
    for row in rows.iter().filter(|r| r.skipped.is_none() && !r.learning) {
        buildings.entry(&row.building).or_default().push(row);
    }
    buildings
}

/// The mean over buildings, per configuration: each building's evaluated rows averaged (every
/// split and survey fraction of it alike), then the buildings averaged, each counting once
/// however many rows it has; each figure averaged on its own. A configuration counts only when
/// every evaluated row has it. Returns the means and the buildings they are over.
pub fn building_mean(rows: &[RowReport]) -> (BTreeMap<String, MeanFigures>, Vec<String>) {
    let buildings = by_building(rows);
    let evaluated: Vec<&RowReport> = buildings.values().flatten().copied().collect();
    let Some(first) = evaluated.first() else { return (BTreeMap::new(), Vec::new()) };
    let mut mean = BTreeMap::new();
    for key in first.configurations.keys() {
        if !evaluated.iter().all(|r| r.configurations.contains_key(key)) {
            continue;
        }
        let per_building: Vec<MeanFigures> = buildings
            .values()
            .map(|rows| {
                let figures: Vec<MeanFigures> =
                    rows.iter().map(|r| MeanFigures::of(&r.configurations[key])).collect();
                MeanFigures::average(&figures)
            })
            .collect();
        mean.insert(key.clone(), MeanFigures::average(&per_building));
    }
    (mean, buildings.keys().map(|b| b.to_string()).collect())
}

/// What `waymark benchmark --json` writes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BenchmarkReport {
    /// Every row asked for, evaluated or skipped, in the order run.
    pub rows: Vec<RowReport>,
    /// Per configuration key, the mean over buildings ([`building_mean`]).
    pub mean: BTreeMap<String, MeanFigures>,
    /// The buildings `mean` is over: those with an evaluated row.
    pub buildings: Vec<String>,
    /// `--max-walks`, when the run read only the first walks of each floor: not the benchmark.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_walks: Option<usize>,
}

impl BenchmarkReport {
    /// From the rows, with their mean over buildings.
    pub fn new(rows: Vec<RowReport>, max_walks: Option<usize>) -> BenchmarkReport {
        let (mean, buildings) = building_mean(&rows);
        BenchmarkReport { rows, mean, buildings, max_walks }
    }

    /// A report as written by `--out` or `--json`.
    pub fn read(path: &Path) -> Result<BenchmarkReport, String> {
        let text =
            std::fs::read_to_string(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        serde_json::from_str(&text).map_err(|e| format!("{}: not a benchmark report: {e}", path.display()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn figures(mean_m: f64, mean_se_m: Option<f64>) -> Figures {
        Figures {
            mean_m,
            p90_m: 2.0 * mean_m,
            p75_m: 1.5 * mean_m,
            accuracy_68_hit: 0.6,
            accuracy_95_hit: 0.9,
            floor_hit: 1.0,
            mean_se_m,
            epochs: 100,
        }
    }

    fn row(building: &str, split: &str, configurations: &[(&str, f64, f64)]) -> RowReport {
        RowReport {
            building: building.into(),
            split: split.into(),
            survey_fraction: 1.0,
            learning: false,
            skipped: None,
            test_walks: 10,
            seconds: 1.0,
            configurations: configurations
                .iter()
                .map(|&(key, mean, se)| (key.to_string(), figures(mean, Some(se))))
                .collect(),
            walks: Vec::new(),
        }
    }

    /// Walks alike in their errors leave nothing to resample: the SE is 0.
    #[test]
    fn identical_walks_have_no_bootstrap_error() {
        let walks = vec![(12.5, 5); 8];
        assert_eq!(bootstrap_se(&walks, BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED), Some(0.0));
        // One walk is every resample.
        assert_eq!(bootstrap_se(&[(3.0, 2)], 100, 1), Some(0.0));
        assert_eq!(bootstrap_se(&[], 100, 1), None);
        assert_eq!(bootstrap_se(&[(0.0, 0)], 100, 1), None, "a walk without points is not drawn");
        assert_eq!(bootstrap_se(&[(1.0, 1), (2.0, 1)], 1, 1), None);
    }

    /// Two walks of n points with means a and b: a resample holds k ~ Binomial(2, ½) copies of
    /// the first, so its pooled mean is b + (a − b)·k/2, whose SD is |a − b|/2 · √(½), the
    /// binomial's SD being √(2·½·½) = √½. Walks without points are left out.
    #[test]
    fn two_walks_resample_to_the_binomial_spread() {
        let (a, b, n) = (2.0, 6.0, 10);
        let walks = [(a * n as f64, n), (0.0, 0), (b * n as f64, n)];
        let se = bootstrap_se(&walks, 20_000, 7).unwrap();
        assert_relative_eq!(se, (a - b).abs() / 2.0 * 0.5f64.sqrt(), max_relative = 0.03);
    }

    /// Many walks of one point each: the bootstrap SE of a mean tends, as the resamples grow,
    /// to the plug-in SD (divided by n) over √n; here within its resampling error.
    #[test]
    fn many_walks_resample_to_the_plug_in_standard_error() {
        let values: Vec<f64> = (0..40).map(|i| f64::from(i % 7) * 1.5 + f64::from(i % 3)).collect();
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let plug_in = (values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n).sqrt() / n.sqrt();
        let walks: Vec<(f64, usize)> = values.iter().map(|&v| (v, 1)).collect();
        let se = bootstrap_se(&walks, BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED).unwrap();
        // B = 1000: the SE's own relative error is about 1/√(2B) ≈ 2%; 3 of those.
        assert_relative_eq!(se, plug_in, max_relative = 0.07);
        // Fixed seed: the same figure every run.
        assert_eq!(Some(se), bootstrap_se(&walks, BOOTSTRAP_RESAMPLES, BOOTSTRAP_SEED));
    }

    /// Figures take the pooled metrics as they are, and the SE from the walks' points.
    #[test]
    fn figures_take_the_pooled_metrics_and_resample_the_walks() {
        let point = |error_m: f64, floor_correct: bool| Scored {
            error_m,
            accuracy_m: 2.0,
            accuracy_95_m: 4.0,
            floor_correct,
            zone_correct: None,
            in_zone: None,
            floor_probability: None,
        };
        let first = [point(1.0, true), point(3.0, true)];
        let second = [point(1.0, false), point(5.0, true)];
        let all: Vec<Scored> = first.iter().chain(&second).copied().collect();
        let pooled = Metrics::new(&all);
        let f = Figures::new(&pooled, &[&first, &second]);
        assert_eq!((f.mean_m, f.p75_m, f.epochs), ((1.0 + 3.0 + 16.0 + 5.0) / 4.0, 5.0, 4));
        // Walk means 2 and 10.5 m, two points each: SD |a − b|/2·√½ ≈ 3.0 m.
        let se = f.mean_se_m.unwrap();
        assert!((2.6..3.4).contains(&se), "{se}");
    }

    /// A building's rows are averaged first, then buildings count equally.
    #[test]
    fn the_mean_is_over_buildings_each_counting_once() {
        let rows = vec![
            row("a", "F=1", &[("forward-auto", 2.0, 0.1), ("wifi-knn", 8.0, 0.3)]),
            row("a", "F=0.5", &[("forward-auto", 4.0, 0.1), ("wifi-knn", 10.0, 0.3)]),
            row("b", "both", &[("forward-auto", 7.0, 0.2), ("wifi-knn", 12.0, 0.4)]),
            RowReport::skipped(&ROWS[0], "absent".into()),
        ];
        let (mean, buildings) = building_mean(&rows);
        assert_eq!(buildings, ["a", "b"]);
        // (mean(2, 4) + 7) / 2, not (2 + 4 + 7) / 3.
        assert_relative_eq!(mean["forward-auto"].mean_m, 5.0);
        assert_relative_eq!(mean["forward-auto"].p75_m, 7.5);
        assert_relative_eq!(mean["wifi-knn"].mean_m, 10.5);
        assert_relative_eq!(mean["wifi-knn"].accuracy_68_hit, 0.6);
        // A configuration some row lacks is in no mean; no rows, no mean.
        let mut partial = rows.clone();
        partial[2].configurations.remove("wifi-knn");
        assert_eq!(building_mean(&partial).0.keys().collect::<Vec<_>>(), ["forward-auto"]);
        assert_eq!(building_mean(&rows[3..]), (BTreeMap::new(), Vec::new()));
    }

    /// Keep only when the mean over buildings improves and no building is worse beyond its
    /// walk-bootstrap SE.
    #[test]
    fn the_verdict_follows_the_rule() {
        let report = |a: f64, b: f64| {
            BenchmarkReport::new(
                vec![
                    row("a", "F=1", &[("forward-auto", a, 0.1)]),
                    row("a", "F=0.5", &[("forward-auto", a + 1.0, 0.3)]),
                    row("b", "both", &[("forward-auto", b, 0.2)]),
                ],
                None,
            )
        };
        let baseline = report(4.0, 8.0);
        // Both better.
        let c = compare(&baseline, &report(3.8, 7.9), "forward-auto");
        assert_eq!(c.verdict, Verdict::Keep);
        assert_eq!((c.rows.len(), c.buildings.len()), (3, 2));
        assert_relative_eq!(c.buildings[0].baseline_se_m.unwrap(), 0.2);
        assert_relative_eq!(c.mean.as_ref().unwrap().delta_m(), -0.15, epsilon = 1e-12);
        // b worse within its SE (0.2), a much better: kept.
        assert_eq!(compare(&baseline, &report(3.0, 8.15), "forward-auto").verdict, Verdict::Keep);
        // b worse beyond its SE though the mean improves: rejected, naming b.
        let Verdict::Reject(why) = compare(&baseline, &report(3.0, 8.3), "forward-auto").verdict else {
            panic!("kept")
        };
        assert!(why.starts_with("b is worse by 0.300 m") && !why.contains("a is"), "{why}");
        // Every building within its SE but the mean not better: rejected.
        let Verdict::Reject(why) = compare(&baseline, &report(4.05, 7.95), "forward-auto").verdict else {
            panic!("kept")
        };
        assert!(why.contains("does not improve"), "{why}");
        // Nothing to compare, or different walks read: rejected.
        assert!(matches!(compare(&baseline, &report(3.0, 7.0), "wifi-knn").verdict, Verdict::Reject(_)));
        let quick = BenchmarkReport { max_walks: Some(5), ..report(3.0, 7.0) };
        assert!(matches!(compare(&baseline, &quick, "forward-auto").verdict, Verdict::Reject(_)));
    }

    /// Only rows evaluated in both runs are compared, and the means are taken again over them.
    #[test]
    fn only_rows_evaluated_in_both_runs_are_compared() {
        let baseline = BenchmarkReport::new(
            vec![
                row("a", "F=1", &[("forward-auto", 4.0, 0.1)]),
                row("b", "both", &[("forward-auto", 8.0, 0.2)]),
            ],
            None,
        );
        let mut skipped_b = RowReport::skipped(&ROWS[0], "absent".into());
        skipped_b.building = "b".into();
        skipped_b.split = "both".into();
        let current = BenchmarkReport::new(
            vec![row("a", "F=1", &[("forward-auto", 3.9, 0.1)]), skipped_b, row("c", "x", &[])],
            None,
        );
        let c = compare(&baseline, &current, "forward-auto");
        assert_eq!(c.not_compared, ["b/both", "c/x"]);
        assert_eq!(c.buildings.len(), 1);
        assert_relative_eq!(c.mean.unwrap().delta_m(), -0.1, epsilon = 1e-12);
        assert_eq!(c.verdict, Verdict::Keep);
    }

    /// The JSON has the documented shape and reads back as written.
    #[test]
    fn the_report_is_the_documented_json_and_reads_back() {
        let report = BenchmarkReport::new(
            vec![
                row("ilc20-site1", "F=1", &[("forward-auto", 4.0, 0.1)]),
                RowReport::skipped(&ROWS[1], "ilc20-site1/B1 not found".into()),
            ],
            None,
        );
        let json = serde_json::to_value(&report).unwrap();
        let keys = |v: &serde_json::Value| {
            let mut keys: Vec<String> = v.as_object().unwrap().keys().cloned().collect();
            keys.sort();
            keys
        };
        assert_eq!(keys(&json), ["buildings", "mean", "rows"]);
        let row = &json["rows"][0];
        assert_eq!(
            keys(row),
            ["building", "configurations", "seconds", "split", "survey_fraction", "test_walks", "walks"]
        );
        assert_eq!(
            keys(&row["configurations"]["forward-auto"]),
            [
                "accuracy_68_hit",
                "accuracy_95_hit",
                "epochs",
                "floor_hit",
                "mean_m",
                "mean_se_m",
                "p75_m",
                "p90_m"
            ]
        );
        assert_eq!(json["rows"][1]["skipped"], "ilc20-site1/B1 not found");
        assert_eq!(json["rows"][1]["split"], "F=0.5");
        assert_eq!(
            keys(&json["mean"]["forward-auto"]),
            ["accuracy_68_hit", "accuracy_95_hit", "floor_hit", "mean_m", "p75_m"]
        );
        assert_eq!(json["buildings"], serde_json::json!(["ilc20-site1"]));
        let back: BenchmarkReport = serde_json::from_str(&serde_json::to_string(&report).unwrap()).unwrap();
        assert_eq!(back, report);
    }

    /// Row names are unique, and every survey fraction is one `--survey-fraction` accepts.
    #[test]
    fn the_rows_are_named_uniquely_with_valid_fractions() {
        let all: Vec<&Row> = ROWS.iter().chain(&LEARNING_ROWS).collect();
        let mut names: Vec<String> = all.iter().map(|r| r.name()).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), all.len());
        assert!(all.iter().all(|r| r.survey_fraction > 0.0 && r.survey_fraction <= 1.0));
        assert!(ROWS.iter().all(|r| !r.learning()) && LEARNING_ROWS.iter().all(Row::learning));
    }

    /// A row of a map learned from use is reported and never counts in the mean over buildings.
    #[test]
    fn learning_rows_stay_out_of_the_mean() {
        let labelled = vec![row("a", "F=1", &[("forward-auto", 4.0, 0.1)])];
        let mut learned = row("a", "F=0.5+rest-unlabelled", &[("forward-auto", 9.0, 0.1)]);
        learned.learning = true;
        let with = [labelled.clone(), vec![learned]].concat();
        assert_eq!(building_mean(&with), building_mean(&labelled));
        assert_eq!(building_mean(&with).0["forward-auto"].mean_m, 4.0);
    }
}
