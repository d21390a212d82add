//! The verbs for recorded data: `survey`, `replay`, `eval`, and `site` for site files.

use indicatif::{ProgressBar, ProgressStyle};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;
use waymark_engine::sensors::MotionScenario;
use waymark_engine::{Engine, EngineConfig, Salt, Site};
use waymark_eval::real::{self as evaluation, EvalOptions, CONFIGURATIONS};
use waymark_survey::calibrate::{self, CalibrationOptions, FloorData, WalkSplit};
use waymark_survey::io::Trace;
use waymark_survey::replay::{self as replaying, ReplayOptions};

/// The environment variable that may hold the salt (hex) when no `--salt-file` is given.
pub const SALT_ENV: &str = "WAYMARK_SALT";

/// Where a site's salt comes from: a file, else the environment, never a command-line value
/// (it would land in the shell's history and in `ps`).
#[derive(clap::Args)]
pub struct SaltArgs {
    /// File holding the site's salt as hex digits (at least 32; `openssl rand -hex 32 > F`).
    /// Without it, the environment variable WAYMARK_SALT (hex) if set. Site files made with a
    /// salt hold salted hashes of the transmitter ids instead of MAC addresses and UUIDs.
    #[arg(long, value_name = "FILE")]
    salt_file: Option<PathBuf>,
}

