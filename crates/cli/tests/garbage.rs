//! Input that gives no result is a failure with a message that says what was read: a walk
//! `replay` cannot position at all, and survey walks none of which places a scan.

use std::path::Path;
use std::process::{Command, Output};

fn waymark(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_waymark")).args(args).output().unwrap()
}

fn path(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn a_walk_that_gives_no_position_fails_and_says_what_was_read() {
    let dir = tempfile::tempdir().unwrap();
    let export = waymark(&["sim-export", "--walk-length-m", "20", "--out", path(dir.path())]);
    assert!(export.status.success(), "{}", String::from_utf8_lossy(&export.stderr));
    let site = dir.path().join("site.json");
    let random: Vec<u8> = (0..4096u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8).collect();
    for (name, bytes) in [("empty.txt", Vec::new()), ("random.txt", random)] {
        let walk = dir.path().join(name);
        std::fs::write(&walk, bytes).unwrap();
        let run = waymark(&["replay", "--site", path(&site), path(&walk)]);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert!(!run.status.success(), "{name}: {stderr}");
        assert!(stderr.contains("no position") && stderr.contains("data lines read"), "{name}: {stderr}");
    }
}

#[test]
fn survey_walks_without_waypoints_are_named_as_the_cause() {
    let dir = tempfile::tempdir().unwrap();
    let floor = dir.path().join("F1");
    std::fs::create_dir(&floor).unwrap();
    let walk = "1000\tTYPE_ACCELEROMETER\t0.1\t0.2\t9.8\t3\n\
                1500\tTYPE_WIFI\tnet\tAA:BB:CC:DD:EE:01\t-50\t2412\t1500\n\
                2000\tTYPE_WAYPOINT\t1.0\t2.0\n";
    for k in 0..3 {
        std::fs::write(floor.join(format!("walk{k}.txt")), walk).unwrap();
    }
    let out = dir.path().join("site.json");
    let run = waymark(&["survey", path(&floor), "--out", path(&out)]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success(), "{stderr}");
    assert!(stderr.contains("no survey walk has a scan between two waypoints"), "{stderr}");
    assert!(stderr.contains("3 walks read, 0 with no waypoint, 3 with one"), "{stderr}");
    assert!(!out.exists());
}
