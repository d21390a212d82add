//! Site-file format versions: a file of a newer format than this build reads is refused as
//! "newer format", in JSON and in the binary encoding, before any field it has that this build
//! does not know; version-1 and version-2 files (older schemas, subsets of the current) still
//! load.

use waymark_engine::site::{FORMAT_VERSION, OLDEST_FORMAT_VERSION};
use waymark_engine::{Site, SiteError};

/// A version-1 file with a field added within version 1 (`zones`).
const VERSION_1: &str = r#"{
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
  "edges": [{"from": 7, "to": 9}],
  "zones": [{"name": "kitchen", "kind": "room", "states": [7]}]
}"#;

fn with_version(json: &str, version: u64) -> String {
    json.replacen("\"format_version\": 1", &format!("\"format_version\": {version}"), 1)
}

/// [`VERSION_1`] at `version` with `calibration` (a JSON object's fields) as its calibration.
fn with_calibration(version: u64, calibration: &str) -> String {
    with_version(VERSION_1, version).replacen(
        r#""name":"#,
        &format!(r#""calibration": {{{calibration}}}, "name":"#),
        1,
    )
}

/// The binary file `binary` with its header's `format_version` set to `version` (one digit)
/// and its checksum made right again, so only the version differs.
fn binary_with_version(binary: &[u8], version: u32) -> Vec<u8> {
    let (from, to) =
        (format!("\"format_version\":{FORMAT_VERSION}"), format!("\"format_version\":{version}"));
    assert_eq!(from.len(), to.len());
    let at = binary.windows(from.len()).position(|w| w == from.as_bytes()).expect("the header's version");
    let mut out = binary.to_vec();
    out[at..at + to.len()].copy_from_slice(to.as_bytes());
    let body = out.len() - 4;
    let crc = crc32fast::hash(&out[..body]);
    out[body..].copy_from_slice(&crc.to_le_bytes());
    out
}

#[test]
fn the_current_version_is_8_and_reads_back_to_1() {
    assert_eq!((OLDEST_FORMAT_VERSION, FORMAT_VERSION), (1, 8));
}

/// A version-6 file loads with every transmitter a radio of its own; version 7 adds the
/// transmitters that share a radio (`radio.shared_radios`), kept through both encodings and
/// through hashing, written only when there are some, and checked.
#[test]
fn a_version_6_file_still_loads_and_version_7_adds_the_shared_radios() {
    let site = Site::from_json(with_version(VERSION_1, 6).as_bytes()).unwrap();
    assert!(site.radio().shared_radios().is_empty());
    assert!(!site.to_json().contains("shared_radios"));
    let two = with_version(VERSION_1, 7).replacen(
        r#""transmitters": [{"wifi": {"bssid": "00:11:22:33:44:55"}}]"#,
        r#""shared_radios": [[0, 1]],
            "transmitters": [{"wifi": {"bssid": "00:11:22:33:44:55"}}, {"wifi": {"bssid": "02:11:22:33:44:55"}}]"#,
        1,
    );
    let site = Site::from_json(two.as_bytes()).unwrap();
    assert_eq!(site.radio().shared_radios(), [vec![0, 1]]);
    assert!(site.to_json().contains(r#""shared_radios":[[0,1]]"#), "{}", site.to_json());
    let binary = Site::from_bytes(&site.to_binary()).unwrap();
    assert_eq!(binary.radio().shared_radios(), [vec![0, 1]]);
    let hashed = site.hashed(&waymark_engine::radio::Salt::new(b"a salt of sixteen bytes").unwrap()).unwrap();
    assert_eq!(hashed.radio().shared_radios(), [vec![0, 1]]);
    for (bad, says) in [("[[0, 1]]", "[[0, 2]]"), ("[[0, 1]]", "[[0]]")] {
        let err = Site::from_json(two.replace(bad, says).as_bytes()).unwrap_err().to_string();
        assert!(err.contains("radio.shared_radios"), "{err}");
    }
}

/// A version-5 file loads with no floor calibration; version 6 adds it, steady and sparse
/// (`calibration.floor_reliability`, `calibration.sparse_scans.floor_reliability`), kept
/// through both encodings and written only when set.
#[test]
fn a_version_5_file_still_loads_and_version_6_adds_the_floor_reliability() {
    let site = Site::from_json(with_version(VERSION_1, 5).as_bytes()).unwrap();
    assert!(site.calibration().floor_reliability.is_empty());
    assert!(!site.to_json().contains("floor_reliability"));
    let calibrated = with_calibration(
        6,
        r#""floor_reliability": [null, 0.4, 0.8, 0.9, 0.99],
            "sparse_scans": {"floor_reliability": [0.3, 0.5, 0.7, 0.8, 0.95]}"#,
    );
    let site = Site::from_json(calibrated.as_bytes()).unwrap();
    let expected = [None, Some(0.4), Some(0.8), Some(0.9), Some(0.99)];
    assert_eq!(site.calibration().floor_reliability.0, expected);
    assert_eq!(site.calibration().sparse_scans.floor_reliability.0[4], Some(0.95));
    assert!(site.to_json().contains(r#""floor_reliability":[null,0.4,0.8,0.9,0.99]"#), "{}", site.to_json());
    let binary = Site::from_bytes(&site.to_binary()).unwrap();
    assert_eq!(binary.calibration(), site.calibration());
    let out_of_range = calibrated.replace("0.99]", "1.5]");
    let err = Site::from_json(out_of_range.as_bytes()).unwrap_err().to_string();
    assert!(err.contains("calibration.floor_reliability[4]"), "{err}");
}

/// A version-4 file loads with no calibrated M; version 5 adds it
/// (`calibration.estimate_states`), kept through both encodings and written only when set.
#[test]
fn a_version_4_file_still_loads_and_version_5_adds_the_calibrated_m() {
    let site = Site::from_json(with_version(VERSION_1, 4).as_bytes()).unwrap();
    assert_eq!(site.calibration().estimate_states, None);
    assert!(!site.to_json().contains("estimate_states"));
    let calibrated = with_calibration(5, r#""estimate_states": 30"#);
    let site = Site::from_json(calibrated.as_bytes()).unwrap();
    assert_eq!(site.calibration().estimate_states, Some(30));
    assert!(site.to_json().contains(r#""estimate_states":30"#), "{}", site.to_json());
    assert_eq!(Site::from_bytes(&site.to_binary()).unwrap().calibration().estimate_states, Some(30));
    let zero = calibrated.replace(r#""estimate_states": 30"#, r#""estimate_states": 0"#);
    let err = Site::from_json(zero.as_bytes()).unwrap_err().to_string();
    assert!(err.contains("calibration.estimate_states"), "{err}");
}

/// A version-3 file loads with no reading-age limit; version 4 adds the survey's
/// (`radio.max_reading_age_ms`), kept through both encodings and written only when set.
#[test]
fn a_version_3_file_still_loads_and_version_4_adds_the_reading_age_limit() {
    let site = Site::from_json(with_version(VERSION_1, 3).as_bytes()).unwrap();
    assert_eq!(site.max_reading_age_ns(), None);
    assert!(!site.to_json().contains("max_reading_age_ms"));
    let aged = with_version(VERSION_1, 4)
        .replace(r#""clip_dbm": -100,"#, r#""clip_dbm": -100, "max_reading_age_ms": 2000,"#);
    let site = Site::from_json(aged.as_bytes()).unwrap();
    assert_eq!(site.max_reading_age_ns(), Some(2_000_000_000));
    assert!(site.to_json().contains(r#""max_reading_age_ms":2000"#), "{}", site.to_json());
    assert_eq!(Site::from_bytes(&site.to_binary()).unwrap().max_reading_age_ns(), Some(2_000_000_000));
    // Whole milliseconds, rounded up, so that no reading the limit kept is dropped on reload.
    let odd = site.with_max_reading_age_ns(Some(1_500_000_001));
    assert_eq!(Site::from_json(odd.to_json().as_bytes()).unwrap().max_reading_age_ns(), Some(1_501_000_000));
}

/// A version-2 file loads as before; the fields version 3 added (the anchor, floor levels and
/// origins) are absent from it and are written only when a site has them.
#[test]
fn a_version_2_file_still_loads_and_version_3_adds_the_geo_fields() {
    let site = Site::from_json(with_version(VERSION_1, 2).as_bytes()).unwrap();
    assert_eq!(site.to_json(), Site::from_json(VERSION_1.as_bytes()).unwrap().to_json());
    assert!(site.anchor().is_none() && site.floor_level(0).is_none());
    let geo = with_version(VERSION_1, 3).replace(
        r#""floors": [{"name": "G"}]"#,
        r#""anchor": {"lat_deg": 60.17, "lon_deg": 24.94}, "floors": [{"name": "G", "level": 0}]"#,
    );
    let site = Site::from_json(geo.as_bytes()).unwrap();
    assert_eq!((site.anchor().map(|a| a.lat_deg), site.floor_level(0)), (Some(60.17), Some(0)));
}

#[test]
fn a_version_1_file_still_loads_and_is_written_as_the_current_version() {
    let site = Site::from_json(VERSION_1.as_bytes()).unwrap();
    assert_eq!(site.states().len(), 2);
    assert_eq!(site.zones().len(), 1);
    let written = site.to_json();
    assert!(written.contains(&format!("\"format_version\":{FORMAT_VERSION}")), "{written}");
    assert_eq!(Site::from_json(written.as_bytes()).unwrap().to_json(), written);
    let current = Site::from_json(with_version(VERSION_1, u64::from(FORMAT_VERSION)).as_bytes()).unwrap();
    assert_eq!(current.to_json(), written);
}

#[test]
fn a_newer_json_file_is_refused_as_newer_format() {
    let newer = u64::from(FORMAT_VERSION) + 1;
    let expected = SiteError::NewerFormat { found: newer, supported: FORMAT_VERSION };
    assert_eq!(Site::from_json(with_version(VERSION_1, newer).as_bytes()).err(), Some(expected.clone()));
    // A field this build does not know: the version is named, not the field.
    let end = VERSION_1.rfind('}').unwrap();
    let unknown = format!("{}, \"levels\": {{\"elevator\": [7, 9]}}}}", &VERSION_1[..end]);
    assert_eq!(Site::from_json(with_version(&unknown, newer).as_bytes()).err(), Some(expected.clone()));
    let at_1 = Site::from_json(unknown.as_bytes()).unwrap_err();
    assert!(matches!(at_1, SiteError::Invalid { .. }) && at_1.to_string().contains("levels"), "{at_1}");
    // Far newer than a u32: still newer, through `Site::from_bytes` too.
    let far = with_version(&unknown, 1 << 40);
    assert_eq!(
        Site::from_bytes(far.as_bytes()).err(),
        Some(SiteError::NewerFormat { found: 1 << 40, supported: FORMAT_VERSION })
    );
    let message = expected.to_string();
    assert!(message.contains("newer format"), "{message}");
}

#[test]
fn a_version_before_the_first_is_unsupported() {
    assert_eq!(
        Site::from_json(with_version(VERSION_1, 0).as_bytes()).err(),
        Some(SiteError::UnsupportedVersion { found: 0, supported: FORMAT_VERSION })
    );
}

#[test]
fn a_newer_binary_file_is_refused_as_newer_format_and_a_version_1_one_loads() {
    let site = Site::from_json(VERSION_1.as_bytes()).unwrap();
    let binary = site.to_binary();
    assert_eq!(Site::from_bytes(&binary).unwrap().to_json(), site.to_json());
    let newer = binary_with_version(&binary, FORMAT_VERSION + 1);
    assert_eq!(
        Site::from_bytes(&newer).err(),
        Some(SiteError::NewerFormat { found: u64::from(FORMAT_VERSION) + 1, supported: FORMAT_VERSION })
    );
    let version_1 = binary_with_version(&binary, 1);
    assert_eq!(Site::from_bytes(&version_1).unwrap().to_json(), site.to_json());
}

/// A version-7 file loads with no floor-change rate; version 8 adds the survey's
/// (`calibration.floor_change_rate_hz`), kept through both encodings and written only when set.
#[test]
fn a_version_7_file_still_loads_and_version_8_adds_the_floor_change_rate() {
    let site = Site::from_json(with_version(VERSION_1, 7).as_bytes()).unwrap();
    assert_eq!(site.calibration().floor_change_rate_hz, None);
    assert!(!site.to_json().contains("floor_change_rate_hz"));
    let calibrated = with_calibration(8, r#""floor_change_rate_hz": 0.00015"#);
    let site = Site::from_json(calibrated.as_bytes()).unwrap();
    assert_eq!(site.calibration().floor_change_rate_hz, Some(0.00015));
    assert!(site.to_json().contains(r#""floor_change_rate_hz":0.00015"#), "{}", site.to_json());
    let binary = Site::from_bytes(&site.to_binary()).unwrap();
    assert_eq!(binary.calibration().floor_change_rate_hz, Some(0.00015));
    for bad in ["-0.1", "2"] {
        let refused = calibrated.replace("0.00015", bad);
        let err = Site::from_json(refused.as_bytes()).unwrap_err().to_string();
        assert!(err.contains("calibration.floor_change_rate_hz"), "{err}");
    }
    let newer = with_version(VERSION_1, 9);
    assert!(Site::from_json(newer.as_bytes()).is_err());
}
