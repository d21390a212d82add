//! `waymark`: the command-line tool for the engineer who surveys a building and measures
//! accuracy. `waymark demo` runs the engine on a built-in simulated office.

mod bench;
mod real;

use clap::{Parser, Subcommand, ValueEnum};
use std::process::ExitCode;
use waymark::config::TransitionModel;
use waymark::radio::RssiModel;
use waymark::sim::{self, Experiment, PaperExperiment};
use waymark::EngineConfig;

#[derive(Parser)]
#[command(name = "waymark", version, about = "Indoor positioning engine: demo and tools")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Track random walks through a simulated office from raw accelerometer, gyroscope and
    /// magnetometer samples and WiFi scans, and print the error.
    Demo(DemoArgs),
    /// The papers' artificial-data experiments on the same walks: Hoang et al. Table 1 and
    /// HIPE Table 5.
    Simulate(SimulateArgs),
    /// Write a simulated site file and one walk (raw IMU batches and WiFi scans per epoch,
    /// with the truth) as JSON, for testing the engine from other languages.
    SimExport(SimExportArgs),
    /// Build a site file from recorded survey walks (Indoor Location Competition 2.0 format),
    /// one or more floors of one building.
    Survey(real::SurveyArgs),
    /// Replay one recorded walk through the engine as an app would, writing the track.
    Replay(real::ReplayArgs),
    /// Survey on the survey walks of the given floors, replay the test walks through every
    /// configuration, and print the errors (split: file i is a test walk when i % 5 == 4).
    Eval(real::EvalArgs),
    /// Speed and memory at building scale (1 000 to 50 000 states), as one JSON object.
    Bench(bench::BenchArgs),
    /// Site files: hash their transmitter ids with a salt (`site hash`), check a salt
    /// (`site check`).
    Site(real::SiteArgs),
}

#[derive(clap::Args)]
struct SimExportArgs {
    /// Seed of the building and the walk.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Length of the walk, m.
    #[arg(long, default_value_t = 60.0)]
    walk_length_m: f64,
    /// Folder to write `site.json` and `walk.json` into.
    #[arg(long)]
    out: std::path::PathBuf,
}

#[derive(Clone, Copy, ValueEnum)]
enum Model {
    /// HIPE's high/low regions (HIPE eqs. 5-11).
    Hipe,
    /// Hoang's Gaussian on the movement vector (Hoang eqs. 11, 14).
    Hoang,
}

#[derive(clap::Args)]
struct SimulateArgs {
    /// Number of random walks (Hoang: 100).
    #[arg(long, default_value_t = 100)]
    runs: usize,
    /// Seed of the building and its walks.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Print one JSON object instead of the tables.
    #[arg(long)]
    json: bool,
    /// Instead: evaluate the motion tracker alone on simulated raw IMU (steps detected at 20,
    /// 50, 100 and 200 Hz, steps while still and shaken, heading RMSE past steel); prints JSON.
    #[arg(long)]
    motion: bool,
}

#[derive(Clone, Copy, ValueEnum)]
enum Fit {
    /// Censored-Gaussian EM (Hoang §3).
    Em,
    /// Plain mean and variance, censoring disregarded (for comparison).
    Naive,
}

#[derive(clap::Args)]
struct DemoArgs {
    /// Seed of the building and its walks.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Number of random walks (Hoang: 100).
    #[arg(long, default_value_t = 100)]
    walks: usize,
    /// Length of each walk in metres (Hoang: about 200).
    #[arg(long, default_value_t = 200.0)]
    walk_length_m: f64,
    /// How fingerprints are fitted from the training scans.
    #[arg(long, value_enum, default_value_t = Fit::Em)]
    fit: Fit,
    /// M, the number of most likely states averaged into the estimate (Hoang eq. 4).
    #[arg(long)]
    top_m: Option<usize>,
    /// Position from WiFi alone on the surveyed states (Hoang Table 1, "RSSI only").
    #[arg(long)]
    rssi_only: bool,
    /// The transition model for the full fusion.
    #[arg(long, value_enum)]
    model: Option<Model>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Demo(args) => demo(&args),
        Command::Simulate(args) => simulate(&args),
        Command::SimExport(args) => sim_export(&args),
        Command::Survey(args) => real::survey(&args),
        Command::Replay(args) => real::replay(&args),
        Command::Eval(args) => real::eval(&args),
        Command::Bench(args) => bench::bench(&args),
        Command::Site(args) => real::site(&args),
    }
}

