//! Recorded floors, split into survey and test walks.

use super::CalibrationError;
use crate::io::{FloorPlan, Trace};
use crate::{SurveyFloor, WalkedGeo};
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
    /// Where the floor is on the Earth when its walks' truth is WGS84 (a GetSensorData
    /// building, [`load_gsd_building`]).
    pub geo: Option<WalkedGeo>,
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
            geo: None,
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

/// How a building's walks split into survey and test walks, where the files are not in floor
/// folders with a fixed split (GetSensorData logfiles, [`load_gsd_building`]).
#[derive(Clone, Debug, PartialEq)]
pub enum WalkSplit {
    /// Every walk surveys (`waymark survey`).
    All,
    /// Walks recorded with this phone model (the header's `Model:`) survey, the rest test.
    Phone(String),
    /// Walks of these repetitions (`_repetitionRR` in the file name) survey, the rest test.
    Repetitions(Vec<u32>),
}

impl std::str::FromStr for WalkSplit {
    type Err = String;

    /// `all`, `phone:MODEL` or `repetitions:1,3`.
    fn from_str(text: &str) -> Result<WalkSplit, String> {
        match text.trim().split_once(':') {
            None if text.trim() == "all" => Ok(WalkSplit::All),
            Some(("phone", model)) if !model.trim().is_empty() => {
                Ok(WalkSplit::Phone(model.trim().to_owned()))
            }
            Some(("repetitions", list)) => {
                let reps: Vec<u32> = list
                    .split(',')
                    .map(|r| r.trim().parse::<u32>().map_err(|e| format!("`{r}` is not a repetition: {e}")))
                    .collect::<Result<_, _>>()?;
                Ok(WalkSplit::Repetitions(reps))
            }
            _ => Err(format!("`{text}` is not a split: `all`, `phone:MODEL` or `repetitions:1,3`")),
        }
    }
}

impl std::fmt::Display for WalkSplit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            WalkSplit::All => write!(f, "all"),
            WalkSplit::Phone(model) => write!(f, "phone:{model}"),
            WalkSplit::Repetitions(reps) => {
                let list: Vec<String> = reps.iter().map(u32::to_string).collect();
                write!(f, "repetitions:{}", list.join(","))
            }
        }
    }
}

impl WalkSplit {
    /// Whether the walk `name` recorded with `model` is a survey walk.
    fn surveys(&self, name: &str, model: Option<&str>) -> bool {
        match self {
            WalkSplit::All => true,
            WalkSplit::Phone(wanted) => model.is_some_and(|m| m == wanted),
            WalkSplit::Repetitions(reps) => repetition(name).is_some_and(|r| reps.contains(&r)),
        }
    }
}

/// The repetition number in a competition file name (`..._repetition03` → 3).
pub fn repetition(name: &str) -> Option<u32> {
    let (_, rest) = name.rsplit_once("repetition")?;
    let digits: String = rest.chars().take_while(char::is_ascii_digit).collect();
    digits.parse().ok()
}

/// Whether `dir` holds GetSensorData logfiles (directly or in `logfiles/`): its first `.txt`
/// file by name is one.
pub fn is_gsd_building(dir: &Path) -> bool {
    gsd_files(dir).ok().and_then(|files| files.first().cloned()).is_some_and(|first| {
        std::fs::read(&first)
            .is_ok_and(|b| crate::io::gsd::is_gsd(&String::from_utf8_lossy(&b[..b.len().min(4096)])))
    })
}

fn gsd_files(dir: &Path) -> Result<Vec<PathBuf>, CalibrationError> {
    let logs = if dir.join("logfiles").is_dir() { dir.join("logfiles") } else { dir.to_owned() };
    let mut files: Vec<PathBuf> = std::fs::read_dir(&logs)
        .map_err(|source| CalibrationError::Io { path: logs.display().to_string(), source })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "txt"))
        .collect();
    files.sort();
    Ok(files)
}

