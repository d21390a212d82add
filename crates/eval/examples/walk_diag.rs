//! Per-walk look at the evaluation's configurations on recorded floors, much faster than the
//! full `eval`, which spends most of its time choosing the fingerprint radius and calibrating
//! γ and the radius factors by leave-one-walk-out: the site is surveyed from the survey walks
//! with the step length and north calibrated on them, but γ is given (`GAMMA`,
//! `GAMMA_WITHOUT`; by default 0.03 and 0.1, `docs/results.md#five-floors`). Prints, per configuration, the mean
//! error at the WiFi scans and the walks whose first estimate, and whose first scored scan, is
//! on a wrong floor; the paired
//! mean error by the scored scan's place in its walk (scans 1-2, 3-5, 6-10, 11-20, after 20);
//! the error along the walk's direction and across it, mean and rms; the error of the position
//! an app shows at every half second (the latest one);
//! the difference of consecutive configurations (in `CONFIGS` order) with its standard error
//! over walks; and one line per test walk. Errors do not depend on the radius factors, so the means
//! are those of the evaluation ([`waymark_eval::real`]) at the same γ and fingerprint radius (`FP_RADIUS`).
//!
//! ```text
//! CONFIGS=forward-distance,forward-heading-speed,forward-speed \
//!   cargo run --release -p waymark-eval --example walk_diag -- target/ilc/site1/{B1,F1,F2,F3,F4}
//! ```
//!
//! `BEACON_WAIT_MS` replays with another beacon wait (`EventOptions::beacon_wait_ns`).
//! `FP_RADIUS` surveys with that fingerprint radius, m (default the uncalibrated
//! `SurveyOptions` one; the evaluation calibrates it);
//! `ESTIMATE_STATES`, `MAX_SPEED`, `MOVEMENT_VAR`, `SPACING`, `MAX_STD` and `AGE_MS` set
//! `EngineConfig::estimate_states`, `max_speed_mps`, `MovementVectorConfig::movement_variance_m2`,
//! `SurveyOptions::spacing_m`, the fit's `max_std_db` and the reading-age limit (ms);
//! `RADIO_FIT_FLOOR` the site's `Calibration::radio_fit_floor` (none by default; the evaluation
//! calibrates it); `FRACTION` keeps that share of each floor's survey walks, as `eval
//! --survey-fraction` does; `THROTTLE` replays with one scan every 30 s, as `eval --throttle`
//! does (the sparse regime's own γ and radius factors aside, which the errors do not need when
//! the calibration records no sparse γ); `TIMER_MS` sets the replay's timer
//! (`ReplayOptions::timer_ns`).

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;
use waymark_engine::site::Calibration;
use waymark_eval::real::{evaluate_on, survey_site, EvalOptions};
use waymark_survey::calibrate::FloorData;
use waymark_survey::io::ilc::Trace;
use waymark_survey::scoring::{score_scans, Estimate};

/// The first scored scan (from 0) of each band the errors are averaged over by their place in
/// the walk: how much of the error is the start, before the posterior has settled.
const INDEX_BANDS: [usize; 5] = [0, 2, 5, 10, 20];

fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dirs: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    let mut floors = dirs.iter().map(|d| FloorData::load(d, None)).collect::<Result<Vec<_>, _>>()?;
    for f in &mut floors {
        f.keep_survey_fraction(env_or("FRACTION", 1.0));
    }
    let mut options = EvalOptions::default();
    options.calibration.replay.events.beacon_wait_ns =
        env_or("BEACON_WAIT_MS", options.calibration.replay.events.beacon_wait_ns / 1_000_000) * 1_000_000;
    // Unset: the site's calibrated M.
    options.calibration.engine.estimate_states =
        std::env::var("ESTIMATE_STATES").ok().and_then(|v| v.parse().ok());
    options.calibration.engine.max_speed_mps = env_or("MAX_SPEED", options.calibration.engine.max_speed_mps);
    options.calibration.engine.movement_vector.movement_variance_m2 =
        env_or("MOVEMENT_VAR", options.calibration.engine.movement_vector.movement_variance_m2);
    options.calibration.survey.spacing_m = env_or("SPACING", options.calibration.survey.spacing_m);
    options.calibration.survey.fingerprint_radius_m =
        env_or("FP_RADIUS", options.calibration.survey.fingerprint_radius_m);
    options.calibration.survey.build.fit.max_std_db =
        env_or("MAX_STD", options.calibration.survey.build.fit.max_std_db);
    if std::env::var("THROTTLE").is_ok() {
        options.calibration.replay = options.calibration.throttled_replay();
    }
    if let Ok(ms) = std::env::var("TIMER_MS").map(|v| v.parse::<u64>()) {
        options.calibration.replay.timer_ns = Some(ms? * 1_000_000);
    }
    options.calibration.survey.max_reading_age_ns =
        env_or("AGE_MS", options.calibration.survey.max_reading_age_ns / 1_000_000) * 1_000_000;
    let survey: Vec<&Trace> = floors.iter().flat_map(|f| &f.survey).collect();
    let motion = waymark_survey::calibrate_motion(&survey, &options.calibration.engine.motion)
        .ok_or("no motion calibration")?;
    options.calibration.north = motion.north();
    let configs: Vec<String> = env_or("CONFIGS", "forward-auto,viterbi-auto,wifi-knn".to_string())
        .split(',')
        .map(String::from)
        .collect();
    options.configurations = configs.clone();
    let (site, _) = survey_site(&floors, &options)?;
    let calibration = Calibration {
        rssi_weight: Some(env_or("GAMMA", 0.03)),
        rssi_weight_without_movement: Some(env_or("GAMMA_WITHOUT", 0.1)),
        step_length: Some(motion.step_length),
        radio_fit_floor: std::env::var("RADIO_FIT_FLOOR").ok().and_then(|v| v.parse().ok()),
        ..Calibration::default()
    };
    let site = Arc::new(site.with_calibration(calibration)?);
    let (reports, results) = evaluate_on(&site, &floors, &options, &|| ())?;
    let tests: Vec<(usize, &Trace)> =
        floors.iter().enumerate().flat_map(|(f, floor)| floor.test.iter().map(move |t| (f, t))).collect();
    // Per configuration and walk: (Σ error with the floor penalty, scans, first estimate off
    // floor, first scored scan off floor).
    let mut walks: BTreeMap<&str, Vec<(f64, usize, bool, bool)>> = BTreeMap::new();
    // Per configuration, by the scored scan's place in its walk: (Σ error, scans).
    let mut by_index: BTreeMap<&str, [(f64, usize); INDEX_BANDS.len()]> = BTreeMap::new();
    // Per configuration: each scored scan's error along and across the walk's direction, m.
    let mut along: BTreeMap<&str, Vec<(f64, f64)>> = BTreeMap::new();
    // Per configuration: the position shown every half second, (Σ error on the right floor,
    // samples on the right floor, samples).
    let mut shown: BTreeMap<&str, (f64, usize, usize)> = BTreeMap::new();
    for key in &configs {
        for (result, &(f, trace)) in results.iter().zip(&tests) {
            let estimates = result.estimates.get(key).map_or(&[][..], Vec::as_slice);
            let (scans, _) = score_scans(trace, f, estimates, None);
            let track = along.entry(key).or_default();
            for scan in &trace.wifi_scans {
                if let Some(e) = along_across(trace, f, estimates, scan.timestamp_ns) {
                    track.push(e);
                }
            }
            let dot = shown.entry(key).or_default();
            for (error, on_floor) in as_shown(trace, f, estimates) {
                dot.0 += error;
                dot.1 += usize::from(on_floor);
                dot.2 += 1;
            }
            let first_off = estimates.first().is_some_and(|e| e.floor != f);
            let first_scan_off = scans.first().is_some_and(|s| !s.floor_correct);
            let bands = by_index.entry(key).or_default();
            for (k, scan) in scans.iter().enumerate() {
                let band = INDEX_BANDS.iter().rposition(|&first| k >= first).unwrap_or(0);
                bands[band].0 += scan.penalised_m();
                bands[band].1 += 1;
            }
            let sum = scans.iter().map(|s| s.penalised_m()).sum();
            walks.entry(key).or_default().push((sum, scans.len(), first_off, first_scan_off));
        }
    }
    for key in &configs {
        let (r, w) = (&reports[key].pooled, &walks[key.as_str()]);
        let off = w.iter().filter(|x| x.2).count();
        let scan_off = w.iter().filter(|x| x.3).count();
        println!(
            "{key:<26} mean {:.3} m  floor hit {:.4}  scans {}  first estimate on a wrong floor in {off} of {} walks, first scored scan in {scan_off}",
            r.mean_m,
            r.floor_hit,
            r.epochs,
            w.len()
        );
    }
    for key in &configs {
        let bands: Vec<String> = (0..INDEX_BANDS.len())
            .map(|b| {
                let (sum, n) = by_index[key.as_str()][b];
                let scans = match INDEX_BANDS.get(b + 1) {
                    Some(next) => format!("{}-{next}", INDEX_BANDS[b] + 1),
                    None => format!("{}+", INDEX_BANDS[b] + 1),
                };
                format!("{scans} {:.2} m ({n})", sum / n.max(1) as f64)
            })
            .collect();
        println!("{key:<26} by scored scan of the walk: {}", bands.join(", "));
    }
    for key in &configs {
        let e = &along[key.as_str()];
        let n = e.len().max(1) as f64;
        let mean = |f: fn(&(f64, f64)) -> f64| e.iter().map(f).sum::<f64>() / n;
        let rms = |f: fn(&(f64, f64)) -> f64| (e.iter().map(|x| f(x).powi(2)).sum::<f64>() / n).sqrt();
        println!(
            "{key:<26} along the walk mean {:+.2} m (rms {:.2}), across {:+.2} m (rms {:.2}), over {} scans on the floor while walking",
            mean(|x| x.0),
            rms(|x| x.0),
            mean(|x| x.1),
            rms(|x| x.1),
            e.len()
        );
    }
    for key in &configs {
        let (sum, on_floor, n) = shown[key.as_str()];
        println!(
            "{key:<26} as shown every 0.5 s: mean {:.3} m on the walk's floor, there {:.4} of {n}",
            sum / on_floor.max(1) as f64,
            on_floor as f64 / n.max(1) as f64
        );
    }
    for pair in configs.windows(2) {
        let (a, b) = (&walks[pair[0].as_str()], &walks[pair[1].as_str()]);
        let n: usize = a.iter().map(|x| x.1).sum();
        let d: Vec<(f64, f64)> = a.iter().zip(b).map(|(x, y)| (x.0 - y.0, x.1 as f64)).collect();
        let delta = d.iter().map(|x| x.0).sum::<f64>() / n as f64;
        // Standard error of a ratio estimate, clustered by walk.
        let se = d.iter().map(|&(s, k)| (s - k * delta).powi(2)).sum::<f64>().sqrt() / n as f64;
        println!("{} − {}: {delta:+.3} ± {se:.3} m", pair[0], pair[1]);
    }
    for (w, &(f, trace)) in tests.iter().enumerate() {
        let mut line = format!("{} {:<26} {:5.0} m", floors[f].name, trace.name, trace.path_length_m());
        for key in &configs {
            let (sum, n, off, _) = walks[key.as_str()][w];
            line += &format!(
                " | {key} {:6.2} m over {n:3}{}",
                sum / n.max(1) as f64,
                if off { " first off floor" } else { "" }
            );
        }
        println!("{line}");
    }
    Ok(())
}

