//! `waymark replay`: one recorded walk through the engine as an app would feed it, the track
//! written as CSV or JSON.

use crate::shared::{fail, SaltArgs};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use waymark_engine::{Engine, EngineConfig, Site};
use waymark_survey::replay::{self as replaying, ReplayOptions};

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
                    "floor_level": p.level(&site),
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
                p.level(&site).map_or(String::new(), |l| l.to_string()),
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
