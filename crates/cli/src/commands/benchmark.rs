//! `waymark benchmark`: the accuracy benchmark over buildings (`docs/benchmark.md`), and its
//! verdict on a change against a baseline run.

use crate::shared;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;
use waymark_eval::benchmark::{
    compare, evaluate_row, BenchmarkReport, Comparison, DataSource, LoadError, RowReport, Verdict,
    LEARNING_ROWS, ROWS,
};
use waymark_eval::real::{EvalOptions, CONFIGURATIONS};
use waymark_survey::calibrate::calibration_steps;

#[derive(clap::Args)]
pub struct BenchmarkArgs {
    /// Print one JSON object instead of the tables.
    #[arg(long)]
    json: bool,
    /// Also write the JSON to FILE.
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
    /// Also the rows of a map learned from use, after the others and not in the mean over
    /// buildings (docs/evidence.md#measured).
    #[arg(long)]
    learning: bool,
    /// Only these rows (comma-separated `building/split`, as `ilc20-site1/F=1`); default all
    /// (with --learning, the learning rows too).
    #[arg(long, value_delimiter = ',')]
    rows: Vec<String>,
    /// Only these configurations (comma-separated keys); default all.
    #[arg(long, value_delimiter = ',')]
    configurations: Vec<String>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// A benchmark JSON to judge this run against: the change per row and building against
    /// the baseline's walk-bootstrap standard error, and whether the change is kept.
    #[arg(long, value_name = "OLD.json")]
    baseline: Option<PathBuf>,
    /// With --baseline: judge this stored run instead of running the benchmark.
    #[arg(long, value_name = "NEW.json", requires = "baseline")]
    current: Option<PathBuf>,
    /// The configuration the verdict judges (the others' changes are shown).
    #[arg(long, default_value = "forward-auto")]
    judge: String,
    /// Use only the first N walk files of each floor (a quick look; the JSON says so, and such
    /// a run is not compared with a full one).
    #[arg(long)]
    max_walks: Option<usize>,
}

fn fail(e: impl std::fmt::Display) -> ExitCode {
    shared::fail("benchmark", e)
}

pub fn benchmark(args: &BenchmarkArgs) -> ExitCode {
    if let Some(unknown) = args.configurations.iter().find(|c| !CONFIGURATIONS.contains(&c.as_str())) {
        return fail(format!("unknown configuration `{unknown}`; known: {}", CONFIGURATIONS.join(", ")));
    }
    let known: Vec<String> = ROWS.iter().chain(&LEARNING_ROWS).map(|r| r.name()).collect();
    if let Some(unknown) = args.rows.iter().find(|r| !known.contains(r)) {
        return fail(format!("unknown row `{unknown}`; known: {}", known.join(", ")));
    }
    let baseline = match args.baseline.as_deref().map(BenchmarkReport::read).transpose() {
        Ok(b) => b.map(|b| BenchmarkReport::new(b.rows, b.max_walks)),
        Err(e) => return fail(e),
    };
    let report = match &args.current {
        // Its mean taken again from its rows, as this build takes it.
        Some(path) => match BenchmarkReport::read(path) {
            Ok(r) => BenchmarkReport::new(r.rows, r.max_walks),
            Err(e) => return fail(e),
        },
        None => match run(args) {
            Ok(r) => r,
            Err(e) => return fail(e),
        },
    };
    if let Some(path) = args.out.as_ref().filter(|_| args.current.is_none()) {
        let text = serde_json::to_string_pretty(&report).unwrap_or_default();
        if let Err(e) = std::fs::write(path, text + "\n") {
            return fail(format!("cannot write {}: {e}", path.display()));
        }
        eprintln!("written to {}", path.display());
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report).unwrap_or_default());
    } else {
        if args.current.is_some() {
            report.rows.iter().for_each(print_row);
        }
        print_mean(&report);
    }
    if let Some(baseline) = &baseline {
        let keys: Vec<&String> = baseline.mean.keys().filter(|k| report.mean.contains_key(*k)).collect();
        // The judged configuration's table, then a line for every other one. On stderr under
        // --json, whose standard output is the JSON alone.
        let mut text = comparison_table(&compare(baseline, &report, &args.judge));
        for key in keys.into_iter().filter(|k| **k != args.judge) {
            let c = compare(baseline, &report, key);
            text += &format!("{key:<26} {}\n", verdict_line(&c));
        }
        if args.json {
            eprint!("{text}");
        } else {
            print!("\n{text}");
        }
    }
    if report.rows.iter().all(|r| r.skipped.is_some()) {
        return fail("every row was skipped: no data (docs/testing.md#real-data)");
    }
    ExitCode::SUCCESS
}

