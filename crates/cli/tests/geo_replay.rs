//! Geo-referenced sites on the competition's site1 (all five floors): the survey writes an
//! anchor and floor levels that match the GeoJSON plans, and `waymark replay --out track.csv`
//! writes `lat` and `lon` columns whose error against the waypoints (converted to
//! longitude/latitude through the plan's box, as the competition defines its frame) equals the
//! error in metres within 0.1 m. Skips, saying so, when the data is not there
//! (docs/testing.md#real-data).

use std::path::{Path, PathBuf};
use std::process::Command;
use waymark_engine::site::LatLon;
use waymark_survey::calibrate::{survey_inputs, FloorData};
use waymark_survey::io::FloorPlan;
use waymark_survey::{survey, SurveyOptions};

use waymark_eval::data::SITE1_FLOORS as FLOORS;

/// Walk files read per floor: enough for a map around a few test walks, quick to survey.
const WALKS_PER_FLOOR: usize = 10;

/// Site1's floors unpacked under `target/`, or `None` (with a message) without the data.
fn floor_dirs() -> Option<Vec<PathBuf>> {
    // The workspace root, two levels above this crate.
    waymark_eval::data::site1_floors(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../.."))
}

/// Each floor's `floor_num` and the corners of its plan's longitude/latitude box, read from the
/// GeoJSON directly (not through the survey's reader).
fn geojson_floor(dir: &Path) -> (i64, [[f64; 2]; 2]) {
    let text = std::fs::read_to_string(dir.join("geojson_map.json")).unwrap();
    let geojson: serde_json::Value = serde_json::from_str(&text).unwrap();
    let floor = geojson["features"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["properties"]["type"] == "floor")
        .expect("a floor feature");
    let mut points = Vec::new();
    let mut stack = vec![&floor["geometry"]["coordinates"]];
    while let Some(v) = stack.pop() {
        match v.as_array() {
            Some(a) if a.first().is_some_and(|x| x.is_number()) => {
                points.push([a[0].as_f64().unwrap(), a[1].as_f64().unwrap()])
            }
            Some(a) => stack.extend(a),
            None => {}
        }
    }
    let fold = |i: usize, f: fn(f64, f64) -> f64, init: f64| points.iter().map(|p| p[i]).fold(init, f);
    let lo = [fold(0, f64::min, f64::INFINITY), fold(1, f64::min, f64::INFINITY)];
    let hi = [fold(0, f64::max, f64::NEG_INFINITY), fold(1, f64::max, f64::NEG_INFINITY)];
    (floor["properties"]["floor_num"].as_i64().expect("floor_num"), [lo, hi])
}

/// Distance between two longitude/latitude points in the plan's frame, m: the box's linear
/// map, the frame the competition's waypoints (and the metres error) are in.
fn plan_distance(plan: &FloorPlan, a: [f64; 2], b: [f64; 2]) -> f64 {
    let [lo, hi] = plan.lon_lat_box.expect("a plan read from GeoJSON");
    let dx = (a[0] - b[0]) / (hi[0] - lo[0]) * plan.width_m;
    let dy = (a[1] - b[1]) / (hi[1] - lo[1]) * plan.height_m;
    dx.hypot(dy)
}

#[test]
fn site1_is_geo_referenced_and_replays_with_lat_lon() {
    let Some(dirs) = waymark_eval::data::or_skip(floor_dirs()) else {
        return;
    };
    let floors: Vec<FloorData> =
        dirs.iter().map(|d| FloorData::load(d, Some(WALKS_PER_FLOOR)).expect("the floor reads")).collect();
    let (site, _) = survey("site1", &survey_inputs(&floors), Default::default(), &SurveyOptions::default())
        .expect("survey");

    // The anchor and levels match the GeoJSON: each floor's box corners land on their
    // longitude/latitude to a centimetre, and its level is its floor_num.
    let anchor = site.anchor().expect("a site surveyed from geo-referenced plans has an anchor");
    assert_eq!(anchor.azimuth_rad, 0.0, "the plans' frames are x east, y north");
    for (f, (dir, data)) in dirs.iter().zip(&floors).enumerate() {
        let (floor_num, [lo, hi]) = geojson_floor(dir);
        assert_eq!(site.floor_level(f).map(i64::from), Some(floor_num), "{}", FLOORS[f]);
        let plan = data.plan.as_ref().expect("a plan");
        for (x, y, lon, lat) in [(0.0, 0.0, lo[0], lo[1]), (plan.width_m, plan.height_m, hi[0], hi[1])] {
            let at = site.lat_lon(f, x, y).unwrap();
            let off = plan_distance(plan, [at.lon_deg, at.lat_deg], [lon, lat]);
            assert!(off < 0.01, "{} corner ({x:.1}, {y:.1}) is {off:.4} m off", FLOORS[f]);
        }
    }
    assert_eq!(site.floor_level(0), Some(-1), "B1");

    // Replay test walks through the CLI, one per floor, into CSV.
    let work = Path::new(env!("CARGO_TARGET_TMPDIR")).join("geo_replay");
    std::fs::create_dir_all(&work).unwrap();
    let site_path = work.join("site.json");
    std::fs::write(&site_path, site.to_json()).unwrap();
    let (mut compared, mut worst) = (0usize, 0.0f64);
    let (mut sum_metres, mut sum_geo) = (0.0, 0.0);
    for (f, data) in floors.iter().enumerate() {
        let plan = data.plan.as_ref().unwrap();
        let trace = data.test.first().expect("a test walk");
        let walk = data.dir.join("path_data_files").join(format!("{}.txt", trace.name));
        let csv = work.join(format!("{}.csv", FLOORS[f]));
        let status = Command::new(env!("CARGO_BIN_EXE_waymark"))
            .args(["replay", "--site"])
            .arg(&site_path)
            .arg(&walk)
            .arg("--out")
            .arg(&csv)
            .status()
            .unwrap();
        assert!(status.success(), "waymark replay {}", walk.display());
        let text = std::fs::read_to_string(&csv).unwrap();
        let mut lines = text.lines();
        let header: Vec<&str> = lines.next().unwrap().split(',').collect();
        let col = |name: &str| header.iter().position(|h| *h == name).unwrap_or_else(|| panic!("no {name}"));
        let (t, floor, x, y, lat, lon) =
            (col("timestamp_ms"), col("floor"), col("x"), col("y"), col("lat"), col("lon"));
        for line in lines {
            let row: Vec<&str> = line.split(',').collect();
            // Scored on the walk's floor, where the metres error has a meaning.
            if row[floor] != FLOORS[f] {
                continue;
            }
            let Some((tx, ty)) = trace.position_at(row[t].parse::<u64>().unwrap() * 1_000_000) else {
                continue;
            };
            let num = |c: usize| row[c].parse::<f64>().unwrap();
            let metres = (num(x) - tx).hypot(num(y) - ty);
            let truth = plan.lon_lat(tx, ty).unwrap();
            let geo = plan_distance(plan, [num(lon), num(lat)], truth);
            worst = worst.max((geo - metres).abs());
            sum_metres += metres;
            sum_geo += geo;
            compared += 1;
        }
    }
    assert!(compared > 50, "{compared} epochs compared");
    assert!(worst < 0.1, "the lat/lon error differs from the metres error by up to {worst:.3} m");
    let (mean_metres, mean_geo) = (sum_metres / compared as f64, sum_geo / compared as f64);
    eprintln!(
        "{compared} epochs: mean error {mean_metres:.3} m from x, y and {mean_geo:.3} m from lat, lon; \
         largest difference {worst:.4} m"
    );
    assert!((mean_metres - mean_geo).abs() < 0.1);
    // And a lat/lon fix lands where it was meant to: the round trip through the site.
    let at: LatLon = site.lat_lon(1, 50.0, 60.0).unwrap();
    let back = site.site_point(Some(1), at).unwrap();
    assert!((back.x - 50.0).abs() < 1e-3 && (back.y - 60.0).abs() < 1e-3, "{back}");
}
