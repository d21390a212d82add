//! Pedestrian dead reckoning on real walks (Indoor Location Competition 2.0 format): per floor
//! directory and pooled, calibrates the step length and north on the SURVEY walks (sorted by
//! file name, index i with i % 5 ≠ 4) and scores the TEST walks (i % 5 == 4).
//!
//! ```text
//! cargo run --release -p waymark-eval --example pdr_real -- site1/B1/path_data_files site1/F1/path_data_files ...
//! ```
//!
//! The figures on the competition's site 1: `docs/tuning.md#step-detector`.
//!
//! `WAYMARK_MOTION_CONFIG` may hold a `MotionConfig` as JSON (missing fields at their
//! defaults) to try other tracker settings.

use std::path::{Path, PathBuf};
use waymark_engine::sensors::MotionConfig;
use waymark_eval::pdr::{evaluate_pdr, PdrReport};
use waymark_survey::calibrate_motion;
use waymark_survey::io::ilc::Trace;

fn read_floor(dir: &Path) -> (Vec<Trace>, Vec<Trace>) {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("cannot list {}: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "txt"))
        .collect();
    files.sort();
    let (mut survey, mut test) = (Vec::new(), Vec::new());
    for (i, file) in files.iter().enumerate() {
        match Trace::read(file) {
            Ok(t) if i % 5 == 4 => test.push(t),
            Ok(t) => survey.push(t),
            Err(e) => eprintln!("skipped: {e}"),
        }
    }
    (survey, test)
}

fn line(name: &str, r: &PdrReport) {
    println!(
        "{name:<8} test walks {:>3} (skipped {}) | distance error mean {:5.1} % median {:5.1} % pooled {:5.1} % \
         | zero-step walks {} | steps {:>5} | heading RMSE {:5.1}° median |e| {:5.1}° over {} steps",
        r.walks,
        r.skipped_walks,
        100.0 * r.distance_error,
        100.0 * r.median_distance_error,
        100.0 * r.pooled_distance_error,
        r.zero_step_walks,
        r.steps,
        r.heading_rmse_deg,
        r.heading_median_abs_deg,
        r.heading_samples
    );
}

fn main() {
    let base: MotionConfig = std::env::var("WAYMARK_MOTION_CONFIG")
        .ok()
        .map(|json| serde_json::from_str(&json).expect("WAYMARK_MOTION_CONFIG is a MotionConfig"))
        .unwrap_or_default();
    let dirs: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    if dirs.is_empty() {
        eprintln!("usage: pdr_real FLOOR_DIR...  (each holding ILC 2.0 walk .txt files)");
        std::process::exit(2);
    }
    let floors: Vec<(String, Vec<Trace>, Vec<Trace>)> = dirs
        .iter()
        .map(|d| {
            let name = d
                .components()
                .rev()
                .map(|c| c.as_os_str().to_string_lossy().into_owned())
                .find(|c| c != "path_data_files")
                .unwrap_or_default();
            let (survey, test) = read_floor(d);
            (name, survey, test)
        })
        .collect();
    let calibrate = |survey: &[&Trace]| {
        let calibration = calibrate_motion(survey, &base);
        let mut config = base.clone();
        if let Some(c) = &calibration {
            c.apply(&mut config);
        }
        (calibration, config)
    };
    let show = |name: &str, survey: &[&Trace], test: &[&Trace]| {
        let (calibration, config) = calibrate(survey);
        if let Some(c) = &calibration {
            let fits: Vec<String> = c
                .candidates
                .iter()
                .map(|f| format!("{:?} cv mean {:.1} %", f.model, 100.0 * f.mean_error))
                .collect();
            println!(
                "{name:<8} calibrated on {} survey walks ({} for distance, {} for heading): {:?}, \
                 heading offset {:+.1}° | {}",
                c.walks,
                c.distance_walks,
                c.heading_walks,
                c.step_length,
                c.heading_offset_rad.to_degrees(),
                fits.join("; ")
            );
        } else {
            println!("{name:<8} calibration failed; defaults used");
        }
        line(name, &evaluate_pdr(test, &config));
    };
    for (name, survey, test) in &floors {
        let survey: Vec<&Trace> = survey.iter().collect();
        let test: Vec<&Trace> = test.iter().collect();
        show(name, &survey, &test);
    }
    let survey: Vec<&Trace> = floors.iter().flat_map(|f| f.1.iter()).collect();
    let test: Vec<&Trace> = floors.iter().flat_map(|f| f.2.iter()).collect();
    show("pooled", &survey, &test);
    line("uncalib.", &evaluate_pdr(&test, &base));
}
