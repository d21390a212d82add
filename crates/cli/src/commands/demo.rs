//! `waymark demo`: random walks through the simulated office tracked from raw inertial samples
//! and WiFi scans (Hoang §6.1), and their error.

use clap::ValueEnum;
use std::process::ExitCode;
use waymark_engine::radio::RssiModel;
use waymark_engine::EngineConfig;
use waymark_engine::TransitionModel;
use waymark_experiments as experiments;
use waymark_experiments::Experiment;

#[derive(Clone, Copy, ValueEnum)]
pub enum Model {
    /// High/low probability regions from distance and heading (HIPE eqs. 5-11).
    #[value(alias = "hipe")]
    Regions,
    /// A Gaussian on the movement vector (Hoang eqs. 11, 14).
    #[value(alias = "hoang")]
    MovementVector,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum Fit {
    /// Censored-Gaussian EM (Hoang §3).
    Em,
    /// Plain mean and variance, censoring disregarded (for comparison).
    Naive,
}

#[derive(clap::Args)]
pub struct DemoArgs {
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

pub fn demo(args: &DemoArgs) -> ExitCode {
    let base = if args.rssi_only { Experiment::rssi_only() } else { Experiment::default() };
    let mut experiment = Experiment { walks: args.walks, walk_length_m: args.walk_length_m, ..base };
    if let Some(model) = args.model {
        experiment.engine.transition = match model {
            Model::Regions => TransitionModel::Regions,
            Model::MovementVector => TransitionModel::MovementVector,
        };
    }
    experiment.office.seed = args.seed;
    experiment.office.model = match args.fit {
        Fit::Em => RssiModel::CensoredGaussian,
        Fit::Naive => RssiModel::NaiveGaussian,
    };
    if let Some(m) = args.top_m {
        experiment.engine = EngineConfig { estimate_states: Some(m), ..experiment.engine };
    }
    let report = match experiments::run(&experiment) {
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
    // The model's wire name, as site and option files write it (`hipe`, `hoang`, `reach`).
    let mode = if args.rssi_only {
        serde_json::json!("rssi_only")
    } else {
        serde_json::to_value(experiment.engine.transition).expect("a unit variant serialises")
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
            "top_m": experiment.engine.estimate_states.unwrap_or(waymark_engine::DEFAULT_ESTIMATE_STATES),
            "epochs": s.epochs,
            "mean_error_m": s.mean_error_m,
            "median_error_m": s.median_error_m,
            "p90_error_m": s.p90_error_m,
            "rmse_m": s.rmse_m,
            "max_error_m": s.max_error_m,
            "accuracy_68_hit": s.accuracy_68_hit,
            "median_accuracy_m": s.median_accuracy_m,
            "room_accuracy": s.zone_hit,
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
                TransitionModel::Regions => "HIPE",
                TransitionModel::MovementVector => "Hoang",
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
    if let Some(hit) = s.zone_hit {
        println!("  right room (10 rooms, the aisle, the stair hall) in {:.1}% of epochs", 100.0 * hit);
    }
    ExitCode::SUCCESS
}
