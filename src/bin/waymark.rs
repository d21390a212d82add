//! `waymark`: the command-line tool for the engineer who surveys a building and measures
//! accuracy. `waymark demo` runs the engine on a built-in simulated office.

use clap::{Parser, Subcommand, ValueEnum};
use std::process::ExitCode;
use waymark::radio::RssiModel;
use waymark::sim::{self, Experiment};
use waymark::EngineConfig;

#[derive(Parser)]
#[command(name = "waymark", version, about = "Indoor positioning engine: demo and tools")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Track random walks through a simulated office from WiFi scans alone and print the error
    /// (Hoang et al. §6.1, Table 1 "RSSI only").
    Demo(DemoArgs),
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
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Demo(args) => demo(&args),
    }
}

fn demo(args: &DemoArgs) -> ExitCode {
    let mut experiment =
        Experiment { walks: args.walks, walk_length_m: args.walk_length_m, ..Experiment::default() };
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
    if args.json {
        let value = serde_json::json!({
            "seed": args.seed,
            "fit": fit,
            "walks": args.walks,
            "walk_length_m": args.walk_length_m,
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
            "hoang_table1_rssi_only_mean_error_m": 1.74,
        });
        println!("{value}");
        return ExitCode::SUCCESS;
    }
    println!(
        "Waymark demo: simulated office (seed {}), {} states, {} access points, {} walks of ~{:.0} m, a WiFi scan every 1.5 s",
        args.seed, report.states, report.access_points, args.walks, args.walk_length_m
    );
    println!(
        "Positioning from WiFi alone, fingerprints fitted by {}\n",
        match args.fit {
            Fit::Em => "the censored-Gaussian EM (Hoang et al. §3)",
            Fit::Naive => "plain mean and variance, censoring disregarded",
        }
    );
    println!("First walk, every 10th epoch:");
    println!(
        "  {:>6}  {:>15}  {:>15}  {:>7}  {:>10}",
        "t [s]", "truth [m]", "estimate [m]", "error", "accuracy"
    );
    let t0 = report.first_track.first().map_or(0, |p| p.position.timestamp_ns);
    for p in report.first_track.iter().step_by(10) {
        let error = nalgebra::distance(&p.truth, &nalgebra::Point2::new(p.position.x, p.position.y));
        println!(
            "  {:>6.1}  ({:>5.1}, {:>5.1})  ({:>5.1}, {:>5.1})  {:>5.2} m  {:>8.2} m",
            (p.position.timestamp_ns - t0) as f64 * 1e-9,
            p.truth.x,
            p.truth.y,
            p.position.x,
            p.position.y,
            error,
            p.position.accuracy_m
        );
    }
    println!("\nAll walks, {} epochs:", s.epochs);
    println!("  mean error     {:>6.2} m    (Hoang Table 1, RSSI only: 1.74 m)", s.mean_error_m);
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
