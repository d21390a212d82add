//! `waymark sim-export`: a simulated site and walks as JSON files, for testing the engine from
//! other languages (the binding tests replay them).

use std::process::ExitCode;
use waymark_experiments as experiments;
use waymark_sim as sim;

#[derive(clap::Args)]
pub struct SimExportArgs {
    /// Seed of the building and the walk.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Length of the walk, m.
    #[arg(long, default_value_t = 60.0)]
    walk_length_m: f64,
    /// Survey walks to write into `survey/`: what a surveyor's phone would record, with a
    /// waypoint at every state passed. Twelve of 150 m cover the office well enough for a site
    /// surveyed from them to position like the office's own (docs/surveying.md).
    #[arg(long, default_value_t = 12)]
    survey_walks: u64,
    /// Length of each survey walk, m.
    #[arg(long, default_value_t = 150.0)]
    survey_length_m: f64,
    /// Folder to write `site.json`, `walk.json` and `survey/walk-K.json` into.
    #[arg(long)]
    out: std::path::PathBuf,
}

pub fn sim_export(args: &SimExportArgs) -> ExitCode {
    let office =
        sim::Office::generate(&sim::OfficeConfig { seed: args.seed, ..sim::OfficeConfig::default() });
    let walk = office.walk(experiments::walk_seed(args.seed, 0), args.walk_length_m);
    let write = |name: &str, text: String| std::fs::write(args.out.join(name), text);
    let result = std::fs::create_dir_all(args.out.join("survey"))
        .and_then(|_| write("site.json", office.site.to_json()))
        .and_then(|_| write("walk.json", walk_json(&walk, args.seed, false).to_string()));
    // Survey walks: other seeds than the test walk's, so the survey never saw it.
    let result = (1..=args.survey_walks).try_fold((), |(), k| {
        result.as_ref().map_err(|e| std::io::Error::new(e.kind(), e.to_string()))?;
        let seed = args.seed.wrapping_add(1000 + k);
        let survey = office.walk(experiments::walk_seed(seed, 0), args.survey_length_m);
        write(&format!("survey/walk-{k}.json"), walk_json(&survey, seed, true).to_string())
    });
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("waymark sim-export: {}: {e}", args.out.display());
            ExitCode::FAILURE
        }
    }
}

/// A simulated walk as the binding tests replay it: per scan epoch the truth, the IMU batches
/// since the previous epoch and the WiFi readings; with `waypoints`, the surveyor's taps at
/// every state passed.
fn walk_json(walk: &sim::Walk, seed: u64, waypoints: bool) -> serde_json::Value {
    use waymark_engine::sensors::SensorSample;
    let imu = sim::imu::synthesize(&walk.trajectory, &sim::imu::ImuConfig::default(), seed);
    let rows =
        |v: &[SensorSample]| v.iter().map(|s| [s.timestamp_ns as f64, s.x, s.y, s.z]).collect::<Vec<_>>();
    let mut previous = 0u64;
    let epochs: Vec<serde_json::Value> = walk
        .epochs
        .iter()
        .map(|e| {
            let t = e.scan.timestamp_ns;
            let batch = |v: &[SensorSample]| {
                rows(
                    &v[v.partition_point(|s| s.timestamp_ns <= previous)
                        ..v.partition_point(|s| s.timestamp_ns <= t)],
                )
            };
            let value = serde_json::json!({
                "timestamp_ns": t,
                "truth": [e.truth.x, e.truth.y],
                "accelerometer": batch(&imu.accelerometer),
                "gyroscope": batch(&imu.gyroscope),
                "magnetometer": batch(&imu.magnetometer),
                "wifi": e.scan.readings.iter().map(|r| serde_json::json!({
                    "bssid": match &r.transmitter {
                        waymark_engine::TransmitterId::Wifi { bssid } => bssid.clone(),
                        other => other.to_string(),
                    },
                    "rssi_dbm": r.rssi_dbm,
                })).collect::<Vec<_>>(),
            });
            previous = t;
            value
        })
        .collect();
    let mut json = serde_json::json!({
        "seed": seed,
        "note": "IMU rows are [timestamp_ns, x, y, z] in the phone frame: m/s², rad/s, µT. Each epoch's batches cover (previous epoch, this epoch]. Waypoints, in a survey walk, are [timestamp_ns, x, y]: the states passed.",
        "epochs": epochs,
    });
    if waypoints {
        let taps: Vec<serde_json::Value> = walk
            .trajectory
            .vertices()
            .iter()
            .map(|(t, p)| serde_json::json!([*t as f64, p.x, p.y]))
            .collect();
        json["waypoints"] = serde_json::Value::Array(taps);
    }
    json
}