impl SaltArgs {
    /// The salt, with where it came from; `None` when neither a file nor the variable gives one.
    pub fn salt(&self) -> Result<Option<(Salt, String)>, String> {
        let (text, source) = match &self.salt_file {
            Some(path) => (
                std::fs::read_to_string(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?,
                path.display().to_string(),
            ),
            None => match std::env::var(SALT_ENV) {
                Ok(text) if !text.trim().is_empty() => (text, format!("${SALT_ENV}")),
                _ => return Ok(None),
            },
        };
        Salt::from_hex(&text)
            .map(|salt| Some((salt, source.clone())))
            .map_err(|e| format!("salt from {source}: {e}"))
    }
}

#[derive(clap::Args)]
pub struct SurveyArgs {
    /// Floor folders of one building (each with `path_data_files/`, and `floor_info.json` +
    /// `geojson_map.json` if there is a plan), or one folder of GetSensorData logfiles. Every
    /// walk in them is a survey walk.
    #[arg(required = true)]
    floors: Vec<PathBuf>,
    /// Where to write the site file.
    #[arg(long)]
    out: PathBuf,
    /// The site's name.
    #[arg(long, default_value = "site")]
    name: String,
    /// Unsurveyed states (no fingerprint) fill walkable space this far beyond the surveyed
    /// states, m, for the estimate to follow the motion off the map (0: none; the site then
    /// loads in builds before unsurveyed states).
    #[arg(long, default_value_t = waymark_survey::UNSURVEYED_MARGIN_M)]
    unsurveyed_margin_m: f64,
    /// Also write where the held-out walks went beyond the map the other walks made, as
    /// GeoJSON points: the stretches to walk again. Needs every floor's plan (for WGS84), and
    /// fails at once without.
    #[arg(long)]
    coverage_out: Option<PathBuf>,
    #[command(flatten)]
    salt: SaltArgs,
}

#[derive(clap::Args)]
pub struct ReplayArgs {
    /// The site file (from `waymark survey`).
    #[arg(long)]
    site: PathBuf,
    /// The walk (a competition-format text file, or a GetSensorData logfile).
    walk: PathBuf,
    /// Where to write the track: `.json` for JSON, anything else CSV. Default: CSV on stdout.
    /// On a geo-referenced site (with an anchor) each row has `lat` and `lon`, WGS84 degrees.
    #[arg(long)]
    out: Option<PathBuf>,
    /// γ of Hoang eq. 14 (the radio likelihood's weight); default: the site's calibrated one.
    #[arg(long)]
    gamma: Option<f64>,
    /// The salt of a site whose transmitter ids are hashed.
    #[command(flatten)]
    salt: SaltArgs,
}

#[derive(clap::Args)]
pub struct SiteArgs {
    #[command(subcommand)]
    command: SiteCommand,
}

#[derive(clap::Subcommand)]
enum SiteCommand {
    /// Write a copy of a site file whose transmitter ids are salted hashes (HMAC-SHA256,
    /// 128 bits) instead of MAC addresses and UUIDs, for shipping inside an app.
    Hash {
        /// The site file with raw ids.
        input: PathBuf,
        /// Where to write the hashed site file.
        output: PathBuf,
        #[command(flatten)]
        salt: SaltArgs,
    },
    /// Write a site file (JSON or binary) in the binary encoding, what an app should ship: it
    /// loads several times faster than JSON and without the parser's garbage (see README,
    /// "Speed and memory").
    Pack {
        /// The site file.
        input: PathBuf,
        /// Where to write the binary site file (by convention `.wmsite`).
        output: PathBuf,
    },
    /// Write a site file (binary or JSON) as JSON, to read or diff it.
    Unpack {
        /// The site file.
        input: PathBuf,
        /// Where to write the JSON.
        output: PathBuf,
    },
    /// Say whether a site file's ids are hashed and, given a salt, whether it is the right one
    /// (exit status 1 if not).
    Check {
        /// The site file.
        site: PathBuf,
        #[command(flatten)]
        salt: SaltArgs,
    },
}

#[derive(clap::Args)]
pub struct EvalArgs {
    /// Floor folders of one building: given together, they make one multi-floor site and the
    /// engine must find the floor itself. Or one folder of GetSensorData logfiles (the IPIN
    /// competitions' format), split by `--split`.
    #[arg(required = true)]
    floors: Vec<PathBuf>,
    /// How a folder of GetSensorData logfiles splits into survey and test walks:
    /// `phone:MODEL` (that phone's walks survey), `repetitions:1,3` (those repetitions survey).
    /// Floor folders split by file index whatever this says.
    #[arg(long, default_value = "repetitions:1,3")]
    split: WalkSplit,
    /// Print one JSON object instead of the tables.
    #[arg(long)]
    json: bool,
    /// Draw each test walk (floor plan, truth, tracks) and the error CDFs as SVG into DIR.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Only these configurations (comma-separated keys); default all.
    #[arg(long, value_delimiter = ',')]
    configurations: Vec<String>,
    /// Use only the first N walk files of each floor (by name; the split applies after).
    #[arg(long)]
    max_walks: Option<usize>,
    /// Keep this share F (0 < F ≤ 1) of each floor's survey walks, the same ones on every run
    /// (walk i of the floor's survey walks by name when ⌈(i+1)·F⌉ > ⌈i·F⌉); the test walks do
    /// not change.
    #[arg(long, default_value_t = 1.0, value_parser = calibrate::parse_survey_fraction)]
    survey_fraction: f64,
    /// γ of Hoang eq. 14; default: calibrated by the survey.
    #[arg(long)]
    gamma: Option<f64>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Grid spacing of the surveyed states, m (default 2).
    #[arg(long)]
    spacing_m: Option<f64>,
    /// A survey scan trains the states within this distance, m (default: chosen by the
    /// survey's cross-validation, `FINGERPRINT_RADIUS_GRID`).
    #[arg(long)]
    fingerprint_radius_m: Option<f64>,
    /// Unsurveyed states (no fingerprint) fill walkable space this far beyond the surveyed
    /// states, m, for the estimate to follow the motion off the map (default 10; 0: none).
    #[arg(long)]
    unsurveyed_margin_m: Option<f64>,
    /// Readings older than this before their scan count as not heard, ms (default 2000).
    #[arg(long)]
    max_age_ms: Option<u64>,
    /// Smallest σ a fitted fingerprint may have, dB.
    #[arg(long)]
    min_std_db: Option<f64>,
    /// Also replay the test walks as a foreground app under Android 9+'s scan throttling (at
    /// most one scan every 30 s, 4 per 2 minutes, reaches the engine; timer epochs carry the
    /// motion between) on the same site: a second table (`throttled` in JSON)
    #[arg(long)]
    throttle: bool,
    /// Hoang's fixed Σ_v, without the tracker's own distance and heading spreads.
    #[arg(long)]
    fixed_movement_variance: bool,
    /// M of Hoang eq. 4: the most likely states averaged into the estimate.
    #[arg(long)]
    top_m: Option<usize>,
    /// Lag of the fixed-lag estimate, epochs.
    #[arg(long)]
    fixed_lag: Option<usize>,
    /// Ignore the floor plans' walls (the walkable graph then comes from the walks alone).
    #[arg(long)]
    no_plan: bool,
    /// Leave BLE beacons out (survey and replay).
    #[arg(long)]
    no_beacons: bool,
    /// Largest σ a fitted fingerprint may have, dB.
    #[arg(long)]
    max_std_db: Option<f64>,
    /// Also learn habits from the survey walks (their waypoints as the surveyor's feedback) and
    /// run every configuration again with them: the table compares the two.
    #[arg(long)]
    habits: bool,
    /// Strength of the applied habits, as a pseudo-count per reachable move (default: chosen
    /// on held-out survey walks).
    #[arg(long)]
    habit_strength: Option<f64>,
}

fn fail(verb: &str, e: impl std::fmt::Display) -> ExitCode {
    eprintln!("waymark {verb}: {e}");
    ExitCode::FAILURE
}

pub fn survey(args: &SurveyArgs) -> ExitCode {
    // Every walk surveys.
    let floors = match calibrate::load_building(&args.floors, &WalkSplit::All, None) {
        Ok(f) => f,
        Err(e) => return fail("survey", e),
    };
    // A coverage map needs WGS84, which only plans for every floor give: say so before the
    // calibration's minutes, not after.
    if args.coverage_out.is_some() {
        let plans: Vec<_> = floors.iter().map(|f| f.plan.as_ref()).collect();
        if waymark_survey::geo_reference(&plans).0.is_none() {
            let missing: Vec<&str> =
                floors.iter().filter(|f| f.plan.is_none()).map(|f| f.name.as_str()).collect();
            return fail(
                "survey",
                if missing.is_empty() {
                    "--coverage-out needs a geo-referenced site, and the plans give no place on the Earth"
                        .to_owned()
                } else {
                    format!(
                        "--coverage-out needs a geo-referenced site, which needs every floor's plan: none for {}",
                        missing.join(", ")
                    )
                },
            );
        }
    }
    let mut options = CalibrationOptions::default();
    options.survey.unsurveyed_margin_m = args.unsurveyed_margin_m;
    let bar = progress_bar(
        false,
        calibrate::calibration_steps(&floors, &options) as u64,
        "calibrating (leave one walk out)",
    );
    let (site, report, calibration) = match calibrate::survey_calibrated(&floors, &options, &|| bar.inc(1)) {
        Ok(s) => s,
        Err(e) => return fail("survey", e),
    };
    bar.finish_and_clear();
    let site = site.with_name(&args.name);
    let site = match args.salt.salt() {
        Err(e) => return fail("survey", e),
        Ok(None) => site,
        Ok(Some((salt, source))) => match site.hashed(&salt) {
            Ok(hashed) => {
                println!("transmitter ids hashed with the salt from {source}");
                hashed
            }
            Err(e) => return fail("survey", e),
        },
    };
    if let Err(e) = write_site(&args.out, &site) {
        return fail("survey", e);
    }
    if let Some(path) = &args.coverage_out {
        // Checked before the calibration; only a site that lost its anchor on the way fails here.
        let Some(geojson) = calibrate::coverage_geojson(&site, &calibration) else {
            return fail(
                "survey",
                format!("{} written, but it is not geo-referenced: no coverage map", args.out.display()),
            );
        };
        if let Err(e) = std::fs::write(path, geojson.to_string()) {
            return fail("survey", format!("{}: {e}", path.display()));
        }
        let points = geojson.features.len();
        println!(
            "coverage map: {points} held-out epochs beyond the others' map written to {}",
            path.display()
        );
    }
    for f in &report.floors {
        println!(
            "{:>4}: {} walks, {} scans → {} states and {} unsurveyed around them, {} edges ({} through walls the plan has, walked)",
            f.name, f.walks, f.scans, f.states, f.unsurveyed_states, f.edges, f.walked_edges
        );
    }
    print_calibration(&calibration);
    match site.anchor() {
        Some(a) => {
            let levels: Vec<String> = site
                .floors()
                .iter()
                .map(|f| format!("{} {}", f.name, f.level.map_or("-".into(), |l| l.to_string())))
                .collect();
            println!(
                "geo-referenced from the plans: origin {:.7}, {:.7}, scale {:.5} x {:.5}; levels {}",
                a.lat_deg,
                a.lon_deg,
                a.scale[0],
                a.scale[1],
                levels.join(", ")
            );
        }
        None => println!("not geo-referenced (a floor has no plan)"),
    }
    println!(
        "{} transmitters ({} radios send two or more); site written to {}",
        report.transmitters,
        report.shared_radios,
        args.out.display()
    );
    ExitCode::SUCCESS
}

/// The calibration: site-wide figures, then per floor the γ chosen by leave-one-walk-out, its
/// jackknife standard error, and the error curve over γ with how many walks prefer each γ.
fn print_calibration(c: &calibrate::CalibrationReport) {
    println!(
        "calibrated: γ {:?} site-wide (without movement {:?}), accuracy scales {:?}, step length {:?}, heading offset {:.1}°",
        c.rssi_weight,
        c.rssi_weight_without_movement,
        c.accuracy_scale,
        c.motion.as_ref().map(|m| m.step_length),
        c.motion.as_ref().map_or(0.0, |m| m.heading_offset_deg)
    );
    let radius_curve: Vec<String> =
        c.fingerprint_radius_mean_error_m.iter().map(|(r, e, _)| format!("{r:.1} m: {e:.2}")).collect();
    println!(
        "fingerprint radius {:.1} m{}",
        c.fingerprint_radius_m,
        if radius_curve.is_empty() {
            " (given)".to_string()
        } else {
            format!(" by 5-fold held-out engine error at each radius's best γ | {}", radius_curve.join(", "))
        }
    );
    for (name, scenario) in
        [("distance only", MotionScenario::Distance), ("heading only", MotionScenario::HeadingSpeed)]
    {
        let Some(curve) = c.gamma_by_scenario.get(scenario) else { continue };
        let curve: Vec<String> = curve
            .iter()
            .map(|p| format!("{}: {:.2} ± {:.2}", p.gamma, p.mean_error_m, p.jackknife_se_m))
            .collect();
        println!(
            "γ {name}: {} | {}",
            c.rssi_weight_by_scenario.get(scenario).map_or("as without movement".into(), |g| g.to_string()),
            curve.join(", ")
        );
    }
    println!(
        "γ per floor by leave-one-walk-out ({} sites, {:.0}% of states refitted per site); mean held-out error, m, at each γ (walks preferring it):",
        c.sites,
        100.0 * c.refitted_share
    );
    for f in &c.floors {
        let curve: Vec<String> = f
            .gamma
            .iter()
            .map(|p| format!("{}: {:.2} ({})", p.gamma, p.mean_error_m, p.walks_preferring))
            .collect();
        println!(
            "{:>4}: best γ {} ± {:.2} m, recorded {} (without movement {}), {} walks, {} epochs | {}",
            f.name,
            f.best_rssi_weight.map_or("-".into(), |g| g.to_string()),
            f.jackknife_se_m.unwrap_or(f64::NAN),
            f.rssi_weight.map_or("site-wide".into(), |g| g.to_string()),
            f.rssi_weight_without_movement.map_or("site-wide".into(), |g| g.to_string()),
            f.walks,
            f.epochs,
            curve.join(", ")
        );
    }
    println!("coverage: held-out epochs beyond the map the floor's other walks make (docs/surveying.md#is-the-survey-enough):");
    for f in &c.floors {
        let cov = &f.coverage;
        if cov.epochs == 0 {
            println!("{:>4}: no held-out epochs (a floor needs two walks or more)", f.name);
            continue;
        }
        let mean = |m: f64| if m.is_finite() { format!("{m:.2} m") } else { "-".into() };
        println!(
            "{:>4}: {:.0}% of {} (mean error {} on that map, {} beyond it)",
            f.name,
            100.0 * cov.beyond_map_share(),
            cov.epochs,
            mean(cov.mean_error_on_map_m),
            mean(cov.mean_error_beyond_map_m)
        );
    }
    let bands = |r: &calibrate::OffMapReport| -> String {
        let bands: Vec<String> = r
            .bands
            .iter()
            .map(|b| {
                let range =
                    if b.to_m == 0.0 { "on the map".into() } else { format!("{}-{} m", b.from_m, b.to_m) };
                format!(
                    "{range}: {} epochs, mean {:.2} m, 68% radius holds {:.2}, 95% {:.2}",
                    b.epochs, b.mean_error_m, b.accuracy_68_hit, b.accuracy_95_hit
                )
            })
            .collect();
        bands.join("; ")
    };
    let candidates: Vec<String> = (c.radio_fit_floor_mean_error_m.iter())
        .map(|(share, floor, error)| format!("{:.0}%: {floor:.2} nats, {error:.2} m", 100.0 * share))
        .collect();
    println!(
        "radio fit floor {} nats per radio heard (the {} quantile of the fits of {} held-out scans on the map, of least held-out error as shipped among {}); held-out walks replayed as shipped:",
        c.radio_fit_floor.map_or("-".into(), |f| format!("{f:.2}")),
        c.radio_fit_floor_share.map_or("-".into(), |s| format!("{:.0}%", 100.0 * s)),
        c.radio_fit_scans,
        candidates.join(", ")
    );
    println!("  {}", bands(&c.on_map));
    println!("  beyond the held-out map, by distance beyond it | {}", bands(&c.off_map));
    println!("  the same without the radio fit floor | {}", bands(&c.off_map_without_floor));
    let sparse = &c.sparse_scans;
    let curve: Vec<String> = sparse
        .gamma
        .iter()
        .map(|p| format!("{}: {:.2} ± {:.2}", p.gamma, p.mean_error_m, p.jackknife_se_m))
        .collect();
    let edges = waymark_engine::site::SINCE_SPARSE_SCAN_BANDS_S;
    let factors: Vec<String> = (0..=edges.len())
        .map(|band| {
            let from = band.checked_sub(1).map_or(0.0, |b| edges[b]);
            let range = edges.get(band).map_or(format!("over {from} s"), |to| format!("{from}-{to} s"));
            let scale = sparse.calibration.accuracy_scale_by_since[band]
                .map_or("-".into(), |[a, b]| format!("{a:.2}/{b:.2}"));
            format!("{range}: {scale} ({} epochs)", sparse.epochs_by_since[band])
        })
        .collect();
    println!(
        "sparse scans (held-out walks with one scan every 30 s): γ {} | {}",
        sparse.calibration.rssi_weight.map_or("site-wide".into(), |g| g.to_string()),
        curve.join(", ")
    );
    println!("  radius factors 68%/95% by time since the sparse scan | {}", factors.join(", "));
    let floor_table = |r: &calibrate::FloorReliabilityReport| -> String {
        let edges = waymark_engine::site::FLOOR_MISS_BANDS.map(|miss| 1.0 - miss);
        let bands: Vec<String> = (r.epochs_right_by_band.iter().enumerate())
            .map(|(band, [right, all])| {
                let from = band.checked_sub(1).map_or("0".into(), |b| edges[b].to_string());
                let to = edges.get(band).map_or("1".into(), f64::to_string);
                let share = r.calibration.0[band].map_or("-".into(), |p| format!("{p:.3}"));
                format!("{from}-{to}: {share} ({right} of {all} right)")
            })
            .collect();
        bands.join(", ")
    };
    if !c.floor_reliability.calibration.is_empty() || !sparse.floor_reliability.calibration.is_empty() {
        println!("floor probability reported, by the posterior's mass on the floor, on held-out epochs on the map:");
        println!("  steady scans | {}", floor_table(&c.floor_reliability));
        println!("  sparse scans | {}", floor_table(&sparse.floor_reliability));
    }
}

pub fn replay(args: &ReplayArgs) -> ExitCode {
    let site = match Site::load(&args.site) {
        Ok(s) => Arc::new(s),
        Err(e) => return fail("replay", e),
    };
    let trace = match waymark_survey::io::read_walk(&args.walk, &site) {
        Ok(t) => t,
        Err(e) => return fail("replay", e),
    };
    let site_salt = match args.salt.salt() {
        Ok(salt) => salt.map(|(salt, _)| salt),
        Err(e) => return fail("replay", e),
    };
    // The engine as an app runs it, which is the one `eval` runs: stale readings dropped at
    // the age limit the site's survey applied.
    let config = EngineConfig { rssi_weight: args.gamma, site_salt, ..EngineConfig::default() };
    let mut engine = match Engine::new(Arc::clone(&site), config) {
        Ok(e) => e,
        Err(e) => return fail("replay", e),
    };
    let replay = replaying::replay(&mut engine, &trace, &ReplayOptions::default());
    if replay.positions.is_empty() {
        // Input that gave no result is a failure, with what was read (docs/errors.md#the-command-line).
        let s = &trace.stats;
        return fail(
            "replay",
            format!(
                "{}: no position: {} data lines read, {} malformed, {} of types Waymark does not use; \
                 {} scans ({} rejected), {} accelerometer samples",
                args.walk.display(),
                s.lines,
                s.malformed,
                s.ignored,
                trace.wifi_scans.len(),
                replay.rejected_scans,
                trace.accelerometer.len()
            ),
        );
    }
    let floor_name = |f: usize| site.floors().get(f).map_or("?", |fl| fl.name.as_str()).to_owned();
    let json = args.out.as_ref().is_some_and(|p| p.extension().is_some_and(|e| e == "json"));
    let text = if json {
        let rows: Vec<serde_json::Value> = replay
            .positions
            .iter()
            .map(|p| {
                let geo = site.lat_lon(p.floor, p.x, p.y);
                serde_json::json!({
                    "timestamp_ms": p.timestamp_ns / 1_000_000,
                    "floor": floor_name(p.floor),
                    "floor_level": site.floor_level(p.floor),
                    "x": p.x, "y": p.y,
                    "lat": geo.map(|g| g.lat_deg), "lon": geo.map(|g| g.lon_deg),
                    "accuracy_m": p.accuracy_m, "accuracy_95_m": p.accuracy_95_m,
                    "heading_deg": p.heading_rad.map(f64::to_degrees),
                    "scenario": p.scenario, "motion_state": p.motion_state, "steps": p.steps,
                })
            })
            .collect();
        serde_json::to_string_pretty(&rows).unwrap_or_default()
    } else {
        // lat and lon to 1e-8° (about a millimetre), empty on a site without an anchor.
        let mut csv = String::from(
            "timestamp_ms,floor,floor_level,x,y,lat,lon,accuracy_m,accuracy_95_m,heading_deg,scenario,motion_state,steps\n",
        );
        for p in &replay.positions {
            let geo = site.lat_lon(p.floor, p.x, p.y);
            csv += &format!(
                "{},{},{},{:.2},{:.2},{},{},{:.2},{:.2},{},{:?},{:?},{}\n",
                p.timestamp_ns / 1_000_000,
                floor_name(p.floor),
                site.floor_level(p.floor).map_or(String::new(), |l| l.to_string()),
                p.x,
                p.y,
                geo.map_or(String::new(), |g| format!("{:.8}", g.lat_deg)),
                geo.map_or(String::new(), |g| format!("{:.8}", g.lon_deg)),
                p.accuracy_m,
                p.accuracy_95_m,
                p.heading_rad.map_or(String::new(), |h| format!("{:.1}", h.to_degrees())),
                p.scenario,
                p.motion_state,
                p.steps
            );
        }
        csv
    };
    match &args.out {
        Some(path) => {
            if let Err(e) = std::fs::write(path, text) {
                return fail("replay", format!("cannot write {}: {e}", path.display()));
            }
            eprintln!(
                "{} epochs ({} scans rejected) written to {}",
                replay.positions.len(),
                replay.rejected_scans,
                path.display()
            );
        }
        None => print!("{text}"),
    }
    ExitCode::SUCCESS
}

/// Writes a site file: binary if the name ends in `.wmsite`, JSON otherwise.
fn write_site(path: &std::path::Path, site: &Site) -> Result<(), String> {
    let contents = if path.extension().is_some_and(|e| e == "wmsite") {
        site.to_binary()
    } else {
        site.to_json().into_bytes()
    };
    std::fs::write(path, contents).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

pub fn site(args: &SiteArgs) -> ExitCode {
    match &args.command {
        SiteCommand::Hash { input, output, salt } => {
            let salt = match salt.salt() {
                Ok(Some((salt, _))) => salt,
                Ok(None) => return fail("site hash", format!("no salt: give --salt-file or set {SALT_ENV}")),
                Err(e) => return fail("site hash", e),
            };
            let hashed = match Site::load(input).and_then(|site| site.hashed(&salt)) {
                Ok(site) => site,
                Err(e) => return fail("site hash", e),
            };
            if let Err(e) = write_site(output, &hashed) {
                return fail("site hash", e);
            }
            println!(
                "{} transmitter ids hashed ({} version {}); written to {}",
                hashed.radio().transmitters().len(),
                waymark_engine::radio::ID_HASH_SCHEME,
                waymark_engine::radio::ID_HASH_VERSION,
                output.display()
            );
            ExitCode::SUCCESS
        }
        SiteCommand::Pack { input, output } | SiteCommand::Unpack { input, output } => {
            let (verb, binary) = match &args.command {
                SiteCommand::Pack { .. } => ("site pack", true),
                _ => ("site unpack", false),
            };
            let site = match Site::load(input) {
                Ok(site) => site,
                Err(e) => return fail(verb, e),
            };
            let contents = if binary { site.to_binary() } else { site.to_json().into_bytes() };
            if let Err(e) = std::fs::write(output, &contents) {
                return fail(verb, format!("cannot write {}: {e}", output.display()));
            }
            println!(
                "{} states, {} fingerprint entries: {} bytes written to {}",
                site.states().len(),
                site.radio().fingerprints().count(),
                contents.len(),
                output.display()
            );
            ExitCode::SUCCESS
        }
        SiteCommand::Check { site, salt } => {
            let (site, salt) = match (Site::load(site), salt.salt()) {
                (Ok(site), Ok(salt)) => (site, salt.map(|(salt, _)| salt)),
                (Err(e), _) => return fail("site check", e),
                (_, Err(e)) => return fail("site check", e),
            };
            let count = site.radio().transmitters().len();
            match (site.id_hashing(), site.scan_hasher(salt.as_ref())) {
                (None, _) => println!("{count} raw transmitter ids (MAC addresses, UUIDs): not hashed"),
                (Some(_), Ok(_)) => println!("{count} hashed transmitter ids; the salt matches"),
                (Some(_), Err(e)) => {
                    return fail("site check", format!("{count} hashed transmitter ids; {e}"))
                }
            }
            ExitCode::SUCCESS
        }
    }
}

fn progress_bar(hidden: bool, len: u64, message: &'static str) -> ProgressBar {
    let bar = if hidden { ProgressBar::hidden() } else { ProgressBar::new(len) };
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len}, {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message(message);
    bar
}

pub fn eval(args: &EvalArgs) -> ExitCode {
    let started = Instant::now();
    let floors = match calibrate::load_building(&args.floors, &args.split, args.max_walks) {
        Ok(f) => f,
        Err(e) => return fail("eval", e),
    };
    let floors: Vec<FloorData> = floors
        .into_iter()
        .map(|f| if args.no_plan { FloorData { plan: None, ..f } } else { f })
        .map(|mut f| {
            f.keep_survey_fraction(args.survey_fraction);
            f
        })
        .collect();
    let mut options = EvalOptions { configurations: args.configurations.clone(), ..EvalOptions::default() };
    if let Some(unknown) = options.configurations.iter().find(|c| !CONFIGURATIONS.contains(&c.as_str())) {
        return fail(
            "eval",
            format!("unknown configuration `{unknown}`; known: {}", CONFIGURATIONS.join(", ")),
        );
    }
    options.calibration.engine.rssi_weight = args.gamma;
    if let Some(s) = args.spacing_m {
        options.calibration.survey.spacing_m = s;
        options.calibration.survey.coverage_m = s;
    }
    if let Some(m) = args.unsurveyed_margin_m {
        options.calibration.survey.unsurveyed_margin_m = m;
    }
    if let Some(r) = args.fingerprint_radius_m {
        options.calibration.survey.fingerprint_radius_m = r;
        options.calibration.calibrate_fingerprint_radius = false;
    }
    if let Some(v) = args.min_std_db {
        options.calibration.survey.build.fit.min_std_db = v;
    }
    if args.fixed_movement_variance {
        options.calibration.engine.movement_vector.measured_spread = false;
    }
    if let Some(m) = args.top_m {
        options.calibration.engine.estimate_states = Some(m);
    }
    if let Some(lag) = args.fixed_lag {
        options.calibration.engine.fixed_lag_epochs = lag;
    }
    if args.no_beacons {
        options.calibration.survey.events.beacons = false;
        options.calibration.replay.events.beacons = false;
    }
    if let Some(v) = args.max_std_db {
        options.calibration.survey.build.fit.max_std_db = v;
    }
    if let Some(ms) = args.max_age_ms {
        options.calibration.survey.max_reading_age_ns = ms * 1_000_000;
    }
    if let Some(t) = args.threads {
        options.calibration.threads = t;
    }
    if let Some(k) = args.habit_strength {
        options.calibration.engine.habits.strength = Some(k);
    }
    let loaded_s = started.elapsed().as_secs_f64();
    let bar = progress_bar(
        args.json,
        calibrate::calibration_steps(&floors, &options.calibration) as u64,
        "calibrating (leave one walk out)",
    );
    let (site, survey, calibration) =
        match calibrate::survey_calibrated(&floors, &options.calibration, &|| bar.inc(1)) {
            Ok(s) => s,
            Err(e) => return fail("eval", e),
        };
    bar.finish_and_clear();
    let options = options.surveyed_with(&calibration);
    let surveyed_s = started.elapsed().as_secs_f64();
    let site = Arc::new(site);
    let walks: usize = floors.iter().map(|f| f.test.len()).sum();
    let bar = progress_bar(args.json, walks as u64, "replaying test walks");
    let (configurations, results) = match evaluation::evaluate_on(&site, &floors, &options, &|| bar.inc(1)) {
        Ok(r) => r,
        Err(e) => return fail("eval", e),
    };
    bar.finish_and_clear();
    if let Some(dir) = &args.plot {
        if let Err(e) = plot(dir, &floors, &results) {
            return fail("eval", e);
        }
    }
    let habits = if args.habits {
        let learning_started = Instant::now();
        let bar = progress_bar(args.json, 1, "learning habits from the survey walks");
        let (model, learning, selection) = match evaluation::survey_habits(&site, &floors, &options) {
            Ok(m) => m,
            Err(e) => return fail("eval", e),
        };
        bar.finish_and_clear();
        let learning_seconds = learning_started.elapsed().as_secs_f64();
        let with = EvalOptions { habits: Some(Arc::new(model)), ..options.clone() };
        let bar = progress_bar(args.json, walks as u64, "replaying test walks with habits");
        let (configurations, _) = match evaluation::evaluate_on(&site, &floors, &with, &|| bar.inc(1)) {
            Ok(r) => r,
            Err(e) => return fail("eval", e),
        };
        bar.finish_and_clear();
        Some(evaluation::HabitsComparison { learning, selection, learning_seconds, configurations })
    } else {
        None
    };
    let throttled = if args.throttle {
        let mut throttled = options.clone();
        throttled.calibration.replay = options.calibration.throttled_replay();
        let bar = progress_bar(args.json, walks as u64, "replaying test walks with throttled scans");
        let (configurations, _) = match evaluation::evaluate_on(&site, &floors, &throttled, &|| bar.inc(1)) {
            Ok(r) => r,
            Err(e) => return fail("eval", e),
        };
        bar.finish_and_clear();
        Some(configurations)
    } else {
        None
    };
    let test: Vec<&Trace> = floors.iter().flat_map(|f| &f.test).collect();
    let pdr = waymark_eval::pdr::evaluate_pdr(&test, &options.calibration.engine.motion_for(&site));
    let report = evaluation::EvalReport {
        configurations,
        survey,
        calibration,
        pdr,
        test_walks: walks,
        survey_fraction: args.survey_fraction,
        states: site.states().len(),
        seconds: started.elapsed().as_secs_f64(),
        habits,
        throttled,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report).unwrap_or_default());
    } else {
        let fraction = if args.survey_fraction < 1.0 {
            format!(" ({} of the survey walks)", args.survey_fraction)
        } else {
            String::new()
        };
        println!(
            "{} floors, {} test walks, {} states{fraction}; read {:.1} s, survey {:.1} s, replay {:.1} s",
            floors.len(),
            walks,
            report.states,
            loaded_s,
            surveyed_s - loaded_s,
            started.elapsed().as_secs_f64() - surveyed_s
        );
        print_configurations(&report.configurations);
        if let Some(throttled) = &report.throttled {
            println!("\nthe same test walks with throttled scans (one every 30 s at most):");
            print_configurations(throttled);
        }
        print_calibration(&report.calibration);
        if let Some(share) = report.configurations.values().find_map(|r| r.pooled.in_zone) {
            println!(
                "zone: the most likely zone is the zone of the state nearest the truth (or both none); \
                 the truth was in a zone at {:.1}% of the scored points",
                100.0 * share
            );
        }
        if let Some(h) = &report.habits {
            print_habits(&report.configurations, h);
        }
    }
    ExitCode::SUCCESS
}

