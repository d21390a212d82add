//! `waymark`: the command-line tool for the engineer who surveys a building and measures
//! accuracy. `waymark demo` runs the engine on a built-in simulated office.

mod app_engine;
mod bench;
mod benchmark;
mod hmm;
mod real;
mod results;
mod route;
mod view;

use clap::{Parser, Subcommand, ValueEnum};
use std::process::ExitCode;
use waymark_engine::radio::RssiModel;
use waymark_engine::EngineConfig;
use waymark_engine::TransitionModel;
use waymark_experiments as experiments;
use waymark_experiments::{Experiment, PaperExperiment};
use waymark_sim as sim;

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
    /// The accuracy benchmark over buildings: every row (a building and a split of its walks)
    /// evaluated as `eval` does, a table per row and the mean over buildings; with
    /// `--baseline`, whether a change is kept (docs/benchmark.md).
    Benchmark(benchmark::BenchmarkArgs),
    /// `docs/results.md` from the committed JSON in `docs/results/` (`--check FILE`: fail when
    /// FILE is not what the JSON makes).
    Results(results::ResultsArgs),
    /// Speed and memory at building scale (1 000 to 50 000 states), as one JSON object.
    Bench(bench::BenchArgs),
    /// Site files: pack into the binary encoding apps ship (`site pack`) and back to JSON
    /// (`site unpack`), hash their transmitter ids with a salt (`site hash`), check a salt
    /// (`site check`).
    Site(real::SiteArgs),
    /// The HMM learning core on a JSON model (`hmm decode`: forward-backward and Viterbi;
    /// `hmm fit`: Baum-Welch), for checking against other implementations. Input from a file
    /// or standard input, JSON on standard output, exit status 2 on bad input.
    Hmm(hmm::HmmArgs),
    /// Write one self-contained HTML page showing a site's floors (plan, states, zones) and
    /// optionally a walk: the estimate with its 68% circle and the truth, to play back.
    View(view::ViewArgs),
    /// The shortest walkable route on a site (or the demo's office) from a point to a point
    /// or a zone, as legs with turns; `--json` for one JSON object.
    Route(route::RouteArgs),
}