fn demo(args: &DemoArgs) -> ExitCode {
    let base = if args.rssi_only { Experiment::rssi_only() } else { Experiment::default() };
    let mut experiment = Experiment { walks: args.walks, walk_length_m: args.walk_length_m, ..base };
    if let Some(model) = args.model {
        experiment.engine.transition = match model {
            Model::Hipe => TransitionModel::Hipe,
            Model::Hoang => TransitionModel::Hoang,
        };
    }
    experiment.office.seed = args.seed;
    experiment.office.model = match args.fit {
        Fit::Em => RssiModel::CensoredGaussian,
        Fit::Naive => RssiModel::NaiveGaussian,
    };
    if let Some(m) = args.top_m {
        experiment.engine = EngineConfig { estimate_states: m, ..experiment.engine };
    }
    let report = match sim::run(&experiment) {
        Ok(report) => report,
        Err(e) => {
            eprintln!("waymark demo: {e}");
            return ExitCode::FAILURE;
        }
    };
    let s = &report.summary;
    let fit = match args.fit {
        Fit::Em => "censored_em",
        Fit::Naive => "naive",
    };
    let mode = if args.rssi_only {
        "rssi_only".to_owned()
    } else {
        format!("{:?}", experiment.engine.transition).to_lowercase()
    };
    if args.json {
        let value = serde_json::json!({
            "seed": args.seed,
            "mode": mode,
            "fit": fit,
            "walks": args.walks,
            "walk_length_m": args.walk_length_m,
            "surveyed_states": report.surveyed_states,
            "states": report.states,
            "access_points": report.access_points,
            "top_m": experiment.engine.estimate_states,
            "epochs": s.epochs,
            "mean_error_m": s.mean_error_m,
            "median_error_m": s.median_error_m,
            "p90_error_m": s.p90_error_m,
            "rmse_m": s.rmse_m,
            "max_error_m": s.max_error_m,
            "accuracy_68_hit": s.accuracy_68_hit,
            "median_accuracy_m": s.median_accuracy_m,
        });
        println!("{value}");
        return ExitCode::SUCCESS;
    }
    println!(
        "Waymark demo: simulated office (seed {}), {} surveyed states ({} with pseudo states), {} access points,\n\
         {} walks of ~{:.0} m, a WiFi scan every 1.5 s",
        args.seed, report.surveyed_states, report.states, report.access_points, args.walks, args.walk_length_m
    );
    if args.rssi_only {
        println!("Positioning from WiFi alone (Hoang Table 1, RSSI only: 1.74 m)");
    } else {
        println!(
            "Full fusion: raw accelerometer, gyroscope and magnetometer at {:.0} Hz -> steps and heading -> {} transitions, with WiFi",
            experiment.imu.rate_hz,
            match experiment.engine.transition {
                TransitionModel::Hipe => "HIPE",
                TransitionModel::Hoang => "Hoang",
                TransitionModel::Reach => "reachability",
            }
        );
    }
    println!(
        "Fingerprints fitted by {}\n",
        match args.fit {
            Fit::Em => "the censored-Gaussian EM (Hoang et al. §3)",
            Fit::Naive => "plain mean and variance, censoring disregarded",
        }
    );
    println!("First walk, every 10th epoch:");
    println!(
        "  {:>6}  {:>15}  {:>15}  {:>7}  {:>9}  {:>7}  {:>5}  {:<16}",
        "t [s]", "truth [m]", "estimate [m]", "error", "accuracy", "heading", "steps", "scenario"
    );
    let t0 = report.first_track.first().map_or(0, |p| p.position.timestamp_ns);
    for p in report.first_track.iter().step_by(10) {
        let position = &p.position;
        let error = nalgebra::distance(&p.truth, &nalgebra::Point2::new(position.x, position.y));
        let heading = position.heading_rad.map_or("-".to_owned(), |h| format!("{:.0}°", h.to_degrees()));
        println!(
            "  {:>6.1}  ({:>5.1}, {:>5.1})  ({:>5.1}, {:>5.1})  {:>5.2} m  {:>7.2} m  {:>7}  {:>5}  {:<16}",
            (position.timestamp_ns - t0) as f64 * 1e-9,
            p.truth.x,
            p.truth.y,
            position.x,
            position.y,
            error,
            position.accuracy_m,
            heading,
            position.steps,
            format!("{:?}", position.scenario),
        );
    }
    println!("\nAll walks, {} epochs:", s.epochs);
    println!("  mean error     {:>6.2} m", s.mean_error_m);
    println!("  median error   {:>6.2} m", s.median_error_m);
    println!("  90% error      {:>6.2} m", s.p90_error_m);
    println!("  RMSE           {:>6.2} m", s.rmse_m);
    println!("  max error      {:>6.2} m", s.max_error_m);
    println!(
        "  accuracy_m held the truth in {:.1}% of epochs (68% when calibrated; median radius {:.2} m)",
        100.0 * s.accuracy_68_hit,
        s.median_accuracy_m
    );
    ExitCode::SUCCESS
}

