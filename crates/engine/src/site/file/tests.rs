//! Site file reading and writing: round trips, and errors named by path.

use super::*;
use crate::site::{GeoError, ZoneKind};

/// A small valid site file: two states on one floor, one transmitter.
pub(crate) const GOOD: &str = r#"{
  "format_version": 1,
  "name": "tiny",
  "floors": [{"name": "G"}],
  "radio": {"clip_dbm": -100, "unheard": {"mean_dbm": -115, "std_db": 5},
            "transmitters": [{"wifi": {"bssid": "00:11:22:33:44:55"}}]},
  "states": [
    {"id": 7, "floor": 0, "x": 0, "y": 0, "training_scans": 10,
     "fingerprint": [{"tx": 0, "mean_dbm": -60, "std_db": 4}]},
    {"id": 9, "floor": 0, "x": 3, "y": 4}
  ],
  "edges": [{"from": 7, "to": 9}]
}"#;

/// The error loading `text` gives.
pub(crate) fn err(text: &str) -> SiteError {
    Site::from_json(text.as_bytes()).unwrap_err()
}

#[test]
fn loads_and_round_trips() {
    let site = Site::from_json(GOOD.as_bytes()).unwrap();
    assert_eq!(site.states().len(), 2);
    assert_eq!(site.edges()[0].length_m, 5.0);
    assert_eq!(site.neighbours(1).collect::<Vec<_>>(), [(0, 5.0)]);
    let again = Site::from_json(site.to_json().as_bytes()).unwrap();
    assert_eq!(again.to_json(), site.to_json());
    assert_eq!(again.states(), site.states());
}

/// States without a fingerprint first, between and last: every model reaches the map at
/// its own state, from JSON and from the binary file's columns.
#[test]
fn models_reach_their_states_around_states_without_any() {
    let json = r#"{
      "format_version": 1,
      "name": "gaps",
      "floors": [{"name": "G"}],
      "radio": {"clip_dbm": -100, "unheard": {"mean_dbm": -115, "std_db": 5},
                "transmitters": [{"wifi": {"bssid": "00:11:22:33:44:55"}},
                                 {"wifi": {"bssid": "00:11:22:33:44:66"}}]},
      "states": [
        {"id": 1, "floor": 0, "x": 0, "y": 0},
        {"id": 2, "floor": 0, "x": 2, "y": 0, "training_scans": 3,
         "fingerprint": [{"tx": 1, "mean_dbm": -61.5, "std_db": 4}, {"tx": 0, "mean_dbm": -70, "std_db": 3}]},
        {"id": 3, "floor": 0, "x": 4, "y": 0},
        {"id": 4, "floor": 0, "x": 6, "y": 0},
        {"id": 5, "floor": 0, "x": 8, "y": 0, "training_scans": 2,
         "fingerprint": [{"tx": 0, "mean_dbm": -55.25, "std_db": 2.5}]},
        {"id": 6, "floor": 0, "x": 10, "y": 0}
      ],
      "edges": [{"from": 1, "to": 2}]
    }"#;
    let expected = [(1, 0, -70.0, 3.0), (4, 0, -55.25, 2.5), (1, 1, -61.5, 4.0)];
    let from_json = Site::from_json(json.as_bytes()).unwrap();
    let from_binary = Site::from_bytes(&from_json.to_binary()).unwrap();
    for site in [from_json, from_binary] {
        let models: Vec<(u32, u32, f64, f64)> =
            site.radio().fingerprints().map(|(s, t, g)| (s, t, g.mean_dbm, g.std_db)).collect();
        assert_eq!(models, expected);
    }
}

