//! `waymark view` end to end (docs/view.md): the page is self-contained (no address outside
//! it, no external script, style or font) and embeds every floor of the site, the walk given as
//! a track CSV or replayed from a recorded walk, and the demo's walk with its truth; bad input
//! is an error message and a failure status, never a panic. Rendering in a browser is
//! scripts/view-test.sh's part.

use nalgebra::Point2;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use waymark_engine::site::{BuildOptions, SiteBuilder};
use waymark_engine::{Reading, Scan, TransmitterId, ZoneKind};

fn waymark(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_waymark")).args(args).output().expect("the waymark binary runs")
}

/// A fresh folder for one test.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("view").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("a scratch folder");
    dir
}

fn arg(p: &Path) -> &str {
    p.to_str().expect("a UTF-8 path")
}

/// Writes the page `args` ask for into `dir/page.html`, and returns it.
fn page(dir: &Path, args: &[&str]) -> String {
    let out = dir.join("page.html");
    let mut all = vec!["view", "--out", arg(&out)];
    all.extend_from_slice(args);
    let run = waymark(&all);
    assert!(run.status.success(), "waymark {all:?}: {}", String::from_utf8_lossy(&run.stderr));
    std::fs::read_to_string(out).expect("the page was written")
}

/// The page's embedded data.
fn data(html: &str) -> Value {
    let open = r#"<script type="application/json" id="waymark-data">"#;
    let start = html.find(open).expect("the data element") + open.len();
    let end = start + html[start..].find("</script>").expect("the data element's end");
    serde_json::from_str(&html[start..end]).expect("the data is JSON")
}

/// Nothing the page would fetch: no address in an attribute or in CSS, no external script,
/// style sheet, font or frame.
fn assert_self_contained(html: &str) {
    let lower = html.to_lowercase();
    for attribute in ["src=", "href=", "srcset=", "action=", "poster="] {
        for (at, _) in lower.match_indices(attribute) {
            let value = lower[at + attribute.len()..].trim_start_matches(['"', '\'']);
            assert!(
                !(value.starts_with("http:") || value.starts_with("https:") || value.starts_with("//")),
                "an external {attribute} at byte {at}"
            );
        }
    }
    for needle in ["http://", "https://", "<link", "@import", "url(", "<iframe", "fetch(", "xmlhttprequest"] {
        assert!(!lower.contains(needle), "the page contains {needle:?}");
    }
    assert_eq!(lower.matches("<script").count(), 2, "the data and the inline script, nothing else");
}

/// Two floors, a stair edge between them, zones on both; one transmitter.
fn two_floor_site(dir: &Path) -> PathBuf {
    let ap = TransmitterId::wifi("02:00:00:00:00:01").expect("a BSSID");
    let scans = |rssi: f64| -> Vec<Scan> {
        (0..5)
            .map(|k| Scan {
                timestamp_ns: k,
                readings: vec![Reading { transmitter: ap.clone(), rssi_dbm: rssi, age_ns: 0 }],
            })
            .collect()
    };
    let mut b = SiteBuilder::new("two floors");
    let ground = b.floor("G", 0.0);
    let first = b.floor("F1", 4.0);
    let a = b.state(ground, Point2::new(0.0, 0.0), scans(-50.0));
    let c = b.state(ground, Point2::new(3.0, 0.0), scans(-60.0));
    let d = b.state(first, Point2::new(3.0, 0.0), scans(-70.0));
    let e = b.state(first, Point2::new(3.0, 3.0), scans(-80.0));
    let f = b.state(first, Point2::new(6.0, 3.0), scans(-85.0));
    b.edge(a, c, None);
    b.edge(c, d, Some(5.0));
    b.edge(d, e, None);
    b.edge(e, f, None);
    b.zone("lobby", ZoneKind::Hall, vec![a, c]);
    b.zone("kitchen & <bar>", ZoneKind::Room, vec![e, f]);
    let site = b.build(BuildOptions::default()).expect("a valid site");
    let path = dir.join("site.json");
    std::fs::write(&path, site.to_json()).expect("the site file was written");
    path
}

#[test]
fn the_site_page_is_self_contained_and_embeds_every_floor_and_zone() {
    let dir = scratch("site");
    let site = two_floor_site(&dir);
    let html = page(&dir, &["--site", arg(&site)]);
    assert_self_contained(&html);
    let data = data(&html);
    let floors = data["floors"].as_array().expect("floors");
    let names: Vec<&str> = floors.iter().map(|f| f["name"].as_str().unwrap_or_default()).collect();
    assert_eq!(names, ["G", "F1"]);
    let states: Vec<usize> = floors.iter().map(|f| f["kinds"].as_array().map_or(0, Vec::len)).collect();
    assert_eq!(states, [2, 3]);
    assert_eq!(floors[1]["states"], serde_json::json!([3.0, 0.0, 3.0, 3.0, 6.0, 3.0]));
    assert_eq!(floors[0]["connectors"], serde_json::json!([1]));
    assert_eq!(floors[1]["connectors"], serde_json::json!([0]));
    assert_eq!(data["zones"][1]["name"], "kitchen & <bar>");
    assert!(!html.contains("<bar>"), "names in the data are escaped");
    assert!(data["track"].is_null());
}