fn simulate(args: &SimulateArgs) -> ExitCode {
    if args.motion {
        let report = sim::motion_eval::evaluate(args.seed, args.runs);
        match serde_json::to_string_pretty(&report) {
            Ok(text) => println!("{text}"),
            Err(e) => {
                eprintln!("waymark simulate --motion: {e}");
                return ExitCode::FAILURE;
            }
        }
        return ExitCode::SUCCESS;
    }
    let experiment = PaperExperiment { seed: args.seed, runs: args.runs, ..PaperExperiment::default() };
    let report = match sim::run_papers(&experiment) {
        Ok(report) => report,
        Err(e) => {
            eprintln!("waymark simulate: {e}");
            return ExitCode::FAILURE;
        }
    };
    if args.json {
        let value = serde_json::json!({
            "seed": args.seed,
            "runs": args.runs,
            "epochs": report.epochs,
            "surveyed_states": report.surveyed_states,
            "states_with_pseudo": report.states_with_pseudo,
            "hoang_table1": report.hoang_table1,
            "hipe_table5": report.hipe_table5,
            "fixed_lag_mean_error_m": report.fixed_lag_mean_error_m,
            "summaries": report.summaries.iter().map(|(n, s)| (n.clone(), s)).collect::<std::collections::BTreeMap<_, _>>(),
        });
        println!("{value}");
        return ExitCode::SUCCESS;
    }
    println!(
        "Simulated office (seed {}), {} walks of ~200 m, {} epochs per method; {} surveyed states, {} with pseudo states\n",
        args.seed, args.runs, report.epochs, report.surveyed_states, report.states_with_pseudo
    );
    let t = &report.hoang_table1;
    println!("Hoang et al., Table 1: mean positioning error");
    println!("  {:<42} {:>8} {:>8}", "method", "Waymark", "paper");
    for (name, ours, paper) in [
        ("RSSI only", t.rssi_only, 1.74),
        ("RSSI + step det., censoring ignored", t.rssi_step_uncensored, 1.42),
        ("RSSI + step det.", t.rssi_step, 1.37),
        ("RSSI + step det. + pseudo states", t.rssi_step_pseudo, 1.02),
    ] {
        println!("  {name:<42} {ours:>6.2} m {paper:>6.2} m");
    }
    let h = &report.hipe_table5;
    println!(
        "\nHIPE, Table 5 scenarios on the same walks (HIPE's own figures are from its office, not this one)"
    );
    println!("  {:<36} {:>8} {:>8} {:>8}", "scenario", "RMSE", "mean", "max");
    for (name, row) in [
        ("measured distance & heading", &h.distance_heading),
        ("measured distance", &h.distance),
        ("measured heading & assumed speed", &h.heading_speed),
        ("assumed speed", &h.speed),
        ("MLE fingerprinting (no HMM)", &h.mle),
    ] {
        println!("  {name:<36} {:>6.2} m {:>6.2} m {:>6.2} m", row.rmse_m, row.mean_m, row.max_m);
    }
    println!("\nViterbi track of the default engine (Hoang, full motion, pseudo states): mean error by lag");
    for (lag, e) in &report.fixed_lag_mean_error_m {
        println!("  lag {lag}: {e:.2} m");
    }
    ExitCode::SUCCESS
}

fn sim_export(args: &SimExportArgs) -> ExitCode {
    use waymark::sensors::SensorSample;
    let office =
        sim::Office::generate(&sim::OfficeConfig { seed: args.seed, ..sim::OfficeConfig::default() });
    let walk = office.walk(sim::walk_seed(args.seed, 0), args.walk_length_m);
    let imu = sim::imu::synthesize(&walk.trajectory, &sim::imu::ImuConfig::default(), args.seed);
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
                        waymark::TransmitterId::Wifi { bssid } => bssid.clone(),
                        other => other.to_string(),
                    },
                    "rssi_dbm": r.rssi_dbm,
                })).collect::<Vec<_>>(),
            });
            previous = t;
            value
        })
        .collect();
    let walk_json = serde_json::json!({
        "seed": args.seed,
        "note": "IMU rows are [timestamp_ns, x, y, z] in the phone frame: m/s², rad/s, µT. Each epoch's batches cover (previous epoch, this epoch].",
        "epochs": epochs,
    });
    let write = |name: &str, text: String| std::fs::write(args.out.join(name), text);
    let result = std::fs::create_dir_all(&args.out)
        .and_then(|_| write("site.json", office.site.to_json()))
        .and_then(|_| write("walk.json", walk_json.to_string()));
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("waymark sim-export: {}: {e}", args.out.display());
            ExitCode::FAILURE
        }
    }
}
