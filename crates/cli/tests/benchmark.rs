//! `waymark benchmark` through the binary, without the real data: rows whose data is absent are
//! skipped and said so (and a run of nothing but skipped rows fails), and two stored runs are
//! judged by the rule of docs/benchmark.md.

use serde_json::{json, Value};
use std::path::Path;
use std::process::{Command, Output};

/// Runs the CLI in `dir`, finding no data there nor in `WAYMARK_DATA`.
fn waymark(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_waymark"))
        .arg("benchmark")
        .args(args)
        .current_dir(dir)
        .env("WAYMARK_DATA", dir.join("no-data"))
        .output()
        .unwrap()
}

#[test]
fn rows_without_data_are_skipped_and_a_run_of_only_those_fails() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench.json");
    let run = waymark(dir.path(), &["--json", "--out", out.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(!run.status.success(), "every row skipped must fail: {stderr}");
    assert!(stderr.contains("skipped: ilc20-site1/B1 not found"), "{stderr}");
    let printed: Value = serde_json::from_slice(&run.stdout).unwrap();
    let written: Value = serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(printed, written);
    let rows = printed["rows"].as_array().unwrap();
    let names: Vec<String> = rows
        .iter()
        .map(|r| format!("{}/{}", r["building"].as_str().unwrap(), r["split"].as_str().unwrap()))
        .collect();
    assert_eq!(
        names,
        [
            "ilc20-site1/F=1",
            "ilc20-site1/F=0.5",
            "ipin2023-t3/A520F-surveys",
            "ipin2023-t3/G930F-surveys",
            "ipin2023-t3/both-phones"
        ]
    );
    assert!(rows.iter().all(|r| r["skipped"].is_string() && r.get("configurations").is_some()));
    assert_eq!((&printed["mean"], &printed["buildings"]), (&json!({}), &json!([])));

    // Only the rows asked for; an unknown one is refused before anything runs.
    let one = waymark(dir.path(), &["--json", "--rows", "ilc20-site1/F=0.5"]);
    let printed: Value = serde_json::from_slice(&one.stdout).unwrap();
    assert_eq!(printed["rows"].as_array().unwrap().len(), 1);
    let unknown = waymark(dir.path(), &["--rows", "ilc20-site1/F=2"]);
    let stderr = String::from_utf8_lossy(&unknown.stderr);
    assert!(!unknown.status.success() && stderr.contains("unknown row `ilc20-site1/F=2`"), "{stderr}");
}

/// A stored run: forward-auto's mean and SE per (building, split).
fn stored(dir: &Path, name: &str, rows: &[(&str, &str, f64, f64)]) -> String {
    let rows: Vec<Value> = rows
        .iter()
        .map(|&(building, split, mean_m, se)| {
            let figures = json!({
                "mean_m": mean_m, "p90_m": 2.0 * mean_m, "p75_m": 1.5 * mean_m,
                "accuracy_68_hit": 0.6, "accuracy_95_hit": 0.9, "floor_hit": 1.0,
                "mean_se_m": se, "epochs": 1000
            });
            json!({
                "building": building, "split": split, "survey_fraction": 1.0,
                "test_walks": 20, "seconds": 60.0,
                "configurations": { "forward-auto": figures }
            })
        })
        .collect();
    let path = dir.join(name);
    // `mean` and `buildings` as written; the comparison takes its means again from the rows.
    std::fs::write(&path, json!({ "rows": rows, "mean": {}, "buildings": [] }).to_string()).unwrap();
    path.to_str().unwrap().to_owned()
}

#[test]
fn two_stored_runs_are_judged_by_the_rule() {
    let dir = tempfile::tempdir().unwrap();
    let baseline = stored(dir.path(), "old.json", &[("a", "F=1", 4.0, 0.1), ("b", "x", 8.0, 0.2)]);
    let verdict = |current: &str| {
        let run = waymark(dir.path(), &["--baseline", &baseline, "--current", current]);
        assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
        let stdout = String::from_utf8(run.stdout).unwrap();
        stdout.lines().find(|l| l.starts_with("verdict on forward-auto")).unwrap_or_default().to_owned()
    };
    let better = stored(dir.path(), "better.json", &[("a", "F=1", 3.5, 0.1), ("b", "x", 8.1, 0.2)]);
    assert!(verdict(&better).contains(": keep"), "{}", verdict(&better));
    let worse = stored(dir.path(), "worse.json", &[("a", "F=1", 3.0, 0.1), ("b", "x", 8.3, 0.2)]);
    let line = verdict(&worse);
    assert!(line.contains("reject: b is worse by 0.300 m"), "{line}");
}