/// One row per configuration, pooled.
fn print_configurations(
    configurations: &std::collections::BTreeMap<String, evaluation::ConfigurationReport>,
) {
    // Room-level accuracy only for a site with zones (from named plan polygons).
    let zones = configurations.values().any(|r| r.pooled.zone_hit.is_some());
    println!(
        "{:<26} {:>7} {:>7} {:>7} {:>7} {:>7} {:>6} {:>6} {:>6}{} {:>7}",
        "configuration",
        "mean",
        "rmse",
        "p50",
        "p90",
        "max",
        "hit68",
        "hit95",
        "floor",
        if zones { format!(" {:>6}", "zone") } else { String::new() },
        "epochs"
    );
    for (key, r) in configurations {
        let m = &r.pooled;
        let zone = match (zones, m.zone_hit) {
            (false, _) => String::new(),
            (true, Some(hit)) => format!(" {hit:>6.3}"),
            (true, None) => format!(" {:>6}", "-"),
        };
        println!(
            "{key:<26} {:>7.2} {:>7.2} {:>7.2} {:>7.2} {:>7.1} {:>6.2} {:>6.2} {:>6.3}{zone} {:>7}",
            m.mean_m,
            m.rmse_m,
            m.p50_m,
            m.p90_m,
            m.max_m,
            m.accuracy_68_hit,
            m.accuracy_95_hit,
            m.floor_hit,
            m.epochs
        );
    }
}

