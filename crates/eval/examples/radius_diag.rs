//! Why the radius factors the survey's calibration fits on held-out survey walks hold the
//! truth more or less often on the test walks: surveys and calibrates the site as `eval`
//! does, then replays every survey walk held out (on the site surveyed without it) and every
//! test walk (on the site of all survey walks), both with the engine as shipped but without
//! radius factors, steady and throttled, and prints one CSV row per scored epoch with what a
//! radius could be predicted from.
//!
//! ```text
//! FRACTION=0.25 cargo run --release -p waymark-eval --example radius_diag -- \
//!   target/ilc/site1/{B1,F1,F2,F3,F4} > rows.csv
//! ROW=ipin2023-t3/both-phones cargo run --release -p waymark-eval --example radius_diag > rows.csv
//! ```
//!
//! Columns: `set` (held: a held-out survey walk scored at each of its positions, as the
//! calibration scores them; test: a test walk scored at its WiFi scans, as `eval` does),
//! `throttled`, `floor`, `walk`, `error_m` (horizontal), `r68`, `r95` (the posterior's radii,
//! without factors or `beyond_radio_m`), `beyond_radio_m`, `scenario` (index in
//! `MotionScenario::ALL`), `fit` (radio fit of the latest scan), `band` (sparse band, -1 none),
//! `off_map_m` (how far the truth is beyond the map the walk was replayed on), `floor_ok`,
//! `states_8m` (fingerprinted states of the estimate's floor within 8 m of it), `lag_d` (how far
//! the fixed-lag estimate of the epoch `lag` epochs back lies from that epoch's live one: what
//! the engine knows at this epoch of how much later evidence moved it), `jump` (how far the live
//! estimate moved since the epoch before), `k` (the epoch's index in the walk), `floor_p` (the
//! posterior's mass on the estimate's floor: every replay runs without the site's floor
//! calibration, as without its radius factors, which the script applies), `walks_r` and
//! `scans_r` (the survey walks, and their WiFi scans, within the site's fingerprint radius of
//! the estimate on its floor, of those the replayed site was surveyed from: how much survey
//! the estimate's fingerprints rest on), `walks_4m` (the same walks within 4 m).

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use waymark_engine::site::{Calibration, StateKind};
use waymark_engine::{Engine, Position, ScanTiming, Site, TrackPoint};
use waymark_eval::real::EvalOptions;
use waymark_survey::calibrate::{parallel_map, survey_calibrated, survey_inputs, FloorData};
use waymark_survey::io::ilc::Trace;
use waymark_survey::replay::{replay, ReplayOptions};
use waymark_survey::PreparedSurvey;

/// Fingerprinted states per floor, and the radius of a cell.
struct Map {
    states: Vec<Vec<(f64, f64)>>,
    cell_m: f64,
}

impl Map {
    fn new(site: &Site, floors: usize) -> Map {
        let mut states = vec![Vec::new(); floors];
        for s in site.states().iter().filter(|s| s.kind != StateKind::Unsurveyed) {
            states[s.floor].push((s.position.x, s.position.y));
        }
        Map { states, cell_m: site.spacing_m() * std::f64::consts::FRAC_1_SQRT_2 + 1e-9 }
    }

    fn beyond_m(&self, floor: usize, (x, y): (f64, f64)) -> f64 {
        let nearest =
            self.states[floor].iter().map(|&(sx, sy)| (sx - x).hypot(sy - y)).fold(f64::INFINITY, f64::min);
        (nearest - self.cell_m).max(0.0)
    }

    fn within(&self, floor: usize, (x, y): (f64, f64), r: f64) -> usize {
        self.states
            .get(floor)
            .map_or(0, |s| s.iter().filter(|&&(sx, sy)| (sx - x).hypot(sy - y) <= r).count())
    }
}

/// Where each floor's survey walks scanned: (x, y, walk) per WiFi scan with a position.
struct Survey {
    scans: Vec<Vec<(f64, f64, usize)>>,
    radius_m: f64,
}

impl Survey {
    fn new(floors: &[FloorData], radius_m: f64) -> Survey {
        let scans = floors
            .iter()
            .map(|f| {
                f.survey
                    .iter()
                    .enumerate()
                    .flat_map(|(w, t)| {
                        t.wifi_scans
                            .iter()
                            .filter_map(move |s| t.position_at(s.timestamp_ns).map(|(x, y)| (x, y, w)))
                    })
                    .collect()
            })
            .collect();
        Survey { scans, radius_m }
    }

