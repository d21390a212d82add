//! `waymark simulate`: the papers' artificial-data experiments on the simulated office (Hoang
//! Table 1, HIPE Table 5), the motion tracker alone, the long run, recovery, and El Gemayel's
//! Baum-Welch experiment (§IV).

use crate::app_engine;
use clap::ValueEnum;
use std::process::ExitCode;
use waymark_experiments as experiments;
use waymark_experiments::PaperExperiment;

#[derive(clap::Args)]
pub struct SimulateArgs {
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
    /// drift: share of the access points changed after the survey (moved, vanished, new).
    #[arg(long, default_value_t = 0.3)]
    share: f64,
    /// drift: walks without labels recorded on the drifted radio.
    #[arg(long, default_value_t = 20)]
    unlabelled_walks: usize,
    /// drift: seeds, `--seed`, `--seed` + 1, ... (default 5).
    #[arg(long)]
    drift_seeds: Option<u64>,
    /// drift: rounds of anchoring the walks without labels (`waymark eval --anchor-rounds`;
    /// 1, as `waymark survey --unlabelled`).
    #[arg(long, default_value_t = 1)]
    anchor_rounds: usize,
    /// drift: where the walks after the drift confirm a labelled fingerprint, keep the
    /// labelled scans' own fit instead of pooling both (`ReplaceRule::pool_confirmed`).
    #[arg(long)]
    keep_confirmed: bool,
    /// drift: worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
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
    /// Radio drift after the survey: the stale site, the site refitted from walks without
    /// labels recorded after it, and a fresh survey (docs/evidence.md#drift).
    Drift,
}

pub fn simulate(args: &SimulateArgs) -> ExitCode {
    match args.experiment {
        SimExperiment::LongRun => return long_run(args),
        SimExperiment::Recovery => return recovery(args),
        SimExperiment::BaumWelch => return baum_welch(args),
        SimExperiment::Drift => return drift(args),
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

fn drift(args: &SimulateArgs) -> ExitCode {
    use waymark_eval::drift::{self, DriftExperiment, ARMS};
    let mut defaults = DriftExperiment::default();
    defaults.rule.pool_confirmed = !args.keep_confirmed;
    let config = DriftExperiment {
        share: args.share,
        unlabelled_walks: args.unlabelled_walks,
        first_seed: args.seed,
        seeds: args.drift_seeds.unwrap_or(defaults.seeds),
        anchor_rounds: args.anchor_rounds,
        threads: args.threads.unwrap_or(defaults.threads),
        ..defaults
    };
    let json = args.json;
    let result = drift::run(&config, |r| {
        if !json {
            let arms: Vec<String> = ARMS.iter().map(|a| format!("{a} {:.2} m", r.arms[*a].mean_m)).collect();
            eprintln!(
                "  seed {}: {} of {} access points changed, {} of {} walks anchored (anchors {:.2} m from the truth), {} of {} pairs replaced; {}",
                r.seed,
                r.drift.changed(),
                r.drift.before,
                r.anchored,
                config.unlabelled_walks,
                r.anchor_error_m,
                r.replaced.replaced,
                r.replaced.tested,
                arms.join(", ")
            );
        }
    });
    let report = match result {
        Ok(report) => report,
        Err(e) => {
            eprintln!("waymark simulate --experiment drift: {e}");
            return ExitCode::FAILURE;
        }
    };
    if json {
        match serde_json::to_string(&report) {
            Ok(text) => println!("{text}"),
            Err(e) => {
                eprintln!("waymark simulate --experiment drift: {e}");
                return ExitCode::FAILURE;
            }
        }
        return ExitCode::SUCCESS;
    }
    let [moved, vanished, appeared] =
        waymark_sim::drift::split(report.runs.first().map_or(0, |r| r.drift.changed()));
    println!(
        "Radio drift on the simulated office: {} seeds from {}, {:.0}% of the access points changed \
         ({moved} moved, {vanished} vanished, {appeared} new), {} labelled survey walks, {} walks without labels \
         after the drift, {} test walks after it, all of {} m. Forward-auto, mean over seeds ± standard error.\n",
        config.seeds,
        config.first_seed,
        100.0 * config.share,
        config.survey_walks,
        config.unlabelled_walks,
        config.test_walks,
        config.walk_length_m
    );
    println!(
        "  {:<14} {:>15} {:>15} {:>13} {:>13} {:>15}",
        "site", "mean", "p90", "68% holds", "95% holds", "÷ fresh"
    );
    for arm in ARMS {
        let s = &report.summary[arm];
        let m = |v: drift::MeanSe, unit: &str| format!("{:.2}{unit} ± {:.2}", v.mean, v.se);
        println!(
            "  {arm:<14} {:>15} {:>15} {:>13} {:>13} {:>15}",
            m(s.mean_m, " m"),
            m(s.p90_m, " m"),
            m(s.hold_68, ""),
            m(s.hold_95, ""),
            m(s.over_fresh, "")
        );
    }
    println!("\nWall time {:.0} s", report.seconds);
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
