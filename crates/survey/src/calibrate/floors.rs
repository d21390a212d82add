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
    /// `floor_info.json` + `geojson_map.json` if present. `max_walks` keeps only the first
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
            plan: FloorPlan::read(dir).ok(),
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