#[derive(clap::Args)]
struct SimExportArgs {
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

#[derive(Clone, Copy, ValueEnum)]
enum Model {
    /// High/low probability regions from distance and heading (HIPE eqs. 5-11).
    #[value(alias = "hipe")]
    Regions,
    /// A Gaussian on the movement vector (Hoang eqs. 11, 14).
    #[value(alias = "hoang")]
    MovementVector,
}

#[derive(clap::Args)]
struct SimulateArgs {
    /// Number of random walks (Hoang: 100); baum-welch: Baum-Welch runs, each on a new
    /// 500-epoch walk (default 10).
    #[arg(long)]
    runs: Option<usize>,
    /// Seed of the building and its walks.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Print one JSON object instead of the tables.
    #[arg(long)]
    json: bool,
    /// Instead: evaluate the motion tracker alone on simulated raw IMU (steps detected at 20,
    /// 50, 100 and 200 Hz, steps while still and shaken, heading RMSE past steel); prints JSON.
    /// The same as `--experiment motion`.
    #[arg(long)]
    motion: bool,
    /// Which experiment.
    #[arg(long, value_enum, default_value_t = SimExperiment::Papers)]
    experiment: SimExperiment,
    /// long-run: simulated hours (24: a day).
    #[arg(long, default_value_t = 24.0)]
    hours: f64,
    /// long-run: a report every this many simulated seconds.
    #[arg(long, default_value_t = 3600.0)]
    report_every_s: f64,
    /// recovery: runs per scenario, seeded `--seed`, `--seed` + 1, ...
    #[arg(long, default_value_t = 20)]
    seeds: u64,
    /// baum-welch: per-cell range biases exponential with the same mean instead of uniform
    /// (El Gemayel §II-C).
    #[arg(long)]
    exponential_bias: bool,
    /// baum-welch: variance of the initial mixture components, m² (El Gemayel eq. 15: 2500).
    #[arg(long)]
    initial_variance: Option<f64>,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum SimExperiment {
    /// Hoang et al. Table 1 and HIPE Table 5 on the same walks.
    Papers,
    /// The motion tracker alone on simulated raw IMU.
    Motion,
    /// A simulated day at 100 Hz through the FFI engine: memory and finiteness per hour.
    LongRun,
    /// Kidnapped and radio-outage recovery: epochs of good data back to the normal error.
    Recovery,
    /// El Gemayel et al. §IV: room accuracy of the forward algorithm with true parameters and
    /// with parameters learned by Baum-Welch run after run, with user feedback (Fig. 5).
    BaumWelch,
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
        Command::Benchmark(args) => benchmark::benchmark(&args),
        Command::Results(args) => results::run(&args),
        Command::Site(args) => real::site(&args),
        Command::Hmm(args) => hmm::hmm(&args),
        Command::View(args) => view::view(&args),
        Command::Route(args) => route::route(&args),
    }
}

fn demo(args: &DemoArgs) -> ExitCode {
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

fn simulate(args: &SimulateArgs) -> ExitCode {
    match args.experiment {
        SimExperiment::LongRun => return long_run(args),
        SimExperiment::Recovery => return recovery(args),
        SimExperiment::BaumWelch => return baum_welch(args),
        SimExperiment::Papers | SimExperiment::Motion => {}
    }
    let runs = args.runs.unwrap_or(100);
    if args.motion || args.experiment == SimExperiment::Motion {
        let report = experiments::motion_eval::evaluate(args.seed, runs);
        match serde_json::to_string_pretty(&report) {
            Ok(text) => println!("{text}"),
            Err(e) => {
                eprintln!("waymark simulate --motion: {e}");
                return ExitCode::FAILURE;
            }
        }
        return ExitCode::SUCCESS;
    }
    let experiment = PaperExperiment { seed: args.seed, runs, ..PaperExperiment::default() };
    let report = match experiments::run_papers(&experiment) {
        Ok(report) => report,
        Err(e) => {
            eprintln!("waymark simulate: {e}");
            return ExitCode::FAILURE;
        }
    };
    if args.json {
        let value = serde_json::json!({
            "seed": args.seed,
            "runs": runs,
            "epochs": report.epochs,
            "surveyed_states": report.surveyed_states,
            "states_with_pseudo": report.states_with_pseudo,
            "hoang_table1": report.hoang_table1,
            "hipe_table5": report.hipe_table5,
            "fixed_lag_mean_error_m": report.fixed_lag_mean_error_m,
            "room_accuracy": report.room_accuracy.iter().cloned().collect::<std::collections::BTreeMap<_, _>>(),
            "summaries": report.summaries.iter().map(|(n, s)| (n.clone(), s)).collect::<std::collections::BTreeMap<_, _>>(),
        });
        println!("{value}");
        return ExitCode::SUCCESS;
    }
    println!(
        "Simulated office (seed {}), {} walks of ~200 m, {} epochs per method; {} surveyed states, {} with pseudo states\n",
        args.seed, runs, report.epochs, report.surveyed_states, report.states_with_pseudo
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
    println!(
        "\nFixed-lag estimate of the default engine (Hoang, full motion, pseudo states): mean error by lag"
    );
    for (lag, e) in &report.fixed_lag_mean_error_m {
        println!("  lag {lag}: {e:.2} m");
    }
    println!(
        "\nRoom-level accuracy (El Gemayel et al.): epochs whose most likely zone (10 rooms, the aisle, the stair hall) is the true one"
    );
    for (name, hit) in &report.room_accuracy {
        println!("  {name:<36} {:>6.1}%", 100.0 * hit);
    }
    ExitCode::SUCCESS
}

fn baum_welch(args: &SimulateArgs) -> ExitCode {
    use experiments::baum_welch::{self, BaumWelchExperiment, Bias};
    let defaults = BaumWelchExperiment::default();
    let bias = match (args.exponential_bias, defaults.bias) {
        // The same mean bias, as the paper compares them (§IV-B).
        (true, Bias::Uniform { max_m }) => Bias::Exponential { mean_m: max_m / 2.0 },
        (_, bias) => bias,
    };
    let config = BaumWelchExperiment {
        seed: args.seed,
        runs: args.runs.unwrap_or(defaults.runs),
        bias,
        initial_variance_m2: args.initial_variance.unwrap_or(defaults.initial_variance_m2),
        ..defaults
    };
    let report = match baum_welch::run(&config) {
        Ok(report) => report,
        Err(e) => {
            eprintln!("waymark simulate --experiment baum-welch: {e}");
            return ExitCode::FAILURE;
        }
    };
    if args.json {
        match serde_json::to_string(&report) {
            Ok(text) => println!("{text}"),
            Err(e) => {
                eprintln!("waymark simulate --experiment baum-welch: {e}");
                return ExitCode::FAILURE;
            }
        }
        return ExitCode::SUCCESS;
    }
    let bias = match report.bias {
        Bias::Uniform { max_m } => format!("U(0, {max_m} m)"),
        Bias::Exponential { mean_m } => format!("exponential with mean {mean_m} m"),
    };
    println!(
        "El Gemayel et al. §IV on a simulated floor (seed {}): {} states (9 corridor sections, 18 rooms), {} cells of\n\
         1 m x 1 m; TDoA from 4 anchors off the corners, range biases per cell {bias}, noise σ_n {} m, least-squares positions.\n\
         Run k: a new walk of {} epochs, then Baum-Welch to convergence on walks 1..k from run k-1's parameters. Run 0\n\
         is §IV's initialisation: floor-plan transitions uniform, means at the cell centres, Σ = {} I m².\n\
         Room accuracy (the forward algorithm's most probable state is the true one) on {} held-out epochs.\n",
        report.seed,
        report.states,
        report.cells,
        report.noise_m,
        report.run_length,
        report.initial_variance_m2,
        report.test_epochs
    );
    println!("  position estimate alone (in the true state)  {:>5.1}%", 100.0 * report.estimate_accuracy);
    println!(
        "  forward algorithm, true parameters           {:>5.1}%   (paper, Fig. 3: above 80% even at σ_n = 35 m)\n",
        100.0 * report.true_accuracy
    );
    print!("  {:>4}", "run");
    for c in &report.curves {
        print!("  {:>17}", c.name);
    }
    println!();
    for run in 0..report.curves.first().map_or(0, |c| c.accuracy.len()) {
        print!("  {run:>4}");
        for c in &report.curves {
            let rate = run.checked_sub(1).map_or(String::new(), |r| format!(" ({:.2})", c.feedback[r]));
            print!("  {:>17}", format!("{:.1}%{rate}", 100.0 * c.accuracy[run]));
        }
        println!();
    }
    print!("  {:>4}", "its");
    for c in &report.curves {
        let mean = c.iterations.iter().sum::<usize>() as f64 / c.iterations.len().max(1) as f64;
        print!("  {:>17}", format!("{mean:.1} per run"));
    }
    println!(
        "\n\n(rate): the run's feedback rate; its: Baum-Welch iterations. \"A known\": the true transitions, emissions learned\n\
         (Fig. 4: learned \"after only one run\" of 200 epochs). Fig. 5 (all parameters, 500-epoch runs) is plotted only:\n\
         \"feedback is needed mainly at the beginning and higher feedback rates at the beginning accelerate the learning\n\
         curve\"; without feedback Baum-Welch \"may converge to a local maximum\" (§IV-C)."
    );
    ExitCode::SUCCESS
}

fn long_run(args: &SimulateArgs) -> ExitCode {
    use experiments::longrun::{self, LongRunConfig};
    let config = LongRunConfig {
        hours: args.hours,
        seed: args.seed,
        report_every_s: args.report_every_s,
        ..LongRunConfig::default()
    };
    let mb = |kb: Option<u64>| kb.map_or("-".to_owned(), |kb| format!("{:.1}", kb as f64 / 1024.0));
    if !args.json {
        println!(
            "Long run: {} simulated hours on the office (seed {}), accelerometer, gyroscope and magnetometer at 100 Hz \
             in batches of {}, a WiFi scan every {} s, through the FFI engine and the core engine in lockstep\n",
            args.hours,
            args.seed,
            longrun::BATCH_SAMPLES,
            longrun::SCAN_INTERVAL_NS as f64 * 1e-9
        );
        println!(
            "  {:>6} {:>7} {:>8} {:>8} {:>9} {:>6} {:>6} {:>9} {:>7} {:>7} {:>6} {:>6} {:>8} {:>7} {:>8}",
            "hour",
            "wall s",
            "RSS MiB",
            "HWM MiB",
            "track B",
            "window",
            "epochs",
            "non-fin.",
            "mean m",
            "p90 m",
            "walk",
            "table",
            "steps",
            "dropped",
            "restarts"
        );
        println!("  (mean error while walking / standing / on a table in brackets)");
    }
    let json = args.json;
    let result = longrun::run(&config, app_engine::ffi_engine, |i| {
        if !json {
            println!(
                "  {:>6.2} {:>7.1} {:>8} {:>8} {:>9} {:>6} {:>6} {:>9} {:>7.2} {:>7.2} {:>5.0}% {:>5.0}% {:>8} {:>7} {:>8}",
                i.hours,
                i.wall_s,
                mb(i.rss_kb),
                mb(i.hwm_kb),
                i.track_memory_bytes,
                i.track_window_epochs,
                i.epochs,
                i.non_finite_positions,
                i.mean_error_m,
                i.p90_error_m,
                100.0 * i.walking_share,
                100.0 * i.table_share,
                i.input.steps,
                i.input.samples_dropped,
                i.input.filter_restarts,
            );
            let [w, s, t] = i.mean_error_by_activity_m;
            println!("  {:>6} ({w:.2} / {s:.2} / {t:.2} m)", "");
        }
    });
    let report = match result {
        Ok(report) => report,
        Err(e) => {
            eprintln!("waymark simulate --experiment long-run: {e}");
            return ExitCode::FAILURE;
        }
    };
    if json {
        match serde_json::to_string(&report) {
            Ok(text) => println!("{text}"),
            Err(e) => {
                eprintln!("waymark simulate --experiment long-run: {e}");
                return ExitCode::FAILURE;
            }
        }
    } else {
        let last = report.intervals.last();
        println!(
            "\nRSS at 1 h: {} MiB; at {} h: {} MiB; ratio {}",
            mb(report.rss_1h_kb),
            args.hours,
            mb(report.rss_end_kb),
            report.rss_end_over_1h.map_or("-".to_owned(), |r| format!("{r:.3}"))
        );
        println!(
            "Viterbi window: {} epochs of {} states, {} B accounted (bound {} B); fixed lag {} epochs, {} B (bound {} B)",
            report.track_window_capacity,
            report.states,
            last.map_or(0, |i| i.track_memory_bytes),
            report.track_memory_bound_bytes,
            report.fixed_lag_epochs,
            last.map_or(0, |i| i.fixed_lag_memory_bytes),
            report.fixed_lag_memory_bound_bytes
        );
        println!(
            "Generator: largest segment held {:.1} MiB. Positions: {} epochs, {} non-finite; mean error {:.2} m. FFI/core mismatches: {}",
            report.generator_peak_bytes as f64 / 1048576.0,
            report.epochs,
            report.non_finite_positions,
            report.mean_error_m,
            report.intervals.iter().map(|i| i.ffi_core_mismatches).sum::<u64>()
        );
        if let Some(i) = last {
            println!("Input: {:?}", i.input);
        }
        println!("Wall time {:.1} s", report.wall_s);
    }
    ExitCode::SUCCESS
}

fn recovery(args: &SimulateArgs) -> ExitCode {
    use experiments::recovery::{self, RecoveryConfig, ScenarioReport};
    let config = RecoveryConfig { seeds: args.seeds, first_seed: args.seed, ..RecoveryConfig::default() };
    let json = args.json;
    let result = recovery::run(&config, |scenario, run| {
        if !json {
            eprintln!(
                "  {scenario:<12} seed {:>3}: {:>5.1} m disturbance, error before {:>5.2} m, first good epochs {}",
                run.seed,
                run.disturbance_m,
                run.error_before_m,
                run.errors_m.iter().take(12).map(|e| format!("{e:.1}")).collect::<Vec<_>>().join(" ")
            );
        }
    });
    let report = match result {
        Ok(report) => report,
        Err(e) => {
            eprintln!("waymark simulate --experiment recovery: {e}");
            return ExitCode::FAILURE;
        }
    };
    if json {
        match serde_json::to_string(&report) {
            Ok(text) => println!("{text}"),
            Err(e) => {
                eprintln!("waymark simulate --experiment recovery: {e}");
                return ExitCode::FAILURE;
            }
        }
        return ExitCode::SUCCESS;
    }
    println!(
        "Recovery on the simulated office, {} runs per scenario (seeds {}..{}), an epoch every {} s, the default engine.\n\
         Normal error: the undisturbed twin runs' error in their steady state (every epoch after the first {}),\n\
         pooled median and p90; tolerance max(1.5 x normal median, normal p90).\n\
         Reference: an undisturbed engine with the same input from the first good epoch on (outage: the twin;\n\
         kidnap: the phone lay where the person is put down until then).\n\
         Recovered after r epochs: r is the first epoch of good data from which, for {} consecutive epochs, the\n\
         error is within the tolerance or no more than the reference's error + {} m. Target: r <= {}.\n\
         First rule (within the tolerance for {} epochs, whatever the reference does), shown alongside.\n",
        args.seeds,
        args.seed,
        args.seed + args.seeds.saturating_sub(1),
        report.epoch_s,
        recovery::WARMUP_EPOCHS,
        report.hold_epochs,
        recovery::SAME_PLACE_M,
        report.target_epochs,
        report.hold_epochs
    );
    let target = report.target_epochs;
    let line = |d: &recovery::RecoveryDistribution| {
        format!(
            "median {}, p90 {}, max {}, within {target}: {:.0}%",
            d.median,
            d.p90,
            d.max,
            100.0 * d.within_target
        )
    };
    let per_run = |epochs: &mut dyn Iterator<Item = Option<usize>>| {
        epochs.map(|e| e.map_or("-".to_owned(), |e| e.to_string())).collect::<Vec<_>>().join(" ")
    };
    let show = |s: &ScenarioReport| {
        println!("{}:", s.scenario);
        println!(
            "  normal error: median {:.2} m, p90 {:.2} m -> tolerance {:.2} m; error just before good data (median) {:.2} m",
            s.normal_median_m, s.normal_p90_m, s.tolerance_m, s.median_error_before_m
        );
        println!(
            "  the references' error over the scored epochs: median {:.2} m, p90 {:.2} m",
            s.reference_error_m[0], s.reference_error_m[1]
        );
        println!(
            "  epochs to recover: {} ({} not recovered in the scored epochs)",
            line(&s.recovery),
            s.recovery.not_recovered
        );
        if let Some(c) = &s.cold_recovery {
            println!("  the same rule on a fresh engine started at the first good epoch: {}", line(c));
        }
        if let Some(t) = &s.twin_recovery {
            println!("  the same rule on the undisturbed twins, each against its own reference: {}", line(t));
        }
        if let Some(f) = &s.forget {
            println!(
                "  epochs until it reports what an undisturbed engine with the same input reports (within {} m): {}",
                recovery::SAME_PLACE_M,
                line(f)
            );
        }
        println!("  first rule: disturbed {}", line(&s.tolerance_recovery));
        println!("              reference {}", line(&s.reference_tolerance_recovery));
        println!("              twin      {}", line(&s.twin_tolerance_recovery));
        if let Some(c) = &s.cold_tolerance_recovery {
            println!("              fresh     {}", line(c));
        }
        println!(
            "  error at recovery (median) {:.2} m; mean error from epoch {} on: {:.2} m disturbed, {:.2} m references, {:.2} m twins",
            s.median_error_at_recovery_m,
            target + 1,
            s.settled_mean_error_m[0],
            s.settled_mean_error_m[1],
            s.settled_mean_error_m[2]
        );
        println!("  per run:             {}", per_run(&mut s.runs.iter().map(|r| r.epochs_to_recover)));
        println!(
            "  per run, first rule: {}\n",
            per_run(&mut s.runs.iter().map(|r| r.epochs_within_tolerance))
        );
    };
    show(&report.kidnapped);
    show(&report.radio_outage);
    ExitCode::SUCCESS
}

fn sim_export(args: &SimExportArgs) -> ExitCode {
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
