//! How far the anchors of walks given without labels lie from their truth
//! (docs/evidence.md#refitting): surveys and calibrates the site as `eval` does, then anchors
//! each walk given back (its waypoints withheld) as `--unlabelled-rest` does, and prints one
//! CSV row per walk with its anchors' distance from the walk's own ground truth at their
//! times.
//!
//! ```text
//! cargo run --release -p waymark-eval --example anchor_diag -- target/ipin/ipin2023-t3 \
//!   --split phone:SM-A520F --test-as-unlabelled 3 > anchors.csv
//! cargo run --release -p waymark-eval --example anchor_diag -- target/ilc/site1/F1 \
//!   --survey-fraction 0.5 > anchors.csv
//! ```
//!
//! Columns: `walk`, `anchors`, `wrong_floor` (anchors on another floor than the truth's, where
//! the walk's format gives the floor), `mean_m`, `p50_m`, `p90_m` (horizontal distance from the
//! truth at the anchor's time).

use std::path::PathBuf;
use std::sync::Arc;
use waymark_eval::real::EvalOptions;
use waymark_survey::calibrate::{
    anchored_walk, load_building, repetition, survey_calibrated, survey_subset, WalkSplit, ANCHOR_FLOOR_MASS,
};
use waymark_survey::io::ilc::Trace;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value = |flag: &str| args.iter().position(|a| a == flag).and_then(|i| args.get(i + 1)).cloned();
    // As `eval`'s default: floor folders split by file index.
    let split: WalkSplit = value("--split").unwrap_or("repetitions:1,3".into()).parse().expect("a split");
    let fraction: f64 = value("--survey-fraction").map_or(1.0, |f| f.parse().expect("a fraction"));
    let reps: Vec<u32> = value("--test-as-unlabelled")
        .map_or_else(Vec::new, |r| r.split(',').map(|x| x.parse().unwrap()).collect());
    let dirs: Vec<PathBuf> = args.iter().take_while(|a| !a.starts_with("--")).map(PathBuf::from).collect();
    let mut floors = load_building(&dirs, &split, None).expect("the building");
    // The walks given back: the survey walks F leaves out, or the test walks of `reps`.
    let mut given: Vec<(usize, Trace)> = Vec::new();
    for (f, floor) in floors.iter_mut().enumerate() {
        let keep = survey_subset(floor.survey.len(), fraction);
        let walks = std::mem::take(&mut floor.survey);
        for (i, walk) in walks.into_iter().enumerate() {
            if keep.binary_search(&i).is_ok() {
                floor.survey.push(walk);
            } else {
                given.push((f, walk));
            }
        }
        let tests = std::mem::take(&mut floor.test);
        for walk in tests {
            if repetition(&walk.name).is_some_and(|r| reps.contains(&r)) {
                given.push((f, walk));
            } else {
                floor.test.push(walk);
            }
        }
    }
    let options = EvalOptions::default().calibration;
    let (site, _, report) = survey_calibrated(&floors, &options, &|| {}).expect("the survey");
    let site = Arc::new(site);
    let spread_m = report.fingerprint_radius_m / 2.0;
    println!("walk,anchors,wrong_floor,mean_m,p50_m,p90_m");
    for (filed, truth) in &given {
        let blind = Trace { waypoints: Vec::new(), ..truth.clone() };
        let Ok(Some((floor, anchored))) = anchored_walk(&site, &blind, &options, spread_m, ANCHOR_FLOOR_MASS)
        else {
            println!("{},0,0,,,", truth.name);
            continue;
        };
        let mut errors = Vec::new();
        let mut wrong_floor = 0;
        for a in &anchored.waypoints {
            // The truth's floor: the waypoint's own where the format gives it, else the walk's.
            let k = truth.waypoints.partition_point(|w| w.timestamp_ns <= a.timestamp_ns).saturating_sub(1);
            let true_floor = truth.waypoints.get(k).and_then(|w| w.floor).unwrap_or(*filed);
            if true_floor != floor {
                wrong_floor += 1;
            }
            if let Some((x, y)) = truth.position_at(a.timestamp_ns) {
                errors.push((x - a.x).hypot(y - a.y));
            }
        }
        errors.sort_by(f64::total_cmp);
        let at = |q: f64| {
            errors.get(((errors.len() as f64 - 1.0) * q).round() as usize).copied().unwrap_or(f64::NAN)
        };
        let mean = errors.iter().sum::<f64>() / errors.len().max(1) as f64;
        println!(
            "{},{},{},{:.2},{:.2},{:.2}",
            truth.name,
            anchored.waypoints.len(),
            wrong_floor,
            mean,
            at(0.5),
            at(0.9)
        );
    }
}