/// The configurations without and with habits, side by side.
fn print_habits(
    without: &std::collections::BTreeMap<String, evaluation::ConfigurationReport>,
    habits: &evaluation::HabitsComparison,
) {
    let l = &habits.learning;
    println!(
        "\nhabits from the survey walks: {} epochs in {} segments ({} with feedback), {} iterations, \
         {} transitions learned, largest segment {} states, {} restarts; {:.1} s",
        l.epochs,
        l.segments,
        l.feedback_epochs,
        l.iterations,
        l.learned_transitions,
        l.largest_segment_states,
        l.restarts,
        habits.learning_seconds
    );
    let s = &habits.selection;
    println!(
        "strength on {} held-out survey walks ({} epochs), mean error with the other half's habits \
         minus without, ± SE, m:",
        s.walks, s.epochs
    );
    println!("{:>8} {:>17} {:>17} {:>17}", "κ", "forward", "fixed-lag", "viterbi");
    for p in &s.strengths {
        let cell = |d: [f64; 2]| format!("{:+.3} ± {:.3}", d[0], d[1]);
        println!(
            "{:>8} {:>17} {:>17} {:>17}",
            p.strength,
            cell(p.forward_m),
            cell(p.fixed_lag_m),
            cell(p.viterbi_m)
        );
    }
    let shown = |k: Option<f64>| k.map_or("none".to_string(), |k| format!("{k:.3}"));
    println!(
        "strength applied: {} (the learning pass alone, by move prediction: {})",
        shown(s.strength),
        shown(s.pass_strength)
    );
    println!(
        "{:<26} {:>15} {:>15} {:>13} {:>13} {:>7}",
        "configuration", "mean (without)", "mean (habits)", "p50", "hit68", "floor"
    );
    for (key, with) in &habits.configurations {
        let Some(plain) = without.get(key) else { continue };
        let (a, b) = (&plain.pooled, &with.pooled);
        println!(
            "{key:<26} {:>15.3} {:>15.3} {:>6.2}→{:<6.2} {:>6.3}→{:<6.3} {:>7.3}",
            a.mean_m, b.mean_m, a.p50_m, b.p50_m, a.accuracy_68_hit, b.accuracy_68_hit, b.floor_hit
        );
    }
}