/// Runs the rows asked for, printing each row's table as it ends unless `--json`.
fn run(args: &BenchmarkArgs) -> Result<BenchmarkReport, String> {
    let workspace = std::env::current_dir().map_err(|e| format!("no working folder: {e}"))?;
    let source = DataSource { workspace, max_walks: args.max_walks };
    let mut options = EvalOptions { configurations: args.configurations.clone(), ..EvalOptions::default() };
    if let Some(t) = args.threads {
        options.calibration.threads = t;
    }
    let rows: Vec<_> = (ROWS.iter().chain(&LEARNING_ROWS))
        .filter(|r| match args.rows.is_empty() {
            true => !r.learning() || args.learning,
            false => args.rows.contains(&r.name()),
        })
        .collect();
    let mut reports = Vec::new();
    for (i, row) in rows.iter().enumerate() {
        let started = Instant::now();
        eprintln!("row {}/{}: {}", i + 1, rows.len(), row.name());
        let (floors, unlabelled) = match row.floors(&source) {
            Ok(f) => f,
            Err(LoadError::Absent(reason)) => {
                eprintln!("  skipped: {reason}");
                reports.push(RowReport::skipped(row, reason));
                continue;
            }
            Err(e) => return Err(format!("{}: {e}", row.name())),
        };
        // One bar: the calibration's steps, then one step per test walk.
        let walks: usize = floors.iter().map(|f| f.test.len()).sum();
        let bar = shared::progress_bar(
            false,
            (calibration_steps(&floors, &options.calibration) + walks) as u64,
            "  calibrating, then replaying the test walks",
        );
        let tick = || bar.inc(1);
        let report = evaluate_row(row, &floors, &unlabelled, &options, started, &tick, &tick)
            .map_err(|e| format!("{}: {e}", row.name()))?;
        bar.finish_and_clear();
        eprintln!("  {} test walks in {:.0} s", report.test_walks, report.seconds);
        if !args.json {
            print_row(&report);
        }
        reports.push(report);
    }
    Ok(BenchmarkReport::new(reports, args.max_walks))
}

/// One row's table.
fn print_row(row: &RowReport) {
    if let Some(reason) = &row.skipped {
        println!("\n{}: skipped ({reason})", row.name());
        return;
    }
    println!(
        "\n{}{}: {} test walks, survey fraction {}, {:.0} s",
        row.name(),
        if row.learning { " (learned from use, not in the mean)" } else { "" },
        row.test_walks,
        row.survey_fraction,
        row.seconds
    );
    println!(
        "{:<26} {:>7} {:>6} {:>7} {:>7} {:>6} {:>6} {:>6} {:>7}",
        "configuration", "mean", "± SE", "p75", "p90", "hit68", "hit95", "floor", "epochs"
    );
    for (key, f) in &row.configurations {
        println!(
            "{key:<26} {:>7.2} {:>6} {:>7.2} {:>7.2} {:>6.3} {:>6.3} {:>6.3} {:>7}",
            f.mean_m,
            f.mean_se_m.map_or("-".into(), |se| format!("{se:.2}")),
            f.p75_m,
            f.p90_m,
            f.accuracy_68_hit,
            f.accuracy_95_hit,
            f.floor_hit,
            f.epochs
        );
    }
}

/// The mean over buildings.
fn print_mean(report: &BenchmarkReport) {
    if report.buildings.is_empty() {
        println!("\nno row evaluated: no mean over buildings");
        return;
    }
    let quick = report.max_walks.map_or(String::new(), |n| format!("; only {n} walk files per floor"));
    println!("\nmean over buildings ({}){quick}:", report.buildings.join(", "));
    println!(
        "{:<26} {:>7} {:>7} {:>6} {:>6} {:>6}",
        "configuration", "mean", "p75", "hit68", "hit95", "floor"
    );
    for (key, m) in &report.mean {
        println!(
            "{key:<26} {:>7.2} {:>7.2} {:>6.3} {:>6.3} {:>6.3}",
            m.mean_m, m.p75_m, m.accuracy_68_hit, m.accuracy_95_hit, m.floor_hit
        );
    }
}

/// The verdict in a line.
fn verdict_line(c: &Comparison) -> String {
    let mean = c.mean.as_ref().map_or(String::new(), |m| format!("mean {:+.3} m: ", m.delta_m()));
    match &c.verdict {
        Verdict::Keep => {
            format!("{mean}keep (the mean over buildings improves, no building worse beyond its SE)")
        }
        Verdict::Reject(why) => format!("{mean}reject: {why}"),
    }
}

/// The judged configuration's changes per row and building, and the verdict.
fn comparison_table(c: &Comparison) -> String {
    let mut text = format!(
        "`{}` against the baseline, mean error, m (SE: the baseline's walk bootstrap):\n",
        c.configuration
    );
    text += &format!("{:<26} {:>9} {:>9} {:>8} {:>7}\n", "", "baseline", "this run", "change", "SE");
    for change in c.rows.iter().chain(&c.buildings).chain(&c.mean) {
        let flag = if change.baseline_se_m.is_some() && change.worse_beyond_se() { " worse" } else { "" };
        text += &format!(
            "{:<26} {:>9.3} {:>9.3} {:>+8.3} {:>7}{flag}\n",
            change.name,
            change.baseline_m,
            change.current_m,
            change.delta_m(),
            change.baseline_se_m.map_or("-".into(), |se| format!("{se:.3}"))
        );
    }
    if !c.not_compared.is_empty() {
        text += &format!("not compared (skipped, or in one run only): {}\n", c.not_compared.join(", "));
    }
    text += &format!("verdict on {}: {}\n", c.configuration, verdict_line(c));
    text
}
