use super::*;
use std::path::PathBuf;

/// The hand-made venue of tests/data/imdf-tiny (its README gives the figures checked here).
fn tiny() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/imdf-tiny")
}

fn options() -> WriteOptions {
    WriteOptions {
        created: "2000-01-01T00:00:00Z".into(),
        venue_category: "shoppingcenter".into(),
        country: "CN".into(),
    }
}

#[test]
fn the_tiny_venue_reads_as_drawn() {
    let venue = Venue::read(&tiny()).unwrap();
    assert_eq!(venue.name, "Tiny Mall");
    let names: Vec<(&str, &str, i32)> =
        venue.levels.iter().map(|l| (l.name.as_str(), l.short_name.as_str(), l.ordinal)).collect();
    assert_eq!(names, [("Ground floor", "G", 0), ("First floor", "L1", 1)]);
    let g = &venue.levels[0];
    let units: Vec<(Option<&str>, &str)> =
        g.units.iter().map(|u| (u.name.as_deref(), u.category.as_str())).collect();
    assert_eq!(units, [(Some("Shop A"), "room"), (Some("B店"), "room"), (None, "walkway")]);
    assert_eq!(g.openings, vec![vec![[120.00004, 30.00005], [120.00006, 30.00005]]]);

    let plan = g.floor_plan(None).unwrap();
    assert!((plan.width_m - 19.297).abs() < 0.001 && (plan.height_m - 11.085).abs() < 0.001, "{plan:?}");
    assert_eq!(plan.level, Some(1), "ordinal 0 is the ground floor, level 1");
    assert_eq!(venue.levels[1].floor_plan(None).unwrap().level, Some(2));
    assert_eq!(plan.rooms.len(), 3);
    assert_eq!(plan.room_kinds, [ZoneKind::Room, ZoneKind::Room, ZoneKind::Corridor]);
    let corner = plan.rooms[0].polygon.rings[0][2];
    assert!((corner.x - 9.649).abs() < 0.001 && (corner.y - 5.543).abs() < 0.001, "{corner:?}");
    let [p, q] = plan.doors[0];
    assert!((p.x - 3.859).abs() < 0.001 && (q.x - 5.789).abs() < 0.001 && (p.y - 5.543).abs() < 0.001);
    // Through Shop A's north wall at the door: no wall; a metre west of the door: a wall.
    assert!(!plan.crosses_wall(Point2::new(4.8, 4.5), Point2::new(4.8, 6.5)));
    assert!(plan.crosses_wall(Point2::new(2.5, 4.5), Point2::new(2.5, 6.5)));
    // Given the walks' frame, the plan stretches onto it.
    let framed = g.floor_plan(Some([200.0, 100.0])).unwrap();
    assert_eq!((framed.width_m, framed.height_m), (200.0, 100.0));
    assert!((framed.rooms[0].polygon.rings[0][2].x - 100.0).abs() < 1e-9);
}

#[test]
fn a_venue_written_reads_back_the_same_as_a_folder_and_a_zip() {
    let venue = Venue::read(&tiny()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    for out in [dir.path().join("folder"), dir.path().join("venue.zip")] {
        venue.write(&out, &options()).unwrap();
        let back = Venue::read(&out).unwrap();
        // The Chinese-only name came out as the first language, and goes back as English.
        assert_eq!(back, venue, "{}", out.display());
    }
    // The same venue is written the same way: ids derive from it.
    let again = dir.path().join("again");
    venue.write(&again, &options()).unwrap();
    for file in ["level.geojson", "unit.geojson", "anchor.geojson"] {
        let read = |d: &Path| std::fs::read_to_string(d.join(file)).unwrap();
        assert_eq!(read(&dir.path().join("folder")), read(&again), "{file}");
    }
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(again.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["version"], "1.0.0");
    let units: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(again.join("unit.geojson")).unwrap()).unwrap();
    for required in
        ["category", "restriction", "accessibility", "name", "alt_name", "display_point", "level_id"]
    {
        assert!(units["features"][0]["properties"].get(required).is_some(), "unit.{required}");
    }
}

#[test]
fn plans_go_to_imdf_and_back_unchanged() {
    let venue = Venue::read(&tiny()).unwrap();
    let size = Some([200.0, 100.0]);
    let plans: Vec<FloorPlan> = venue.levels.iter().map(|l| l.floor_plan(size).unwrap()).collect();
    let floors: Vec<(String, &FloorPlan)> =
        venue.levels.iter().zip(&plans).map(|(l, p)| (l.short_name.clone(), p)).collect();
    let made = Venue::from_plans("Tiny Mall", &floors).unwrap();
    let dir = tempfile::tempdir().unwrap();
    made.write(dir.path(), &options()).unwrap();
    let back = Venue::read(dir.path()).unwrap();
    for (level, plan) in back.levels.iter().zip(&plans) {
        let again = level.floor_plan(size).unwrap();
        assert_eq!(
            (again.level, again.lon_lat_box, &again.room_kinds),
            (plan.level, plan.lon_lat_box, &plan.room_kinds)
        );
        assert_eq!(
            again.rooms.iter().map(|r| &r.name).collect::<Vec<_>>(),
            plan.rooms.iter().map(|r| &r.name).collect::<Vec<_>>()
        );
        let points = |p: &FloorPlan| -> Vec<Point2<f64>> {
            let rooms = p.rooms.iter().map(|r| &r.polygon);
            p.outline
                .iter()
                .chain(rooms)
                .flat_map(|q| q.rings.iter().flatten().copied())
                .chain(p.doors.iter().flatten().copied())
                .collect()
        };
        let (a, b) = (points(&again), points(plan));
        assert_eq!(a.len(), b.len());
        assert!(a.iter().zip(&b).all(|(p, q)| (p - q).norm() < 1e-6));
    }
}