#[test]
fn floor_gammas_round_trip_in_both_encodings_and_old_files_have_none() {
    let plain = Site::from_json(GOOD.as_bytes()).unwrap();
    assert_eq!(plain.floors()[0].rssi_weight, None);
    assert!(!plain.to_json().contains("rssi_weight"));
    let site = plain.with_floor_rssi_weights(&[[Some(0.03), Some(0.1)]]).unwrap();
    let json = site.to_json();
    assert!(json.contains(r#""floors":[{"name":"G","elevation_m":0.0,"rssi_weight":0.03,"rssi_weight_without_movement":0.1}]"#), "{json}");
    let again = Site::from_json(json.as_bytes()).unwrap();
    assert_eq!(again.floors(), site.floors());
    let packed = Site::from_bytes(&site.to_binary()).unwrap();
    assert_eq!(packed.floors(), site.floors());
    assert_eq!(packed.to_json(), json);
}

#[test]
fn truncated_file_is_named_as_such() {
    for cut in [10, GOOD.len() / 2, GOOD.len() - 3] {
        assert!(matches!(err(&GOOD[..cut]), SiteError::Truncated { .. }), "cut at {cut}");
    }
}

#[test]
fn errors_say_what_and_where() {
    assert!(matches!(err("{\"format_version\": 1,, }"), SiteError::Syntax { line: 1, .. }));
    let newer = FORMAT_VERSION + 1;
    assert_eq!(
        err(&GOOD.replace("\"format_version\": 1", &format!("\"format_version\": {newer}"))),
        SiteError::NewerFormat { found: newer.into(), supported: FORMAT_VERSION }
    );
    let cases = [
        (GOOD.replace("\"format_version\": 1,", ""), "format_version"),
        (
            GOOD.replace("{\"name\": \"G\"}", "{\"name\": \"G\", \"rssi_weight\": 1.5}"),
            "floors[0].rssi_weight",
        ),
        (
            GOOD.replace("{\"name\": \"G\"}", "{\"name\": \"G\", \"rssi_weight_without_movement\": 0}"),
            "floors[0].rssi_weight_without_movement",
        ),
        (GOOD.replace("\"std_db\": 4", "\"std_db\": 0"), "states[0].fingerprint[0]"),
        (GOOD.replace("\"tx\": 0", "\"tx\": 3"), "states[0].fingerprint[0].tx"),
        (GOOD.replace("\"id\": 9", "\"id\": 7"), "states[1].id"),
        (GOOD.replace("\"to\": 9", "\"to\": 8"), "edges[0].to"),
        (GOOD.replace("\"x\": 3", "\"x\": \"3\""), "states[1].x"),
        (GOOD.replace("\"floor\": 0, \"x\": 3", "\"floor\": 4, \"x\": 3"), "states[1].floor"),
        (GOOD.replace("\"bssid\": \"00:11:22:33:44:55\"", "\"bssid\": \"zz\""), "radio.transmitters[0]"),
        (GOOD.replace("\"training_scans\": 10,", "\"trainingscans\": 10,"), "states[0]"),
        (
            GOOD.replace("{\"from\": 7, \"to\": 9}", "{\"from\": 7, \"to\": 9, \"length_m\": -1}"),
            "edges[0].length_m",
        ),
    ];
    for (text, path) in cases {
        match err(&text) {
            SiteError::Invalid { path: p, message } => {
                assert!(p.starts_with(path), "expected {path}, got {p}: {message}")
            }
            other => panic!("expected Invalid at {path}, got {other:?}"),
        }
    }
}

#[test]
fn values_too_large_or_too_small_to_compute_with_are_refused() {
    // Found with the `site_file` fuzz harness: each of these loaded, and then gave an
    // infinite accuracy radius or a -inf likelihood at every state.
    let cases = [
        (GOOD.replace("\"x\": 3, \"y\": 4", "\"x\": 1e308, \"y\": -1e308"), "states[1].x"),
        (GOOD.replace("\"std_db\": 4", "\"std_db\": 1e-300"), "states[0].fingerprint[0]"),
        (GOOD.replace("\"mean_dbm\": -60", "\"mean_dbm\": -1e300"), "states[0].fingerprint[0]"),
        (GOOD.replace("\"std_db\": 5", "\"std_db\": 0.001"), "radio.unheard"),
        (GOOD.replace("\"clip_dbm\": -100", "\"clip_dbm\": -1e5"), "radio.clip_dbm"),
    ];
    for (text, path) in cases {
        match err(&text) {
            SiteError::Invalid { path: p, .. } => {
                assert!(p.starts_with(path), "expected {path}, got {p}")
            }
            other => panic!("expected Invalid at {path}, got {other:?}"),
        }
    }
    let edge = GOOD
        .replace("\"x\": 3, \"y\": 4", "\"x\": 1e6, \"y\": -1e6")
        .replace("\"std_db\": 4", "\"std_db\": 0.01");
    assert!(Site::from_json(edge.as_bytes()).is_ok(), "the limits themselves load");
}

const ZONES: &str =
    r#","zones": [{"name": "kitchen", "states": [7]}, {"name": "hall", "kind": "corridor", "states": [9]}]}"#;

fn with_zones(zones: &str) -> String {
    let end = GOOD.rfind('}').unwrap();
    format!("{}{}", &GOOD[..end], zones)
}

#[test]
fn zones_load_and_round_trip_in_both_encodings() {
    let site = Site::from_json(with_zones(ZONES).as_bytes()).unwrap();
    assert_eq!(site.zones().len(), 2);
    assert_eq!(site.zones()[0].kind, ZoneKind::Room, "room by default");
    assert_eq!(site.zones()[1].kind, ZoneKind::Corridor);
    assert_eq!((site.zone_of(0), site.zone_of(1)), (Some(0), Some(1)));
    let json = site.to_json();
    assert!(json.contains(r#""zones":[{"name":"kitchen","kind":"room","states":[7]}"#), "{json}");
    let again = Site::from_json(json.as_bytes()).unwrap();
    assert_eq!(again.zones(), site.zones());
    assert_eq!(again.to_json(), json);
    let packed = Site::from_bytes(&site.to_binary()).unwrap();
    assert_eq!(packed.zones(), site.zones());
    assert_eq!(packed.to_json(), json);
    // Without zones, nothing is written.
    let plain = Site::from_json(GOOD.as_bytes()).unwrap();
    assert!(plain.zones().is_empty() && !plain.to_json().contains("zones"));
    assert!(Site::from_bytes(&plain.to_binary()).unwrap().zones().is_empty());
}

#[test]
fn bad_zones_are_named_by_path() {
    let cases = [
        (r#","zones": [{"name": "", "states": [7]}]}"#, "zones[0].name"),
        (r#","zones": [{"name": "a", "states": [7]}, {"name": "a", "states": [9]}]}"#, "zones[1].name"),
        (r#","zones": [{"name": "a", "states": []}]}"#, "zones[0].states"),
        (r#","zones": [{"name": "a", "states": [7, 8]}]}"#, "zones[0].states[1]"),
        (r#","zones": [{"name": "a", "states": [9, 9]}]}"#, "zones[0].states[1]"),
        (
            r#","zones": [{"name": "a", "states": [7]}, {"name": "b", "states": [9, 7]}]}"#,
            "zones[1].states[1]",
        ),
        (r#","zones": [{"name": "a", "kind": "cellar", "states": [7]}]}"#, "zones[0].kind"),
        (r#","zones": [{"name": "a", "states": [7], "floor": 0}]}"#, "zones[0]"),
        (r#","zones": [{"states": [7]}]}"#, "zones[0]"),
        (r#","zones": {"name": "a"}}"#, "zones"),
    ];
    for (zones, path) in cases {
        match err(&with_zones(zones)) {
            SiteError::Invalid { path: p, message } => {
                assert!(p.starts_with(path), "{zones}: expected {path}, got {p}: {message}")
            }
            other => panic!("{zones}: expected Invalid at {path}, got {other:?}"),
        }
    }
    let message = err(&with_zones(cases[5].0)).to_string();
    assert!(message.contains("already in zones[0]"), "{message}");
}

const ANCHOR: &str = r#","anchor": {"lat_deg": 30.292, "lon_deg": 120.074, "scale": [0.999, 1.004]}}"#;

#[test]
fn anchor_levels_and_origins_round_trip_in_both_encodings() {
    let text = with_zones(ANCHOR).replace(
        r#""floors": [{"name": "G"}]"#,
        r#""floors": [{"name": "G", "level": -1, "origin_m": [2.5, -3]}]"#,
    );
    let site = Site::from_json(text.as_bytes()).unwrap();
    let anchor = site.anchor().unwrap();
    assert_eq!((anchor.lat_deg, anchor.azimuth_rad, anchor.scale), (30.292, 0.0, [0.999, 1.004]));
    assert_eq!((site.floor_level(0), site.floor_level(1)), (Some(-1), None));
    assert_eq!(site.floors()[0].origin_m, [2.5, -3.0]);
    let json = site.to_json();
    assert!(
        json.contains(
            r#""anchor":{"lat_deg":30.292,"lon_deg":120.074,"azimuth_rad":0.0,"scale":[0.999,1.004]}"#
        ),
        "{json}"
    );
    assert!(json.contains(r#""level":-1,"origin_m":[2.5,-3.0]"#), "{json}");
    assert_eq!(Site::from_json(json.as_bytes()).unwrap().to_json(), json);
    let packed = Site::from_bytes(&site.to_binary()).unwrap();
    assert_eq!(packed.to_json(), json);
    assert_eq!(site.with_pseudo_states(1.0).anchor(), site.anchor(), "pseudo states keep the anchor");
    // Without them, nothing is written.
    let plain = Site::from_json(GOOD.as_bytes()).unwrap();
    assert!(plain.anchor().is_none() && plain.floor_level(0).is_none());
    let json = plain.to_json();
    assert!(!json.contains("anchor") && !json.contains("level") && !json.contains("origin_m"), "{json}");
}

#[test]
fn positions_convert_through_the_anchor_and_the_floor_origin() {
    let text = with_zones(ANCHOR).replace(
        r#""floors": [{"name": "G"}]"#,
        r#""floors": [{"name": "G"}, {"name": "1", "origin_m": [10, 0]}]"#,
    );
    let site = Site::from_json(text.as_bytes()).unwrap();
    let anchor = *site.anchor().unwrap();
    assert_eq!(site.lat_lon(0, 3.0, 4.0), Some(anchor.to_lat_lon(3.0, 4.0)));
    assert_eq!(site.lat_lon(1, 3.0, 4.0), Some(anchor.to_lat_lon(13.0, 4.0)));
    assert_eq!(site.lat_lon(2, 3.0, 4.0), None);
    let at = anchor.to_lat_lon(13.0, 4.0);
    let p = site.site_point(Some(1), at).unwrap();
    assert!((p.x - 3.0).abs() < 1e-6 && (p.y - 4.0).abs() < 1e-6, "{p}");
    assert_eq!(site.site_point(None, at), Err(GeoError::FloorRequired));
    assert_eq!(site.site_point(Some(2), at), Err(GeoError::UnknownFloor { floor: 2, floors: 2 }));
    let bad = crate::site::LatLon { lat_deg: f64::NAN, lon_deg: 0.0 };
    assert!(matches!(site.site_point(Some(0), bad), Err(GeoError::InvalidCoordinate { .. })));
    assert_eq!(site.bearing_deg(0.0), Some(0.0));
    let plain = Site::from_json(GOOD.as_bytes()).unwrap();
    assert_eq!(plain.site_point(None, at), Err(GeoError::NotGeoReferenced));
    assert_eq!((plain.lat_lon(0, 0.0, 0.0), plain.bearing_deg(0.0)), (None, None));
    // One frame for every floor: no floor needed.
    let one_frame = Site::from_json(with_zones(ANCHOR).as_bytes()).unwrap();
    let p = one_frame.site_point(None, anchor.to_lat_lon(3.0, 4.0)).unwrap();
    assert!((p.x - 3.0).abs() < 1e-6 && (p.y - 4.0).abs() < 1e-6, "{p}");
}

#[test]
fn bad_anchors_and_origins_are_named_by_path() {
    let cases = [
        (r#","anchor": {"lat_deg": 95, "lon_deg": 0}}"#, "anchor.lat_deg"),
        (r#","anchor": {"lat_deg": 0, "lon_deg": 0, "scale": [1, -1]}}"#, "anchor.scale"),
        (r#","anchor": {"lat_deg": 0}}"#, "anchor"),
        (r#","anchor": {"lat_deg": 0, "lon_deg": 0, "height_m": 3}}"#, "anchor"),
    ];
    for (anchor, path) in cases {
        match err(&with_zones(anchor)) {
            SiteError::Invalid { path: p, message } => {
                assert!(p.starts_with(path), "{anchor}: expected {path}, got {p}: {message}")
            }
            other => panic!("{anchor}: expected Invalid at {path}, got {other:?}"),
        }
    }
    let origin = GOOD.replace(r#"{"name": "G"}"#, r#"{"name": "G", "origin_m": [1e7, 0]}"#);
    assert!(matches!(err(&origin), SiteError::Invalid { path, .. } if path == "floors[0].origin_m"));
    let level = GOOD.replace(r#"{"name": "G"}"#, r#"{"name": "G", "level": 1.5}"#);
    assert!(matches!(err(&level), SiteError::Invalid { path, .. } if path.starts_with("floors[0].level")));
}

/// A second document or any other data after the site's is refused, never ignored: the
/// file loaded as its first document (issue 60, item 7). A UTF-8 byte order mark is skipped;
/// a UTF-16 one is named.
#[test]
fn data_after_the_document_is_refused_and_a_utf8_bom_skipped() {
    for tail in ["{}", "x", "\0", &GOOD[..40]] {
        let text = format!("{GOOD}\n{tail}");
        match err(&text) {
            SiteError::Syntax { line: 14, message, .. } => {
                assert!(message.contains("after the end of the site's JSON document"), "{message}")
            }
            other => panic!("{tail:?}: {other:?}"),
        }
        let packed = Site::from_json(GOOD.as_bytes()).unwrap().to_binary();
        assert!(Site::from_bytes(&[&packed[..], tail.as_bytes()].concat()).is_err(), "binary + {tail:?}");
    }
    assert!(Site::from_json(format!("{GOOD} \n\t\r\n").as_bytes()).is_ok(), "white space may follow");
    let with_bom = [&b"\xEF\xBB\xBF"[..], GOOD.as_bytes()].concat();
    assert_eq!(
        Site::from_bytes(&with_bom).unwrap().to_json(),
        Site::from_json(GOOD.as_bytes()).unwrap().to_json()
    );
    let utf16 = [&b"\xFF\xFE"[..], GOOD.as_bytes()].concat();
    match Site::from_bytes(&utf16).unwrap_err() {
        SiteError::Syntax { message, .. } => assert!(message.contains("UTF-16"), "{message}"),
        other => panic!("{other:?}"),
    }
}

/// The limits checked at load name themselves (docs/errors.md#site-limits).
#[test]
fn edges_and_transmitters_per_state_are_limited() {
    use crate::site::budget::{MAX_EDGES_PER_STATE, MAX_TRANSMITTERS_PER_STATE};
    let over = |text: &str| match err(text) {
        SiteError::OverLimit { name, .. } => name,
        other => panic!("{other:?}"),
    };
    // A hub joined to more states than a state may have edges.
    let spokes = MAX_EDGES_PER_STATE + 1;
    let states: Vec<String> =
        (0..=spokes).map(|i| format!(r#"{{"id": {i}, "floor": 0, "x": {i}, "y": 1}}"#)).collect();
    let edges: Vec<String> = (1..=spokes).map(|i| format!(r#"{{"from": 0, "to": {i}}}"#)).collect();
    let hub = format!(
        r#"{{"format_version": 7, "name": "hub", "floors": [{{"name": "G"}}],
            "radio": {{"clip_dbm": -100, "unheard": {{"mean_dbm": -115, "std_db": 5}}, "transmitters": []}},
            "states": [{}], "edges": [{}]}}"#,
        states.join(","),
        edges.join(",")
    );
    assert_eq!(over(&hub), "MAX_EDGES_PER_STATE");
    let fewer = hub.replace(&format!(r#",{{"from": 0, "to": {spokes}}}"#), "");
    assert!(Site::from_json(fewer.as_bytes()).is_ok(), "the limit itself loads");
    // A state modelling more transmitters than a state may.
    let count = MAX_TRANSMITTERS_PER_STATE + 1;
    let ids: Vec<String> = (0..count)
        .map(|k| format!(r#"{{"wifi": {{"bssid": "02:00:00:00:{:02x}:{:02x}"}}}}"#, k >> 8, k & 255))
        .collect();
    let entries: Vec<String> =
        (0..count).map(|k| format!(r#"{{"tx": {k}, "mean_dbm": -60, "std_db": 4}}"#)).collect();
    let loud = GOOD
        .replace(r#"{"wifi": {"bssid": "00:11:22:33:44:55"}}"#, &ids.join(","))
        .replace(r#"{"tx": 0, "mean_dbm": -60, "std_db": 4}"#, &entries.join(","));
    assert_eq!(over(&loud), "MAX_TRANSMITTERS_PER_STATE");
}

#[test]
fn io_error_names_the_path() {
    let e = Site::load("/nonexistent/site.json").unwrap_err();
    assert!(e.to_string().contains("/nonexistent/site.json"));
}
