//! `waymark eval --survey-fraction F --unlabelled-rest` on a few of site1's F1 walks
//! (docs/evidence.md#refitting): the survey walks F leaves out come back without waypoints,
//! are anchored where the labelled site is sure of them and surveyed with the labelled walks,
//! and, with --evidence-rounds, their soft evidence refits the fingerprints. How much it helps
//! is measured by `waymark eval` on whole floors (docs/evidence.md#measured), not here. Skips,
//! saying so, when the data is not there (docs/testing.md#real-data).

use serde_json::Value;
use std::path::Path;
use std::process::Command;

fn eval(floor: &Path, extra: &[&str]) -> Value {
    let mut args = vec!["eval", floor.to_str().unwrap(), "--max-walks", "15", "--survey-fraction", "0.5"];
    args.extend_from_slice(&["--configurations", "forward-auto", "--threads", "2", "--json"]);
    args.extend_from_slice(extra);
    let out = Command::new(env!("CARGO_BIN_EXE_waymark")).args(&args).output().unwrap();
    assert!(out.status.success(), "waymark {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn unlabelled_walks_are_anchored_and_give_evidence() {
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let Some(floor) = waymark_eval::data::or_skip(waymark_eval::data::site1_floor(&workspace, "F1")) else {
        return;
    };
    // 15 walks: 12 survey walks, 6 kept with their waypoints and 6 given back without.
    let labelled = eval(&floor, &[]);
    assert!(labelled.get("evidence_rounds").is_none());
    let report = eval(&floor, &["--unlabelled-rest", "--evidence-rounds", "1"]);
    let rounds = report["evidence_rounds"].as_array().unwrap();
    assert_eq!(rounds.len(), 2, "one round of anchoring, one of soft evidence: {rounds:?}");
    let anchored = rounds[0]["walks"].as_u64().unwrap();
    assert!((1..=6).contains(&anchored), "{rounds:?}");
    // Anchored walks add states where the labelled ones did not go.
    assert!(rounds[0]["site_states"].as_u64().unwrap() >= labelled["states"].as_u64().unwrap());
    // Every unlabelled walk gives soft evidence.
    assert_eq!(rounds[1]["walks"], 6);
    assert!(rounds[1]["entries"].as_u64().unwrap() > 0 && rounds[1]["bytes"].as_u64().unwrap() > 0);
    assert_eq!(
        report["configurations"]["forward-auto"]["pooled"]["epochs"],
        labelled["configurations"]["forward-auto"]["pooled"]["epochs"]
    );
    // The flag gives back what --survey-fraction leaves out: without a fraction below 1, refused.
    let out = Command::new(env!("CARGO_BIN_EXE_waymark"))
        .args(["eval", floor.to_str().unwrap(), "--max-walks", "5", "--unlabelled-rest", "--json"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--survey-fraction"));
}

#[test]
fn waymark_survey_takes_walks_without_labels() {
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let Some(floor) = waymark_eval::data::or_skip(waymark_eval::data::site1_floor(&workspace, "F1")) else {
        return;
    };
    // A floor folder of F1's plan and first 8 walks; the next 4 walks without labels.
    let dir = tempfile::tempdir().unwrap();
    let (small, walks) = waymark_eval::data::floor_with_first_walks(&floor, dir.path(), 8).unwrap();
    let survey = |out: &str, unlabelled: &[std::path::PathBuf]| {
        let mut args: Vec<String> = vec!["survey".into(), small.to_string_lossy().into(), "--out".into()];
        args.push(dir.path().join(out).to_string_lossy().into());
        if !unlabelled.is_empty() {
            args.push("--unlabelled".into());
            args.extend(unlabelled.iter().map(|p| p.to_string_lossy().into_owned()));
        }
        let out = Command::new(env!("CARGO_BIN_EXE_waymark")).args(&args).output().unwrap();
        assert!(out.status.success(), "waymark {args:?}: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8(out.stdout).unwrap()
    };
    survey("labelled.json", &[]);
    let printed = survey("with.json", &walks[8..12]);
    assert!(printed.contains("of 4 walks without labels anchored"), "{printed}");
    let load = |name: &str| waymark_engine::Site::load(dir.path().join(name)).unwrap();
    assert!(load("with.json").states().len() >= load("labelled.json").states().len());
    // A walk that cannot be read fails the survey and writes nothing.
    let out = Command::new(env!("CARGO_BIN_EXE_waymark"))
        .args(["survey", small.to_str().unwrap(), "--out", dir.path().join("bad.json").to_str().unwrap()])
        .args(["--unlabelled", dir.path().join("missing.txt").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(!dir.path().join("bad.json").exists());
}

#[test]
fn one_phones_walks_are_given_without_labels_on_the_museum() {
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let Some(museum) = waymark_eval::data::or_skip(waymark_eval::data::ipin2023_t3(&workspace)) else {
        return;
    };
    // Trials 01-03: the SM-A520F's repetitions 1-2 survey; the SM-G930F's repetition 3 is
    // given without labels (or with them), its repetition 4 is scored.
    let run = |extra: &[&str]| {
        let mut args =
            vec!["eval", museum.to_str().unwrap(), "--split", "phone:SM-A520F", "--max-walks", "12"];
        args.extend_from_slice(&["--configurations", "forward-auto", "--threads", "2", "--json"]);
        args.extend_from_slice(extra);
        let out = Command::new(env!("CARGO_BIN_EXE_waymark")).args(&args).output().unwrap();
        assert!(out.status.success(), "waymark {args:?}: {}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice::<Value>(&out.stdout).unwrap()
    };
    let unlabelled = run(&["--test-as-unlabelled", "3"]);
    assert_eq!(unlabelled["test_walks"], 3);
    let anchored = unlabelled["evidence_rounds"][0]["walks"].as_u64().unwrap();
    assert!(anchored <= 3, "{anchored}");
    let labelled = run(&["--test-as-labelled", "3"]);
    assert_eq!(labelled["test_walks"], 3);
    assert!(labelled.get("evidence_rounds").is_none());
    let walks = |r: &Value| {
        r["survey"]["floors"].as_array().unwrap().iter().map(|f| f["walks"].as_u64().unwrap()).sum::<u64>()
    };
    assert_eq!(walks(&labelled), walks(&unlabelled) + 3);
}