/// One SVG per test walk (plan, truth, the live, Viterbi and k-NN tracks) and the pooled error
/// CDF of every configuration.
fn plot(
    dir: &std::path::Path,
    floors: &[FloorData],
    results: &[evaluation::WalkResult],
) -> Result<(), String> {
    use waymark_eval::plot::{plot_cdf, plot_walk, Track};
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let tests: Vec<(usize, &Trace)> =
        floors.iter().enumerate().flat_map(|(f, floor)| floor.test.iter().map(move |t| (f, t))).collect();
    let mut errors: std::collections::BTreeMap<&str, Vec<f64>> = std::collections::BTreeMap::new();
    for (result, &(f, trace)) in results.iter().zip(&tests) {
        let truth: Vec<(f64, f64)> = trace.waypoints.iter().map(|w| (w.x, w.y)).collect();
        let shown = ["forward-auto", "viterbi-auto", "wifi-knn"];
        let points: Vec<(&str, Vec<(f64, f64)>)> = shown
            .iter()
            .filter_map(|key| {
                result.estimates.get(*key).map(|e| (*key, e.iter().map(|p| (p.x, p.y)).collect()))
            })
            .collect();
        let tracks: Vec<Track> = points.iter().map(|(label, p)| Track { label, points: p }).collect();
        let title = format!("{} {} ({:.0} m)", floors[f].name, trace.name, trace.path_length_m());
        let path = dir.join(format!("{}-{}.svg", floors[f].name, trace.name));
        plot_walk(&path, &title, floors[f].plan.as_ref(), &truth, &tracks).map_err(|e| e.to_string())?;
        for (key, estimates) in &result.estimates {
            let (epochs, _) = waymark_survey::scoring::score_scans(trace, f, estimates, None);
            errors.entry(key).or_default().extend(epochs.iter().map(|s| s.penalised_m()));
        }
    }
    let curves: Vec<(&str, &[f64])> = errors.iter().map(|(k, v)| (*k, v.as_slice())).collect();
    plot_cdf(&dir.join("error-cdf.svg"), "Error CDF, all test walks", &curves).map_err(|e| e.to_string())?;
    eprintln!("{} walk plots and error-cdf.svg written to {}", results.len(), dir.display());
    Ok(())
}

#[cfg(test)]
mod eval_args_tests {
    use super::EvalArgs;
    use clap::Parser;

    #[derive(Parser)]
    struct Eval {
        #[command(flatten)]
        args: EvalArgs,
    }

    #[test]
    fn the_survey_fraction_is_one_by_default_and_must_be_in_zero_to_one() {
        let parse = |extra: &[&str]| Eval::try_parse_from(["eval", "F1"].iter().chain(extra));
        assert_eq!(parse(&[]).map(|e| e.args.survey_fraction).ok(), Some(1.0));
        assert_eq!(parse(&["--survey-fraction", "0.25"]).map(|e| e.args.survey_fraction).ok(), Some(0.25));
        for bad in ["0", "-0.5", "1.5", "NaN", "half"] {
            let error = parse(&[&format!("--survey-fraction={bad}")]).err().map(|e| e.kind());
            assert_eq!(error, Some(clap::error::ErrorKind::ValueValidation), "{bad}");
        }
    }
}
