//! Diagnosis of the PDR distance error on ILC 2.0 walks (analysis, not part of the product):
//! writes one TSV row per walk (`walk` rows) and one per waypoint segment (`seg` rows), with
//! the step length calibrated on the pooled SURVEY walks (i % 5 ≠ 4), as `pdr_real`'s
//! "pooled" line.
//!
//! ```text
//! cargo run --release -p waymark-eval --example pdr_diag -- target/ilc/site1/{B1,F1,F2,F3,F4}/path_data_files > /tmp/diag.tsv
//! ```
//!
//! `walk` rows: waypoint path `L` (m), waypoints `nwp`, span `T` (s), steps inside `N` and in
//! the whole file `Nall`, estimated distance `est` (m), Σ Weinberg term `W`, mean period (s),
//! time from the first waypoint to the first step `lead` and from the last step to the last
//! waypoint `trail` (s), step gaps over 1.5 s (`pause` s, `npause`), Σ |turn| at waypoints and
//! Σ |heading change| between steps (°), shortest segment (m), first / last step and first /
//! last accelerometer sample relative to the first / last waypoint (s).
//! `seg` rows reuse the columns: `L` segment length, `nwp` its index, `T` its duration, `N`
//! its steps, `est` k · `W`, `pause` its time not covered by step periods (s), `turn_wp` the
//! turn at its first waypoint, `turn_steps` Σ |heading change| between its steps, `minseg`
//! the net displacement of its steps along their headings in Weinberg units.
//! `first` rows: the Weinberg term of steps 1-4 and the last over the walk's mean, and the
//! periods of steps 1-4.
//!
//! `WAYMARK_MOTION_CONFIG` may hold a `MotionConfig` as JSON, as for `pdr_real`.

use std::path::{Path, PathBuf};
use waymark_engine::sensors::{wrap_angle, MotionConfig, StepLengthModel};
use waymark_survey::calibrate_motion;
use waymark_survey::io::ilc::Trace;
use waymark_survey::motion::replay_steps;

fn read_floor(dir: &Path) -> Vec<(bool, Trace)> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "txt"))
        .collect();
    files.sort();
    files.iter().enumerate().filter_map(|(i, f)| Trace::read(f).ok().map(|t| (i % 5 == 4, t))).collect()
}