/// A building of GetSensorData logfiles (`dir/logfiles/*.txt` or `dir/*.txt`), split into
/// survey and test walks by `split`, as floors in level order. One site frame for the whole
/// building: x east, y north, in metres from the mean of the survey walks' ground truth
/// (WGS84 `POSI`), and a floor per level the survey walks visit. A survey walk that changes
/// floors surveys each floor it stayed on, from its first to its last point there (the stairs
/// between, and a stay of one point, survey nothing); a test walk is filed under the floor it starts on and scored on
/// the floor each of its points gives ([`Waypoint::floor`](crate::io::Waypoint::floor)).
/// `max_walks` keeps only the first files by name.
pub fn load_gsd_building(
    dir: &Path,
    split: &WalkSplit,
    max_walks: Option<usize>,
) -> Result<Vec<FloorData>, CalibrationError> {
    let mut files = gsd_files(dir)?;
    files.truncate(max_walks.unwrap_or(usize::MAX));
    let mut survey = Vec::new();
    let mut test = Vec::new();
    for file in &files {
        let walk = crate::io::GsdWalk::read(file)?;
        if walk.fixes.is_empty() {
            continue;
        }
        if split.surveys(&walk.trace.name, walk.model.as_deref()) {
            survey.push(walk);
        } else {
            test.push(walk);
        }
    }
    let fixes: Vec<&crate::io::GeoFix> = survey.iter().flat_map(|w| &w.fixes).collect();
    if fixes.is_empty() {
        return Err(CalibrationError::Empty(format!(
            "{}: no survey walk with ground truth (POSI) for split {split}",
            dir.display()
        )));
    }
    let n = fixes.len() as f64;
    let centre = waymark_engine::site::LatLon::new(
        fixes.iter().map(|f| f.position.lat_deg).sum::<f64>() / n,
        fixes.iter().map(|f| f.position.lon_deg).sum::<f64>() / n,
    )
    .map_err(|e| CalibrationError::Empty(format!("{}: the survey's centre: {e}", dir.display())))?;
    let anchor = waymark_engine::site::Anchor::at(centre);
    let mut levels: Vec<i32> = fixes.iter().map(|f| f.level).collect();
    levels.sort_unstable();
    levels.dedup();
    let mut floors: Vec<FloorData> = levels
        .iter()
        .map(|&level| FloorData {
            name: format!("L{level}"),
            dir: dir.to_owned(),
            plan: None,
            survey: Vec::new(),
            test: Vec::new(),
            geo: Some(WalkedGeo { anchor, level }),
        })
        .collect();
    let index = |level: i32| levels.iter().position(|&l| l == level);
    // Scored as the engine reports them: a level between the survey's is its own floor.
    let site_levels = crate::scoring::scoring_levels(&levels);
    for walk in &survey {
        let trace = walk.trace(&anchor, &site_levels);
        let runs = walk.level_runs();
        // A stay of one point places no scan (it has no stretch to interpolate along).
        for &(level, from, to) in runs.iter().filter(|r| runs.len() == 1 || r.1 < r.2) {
            let Some(f) = index(level) else { continue };
            floors[f].survey.push(if runs.len() == 1 { trace.clone() } else { trace.between(from, to) });
        }
    }
    for walk in &test {
        let trace = walk.trace(&anchor, &site_levels);
        let f = walk.level_runs().iter().find_map(|r| index(r.0)).unwrap_or(0);
        floors[f].test.push(trace);
    }
    Ok(floors)
}