/// The error of the estimate scored at `t` along the walk's direction there (positive: ahead)
/// and across it (positive: to the left), m: `None` off the floor, or where the truth moves
/// less than 0.5 m in the 2 s around `t` (standing, or the direction is not known).
/// The position an app shows every half second from the walk's first estimate to its last
/// waypoint (the latest estimate then): its error against the truth then when on the walk's
/// `floor` (0 otherwise), and whether it is.
fn as_shown(trace: &Trace, floor: usize, estimates: &[Estimate]) -> Vec<(f64, bool)> {
    let (Some(first), Some(last)) = (estimates.first(), trace.waypoints.last()) else { return Vec::new() };
    (first.timestamp_ns..=last.timestamp_ns)
        .step_by(500_000_000)
        .filter_map(|t| {
            let e = &estimates[estimates.partition_point(|e| e.timestamp_ns <= t).checked_sub(1)?];
            let (x, y) = trace.position_at(t)?;
            let on_floor = e.floor == floor;
            Some((if on_floor { (e.x - x).hypot(e.y - y) } else { 0.0 }, on_floor))
        })
        .collect()
}

fn along_across(trace: &Trace, floor: usize, estimates: &[Estimate], t: u64) -> Option<(f64, f64)> {
    let k = estimates.partition_point(|e| e.timestamp_ns <= t).checked_sub(1)?;
    let e = estimates.get(k).filter(|e| e.floor == floor)?;
    let truth = trace.position_at(t)?;
    let (a, b) = (trace.position_at(t.checked_sub(1_000_000_000)?)?, trace.position_at(t + 1_000_000_000)?);
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let n = dx.hypot(dy);
    if n < 0.5 {
        return None;
    }
    let (ex, ey) = (e.x - truth.0, e.y - truth.1);
    Some(((ex * dx + ey * dy) / n, (ey * dx - ex * dy) / n))
}