fn main() {
    let base: MotionConfig = std::env::var("WAYMARK_MOTION_CONFIG")
        .ok()
        .map(|j| serde_json::from_str(&j).unwrap())
        .unwrap_or_default();
    let mut walks: Vec<(String, bool, Trace)> = Vec::new();
    for d in std::env::args().skip(1) {
        let floor = Path::new(&d).parent().unwrap().file_name().unwrap().to_string_lossy().into_owned();
        for (test, t) in read_floor(Path::new(&d)) {
            walks.push((floor.clone(), test, t));
        }
    }
    let survey: Vec<&Trace> = walks.iter().filter(|w| !w.1).map(|w| &w.2).collect();
    let cal = calibrate_motion(&survey, &base).expect("calibration");
    let mut config = base.clone();
    cal.apply(&mut config);
    let k = match config.step_length {
        StepLengthModel::Weinberg { k } => k,
        _ => panic!("expected Weinberg"),
    };
    eprintln!("k = {k}");
    println!(
        "kind\tfloor\tname\ttest\tL\tnwp\tT\tN\tNall\test\tW\tperiod\tlead\ttrail\tpause\tnpause\tturn_wp\tturn_steps\tminseg\tfirst_all\tlast_all\tacc_first\tacc_last"
    );
    for (floor, test, t) in &walks {
        let Some(steps) = replay_steps(t, &config) else { continue };
        let w = &t.waypoints;
        if w.len() < 2 {
            continue;
        }
        let (t0, t1) = (w[0].timestamp_ns, w[w.len() - 1].timestamp_ns);
        let inside: Vec<_> = steps.iter().filter(|s| s.timestamp_ns >= t0 && s.timestamp_ns <= t1).collect();
        let l = t.path_length_m();
        let n = inside.len();
        let est: f64 = inside.iter().map(|s| s.length_m).sum();
        let wsum: f64 = inside.iter().map(|s| s.peak_to_peak_mps2.max(0.0).powf(0.25)).sum();
        let period = inside.iter().map(|s| s.period_s).sum::<f64>() / n.max(1) as f64;
        let s_ = |ns: u64| ns as f64 * 1e-9;
        let lead = inside.first().map_or(f64::NAN, |s| s_(s.timestamp_ns - t0));
        let trail = inside.last().map_or(f64::NAN, |s| s_(t1 - s.timestamp_ns));
        let (mut pause, mut npause) = (0.0, 0);
        for p in inside.windows(2) {
            let g = s_(p[1].timestamp_ns - p[0].timestamp_ns);
            if g > 1.5 {
                pause += g - period;
                npause += 1;
            }
        }
        let mut turn_wp = 0.0;
        let mut minseg = f64::INFINITY;
        let bearing = |a: usize| (w[a + 1].x - w[a].x).atan2(w[a + 1].y - w[a].y);
        for i in 0..w.len() - 1 {
            let len = (w[i + 1].x - w[i].x).hypot(w[i + 1].y - w[i].y);
            minseg = f64::min(minseg, len);
            if i > 0 {
                turn_wp += wrap_angle(bearing(i) - bearing(i - 1)).abs().to_degrees();
            }
        }
        let mut turn_steps = 0.0;
        for p in inside.windows(2) {
            if let (Some(a), Some(b)) = (p[0].heading_rad, p[1].heading_rad) {
                turn_steps += wrap_angle(b - a).abs().to_degrees();
            }
        }
        let first_all = steps.first().map_or(f64::NAN, |s| s_(s.timestamp_ns) - s_(t0));
        let last_all = steps.last().map_or(f64::NAN, |s| s_(s.timestamp_ns) - s_(t1));
        let acc_first = s_(t.accelerometer[0].timestamp_ns) - s_(t0);
        let acc_last = s_(t.accelerometer[t.accelerometer.len() - 1].timestamp_ns) - s_(t1);
        println!(
            "walk\t{floor}\t{}\t{}\t{l:.3}\t{}\t{:.2}\t{n}\t{}\t{est:.3}\t{wsum:.3}\t{period:.4}\t{lead:.2}\t{trail:.2}\t{pause:.2}\t{npause}\t{turn_wp:.1}\t{turn_steps:.1}\t{minseg:.2}\t{first_all:.2}\t{last_all:.2}\t{acc_first:.2}\t{acc_last:.2}",
            t.name,
            u8::from(*test),
            w.len(),
            s_(t1 - t0),
            steps.len()
        );
        // The Weinberg term of the first few steps of the walk against the walk's mean.
        let wt: Vec<f64> = inside.iter().map(|s| s.peak_to_peak_mps2.max(0.0).powf(0.25)).collect();
        if wt.len() >= 8 {
            let m = wt.iter().sum::<f64>() / wt.len() as f64;
            let p: Vec<f64> = inside.iter().map(|s| s.period_s).collect();
            println!(
                "first\t{floor}\t{}\t{}\t{:.3}\t{:.3}\t{:.3}\t{:.3}\t{:.3}\t{:.3}\t{:.3}\t{:.3}\t{:.3}",
                t.name,
                u8::from(*test),
                wt[0] / m,
                wt[1] / m,
                wt[2] / m,
                wt[3] / m,
                wt[wt.len() - 1] / m,
                p[0],
                p[1],
                p[2],
                p[3]
            );
        }
        for i in 0..w.len() - 1 {
            let (a, b) = (w[i].timestamp_ns, w[i + 1].timestamp_ns);
            let seg: Vec<_> = inside.iter().filter(|s| s.timestamp_ns >= a && s.timestamp_ns < b).collect();
            let len = (w[i + 1].x - w[i].x).hypot(w[i + 1].y - w[i].y);
            let ws: f64 = seg.iter().map(|s| s.peak_to_peak_mps2.max(0.0).powf(0.25)).sum();
            // Time inside the segment not covered by step periods (pauses or missed steps), s,
            // and the summed |heading change| between its steps, degrees.
            let covered: f64 = seg.iter().map(|s| s.period_s.min(1.0)).sum();
            let gap = s_(b - a) - covered;
            let mut wiggle = 0.0;
            for p in seg.windows(2) {
                if let (Some(x), Some(y)) = (p[0].heading_rad, p[1].heading_rad) {
                    wiggle += wrap_angle(y - x).abs().to_degrees();
                }
            }
            // Net displacement of the segment's steps (Weinberg units) along their headings.
            let (mut ex, mut ny) = (0.0, 0.0);
            for s in &seg {
                if let Some(h) = s.heading_rad {
                    let wv = s.peak_to_peak_mps2.max(0.0).powf(0.25);
                    ex += wv * h.sin();
                    ny += wv * h.cos();
                }
            }
            let net = ex.hypot(ny);
            let tin =
                if i > 0 { wrap_angle(bearing(i) - bearing(i - 1)).abs().to_degrees() } else { f64::NAN };
            println!(
                "seg\t{floor}\t{}\t{}\t{len:.3}\t{i}\t{:.2}\t{}\t0\t{:.3}\t{ws:.3}\t0\t0\t0\t{gap:.2}\t0\t{tin:.1}\t{wiggle:.1}\t{net:.3}\t0\t0\t0\t0",
                t.name,
                u8::from(*test),
                s_(b - a),
                seg.len(),
                k * ws
            );
        }
    }
}