/// The floors of one building from the command line: a folder of GetSensorData logfiles
/// ([`load_gsd_building`], split by `split`), or floor folders of competition walks
/// ([`FloorData::load`], split by file index; `split` is theirs only as [`WalkSplit::All`],
/// which folds the test walks into the survey).
pub fn load_building(
    dirs: &[PathBuf],
    split: &WalkSplit,
    max_walks: Option<usize>,
) -> Result<Vec<FloorData>, CalibrationError> {
    if let [dir] = dirs {
        if is_gsd_building(dir) {
            return load_gsd_building(dir, split, max_walks);
        }
    }
    let mut floors: Vec<FloorData> =
        dirs.iter().map(|d| FloorData::load(d, max_walks)).collect::<Result<_, _>>()?;
    if *split == WalkSplit::All {
        for f in &mut floors {
            f.survey.append(&mut f.test);
        }
    }
    Ok(floors)
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
            geo: f.geo,
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

    /// A GetSensorData walk: `model`'s phone, one WiFi scan and one ground-truth point a
    /// second, at `(lat, lon, level)` each.
    fn gsd_walk(model: &str, points: &[(f64, f64, i32)]) -> String {
        let mut text =
            format!("% LogFile created by the 'GetSensorData' App for Android.\n% Model:\t{model}\n");
        for (k, (lat, lon, level)) in points.iter().enumerate() {
            let t = k as f64 + 0.5;
            text += &format!("ACCE;{t};{};0.1;0.2;9.8;3\n", 1000.0 + t);
            text += &format!("WIFI;{t};{};net;20:23:00:00:00:01;2437;-60\n", 1000.0 + t);
            text += &format!("POSI;{t};{k};{lat};{lon};{level};100\n");
        }
        text
    }

    #[test]
    fn a_gsd_building_splits_by_phone_or_repetition_and_files_floors_by_level() {
        let dir = tempfile::tempdir().unwrap();
        let logs = dir.path().join("logfiles");
        std::fs::create_dir(&logs).unwrap();
        let ground = [(49.4611, 11.1110, 0), (49.4612, 11.1110, 0)];
        let both =
            [(49.4611, 11.1110, 0), (49.4612, 11.1110, 0), (49.4612, 11.1111, -2), (49.4611, 11.1111, -2)];
        for (name, model, points) in [
            ("T01_repetition01", "A", &ground[..]),
            ("T01_repetition02", "B", &ground[..]),
            ("T51_repetition03", "A", &both[..]),
            ("T51_repetition04", "B", &both[..]),
        ] {
            std::fs::write(logs.join(format!("{name}.txt")), gsd_walk(model, points)).unwrap();
        }
        std::fs::write(logs.join("notes.md"), "not a walk").unwrap();
        assert!(is_gsd_building(dir.path()));
        let floors = load_building(&[dir.path().to_owned()], &WalkSplit::Phone("A".into()), None).unwrap();
        // Levels in order; the survey walk that changes floors surveys each.
        assert_eq!(floors.iter().map(|f| f.name.as_str()).collect::<Vec<_>>(), ["L-2", "L0"]);
        assert_eq!(floors.iter().map(|f| f.survey.len()).collect::<Vec<_>>(), [1, 2]);
        assert!(floors[0].survey[0].waypoints.iter().all(|w| w.floor == Some(0)));
        // Test walks under the floor they start on, each point with its own floor.
        assert_eq!(floors.iter().map(|f| f.test.len()).collect::<Vec<_>>(), [0, 2]);
        let changing = floors[1].test.iter().find(|t| t.name.starts_with("T51")).unwrap();
        let levels: Vec<Option<usize>> = changing.waypoints.iter().map(|w| w.floor).collect();
        assert_eq!(levels, [Some(1), Some(1), Some(0), Some(0)]);
        // One frame for the building, centred on the survey's truth; x east, y north.
        let anchor = floors[0].geo.unwrap().anchor;
        assert_eq!(floors[1].geo.unwrap().anchor, anchor);
        let (a, b) = (changing.waypoints[0], changing.waypoints[2]);
        assert!((b.x - a.x - 7.24).abs() < 0.05 && (b.y - a.y - 11.12).abs() < 0.05, "{a:?} {b:?}");

        let by_repetition =
            load_building(&[dir.path().to_owned()], &"repetitions:1,4".parse().unwrap(), None).unwrap();
        let names = |f: &FloorData| f.test.iter().map(|t| t.name.clone()).collect::<Vec<_>>();
        assert_eq!(by_repetition[1].test.iter().chain(&by_repetition[0].test).count(), 2);
        assert!(by_repetition.iter().flat_map(names).all(|n| n.ends_with("02") || n.ends_with("03")));
        let all = load_building(&[dir.path().to_owned()], &WalkSplit::All, None).unwrap();
        assert_eq!(all.iter().map(|f| f.test.len()).sum::<usize>(), 0);
        assert_eq!(all.iter().map(|f| f.survey.len()).sum::<usize>(), 6);
        // A split that leaves nothing to survey says so.
        assert!(load_building(&[dir.path().to_owned()], &WalkSplit::Phone("C".into()), None).is_err());
        for bad in ["", "phone:", "repetitions:x", "reps:1"] {
            assert!(bad.parse::<WalkSplit>().is_err(), "{bad}");
        }
        assert_eq!("repetitions:1,3".parse::<WalkSplit>().unwrap().to_string(), "repetitions:1,3");
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
            geo: None,
        };
        floor.keep_survey_fraction(0.5);
        assert_eq!(floor.survey.iter().map(|t| t.name.as_str()).collect::<Vec<_>>(), ["a", "c"]);
        assert_eq!(floor.test.len(), 1);
    }
}
