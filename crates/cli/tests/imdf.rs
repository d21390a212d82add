//! IMDF on the competition's site1 (all five floors, docs/imdf.md): its GeoJSON plans written
//! as IMDF and read back give the same plans; import, export, import gives the same venue; a
//! survey on the IMDF plans gives the site the GeoJSON plans give (floors, levels, anchor,
//! zones, graph); and `waymark site export` writes a surveyed site's floors and zones. Skips,
//! saying so, when the data is not there (docs/testing.md#real-data).

use std::path::{Path, PathBuf};
use std::process::Command;
use waymark_survey::calibrate::{survey_inputs, FloorData};
use waymark_survey::io::imdf::{plans_from_imdf, Venue, WriteOptions};
use waymark_survey::io::FloorPlan;
use waymark_survey::{survey, SurveyOptions};

use waymark_eval::data::SITE1_FLOORS as FLOORS;

/// Walk files read per floor: enough for a map, quick to survey.
const WALKS_PER_FLOOR: usize = 6;

/// Site1's floors unpacked under `target/`, or `None` (with a message) without the data.
fn floor_dirs() -> Option<Vec<PathBuf>> {
    // The workspace root, two levels above this crate.
    waymark_eval::data::site1_floors(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../.."))
}

fn options() -> WriteOptions {
    WriteOptions {
        created: "2000-01-01T00:00:00Z".into(),
        venue_category: "shoppingcenter".into(),
        country: "CN".into(),
    }
}

/// Every point of a plan (outline, rooms, doors), m, in order.
fn points(plan: &FloorPlan) -> Vec<nalgebra::Point2<f64>> {
    let rooms = plan.rooms.iter().map(|r| &r.polygon);
    let polygons = plan.outline.iter().chain(rooms).flat_map(|p| p.rings.iter().flatten().copied());
    polygons.chain(plan.doors.iter().flatten().copied()).collect()
}

fn assert_same_plan(floor: &str, imdf: &FloorPlan, geojson: &FloorPlan) {
    assert_eq!(
        (imdf.width_m, imdf.height_m, imdf.level),
        (geojson.width_m, geojson.height_m, geojson.level),
        "{floor}"
    );
    assert_eq!(imdf.lon_lat_box, geojson.lon_lat_box, "{floor}");
    let names = |p: &FloorPlan| p.rooms.iter().map(|r| r.name.clone()).collect::<Vec<_>>();
    assert_eq!(names(imdf), names(geojson), "{floor}");
    assert_eq!(
        (0..imdf.rooms.len()).map(|r| imdf.room_kind(r)).collect::<Vec<_>>(),
        (0..geojson.rooms.len()).map(|r| geojson.room_kind(r)).collect::<Vec<_>>()
    );
    let (a, b) = (points(imdf), points(geojson));
    assert_eq!(a.len(), b.len(), "{floor}");
    let worst = a.iter().zip(&b).map(|(p, q)| (p - q).norm()).fold(0.0, f64::max);
    assert!(worst < 1e-6, "{floor}: a point moved {worst} m");
}

#[test]
fn site1_plans_round_trip_through_imdf_and_survey_the_same() {
    let Some(dirs) = waymark_eval::data::or_skip(floor_dirs()) else {
        return;
    };
    let floors: Vec<FloorData> =
        dirs.iter().map(|d| FloorData::load(d, Some(WALKS_PER_FLOOR)).expect("the floor reads")).collect();
    let plans: Vec<(String, &FloorPlan)> = floors
        .iter()
        .map(|f| (f.name.clone(), f.plan.as_ref().expect("site1's floors have plans")))
        .collect();
    let out = tempfile::tempdir().unwrap();
    let archive = out.path().join("site1.zip");
    Venue::from_plans("site1", &plans).unwrap().write(&archive, &options()).unwrap();

    // Import: each floor's plan from IMDF is its GeoJSON plan.
    let mut from_imdf = floors.clone();
    plans_from_imdf(&archive, &mut from_imdf).unwrap();
    for (a, b) in from_imdf.iter().zip(&floors) {
        assert_same_plan(&a.name, a.plan.as_ref().unwrap(), b.plan.as_ref().unwrap());
    }
    // Export and import again: the same venue.
    let imported = Venue::read(&archive).unwrap();
    let plans_again: Vec<(String, &FloorPlan)> =
        from_imdf.iter().map(|f| (f.name.clone(), f.plan.as_ref().unwrap())).collect();
    let again = out.path().join("again");
    Venue::from_plans("site1", &plans_again).unwrap().write(&again, &options()).unwrap();
    assert_eq!(Venue::read(&again).unwrap(), imported);
    assert_eq!(imported.levels.iter().map(|l| l.short_name.as_str()).collect::<Vec<_>>(), FLOORS);
    assert_eq!(imported.levels.iter().map(|l| l.ordinal).collect::<Vec<_>>(), [-1, 0, 1, 2, 3]);

    // A survey on either gives the same site.
    let (geo, _) =
        survey("site1", &survey_inputs(&floors), Default::default(), &SurveyOptions::default()).unwrap();
    let (imdf, _) =
        survey("site1", &survey_inputs(&from_imdf), Default::default(), &SurveyOptions::default()).unwrap();
    let floor_keys =
        |s: &waymark_engine::Site| s.floors().iter().map(|f| (f.name.clone(), f.level)).collect::<Vec<_>>();
    assert_eq!(floor_keys(&imdf), floor_keys(&geo));
    let (a, b) = (imdf.anchor().unwrap(), geo.anchor().unwrap());
    assert!((a.lat_deg - b.lat_deg).abs() < 1e-12 && (a.lon_deg - b.lon_deg).abs() < 1e-12);
    assert!((a.scale[0] - b.scale[0]).abs() < 1e-9 && (a.scale[1] - b.scale[1]).abs() < 1e-9);
    let zones = |s: &waymark_engine::Site| {
        s.zones().iter().map(|z| (z.name.clone(), z.kind, z.states.clone())).collect::<Vec<_>>()
    };
    assert!(!geo.zones().is_empty());
    assert_eq!(zones(&imdf), zones(&geo));
    assert_eq!((imdf.states().len(), imdf.edges().len()), (geo.states().len(), geo.edges().len()));

    // `waymark site export` on the surveyed site: a level per floor, a unit per zone.
    let site_path = out.path().join("site.json");
    std::fs::write(&site_path, geo.to_json()).unwrap();
    let exported = out.path().join("export.zip");
    let status = Command::new(env!("CARGO_BIN_EXE_waymark"))
        .args(["site", "export"])
        .arg(&site_path)
        .arg("--imdf")
        .arg(&exported)
        .status()
        .unwrap();
    assert!(status.success());
    let venue = Venue::read(&exported).unwrap();
    assert_eq!(venue.levels.iter().map(|l| l.short_name.as_str()).collect::<Vec<_>>(), FLOORS);
    let units: usize = venue.levels.iter().map(|l| l.units.len()).sum();
    assert_eq!(units, geo.zones().len());
    // And the plans themselves, through the command.
    let from_plans = out.path().join("plans");
    let status = Command::new(env!("CARGO_BIN_EXE_waymark"))
        .args(["site", "export", "--name", "site1", "--venue-category", "shoppingcenter", "--imdf"])
        .arg(&from_plans)
        .arg("--plans")
        .args(&dirs)
        .status()
        .unwrap();
    assert!(status.success());
    assert_eq!(Venue::read(&from_plans).unwrap(), imported);
}

/// `waymark survey --imdf` with a floor folder no level names, or a broken archive: a non-zero
/// exit and a message that says which, before any walk is surveyed.
#[test]
fn survey_refuses_an_imdf_archive_that_does_not_fit() {
    let tiny = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/imdf-tiny");
    let dir = tempfile::tempdir().unwrap();
    let floor = dir.path().join("F9");
    std::fs::create_dir(&floor).unwrap();
    let run = |imdf: &Path| {
        let out = Command::new(env!("CARGO_BIN_EXE_waymark"))
            .arg("survey")
            .arg(&floor)
            .arg("--imdf")
            .arg(imdf)
            .arg("--out")
            .arg(dir.path().join("site.json"))
            .output()
            .unwrap();
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let message = run(&tiny);
    assert!(message.contains("no level of the venue is called \"F9\" (its levels: G, L1)"), "{message}");
    let broken = dir.path().join("broken.zip");
    std::fs::write(&broken, b"PK not really").unwrap();
    let message = run(&broken);
    assert!(message.contains("broken.zip"), "{message}");
    assert!(!dir.path().join("site.json").exists());
}
