//! `waymark evidence` (docs/evidence.md): files merged in any order give the same bytes, the
//! summary counts what they hold, and a damaged file, evidence of another site (the office at
//! another clip level) or an output that cannot be written fail with a message and leave no
//! partial output.

use std::path::Path;
use std::process::{Command, Output};
use waymark_engine::evidence::{Evidence, EvidenceError, TransmitterKey};
use waymark_engine::{Site, TransmitterId};
use waymark_sim::{Office, OfficeConfig};

fn waymark(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_waymark")).args(args).output().unwrap()
}

/// The simulated office (81 states), with few training scans; `clip_dbm` sets its clip level,
/// part of what evidence is of.
fn office(clip_dbm: f64) -> Site {
    Office::generate(&OfficeConfig { training_scans: 10, clip_dbm, ..OfficeConfig::default() }).site
}

/// One walk's evidence: ten scans at states `start`, `start + 1`, ... of the office, each
/// hearing three access points.
fn walk(site: &Site, start: u32) -> Evidence {
    let mut e = Evidence::new(site);
    let ap = |n: u8| TransmitterKey::of(&TransmitterId::wifi(&format!("02:00:00:00:00:{n:02x}")).unwrap());
    for k in 0..10 {
        let s = start + k;
        let readings = [(ap(1), -50.0 - f64::from(s)), (ap(2), -70.0), (ap(3 + (s % 2) as u8), -88.0)];
        e.add_scan(&[(s, 0.7), (s + 1, 0.3)], &readings, [true, false]).unwrap();
    }
    e.add_walk();
    e
}

fn write(dir: &Path, name: &str, e: &Evidence) -> String {
    let path = dir.join(name);
    std::fs::write(&path, e.to_bytes()).unwrap();
    path.to_string_lossy().into_owned()
}

#[test]
fn merged_in_any_order_the_bytes_are_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let site = office(-100.0);
    let files: Vec<String> =
        [0, 5, 12].iter().map(|&s| write(dir.path(), &format!("walk{s}.wmev"), &walk(&site, s))).collect();
    let out = |name: &str| dir.path().join(name).to_string_lossy().into_owned();
    let (forward, backward) = (out("forward.wmev"), out("backward.wmev"));
    let run = waymark(&["evidence", "merge", "--out", &forward, &files[0], &files[1], &files[2]]);
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let run = waymark(&["evidence", "merge", "--out", &backward, &files[2], &files[0], &files[1]]);
    assert!(run.status.success());
    let bytes = std::fs::read(&forward).unwrap();
    assert_eq!(bytes, std::fs::read(&backward).unwrap());
    // The library's own merge gives the same bytes.
    let mut merged = walk(&site, 0);
    merged.merge(&walk(&site, 5)).unwrap();
    merged.merge(&walk(&site, 12)).unwrap();
    assert_eq!(bytes, merged.to_bytes());
    let show = waymark(&["evidence", "show", "--json", &forward]);
    assert!(show.status.success());
    let summary: serde_json::Value = serde_json::from_slice(&show.stdout).unwrap();
    assert_eq!(summary["walks"], 3);
    assert_eq!(summary["site_states"], 81);
    assert_eq!(summary["transmitters"], 4);
    // Scans at states 0-10, 5-15 and 12-22: 23 states.
    assert_eq!(summary["states"], 23);
}

#[test]
fn bad_inputs_fail_and_leave_no_output() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (office(-100.0), office(-95.0));
    let good = write(dir.path(), "good.wmev", &walk(&a, 0));
    let other = write(dir.path(), "other.wmev", &walk(&b, 0));
    let out = dir.path().join("out.wmev");
    let out_arg = out.to_string_lossy().into_owned();
    // Evidence of another site.
    let run = waymark(&["evidence", "merge", "--out", &out_arg, &good, &other]);
    assert!(!run.status.success());
    assert!(
        String::from_utf8_lossy(&run.stderr).contains("cannot join"),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(!out.exists());
    // A file cut short.
    let bytes = std::fs::read(&good).unwrap();
    let cut = dir.path().join("cut.wmev");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let run = waymark(&["evidence", "merge", "--out", &out_arg, &good, &cut.to_string_lossy()]);
    assert!(!run.status.success());
    assert!(!out.exists());
    assert!(matches!(
        Evidence::from_bytes(&bytes[..bytes.len() / 2]),
        Err(EvidenceError::Truncated(_) | EvidenceError::Corrupt(_))
    ));
    // A folder that does not exist: nothing written, an error.
    let nowhere = dir.path().join("missing").join("out.wmev");
    let run = waymark(&["evidence", "merge", "--out", &nowhere.to_string_lossy(), &good]);
    assert!(!run.status.success());
    // An existing output is replaced whole, or kept when the merge fails.
    std::fs::write(&out, b"old").unwrap();
    let run = waymark(&["evidence", "merge", "--out", &out_arg, &good, &other]);
    assert!(!run.status.success());
    assert_eq!(std::fs::read(&out).unwrap(), b"old");
    let run = waymark(&["evidence", "merge", "--out", &out_arg, &good]);
    assert!(run.status.success());
    assert_eq!(std::fs::read(&out).unwrap(), bytes);
}