/// The tiny venue copied into a fresh folder with `file` replaced by `edit` of its JSON.
fn edited(file: &str, edit: impl FnOnce(&mut serde_json::Value)) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for entry in std::fs::read_dir(tiny()).unwrap() {
        let path = entry.unwrap().path();
        std::fs::copy(&path, dir.path().join(path.file_name().unwrap())).unwrap();
    }
    let path = dir.path().join(file);
    let mut value: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    edit(&mut value);
    std::fs::write(&path, value.to_string()).unwrap();
    dir
}

#[test]
fn bad_archives_are_refused_naming_the_file_and_feature() {
    let refused = |dir: &tempfile::TempDir| Venue::read(dir.path()).unwrap_err().to_string();
    let bowtie = edited("unit.geojson", |v| {
        v["features"][0]["geometry"]["coordinates"] = serde_json::json!([[
            [120.0, 30.0],
            [120.0001, 30.00005],
            [120.0001, 30.0],
            [120.0, 30.00005],
            [120.0, 30.0]
        ]]);
    });
    let message = refused(&bowtie);
    assert!(
        message.starts_with("unit.geojson: features[0]") && message.contains("self-intersection"),
        "{message}"
    );
    let open = edited("level.geojson", |v| {
        v["features"][0]["geometry"]["coordinates"] = serde_json::json!([[[120.0, 30.0], [120.0001, 30.0]]]);
    });
    assert!(refused(&open).contains("level.geojson: features[0]"), "{}", refused(&open));
    let far = edited("unit.geojson", |v| {
        v["features"][1]["geometry"]["coordinates"][0][0] = serde_json::json!([200.0, 30.0])
    });
    assert!(refused(&far).contains("not a longitude/latitude"), "{}", refused(&far));
    let id = edited("unit.geojson", |v| v["features"][0]["id"] = "shop-a".into());
    assert!(refused(&id).contains("not a UUID"), "{}", refused(&id));
    let orphan = edited("opening.geojson", |v| {
        v["features"][0]["properties"]["level_id"] = "00000000-0000-4000-8000-000000000099".into()
    });
    assert!(refused(&orphan).contains("no level of the archive"), "{}", refused(&orphan));
    let ordinal = edited("level.geojson", |v| v["features"][0]["properties"]["ordinal"] = "one".into());
    assert!(refused(&ordinal).contains("no integer ordinal"), "{}", refused(&ordinal));
    let kind = edited("unit.geojson", |v| v["features"][0]["feature_type"] = "level".into());
    assert!(refused(&kind).contains("feature_type"), "{}", refused(&kind));
    let not_geojson =
        edited("venue.geojson", |v| *v = serde_json::json!({"type": "Point", "coordinates": [1.0, 2.0]}));
    assert!(refused(&not_geojson).contains("not a FeatureCollection"), "{}", refused(&not_geojson));
    let missing = edited("venue.geojson", |_| {});
    std::fs::remove_file(missing.path().join("unit.geojson")).unwrap();
    assert!(matches!(Venue::read(missing.path()), Err(ImdfError::Missing { file: "unit.geojson" })));
    let garbage = tempfile::tempdir().unwrap();
    let zip = garbage.path().join("venue.zip");
    std::fs::write(&zip, b"not a zip").unwrap();
    assert!(matches!(Venue::read(&zip), Err(ImdfError::Zip { .. })));
    let venue = Venue::read(&tiny()).unwrap();
    assert!(matches!(venue.level_for_floor("F9"), Err(ImdfError::NoSuchLevel { .. })));
    assert_eq!(venue.level_for_floor("l1").unwrap().name, "First floor");
}

#[test]
fn ordinals_and_levels_and_categories_map_both_ways() {
    for level in [-3, -1, 1, 2, 7] {
        assert_eq!(level_of_ordinal(ordinal_of_level(level)), level);
    }
    assert_eq!((level_of_ordinal(0), level_of_ordinal(-1)), (1, -1));
    for kind in [
        ZoneKind::Room,
        ZoneKind::Corridor,
        ZoneKind::Hall,
        ZoneKind::Stairs,
        ZoneKind::Lift,
        ZoneKind::Other,
    ] {
        assert_eq!(zone_kind(unit_category(kind)), kind);
    }
    assert_eq!(zone_kind("restroom.female"), ZoneKind::Room);
}
