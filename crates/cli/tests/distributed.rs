//! Soft evidence made walk by walk and merged gives the survey's own site
//! (docs/evidence.md#at-scale): on a few of site1's F1 walks, `waymark survey --unlabelled
//! --anchor-rounds 0 --evidence-rounds 1` (one machine) and the labelled survey, `waymark
//! evidence collect` per walk on it, `waymark evidence merge` and `waymark survey --evidence`
//! (many machines) write the same bytes. Skips, saying so, when the data is not there
//! (docs/testing.md#real-data).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn waymark(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_waymark")).args(args).output().unwrap()
}

fn ok(args: &[&str]) -> String {
    let out = waymark(args);
    assert!(out.status.success(), "waymark {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

fn text(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn evidence_collected_per_walk_and_merged_refits_as_the_survey_does() {
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let Some(floor) = waymark_eval::data::or_skip(waymark_eval::data::site1_floor(&workspace, "F1")) else {
        return;
    };
    // A floor folder of F1's plan and first 6 walks; the next 3 walks without labels.
    let dir = tempfile::tempdir().unwrap();
    let at = |name: &str| dir.path().join(name);
    let (small, walks) = waymark_eval::data::floor_with_first_walks(&floor, dir.path(), 6).unwrap();
    let unlabelled: Vec<&str> = walks[6..9].iter().map(|p| text(p)).collect();

    // One machine: the survey gathers the walks' evidence on its labelled site itself.
    let one_site = at("one.json");
    let mut args = vec!["survey", text(&small), "--out", text(&one_site)];
    args.push("--unlabelled");
    args.extend(&unlabelled);
    args.extend(["--anchor-rounds", "0", "--evidence-rounds", "1"]);
    let printed = ok(&args);
    assert!(printed.contains("map evidence of 3 walks"), "{printed}");

    // Many machines: the labelled site, each walk's evidence on it, merged in two steps.
    ok(&["survey", text(&small), "--out", text(&at("site0.json"))]);
    let site0 = at("site0.json");
    let files: Vec<PathBuf> = (0..3).map(|k| at(&format!("walk{k}.wmev"))).collect();
    for (walk, file) in unlabelled.iter().zip(&files) {
        ok(&["evidence", "collect", "--site", text(&site0), "--out", text(file), walk]);
    }
    // Several walks at once into a folder give the same bytes as one by one.
    let folder = at("collected");
    let mut args = vec!["evidence", "collect", "--site", text(&site0), "--out-dir", text(&folder)];
    args.extend(&unlabelled);
    let printed = ok(&args);
    assert_eq!(printed.lines().count(), 3, "{printed}");
    for (walk, file) in walks[6..9].iter().zip(&files) {
        let stem = walk.file_stem().unwrap().to_str().unwrap();
        assert_eq!(std::fs::read(folder.join(format!("{stem}.wmev"))).unwrap(), std::fs::read(file).unwrap());
    }
    ok(&["evidence", "merge", "--out", text(&at("pair.wmev")), text(&files[2]), text(&files[0])]);
    ok(&["evidence", "merge", "--out", text(&at("merged.wmev")), text(&at("pair.wmev")), text(&files[1])]);
    let printed = ok(&[
        "survey",
        text(&small),
        "--evidence",
        text(&at("merged.wmev")),
        "--out",
        text(&at("many.json")),
    ]);
    assert!(printed.contains("map evidence of 3 walks"), "{printed}");
    let (one, many) = (std::fs::read(at("one.json")).unwrap(), std::fs::read(at("many.json")).unwrap());
    assert!(one == many, "the merged evidence's site differs from the survey's own");
    // And the evidence changed the labelled site.
    assert_ne!(one, std::fs::read(&site0).unwrap());

    // One --out takes one walk; a walk that cannot be read writes nothing.
    let collect_into = |out: &str, walks: &[&str]| {
        let out = at(out);
        let mut args = vec!["evidence", "collect", "--site", text(&site0), "--out", text(&out)];
        args.extend(walks);
        waymark(&args)
    };
    let out = collect_into("two.wmev", &unlabelled[..2]);
    assert!(!out.status.success() && String::from_utf8_lossy(&out.stderr).contains("--out-dir"));
    let missing = at("missing.txt");
    let out = collect_into("bad.wmev", &[text(&missing)]);
    assert!(!out.status.success());
    assert!(!at("bad.wmev").exists());
    // Evidence that is not an evidence file fails the survey before its calibration.
    let out = waymark(&["survey", text(&small), "--evidence", text(&site0), "--out", text(&at("bad.json"))]);
    assert!(!out.status.success());
    assert!(!at("bad.json").exists());
}
