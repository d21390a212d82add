//! `waymark bench`: speed and memory at building scale, printed as one JSON object.
//!
//! Every figure is measured here, in this process or a child it starts, on sites made by
//! [`waymark_sim::scale`]; the criterion benches in `crates/engine/benches/` time the same
//! operations with statistics.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;

use serde_json::{json, Value};
use waymark_engine::hmm::UniformReach;
use waymark_engine::sensors::{MotionConfig, MotionTracker, SensorSample};
use waymark_engine::site::ReachTable;
use waymark_engine::{Engine, EngineConfig, Site};
use waymark_sim::imu::{self, ImuConfig};
use waymark_sim::scale::{DenseForward, ScaleConfig, ScaleSite, SCALE_EPOCH_NS};
use waymark_sim::Trajectory;

#[derive(clap::Args)]
pub struct BenchArgs {
    /// Site sizes (states) to time one epoch on.
    #[arg(long, value_delimiter = ',', default_value = "1000,10000,50000")]
    states: Vec<usize>,
    /// Timed epochs per size, after `warm_up` untimed ones.
    #[arg(long, default_value_t = 200)]
    epochs: usize,
    /// Untimed epochs first, while the filter converges from the uniform prior.
    #[arg(long, default_value_t = 20)]
    warm_up: usize,
    /// Largest site the dense reference is timed on (it needs 8·N² bytes: 800 MB at 10 000).
    #[arg(long, default_value_t = 10_000)]
    dense_max_states: usize,
    /// The release cdylib to measure stripped; default: `libwaymark.so` beside this program.
    #[arg(long)]
    cdylib: Option<PathBuf>,
    /// Print only the JSON object (otherwise a table too, on stderr).
    #[arg(long)]
    json: bool,
    /// Measure only the raw IMU ingestion rate (for profiling it).
    #[arg(long)]
    ingest_only: bool,
    /// Measure only the load time and engine memory of the 10 000-state site, binary and JSON.
    #[arg(long)]
    load_only: bool,
    /// Write the site file of the first `--states` size here and stop (to profile loading it
    /// with `--rss-probe`): binary if the name ends in `.wmsite`, JSON otherwise.
    #[arg(long)]
    write_site: Option<PathBuf>,
    /// Internal: load this site file, run an engine on it and print its resident memory.
    #[arg(long, hide = true)]
    rss_probe: Option<PathBuf>,
    /// With `--rss-probe`: replay this recorded walk (ILC 2.0 text) on the engine instead, as
    /// an app would, the fixed-lag estimate asked after every epoch.
    #[arg(long, requires = "rss_probe")]
    probe_walk: Option<PathBuf>,
    /// With `--probe-walk`: the engine without its Viterbi track (`EngineConfig::track` off).
    #[arg(long, requires = "probe_walk")]
    probe_no_track: bool,
}

/// Size of the site whose load time and engine memory are measured.
const REFERENCE_STATES: usize = 10_000;