#[test]
fn a_track_csv_is_shown_on_its_floors_whatever_other_columns_it_has() {
    let dir = scratch("track");
    let site = two_floor_site(&dir);
    let csv = dir.join("track.csv");
    std::fs::write(
        &csv,
        "timestamp_ms,floor,x,y,lat,lon,accuracy_m,accuracy_95_m,heading_deg,scenario,motion_state,steps\n\
         5000,G,0.50,0.00,30.1,120.1,2.00,4.00,,Speed,Unknown,0\n\
         7000,F1,3.00,2.50,30.1,120.1,1.50,3.00,90.0,DistanceHeading,Walking,3\n",
    )
    .expect("the track was written");
    let html = page(&dir, &["--site", arg(&site), "--track", arg(&csv)]);
    assert_self_contained(&html);
    let epochs = data(&html)["track"]["epochs"].clone();
    assert_eq!(
        epochs,
        serde_json::json!([
            [0.0, 0.0, 0.5, 0.0, 2.0, null, null, null],
            [2.0, 1.0, 3.0, 2.5, 1.5, null, null, null]
        ])
    );
}

#[test]
fn a_recorded_walk_is_replayed_and_its_waypoints_are_the_truth() {
    let dir = scratch("walk");
    let office = waymark_sim::Office::generate(&waymark_sim::OfficeConfig::default());
    let site = dir.join("site.json");
    std::fs::write(&site, office.site.to_json()).expect("the site file was written");
    // A competition-format walk: a waypoint and a WiFi scan each epoch, no inertial sensors.
    let walk = office.walk(7, 60.0);
    let mut text = String::from("#\tSiteID:sim\tFloorName:office\n");
    for e in &walk.epochs {
        let t_ms = e.scan.timestamp_ns / 1_000_000;
        text += &format!("{t_ms}\tTYPE_WAYPOINT\t{}\t{}\n", e.truth.x, e.truth.y);
        for r in &e.scan.readings {
            let TransmitterId::Wifi { bssid } = &r.transmitter else { continue };
            text += &format!("{t_ms}\tTYPE_WIFI\tnet\t{bssid}\t{}\t2412\t{t_ms}\n", r.rssi_dbm);
        }
    }
    let path = dir.join("walk.txt");
    std::fs::write(&path, text).expect("the walk was written");
    let html = page(&dir, &["--site", arg(&site), "--walk", arg(&path)]);
    assert_self_contained(&html);
    let epochs = data(&html)["track"]["epochs"].as_array().expect("epochs").clone();
    assert!(epochs.len() >= walk.epochs.len() - 1, "{} epochs of {}", epochs.len(), walk.epochs.len());
    let errors: Vec<f64> = epochs
        .iter()
        .map(|e| {
            let n = |i: usize| e[i].as_f64().expect("a number");
            assert_eq!((n(1), n(5)), (0.0, 0.0), "estimate and truth on the one floor");
            (n(2) - n(6)).hypot(n(3) - n(7))
        })
        .collect();
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    // Room-sized: the engine positioned the walk, against the waypoints it was not given.
    assert!(mean < 6.0, "mean error {mean:.2} m");
}

#[test]
fn the_demo_page_embeds_the_office_and_a_walk_with_its_truth() {
    let dir = scratch("demo");
    let html = page(&dir, &["--demo", "--walk-length-m", "30"]);
    assert_self_contained(&html);
    let data = data(&html);
    assert_eq!(data["floors"].as_array().map(Vec::len), Some(1));
    assert!(data["zones"].as_array().is_some_and(|z| z.iter().any(|z| z["name"] == "stair hall")));
    let epochs = data["track"]["epochs"].as_array().expect("the walk");
    assert!(epochs.len() > 10);
    assert!(epochs.iter().all(|e| e[5] == 0.0 && e[6].is_number() && e[4].as_f64().is_some_and(|r| r > 0.0)));
}

#[test]
fn bad_input_fails_with_a_message() {
    let dir = scratch("bad");
    let site = two_floor_site(&dir);
    let csv = dir.join("track.csv");
    std::fs::write(&csv, "timestamp_ms,floor,x,y,accuracy_m\n1,B9,0,0,1\n").expect("written");
    let plan = dir.join("B9");
    let out = dir.join("page.html");
    for (args, needle) in [
        (vec!["--site", arg(&site), "--track", arg(&csv)], "no floor \"B9\""),
        (vec!["--site", arg(&dir.join("missing.json"))], "missing.json"),
        (vec!["--site", arg(&csv)], "track.csv"),
        (vec!["--site", arg(&site), "--plan", arg(&plan)], "no floor \"B9\""),
        (vec!["--site", arg(&site), "--walk", arg(&dir.join("missing.txt"))], "missing.txt"),
        (vec!["--demo", "--walk-length-m=-3"], "positive"),
        (vec!["--site", arg(&site), "--seed", "3"], "go with --demo"),
    ] {
        let mut all = vec!["view", "--out", arg(&out)];
        all.extend(args);
        let run = waymark(&all);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(1), "{all:?}: {stderr}");
        assert!(stderr.contains(needle) && !stderr.contains("panicked"), "{all:?}: {stderr}");
        assert!(!out.exists(), "{all:?} wrote a page");
    }
}