    /// Walks with a scan within `r` of `at`, walks and scans within the fingerprint radius;
    /// `left_out` (floor, walk) does not count.
    fn near(
        &self,
        floor: usize,
        (x, y): (f64, f64),
        left_out: Option<(usize, usize)>,
    ) -> (usize, usize, usize) {
        let (mut walks_r, mut walks_4m) =
            (std::collections::BTreeSet::new(), std::collections::BTreeSet::new());
        let mut scans_r = 0;
        for &(sx, sy, w) in self.scans.get(floor).map_or(&[][..], |v| &v[..]) {
            if left_out == Some((floor, w)) {
                continue;
            }
            let d = (sx - x).hypot(sy - y);
            if d <= self.radius_m {
                walks_r.insert(w);
                scans_r += 1;
            }
            if d <= 4.0 {
                walks_4m.insert(w);
            }
        }
        (walks_r.len(), scans_r, walks_4m.len())
    }
}

/// Rows of one replay: a held-out walk at each position's own time, as the calibration scores
/// it; a test walk, as `eval` scores it, at each WiFi scan with the latest position before it.
fn rows(
    set: &str,
    throttled: bool,
    floor: usize,
    trace: &Trace,
    positions: &[Position],
    (fixed_lag, lag): (&[TrackPoint], usize),
    (map, survey, left_out): (&Map, &Survey, Option<(usize, usize)>),
) -> Vec<String> {
    let lagged: HashMap<u64, (f64, f64)> = fixed_lag.iter().map(|t| (t.timestamp_ns, (t.x, t.y))).collect();
    let lag_d: Vec<f64> = (0..positions.len())
        .map(|k| {
            let Some(back) = k.checked_sub(lag) else { return f64::NAN };
            let p = &positions[back];
            lagged.get(&p.timestamp_ns).map_or(f64::NAN, |&(x, y)| (x - p.x).hypot(y - p.y))
        })
        .collect();
    let jump: Vec<f64> = (0..positions.len())
        .map(|k| {
            if k == 0 {
                f64::NAN
            } else {
                (positions[k].x - positions[k - 1].x).hypot(positions[k].y - positions[k - 1].y)
            }
        })
        .collect();
    // Per position: the latest scan's fit and the sparse band.
    let mut timing = ScanTiming::default();
    let mut fit = f64::NAN;
    let features: Vec<(f64, i64)> = positions
        .iter()
        .map(|p| {
            if p.radio_log_evidence.is_some() {
                timing = timing.after_scan(p.timestamp_ns);
            }
            if let Some(f) = p.radio_fit {
                fit = f;
            }
            (fit, timing.sparse_band(p.timestamp_ns).map_or(-1, |b| b as i64))
        })
        .collect();
    let instants: Vec<u64> = if set == "test" {
        trace.wifi_scans.iter().map(|s| s.timestamp_ns).collect()
    } else {
        positions.iter().map(|p| p.timestamp_ns).collect()
    };
    instants
        .into_iter()
        .filter_map(|t| {
            let truth = trace.position_at(t)?;
            let k = positions.partition_point(|p| p.timestamp_ns <= t).checked_sub(1)?;
            let p = &positions[k];
            let (fit, band) = features[k];
            let error = (p.x - truth.0).hypot(p.y - truth.1);
            let (walks_r, scans_r, walks_4m) = survey.near(p.floor, (p.x, p.y), left_out);
            Some(format!(
                "{set},{},{floor},{},{error:.3},{:.3},{:.3},{:.3},{},{fit:.4},{band},{:.3},{},{},{:.3},{:.3},{},{:.4},{walks_r},{scans_r},{walks_4m}",
                throttled as u8,
                trace.name,
                p.accuracy_m - p.beyond_radio_m,
                p.accuracy_95_m - p.beyond_radio_m,
                p.beyond_radio_m,
                p.scenario.index(),
                map.beyond_m(floor, truth),
                (p.floor == floor) as u8,
                map.within(p.floor, (p.x, p.y), 8.0),
                lag_d[k],
                jump[k],
                k,
                p.floor_probability,
            ))
        })
        .collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dirs: Vec<PathBuf> = std::env::args().skip(1).map(PathBuf::from).collect();
    let fraction: f64 = std::env::var("FRACTION").ok().and_then(|v| v.parse().ok()).unwrap_or(1.0);
    // `ROW=building/split` reads a benchmark row's floors instead of floor folders.
    let mut floors = match std::env::var("ROW") {
        Ok(name) => {
            let row = waymark_eval::benchmark::ROWS
                .iter()
                .find(|r| format!("{}/{}", r.building, r.split) == name)
                .ok_or_else(|| format!("no benchmark row {name}"))?;
            let source =
                waymark_eval::benchmark::DataSource { workspace: std::env::current_dir()?, max_walks: None };
            (row.load)(&source)?
        }
        Err(_) => dirs.iter().map(|d| FloorData::load(d, None)).collect::<Result<Vec<_>, _>>()?,
    };
    for f in &mut floors {
        f.keep_survey_fraction(fraction);
    }
    let mut options = EvalOptions::default();
    options.calibration.threads = 2;
    let (site, _, report) = survey_calibrated(&floors, &options.calibration, &|| {})?;
    eprintln!(
        "factors {:?} by scenario {:?} sparse {:?}",
        report.accuracy_scale, report.accuracy_scale_by_scenario, report.sparse_scans.calibration
    );
    let options = options.surveyed_with(&report);
    let weights: Vec<[Option<f64>; 2]> =
        report.floors.iter().map(|f| [f.rssi_weight, f.rssi_weight_without_movement]).collect();
    let unscaled = Calibration {
        accuracy_scale: None,
        accuracy_scale_by_scenario: Default::default(),
        sparse_scans: waymark_engine::site::SparseScans {
            accuracy_scale_by_since: Default::default(),
            floor_reliability: Default::default(),
            ..site.calibration().sparse_scans
        },
        floor_reliability: Default::default(),
        ..*site.calibration()
    };
    let engine_config = options.calibration.engine.clone();
    let steady = options.calibration.calibration_replay();
    let throttled = options.calibration.throttled_replay();
    // A walk's live positions, fixed-lag track and the device offset (mean, SD in dB) it ends with.
    type WalkRun = (Vec<Position>, Vec<TrackPoint>, (f64, f64));
    let run = |site: &Site, trace: &Trace, replay_options: &ReplayOptions| -> Option<WalkRun> {
        let replay_options = &ReplayOptions { fixed_lag: true, ..*replay_options };
        let site = site.clone().with_calibration(unscaled).ok()?.with_floor_rssi_weights(&weights).ok()?;
        let mut engine = Engine::new(Arc::new(site), engine_config.clone()).ok()?;
        let r = replay(&mut engine, trace, replay_options);
        Some((r.positions, r.fixed_lag, engine.device_offset().unwrap_or((f64::NAN, f64::NAN))))
    };
    // The rows of one walk on one site, steady and throttled.
    let survey = Survey::new(&floors, options.calibration.survey.fingerprint_radius_m);
    let both =
        |set: &str, site: &Site, f: usize, trace: &Trace, map: &Map, left_out: Option<(usize, usize)>| {
            let mut out = Vec::new();
            for (t, opts) in [(false, &steady), (true, &throttled)] {
                if let Some((p, fl, (offset, offset_sd))) = run(site, trace, opts) {
                    let lag = (&fl[..], engine_config.fixed_lag_epochs);
                    let walk = rows(set, t, f, trace, &p, lag, (map, &survey, left_out));
                    out.extend(walk.into_iter().map(|r| format!("{r},{offset:.2},{offset_sd:.2}")));
                }
            }
            out
        };
    println!(
        "set,throttled,floor,walk,error_m,r68,r95,beyond_radio_m,scenario,fit,band,off_map_m,floor_ok,states_8m,lag_d,jump,k,floor_p,walks_r,scans_r,walks_4m,offset_db,offset_sd_db"
    );
    // Held out.
    let inputs = survey_inputs(&floors);
    let prepared = PreparedSurvey::new("eval", &inputs, site.north(), &options.calibration.survey)?;
    let full = prepared.fit(&|_, _| true, None, 2);
    let jobs: Vec<(usize, usize)> =
        floors.iter().enumerate().flat_map(|(f, fl)| (0..fl.survey.len()).map(move |w| (f, w))).collect();
    let held = parallel_map(&jobs, 2, |&(f, w)| {
        let keep = |ff: usize, ww: usize| !(ff == f && ww == w);
        let fits = prepared.fit(&keep, Some(&full), 1);
        let Ok((held_site, _)) = prepared.assemble(&fits) else { return Vec::new() };
        both("held", &held_site, f, &floors[f].survey[w], &Map::new(&held_site, floors.len()), Some((f, w)))
    });
    for r in held.iter().flatten() {
        println!("{r}");
    }
    // Test walks, on the site of every survey walk.
    let map = Map::new(&site, floors.len());
    let tests: Vec<(usize, &Trace)> =
        floors.iter().enumerate().flat_map(|(f, fl)| fl.test.iter().map(move |t| (f, t))).collect();
    let test = parallel_map(&tests, 2, |&(f, trace)| both("test", &site, f, trace, &map, None));
    for r in test.iter().flatten() {
        println!("{r}");
    }
    Ok(())
}
