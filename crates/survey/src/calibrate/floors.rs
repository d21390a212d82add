//! Recorded floors, split into survey and test walks.

use super::CalibrationError;
use crate::io::{FloorPlan, Trace};
use crate::SurveyFloor;
use std::path::{Path, PathBuf};

/// One floor's walks, split.
#[derive(Clone, Debug)]
pub struct FloorData {
    /// Floor name (the folder's).
    pub name: String,
    /// The folder.
    pub dir: PathBuf,
    /// The plan, if the folder has one.
    pub plan: Option<FloorPlan>,
    /// Survey walks (file index i with i % 5 != 4 after sorting by name).
    pub survey: Vec<Trace>,
    /// Test walks (i % 5 == 4).
    pub test: Vec<Trace>,
}

impl FloorData {
    /// Reads a floor folder: `path_data_files/*.txt` (or `*.txt` directly inside), and
    /// `floor_info.json` + `geojson_map.json` if present: a plan that is there must be valid
    /// ([`FloorPlan::read_if_present`]), since a survey without its walls is another site. `max_walks` keeps only the first
    /// walks by name (a quick look; the split is applied after).
    pub fn load(dir: &Path, max_walks: Option<usize>) -> Result<FloorData, CalibrationError> {
        let walks_dir =
            if dir.join("path_data_files").is_dir() { dir.join("path_data_files") } else { dir.to_owned() };
        let io = |source| CalibrationError::Io { path: walks_dir.display().to_string(), source };
        let mut files: Vec<PathBuf> = std::fs::read_dir(&walks_dir)
            .map_err(io)?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| e == "txt"))
            .collect();
        files.sort();
        files.truncate(max_walks.unwrap_or(usize::MAX));
        let mut floor = FloorData {
            name: dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
            dir: dir.to_owned(),
            plan: FloorPlan::read_if_present(dir)?,
            survey: Vec::new(),
            test: Vec::new(),
        };
        for (i, file) in files.iter().enumerate() {
            let trace = Trace::read(file)?;
            if i % 5 == 4 {
                floor.test.push(trace);
            } else {
                floor.survey.push(trace);
            }
        }
        Ok(floor)
    }

    /// Keeps a share `fraction` (0 < F ≤ 1) of this floor's survey walks by
    /// [`survey_subset`]; the test walks do not change.
    pub fn keep_survey_fraction(&mut self, fraction: f64) {
        let keep = survey_subset(self.survey.len(), fraction);
        let walks = std::mem::take(&mut self.survey);
        self.survey = walks
            .into_iter()
            .enumerate()
            .filter(|(i, _)| keep.binary_search(i).is_ok())
            .map(|w| w.1)
            .collect();
    }
}

/// The survey walks a fraction `F` keeps of `n` (by index, in file-name order): walk i when
/// ⌈(i+1)·F⌉ > ⌈i·F⌉, spread evenly through the floor's walks, the same on every run,
/// ⌈n·F⌉ of them (the first walk always, so a floor keeps at least one), all of them at F = 1
/// (`docs/results.md#survey-fraction`). The products are taken 1e-9 below their value, so
/// that a product that is a whole number in exact arithmetic is one in floating point too.
/// Nothing for F outside (0, 1] ([`parse_survey_fraction`] refuses it).
pub fn survey_subset(n: usize, fraction: f64) -> Vec<usize> {
    if !(fraction > 0.0 && fraction <= 1.0) {
        return Vec::new();
    }
    let kept_before = |i: usize| (i as f64 * fraction - 1e-9).ceil();
    (0..n).filter(|&i| kept_before(i + 1) > kept_before(i)).collect()
}

/// A survey fraction from the command line: a number with 0 < F ≤ 1.
pub fn parse_survey_fraction(text: &str) -> Result<f64, String> {
    let fraction: f64 = text.trim().parse().map_err(|e| format!("`{text}` is not a number: {e}"))?;
    if fraction > 0.0 && fraction <= 1.0 {
        Ok(fraction)
    } else {
        Err(format!("{fraction} is not in (0, 1]"))
    }
}

/// The survey walks of `floors` as the survey reads them.
pub fn survey_inputs(floors: &[FloorData]) -> Vec<SurveyFloor<'_>> {
    floors
        .iter()
        .map(|f| SurveyFloor {
            name: f.name.clone(),
            plan: f.plan.as_ref(),
            walks: f.survey.iter().collect(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::floor_plan::tests::{floor_dir, plan_files};

    /// A floor whose plan is there but not valid is refused, not surveyed without it
    /// (issue 60, item 8: `FloorPlan::read(dir).ok()` built such sites without walls); a floor
    /// with no plan at all is read as before.
    #[test]
    fn a_floor_with_an_invalid_plan_is_refused_and_one_without_a_plan_read() {
        let (info, _) = plan_files("[]", "100");
        let bad = floor_dir(Some(&info), Some(r#"{"type": "FeatureCollection"}"#));
        match FloorData::load(bad.path(), None) {
            Err(e @ CalibrationError::Plan(_)) => {
                let message = e.to_string();
                assert!(message.contains("geojson_map.json") && message.contains("features"), "{message}")
            }
            other => panic!("{other:?}"),
        }
        let none = floor_dir(None, None);
        assert!(FloorData::load(none.path(), None).unwrap().plan.is_none());
    }

    #[test]
    fn the_survey_subset_is_deterministic_even_and_of_the_documented_size() {
        // F = 1 keeps everything.
        assert_eq!(survey_subset(7, 1.0), (0..7).collect::<Vec<_>>());
        // ⌈n·F⌉ walks, the first always, spread through the list.
        assert_eq!(survey_subset(4, 0.5), [0, 2]);
        assert_eq!(survey_subset(8, 0.25), [0, 4]);
        assert_eq!(survey_subset(10, 0.3), [0, 3, 6]);
        assert_eq!(survey_subset(3, 0.1), [0]);
        assert!(survey_subset(0, 0.5).is_empty());
        for n in [1usize, 5, 17, 84, 101] {
            for fraction in [0.1, 0.25, 1.0 / 3.0, 0.5, 0.7, 0.9, 1.0] {
                let kept = survey_subset(n, fraction);
                assert_eq!(kept.len(), (n as f64 * fraction - 1e-9).ceil() as usize, "n {n}, F {fraction}");
                assert_eq!(kept, survey_subset(n, fraction), "the same on every call");
                assert!(kept.windows(2).all(|w| w[0] < w[1]) && kept.iter().all(|&i| i < n));
            }
        }
        // Outside (0, 1]: nothing, and the parser refuses it.
        assert!(survey_subset(5, 0.0).is_empty() && survey_subset(5, 1.5).is_empty());
        assert!(survey_subset(5, f64::NAN).is_empty());
        assert_eq!(parse_survey_fraction("0.25"), Ok(0.25));
        assert_eq!(parse_survey_fraction("1"), Ok(1.0));
        for bad in ["0", "-0.5", "1.01", "NaN", "inf", "half", ""] {
            assert!(parse_survey_fraction(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn keeping_a_fraction_leaves_the_test_walks_alone() {
        let trace = |name: &str| crate::io::Trace { name: name.into(), ..crate::io::Trace::default() };
        let mut floor = FloorData {
            name: "F".into(),
            dir: PathBuf::new(),
            plan: None,
            survey: ["a", "b", "c", "d"].map(trace).to_vec(),
            test: vec![trace("e")],
        };
        floor.keep_survey_fraction(0.5);
        assert_eq!(floor.survey.iter().map(|t| t.name.as_str()).collect::<Vec<_>>(), ["a", "c"]);
        assert_eq!(floor.test.len(), 1);
    }
}
