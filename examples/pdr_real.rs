//! Pedestrian dead reckoning on real walks (Indoor Location Competition 2.0 format): per floor
//! directory and pooled, calibrates the step length and north on the SURVEY walks (sorted by
//! file name, index i with i % 5 ≠ 4) and scores the TEST walks (i % 5 == 4).
//!
//! ```text
//! cargo run --release --example pdr_real -- site1/B1/path_data_files site1/F1/path_data_files ...
//! ```
//!
//! On ILC 2.0 site 1 (`/work/main/target/ilc/site1/{B1,F1,F2,F3,F4}/path_data_files`, one
//! OPPO PBCM10 at 50 Hz) with the default `MotionConfig`, calibrated
//! on all 459 survey walks and scored on the 112 test walks: distance error mean 8.8 %,
//! median 5.7 %, pooled 0.5 %; heading RMSE 18.6°, median |error| 10.7° over 5 850 steps.
//! Per floor (each calibrated on its own survey walks), mean / pooled distance error and
//! heading RMSE: B1 11.0 % / 1.4 % / 19.0°, F1 5.2 % / 1.0 % / 17.5°, F2 10.0 % / 2.2 % /
//! 19.3°, F3 8.8 % / 0.4 % / 16.8°, F4 7.3 % / 1.0 % / 19.9°. The chosen step length model
//! is Kim's (k ≈ 0.47) everywhere: its leave-one-walk-out error on survey walks is 7.5 %
//! pooled, against 8.3 % for Weinberg, 9.8 % for a constant length and 9.6 % linear in
//! frequency. (Before Kim's model, the cadence check on a run's mean period and the step
//! from rest: test walks 10.8 % / 6.8 % / 0.5 %, survey walks 8.8 % with Weinberg.)
//!
//! What is left is mostly the walks' own step length, not their step counts: the error
//! falls with the waypoint path's length (short walks with few waypoints overshoot, and on
//! some the gyro shows the walker did not go straight between two waypoints, so the
//! polyline is shorter than the walk), and on walks without a pause it follows the walk's
//! apparent speed (path / duration), which the acceleration explains only in part.
//!
//! `WAYMARK_MOTION_CONFIG` may hold a `MotionConfig` as JSON (missing fields at their
//! defaults) to try other tracker settings. With `WAYMARK_PDR_WALKS=1` every test walk is
//! also listed (with the pooled calibration): waypoints, path, duration between the first
//! and last waypoint, steps counted there, distance, signed error, cadence and the longest
//! stretch without a step (missed steps, or a pause).

use std::path::{Path, PathBuf};
use waymark::eval::pdr::{evaluate_pdr, PdrReport};
use waymark::io::ilc::Trace;
use waymark::sensors::MotionConfig;
use waymark::survey::calibrate_motion;
use waymark::survey::motion::replay_steps;

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

/// One line per walk: what the tracker counted between the first and last waypoint.
fn walks(floor: &str, test: &[&Trace], config: &MotionConfig) {
    for trace in test {
        let (Some(first), Some(last)) = (trace.waypoints.first(), trace.waypoints.last()) else { continue };
        let (a, b) = (first.timestamp_ns, last.timestamp_ns);
        let (Some(steps), true) = (replay_steps(trace, config), b > a) else { continue };
        let times: Vec<u64> = steps.iter().map(|s| s.timestamp_ns).filter(|&t| t >= a && t <= b).collect();
        let distance: f64 =
            steps.iter().filter(|s| s.timestamp_ns >= a && s.timestamp_ns <= b).map(|s| s.length_m).sum();
        let path = trace.path_length_m();
        let span = (b - a) as f64 * 1e-9;
        let bounds: Vec<u64> =
            std::iter::once(a).chain(times.iter().copied()).chain(std::iter::once(b)).collect();
        let gap = bounds.windows(2).map(|w| (w[1] - w[0]) as f64 * 1e-9).fold(0.0, f64::max);
        println!(
            "{floor:<8} {:<25} {:>9} {path:>6.1} {span:>7.1} {:>5} {distance:>6.1} {:>+6.1} % {:>10.2} {gap:>13.1}",
            trace.name,
            trace.waypoints.len(),
            times.len(),
            100.0 * (distance - path) / path.max(1e-9),
            times.len() as f64 / span
        );
    }
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
    if std::env::var_os("WAYMARK_PDR_WALKS").is_some() {
        let (_, config) = calibrate(&survey);
        println!("floor    walk                      waypoints path_m  span_s steps dist_m  error  cadence_hz longest_gap_s");
        for (name, _, test) in &floors {
            walks(name, &test.iter().collect::<Vec<_>>(), &config);
        }
    }
    line("uncalib.", &evaluate_pdr(&test, &base));
}
