//! The rule a change to the engine is judged by (`docs/benchmark.md#rule`): a configuration's
//! mean error in one benchmark run against a baseline run's, per row, per building and over
//! buildings.

use super::{BenchmarkReport, Figures, RowReport};
use std::collections::BTreeMap;

/// One mean error against the baseline's, m.
#[derive(Clone, Debug, PartialEq)]
pub struct Change {
    /// `building/split`, or the building.
    pub name: String,
    /// The baseline's mean error.
    pub baseline_m: f64,
    /// This run's.
    pub current_m: f64,
    /// The baseline's walk-bootstrap standard error of it, when known.
    pub baseline_se_m: Option<f64>,
}

impl Change {
    /// This run's mean minus the baseline's (negative: better).
    pub fn delta_m(&self) -> f64 {
        self.current_m - self.baseline_m
    }

    /// Whether this run is worse by more than the baseline's standard error (by anything at
    /// all when it has none).
    pub fn worse_beyond_se(&self) -> bool {
        self.delta_m() > self.baseline_se_m.unwrap_or(0.0)
    }
}

/// Whether a change is kept.
#[derive(Clone, Debug, PartialEq)]
pub enum Verdict {
    /// The mean over buildings improves and no building is worse beyond its standard error.
    Keep,
    /// Why not.
    Reject(String),
}

/// One configuration's mean error in two benchmark runs.
#[derive(Clone, Debug, PartialEq)]
pub struct Comparison {
    /// The configuration key.
    pub configuration: String,
    /// Per row evaluated in both runs with this configuration.
    pub rows: Vec<Change>,
    /// Per building, over those rows: the rows' means averaged, and the rows' standard errors
    /// averaged.
    pub buildings: Vec<Change>,
    /// Over buildings, equally weighted; no standard error.
    pub mean: Option<Change>,
    /// Rows of either run not compared (skipped, or in one run only).
    pub not_compared: Vec<String>,
    /// The rule's answer.
    pub verdict: Verdict,
}

/// `configuration`'s mean error in `current` against `baseline`, and the rule a change is
/// judged by (`docs/benchmark.md#rule`): kept only when the mean over buildings improves and no
/// building gets worse by more than its walk-bootstrap standard error.
///
/// Only rows evaluated in both runs count, matched by building and split, and the means are
/// taken again over them (not the reports' own `mean`, which may be over other rows). A
/// building's standard error is the average of its rows' (the baseline's): its rows share
/// test walks, so their errors move together, and the average is the standard error of their
/// mean when they move as one, an upper bound otherwise. Runs that read different walks
/// (`max_walks`) are not compared.
pub fn compare(baseline: &BenchmarkReport, current: &BenchmarkReport, configuration: &str) -> Comparison {
    fn evaluated<'a>(row: &'a RowReport, configuration: &str) -> Option<&'a Figures> {
        row.configurations.get(configuration).filter(|_| row.skipped.is_none())
    }
    let figures = |row| evaluated(row, configuration);
    let mut rows = Vec::new();
    let mut not_compared = Vec::new();
    let mut compared_buildings: BTreeMap<&str, Vec<Change>> = BTreeMap::new();
    for old in &baseline.rows {
        let new = current.rows.iter().find(|r| r.building == old.building && r.split == old.split);
        match (figures(old), new.and_then(figures)) {
            (Some(a), Some(b)) => {
                let change = Change {
                    name: old.name(),
                    baseline_m: a.mean_m,
                    current_m: b.mean_m,
                    baseline_se_m: a.mean_se_m,
                };
                compared_buildings.entry(&old.building).or_default().push(change.clone());
                rows.push(change);
            }
            _ => not_compared.push(old.name()),
        }
    }
    for new in &current.rows {
        if !baseline.rows.iter().any(|r| r.building == new.building && r.split == new.split) {
            not_compared.push(new.name());
        }
    }
    let average = |values: &mut dyn Iterator<Item = f64>| {
        let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
        sum / n as f64
    };
    let buildings: Vec<Change> = compared_buildings
        .iter()
        .map(|(building, changes)| Change {
            name: building.to_string(),
            baseline_m: average(&mut changes.iter().map(|c| c.baseline_m)),
            current_m: average(&mut changes.iter().map(|c| c.current_m)),
            baseline_se_m: changes
                .iter()
                .map(|c| c.baseline_se_m)
                .collect::<Option<Vec<f64>>>()
                .map(|se| average(&mut se.into_iter())),
        })
        .collect();
    let mean = (!buildings.is_empty()).then(|| Change {
        name: "mean over buildings".into(),
        baseline_m: average(&mut buildings.iter().map(|c| c.baseline_m)),
        current_m: average(&mut buildings.iter().map(|c| c.current_m)),
        baseline_se_m: None,
    });
    let verdict = if baseline.max_walks != current.max_walks {
        Verdict::Reject(format!(
            "the runs read different walks (max_walks {:?} against {:?})",
            baseline.max_walks, current.max_walks
        ))
    } else if let Some(mean) = &mean {
        let worse: Vec<String> = buildings
            .iter()
            .filter(|b| b.worse_beyond_se())
            .map(|b| {
                format!(
                    "{} is worse by {:.3} m, beyond its walk-bootstrap SE {}",
                    b.name,
                    b.delta_m(),
                    b.baseline_se_m.map_or("(none)".into(), |se| format!("{se:.3} m"))
                )
            })
            .collect();
        if mean.delta_m() >= 0.0 {
            Verdict::Reject(format!("the mean over buildings does not improve ({:+.3} m)", mean.delta_m()))
        } else if !worse.is_empty() {
            Verdict::Reject(worse.join("; "))
        } else {
            Verdict::Keep
        }
    } else {
        Verdict::Reject(format!("no row has `{configuration}` evaluated in both runs"))
    };
    Comparison { configuration: configuration.into(), rows, buildings, mean, not_compared, verdict }
}