pub fn bench(args: &BenchArgs) -> ExitCode {
    if let Some(path) = &args.rss_probe {
        let config = EngineConfig { track: !args.probe_no_track, ..EngineConfig::default() };
        return rss_probe(path, args.probe_walk.as_deref(), config);
    }
    match run(args) {
        Ok(report) => {
            if !args.json {
                eprintln!("{}", serde_json::to_string_pretty(&report).unwrap_or_default());
            }
            println!("{report}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("waymark bench: {e}");
            ExitCode::FAILURE
        }
    }
}

fn percentile(values: &mut [f64], q: f64) -> f64 {
    values.sort_by(f64::total_cmp);
    if values.is_empty() {
        return f64::NAN;
    }
    values[((values.len() - 1) as f64 * q).round() as usize]
}

/// Time on this thread's CPU clock: one core's work, whatever else the machine runs.
type Clock = cpu_time::ThreadTime;

fn ms(start: Clock) -> f64 {
    start.elapsed().as_secs_f64() * 1e3
}

fn run(args: &BenchArgs) -> Result<Value, String> {
    if let Some(path) = &args.write_site {
        let n = args.states.first().copied().unwrap_or(REFERENCE_STATES);
        let scaled = ScaleSite::generate(&ScaleConfig { states: n, ..ScaleConfig::default() });
        let contents = if path.extension().is_some_and(|e| e == "wmsite") {
            Site::from_json(scaled.json.as_bytes()).map_err(|e| e.to_string())?.to_binary()
        } else {
            scaled.json.into_bytes()
        };
        std::fs::write(path, &contents).map_err(|e| format!("{}: {e}", path.display()))?;
        return Ok(json!({"site": path, "states": n, "bytes": contents.len()}));
    }
    if args.ingest_only {
        return Ok(json!({"ingest_samples_per_s": ingest_samples_per_s()?}));
    }
    let mut report = BTreeMap::<String, Value>::new();
    let mut epoch_p50 = BTreeMap::new();
    let mut epoch_p90 = BTreeMap::new();
    let mut dense_p50 = BTreeMap::new();
    let mut window = BTreeMap::new();
    let mut errors = BTreeMap::new();
    let mut engine_new = BTreeMap::new();
    let mut fingerprints = BTreeMap::new();
    let mut ratio = None;
    let mut sizes = if args.load_only { vec![] } else { args.states.clone() };
    if !sizes.contains(&REFERENCE_STATES) {
        sizes.push(REFERENCE_STATES);
    }
    sizes.sort_unstable();
    sizes.dedup();
    for &n in &sizes {
        let key = n.to_string();
        let scaled = ScaleSite::generate(&ScaleConfig { states: n, ..ScaleConfig::default() });
        fingerprints.insert(key.clone(), json!(scaled.fingerprints));
        let site = Arc::new(Site::from_json(scaled.json.as_bytes()).map_err(|e| e.to_string())?);
        if n == REFERENCE_STATES {
            // The binary encoding is what an app ships (`waymark site pack`); JSON is
            // reported beside it.
            let binary = site.to_binary();
            let (load_ms, rss) = load_and_probe(&binary, "site.wmsite")?;
            report.insert("site_load_ms".into(), json!(load_ms));
            report.insert("site_file_bytes".into(), json!(binary.len()));
            report.insert("engine_rss_mb".into(), rss["engine_rss_mb"].clone());
            report.insert("process_rss_before_site_mb".into(), rss["before_site_mb"].clone());
            let (load_ms, rss) = load_and_probe(scaled.json.as_bytes(), "site.json")?;
            report.insert("site_load_json_ms".into(), json!(load_ms));
            report.insert("site_json_bytes".into(), json!(scaled.json.len()));
            report.insert("engine_rss_json_mb".into(), rss["engine_rss_mb"].clone());
            report.insert("radio_map_bytes".into(), json!(site.radio().memory_bytes()));
            if args.load_only {
                return Ok(json!(report));
            }
        }
        let start = Clock::now();
        let mut engine =
            Engine::new(Arc::clone(&site), EngineConfig::default()).map_err(|e| e.to_string())?;
        engine_new.insert(key.clone(), json!(ms(start)));
        let walk = scaled.walk(args.warm_up + args.epochs, n as u64);
        let mut times = Vec::with_capacity(args.epochs);
        let mut errs = Vec::with_capacity(args.epochs);
        for (k, epoch) in walk.iter().enumerate() {
            let start = Clock::now();
            let position =
                engine.push_scan_with_motion(&epoch.scan, &epoch.motion).map_err(|e| e.to_string())?.position;
            let elapsed = ms(start);
            if k >= args.warm_up {
                times.push(elapsed);
                errs.push((position.x - epoch.truth.x).hypot(position.y - epoch.truth.y));
            }
        }
        let p50 = percentile(&mut times, 0.5);
        epoch_p50.insert(key.clone(), json!(p50));
        epoch_p90.insert(key.clone(), json!(percentile(&mut times, 0.9)));
        errors.insert(key.clone(), json!(percentile(&mut errs, 0.5)));
        window.insert(key.clone(), json!(engine.track_memory_bytes()));
        if !args.json {
            eprintln!("{n} states: epoch p50 {p50:.3} ms");
        }
        if n == REFERENCE_STATES {
            report.extend(habits_figures(&site, &engine, &walk, args.warm_up)?);
        }
        if n <= args.dense_max_states {
            let dense_ms = dense_epoch_ms(&site, &scaled, &walk[..walk.len().min(args.warm_up + 5)]);
            dense_p50.insert(key.clone(), json!(dense_ms));
            if n == REFERENCE_STATES {
                ratio = Some(dense_ms / p50);
            }
            if !args.json {
                eprintln!("{n} states: dense epoch {dense_ms:.1} ms");
            }
        }
    }
    report.insert("epoch_ms_p50".into(), json!(epoch_p50));
    report.insert("epoch_ms_p90".into(), json!(epoch_p90));
    report.insert("epoch_error_m_p50".into(), json!(errors));
    report.insert("engine_new_ms".into(), json!(engine_new));
    report.insert("fingerprint_entries".into(), json!(fingerprints));
    report.insert("dense_epoch_ms_p50".into(), json!(dense_p50));
    report.insert("dense_over_sparse_ratio".into(), json!(ratio));
    report.insert("track_window_bytes".into(), json!(window));
    report.insert("track_window_epochs".into(), json!(EngineConfig::default().track_window_epochs));
    report.insert("ingest_samples_per_s".into(), json!(ingest_samples_per_s()?));
    report.insert("cdylib_bytes".into(), json!(cdylib_bytes(args.cdylib.as_deref())));
    report.insert("heard_per_scan".into(), json!(ScaleConfig::default().heard));
    Ok(json!(report))
}

/// Habits at the reference size: the time `learn_habits` takes over the walk's history (at
/// most `history_epochs`), the model's size, and the epoch time with the learned moves applied
/// (forced on at strength 1: one walk is one segment, which a pass would not apply).
fn habits_figures(
    site: &Arc<Site>,
    walked: &Engine,
    walk: &[waymark_sim::scale::ScaleEpoch],
    warm_up: usize,
) -> Result<BTreeMap<String, Value>, String> {
    let records: Vec<_> = walked.history().iter().cloned().collect();
    let mut config = EngineConfig::default();
    config.habits.strength = Some(1.0);
    let mut engine = Engine::new(Arc::clone(site), config).map_err(|e| e.to_string())?;
    let start = Clock::now();
    let learned = engine.learn_habits_from(&[&records]).map_err(|e| e.to_string())?;
    let learn_ms = ms(start);
    let mut times = Vec::with_capacity(walk.len());
    for (k, epoch) in walk.iter().enumerate() {
        let start = Clock::now();
        engine.push_scan_with_motion(&epoch.scan, &epoch.motion).map_err(|e| e.to_string())?;
        if k >= warm_up {
            times.push(ms(start));
        }
    }
    let mut out = BTreeMap::new();
    out.insert("habits_learn_ms".into(), json!(learn_ms));
    out.insert("habits_learn_epochs".into(), json!(learned.epochs));
    out.insert("habits_learned_transitions".into(), json!(learned.learned_transitions));
    out.insert("habits_largest_segment_states".into(), json!(learned.largest_segment_states));
    out.insert("habits_json_bytes".into(), json!(engine.export_habits().len()));
    out.insert("epoch_ms_p50_with_habits".into(), json!(percentile(&mut times, 0.5)));
    Ok(out)
}

/// Median over the epochs after the warm-up of the dense forward step on the same site and
/// scans, with the reach transition of a 2 s epoch at 3 m/s.
fn dense_epoch_ms(site: &Site, _scaled: &ScaleSite, walk: &[waymark_sim::scale::ScaleEpoch]) -> f64 {
    let config = EngineConfig::default();
    let table = ReachTable::build(site, config.reach_radius_m);
    let transition = UniformReach {
        table: &table,
        rho_m: config.max_speed_mps * SCALE_EPOCH_NS as f64 * 1e-9,
        ratio: config.transition_ratio,
    };
    let mut dense = DenseForward::new(site, &transition);
    let mut times = Vec::new();
    for (k, epoch) in walk.iter().enumerate() {
        let start = Clock::now();
        let observations = site.radio().resolve(&epoch.scan, None).observations;
        dense.step(&observations);
        if k + 5 >= walk.len() {
            times.push(ms(start));
        }
    }
    percentile(&mut times, 0.5)
}

/// Writes the site file (`contents`, JSON or binary) as `name`, times `Site::load` (median of
/// 5, file in the page cache), and runs a child process that reports the resident memory of
/// an engine on it.
fn load_and_probe(contents: &[u8], name: &str) -> Result<(f64, Value), String> {
    let dir = std::env::temp_dir().join(format!("waymark-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let path = dir.join(name);
    std::fs::write(&path, contents).map_err(|e| e.to_string())?;
    let mut times = Vec::new();
    for _ in 0..5 {
        let start = Clock::now();
        let site = Site::load(&path).map_err(|e| e.to_string())?;
        times.push(ms(start));
        drop(site);
    }
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let output = std::process::Command::new(exe)
        .args(["bench", "--rss-probe"])
        .arg(&path)
        .output()
        .map_err(|e| format!("starting the memory probe: {e}"))?;
    let _ = std::fs::remove_dir_all(&dir);
    if !output.status.success() {
        return Err(format!("memory probe failed: {}", String::from_utf8_lossy(&output.stderr)));
    }
    let rss: Value =
        serde_json::from_slice(&output.stdout).map_err(|e| format!("memory probe output: {e}"))?;
    Ok((percentile(&mut times, 0.5), rss))
}

/// Resident set size of this process, MB (Linux `/proc/self/status`), or NaN elsewhere.
fn rss_mb(field: &str) -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with(field))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(f64::NAN, |kb| kb / 1024.0)
}

/// The child of [`load_and_probe`]: loads the site, starts an engine, runs 40 epochs of
/// noise-free scans made from the fingerprints of states along a row, and prints
/// `{"before_site_mb", "after_site_mb", "engine_rss_mb", "peak_mb"}`.
///
/// With `walk`, the engine replays that recorded walk instead, as an app would (sensor
/// batches, scans, a timer epoch after 2 s without one, the fixed-lag estimate after every
/// epoch). The walk is read before the engine is made, and `engine_rss_mb` is the resident
/// memory at the end less what reading it added (`walk_mb`), so that it compares with the
/// scan-only figure; the engine's own accounting of its track window and fixed-lag steps is
/// printed beside it.
fn rss_probe(path: &Path, walk: Option<&Path>, config: EngineConfig) -> ExitCode {
    match probe(path, walk, config) {
        Ok(report) => {
            println!("{report}");
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("{e}");
            ExitCode::FAILURE
        }
    }
}

fn probe(path: &Path, walk: Option<&Path>, config: EngineConfig) -> Result<Value, String> {
    use waymark_survey::io::Trace;
    use waymark_survey::replay::{replay, ReplayOptions};
    let before = rss_mb("VmRSS:");
    let site = Arc::new(Site::load(path).map_err(|e| e.to_string())?);
    let after_site = rss_mb("VmRSS:");
    let trace = walk.map(|w| Trace::read(w).map_err(|e| format!("{}: {e}", w.display()))).transpose()?;
    let walk_mb = if trace.is_some() { rss_mb("VmRSS:") - after_site } else { 0.0 };
    let mut engine = Engine::new(Arc::clone(&site), config).map_err(|e| e.to_string())?;
    let mut report = json!({"before_site_mb": before, "after_site_mb": after_site});
    match &trace {
        Some(trace) => {
            let options = ReplayOptions { fixed_lag: true, ..ReplayOptions::default() };
            let replayed = replay(&mut engine, trace, &options);
            report["walk_mb"] = json!(walk_mb);
            report["positions"] = json!(replayed.positions.len());
            report["track_window_mb"] = json!(engine.track_memory_bytes() as f64 / 1e6);
            report["fixed_lag_mb"] = json!(engine.fixed_lag_memory_bytes() as f64 / 1e6);
        }
        None => push_fingerprint_scans(&site, &mut engine),
    }
    report["engine_rss_mb"] = json!(rss_mb("VmRSS:") - walk_mb);
    report["peak_mb"] = json!(rss_mb("VmHWM:"));
    Ok(report)
}

/// The scan-only probe's 40 epochs: scans made from the fingerprints of states along a row.
fn push_fingerprint_scans(site: &Site, engine: &mut Engine) {
    let n = site.states().len();
    let mut by_state: Vec<Vec<(u32, f64)>> = vec![Vec::new(); n];
    let row: Vec<usize> = (0..40).map(|k| (n / 2 + k).min(n - 1)).collect();
    for (state, tx, g) in site.radio().fingerprints() {
        if row.contains(&(state as usize)) {
            by_state[state as usize].push((tx, g.mean_dbm));
        }
    }
    for (k, &s) in row.iter().enumerate() {
        let mut heard = std::mem::take(&mut by_state[s]);
        heard.sort_by(|a, b| b.1.total_cmp(&a.1));
        heard.truncate(ScaleConfig::default().heard);
        let scan = waymark_engine::Scan {
            timestamp_ns: (k as u64 + 1) * SCALE_EPOCH_NS,
            readings: heard
                .iter()
                .map(|&(tx, rssi)| waymark_engine::Reading {
                    transmitter: site.radio().transmitters()[tx as usize].clone(),
                    rssi_dbm: rssi.round(),
                    age_ns: 0,
                })
                .collect(),
        };
        let _ = engine.push_scan(&scan);
    }
}

/// Samples per second through the motion tracker (three sensors at 100 Hz, step detection and
/// the heading filter), fed in batches of 50 with an update every 2 s as the engine does;
/// median of 5 passes over a 10-minute simulated walk.
fn ingest_samples_per_s() -> Result<f64, String> {
    let points: Vec<nalgebra::Point2<f64>> = (0..40)
        .map(|k| nalgebra::Point2::new(if k % 2 == 0 { 0.0 } else { 30.0 }, 2.0 * (k / 2) as f64))
        .collect();
    let trajectory = Trajectory::new(1_000_000_000, 1.2, &points, Vec::new());
    let trace = imu::synthesize(&trajectory, &ImuConfig::default(), 7);
    let total = trace.accelerometer.len() + trace.gyroscope.len() + trace.magnetometer.len();
    let end_ns = trace.accelerometer.last().map_or(0, |s| s.timestamp_ns);
    let batches =
        |samples: &[SensorSample]| samples.chunks(50).map(<[SensorSample]>::to_vec).collect::<Vec<_>>();
    let (acc, gyro, mag) =
        (batches(&trace.accelerometer), batches(&trace.gyroscope), batches(&trace.magnetometer));
    let mut rates = Vec::new();
    for _ in 0..5 {
        let mut tracker = MotionTracker::new(MotionConfig::default()).map_err(|e| e.to_string())?;
        let mut next_update = 2 * SCALE_EPOCH_NS;
        let start = Clock::now();
        for k in 0..acc.len().max(gyro.len()).max(mag.len()) {
            for stream in [&acc, &gyro, &mag] {
                if let Some(batch) = stream.get(k) {
                    match stream {
                        s if std::ptr::eq(s, &acc) => tracker.push_accelerometer(batch),
                        s if std::ptr::eq(s, &gyro) => tracker.push_gyroscope(batch),
                        _ => tracker.push_magnetometer(batch),
                    };
                }
            }
            let t = acc.get(k).and_then(|b| b.last()).map_or(end_ns, |s| s.timestamp_ns);
            if t >= next_update {
                std::hint::black_box(tracker.update(t));
                next_update += SCALE_EPOCH_NS;
            }
        }
        std::hint::black_box(tracker.update(end_ns));
        rates.push(total as f64 / start.elapsed().as_secs_f64());
    }
    Ok(percentile(&mut rates, 0.5))
}

/// Bytes of the cdylib after `strip`, or null when there is none (build it first with
/// `cargo build --release --lib`; see `scripts/bench.sh`).
fn cdylib_bytes(given: Option<&Path>) -> Option<u64> {
    let path = match given {
        Some(p) => p.to_path_buf(),
        None => std::env::current_exe().ok()?.parent()?.join("libwaymark.so"),
    };
    let copy = std::env::temp_dir().join(format!("waymark-bench-{}.so", std::process::id()));
    std::fs::copy(&path, &copy).ok()?;
    let stripped = std::process::Command::new("strip").arg(&copy).status().ok()?.success();
    let bytes = std::fs::metadata(&copy).ok().map(|m| m.len());
    let _ = std::fs::remove_file(&copy);
    stripped.then_some(bytes).flatten()
}
