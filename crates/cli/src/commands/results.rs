//! `waymark results`: `docs/results.md` from the committed JSON in `docs/results/`, so that
//! every figure the results page shows is one a command wrote (or, for the hand-timed speed
//! figures, one a person wrote down with its command), and a stale page is caught.
//!
//! Each input is recognised by its file name: `benchmark.json` (`waymark benchmark --json`,
//! required), `demo.json` (`waymark demo --json`), `simulate.json` (`waymark simulate --runs 30
//! --json`) and `speed.json` (hand-maintained, [`Speed`]). The page's order does not depend on
//! the order they are given in.

use serde::Deserialize;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use waymark_eval::benchmark::{BenchmarkReport, Figures, RowReport};

/// How the page tells the reader to regenerate it; also what `--check` prints.
const REGENERATE: &str = "cargo run -p waymark-cli -- results docs/results/*.json > docs/results.md";

#[derive(clap::Args)]
pub struct ResultsArgs {
    /// The JSON files (`benchmark.json`, and any of `demo.json`, `simulate.json`,
    /// `speed.json`), as `docs/results/*.json`.
    #[arg(required = true, value_name = "FILE.json")]
    inputs: Vec<PathBuf>,
    /// Instead of printing the page, compare it with FILE and fail when they differ.
    #[arg(long, value_name = "FILE.md")]
    check: Option<PathBuf>,
}

/// The hand-maintained speed figures: timings that no JSON of a command holds (CPU per
/// position on the five-floor site, the engine's resident memory, a whole run's CPU time).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Speed {
    /// Where the figures were measured, said once above the tables.
    pub machine: String,
    /// One table each, under its own heading (`### title`); code comments cite the headings.
    pub sections: Vec<SpeedSection>,
}

/// One table of [`Speed`].
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpeedSection {
    pub title: String,
    /// A paragraph under the heading: what the figures measure.
    #[serde(default)]
    pub text: String,
    pub rows: Vec<SpeedRow>,
}

/// One figure of [`Speed`].
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpeedRow {
    pub figure: String,
    /// As measured, with its unit; a range where runs differ.
    pub value: String,
    #[serde(default)]
    pub target: String,
    /// The command that measures it.
    pub command: String,
}

/// Everything the page is made from.
#[derive(Debug, Default)]
pub struct Inputs {
    pub benchmark: Option<BenchmarkReport>,
    pub demo: Option<Value>,
    pub simulate: Option<Value>,
    pub speed: Option<Speed>,
}

pub fn run(args: &ResultsArgs) -> ExitCode {
    let page = match read(&args.inputs).and_then(|inputs| render(&inputs)) {
        Ok(page) => page,
        Err(e) => {
            eprintln!("waymark results: {e}");
            return ExitCode::FAILURE;
        }
    };
    let Some(path) = &args.check else {
        print!("{page}");
        return ExitCode::SUCCESS;
    };
    let current = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(e) => {
            eprintln!("waymark results: {}: {e}", path.display());
            return ExitCode::FAILURE;
        }
    };
    if current == page {
        return ExitCode::SUCCESS;
    }
    let line = current.lines().zip(page.lines()).position(|(a, b)| a != b);
    let line = line.unwrap_or_else(|| current.lines().count().min(page.lines().count())) + 1;
    eprintln!(
        "waymark results: {} is stale: it differs from what the JSON makes from line {line} on.\n\
         Regenerate it with `{REGENERATE}`.",
        path.display()
    );
    ExitCode::FAILURE
}

/// Reads each file as what its name says it is.
pub fn read(paths: &[PathBuf]) -> Result<Inputs, String> {
    let mut inputs = Inputs::default();
    for path in paths {
        let json = |path: &Path| -> Result<Value, String> {
            let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
            serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))
        };
        match path.file_stem().and_then(|s| s.to_str()) {
            Some("benchmark") => inputs.benchmark = Some(BenchmarkReport::read(path)?),
            Some("demo") => inputs.demo = Some(json(path)?),
            Some("simulate") => inputs.simulate = Some(json(path)?),
            Some("speed") => {
                let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
                inputs.speed =
                    Some(serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?);
            }
            _ => {
                return Err(format!(
                    "{}: not one of benchmark.json, demo.json, simulate.json, speed.json",
                    path.display()
                ))
            }
        }
    }
    Ok(inputs)
}

/// The configurations the summary table shows, in its column order.
const SUMMARY: [&str; 4] = ["forward-auto", "fixed-lag-auto", "viterbi-auto", "wifi-knn"];

/// What a benchmark building is, for the reader (`docs/benchmark.md#rows`).
fn building_title(building: &str) -> (&str, &str) {
    match building {
        "ilc20-site1" => (
            "Five floors",
            "Indoor Location Competition 2.0, site 1: a mall's floors B1 and F1-F4 as one site, one phone \
             model; a test walk is every fifth file of a floor.",
        ),
        "ipin2023-t3" => (
            "The museum",
            "IPIN 2023 Track 3 training logfiles: a museum, floors 0, −1 and −2, two phone models; \
             each split surveys with one set of walks and tests on the other.",
        ),
        other => (other, ""),
    }
}

/// The whole page.
pub fn render(inputs: &Inputs) -> Result<String, String> {
    let benchmark = inputs.benchmark.as_ref().ok_or("benchmark.json is required")?;
    let mut out = String::new();
    let w = &mut out;
    line(w, "# Results");
    line(w, "");
    line(
        w,
        "<!-- Generated from docs/results/*.json by `waymark results`; edit the JSON, not this page. -->",
    );
    line(w, "");
    line(w, "The current figures, each generated from committed JSON in `docs/results/`: the benchmark");
    line(w, "and the simulations as their commands wrote it, the speed figures as measured by hand with");
    line(w, "the command beside each. What the defaults are and why: [tuning.md](tuning.md); what the");
    line(w, "radii mean: [accuracy.md](accuracy.md).");
    line(w, "");
    line(w, "## Reproducing");
    line(w, "");
    line(w, "```sh");
    line(w, "cargo build --release -p waymark-cli       # leaves target/release/waymark");
    line(w, "./target/release/waymark benchmark --threads 2 --json --out docs/results/benchmark.json");
    line(w, "./target/release/waymark demo --json > docs/results/demo.json");
    line(w, "./target/release/waymark simulate --runs 30 --json > docs/results/simulate.json");
    line(w, REGENERATE);
    line(w, "```");
    line(w, "");
    line(
        w,
        "The benchmark reads recorded walks ([testing.md](testing.md#real-data) says where to put them);",
    );
    line(w, "the simulations need nothing. `docs/results/speed.json` is written by hand: each figure names");
    line(w, "the command that measures it. `docs/results/benchmark.json` is also the baseline a change is");
    line(w, "judged against (`waymark benchmark --baseline docs/results/benchmark.json`,");
    line(w, "[benchmark.md](benchmark.md#rule)). The test command (`scripts/test.sh`) fails when this page");
    line(w, "is not what the JSON makes.");
    line(w, "");
    render_benchmark(w, benchmark);
    if inputs.demo.is_some() || inputs.simulate.is_some() {
        line(w, "## Simulated office");
        line(w, "");
        if let Some(demo) = &inputs.demo {
            render_demo(w, demo)?;
        }
        if let Some(simulate) = &inputs.simulate {
            render_simulate(w, simulate)?;
        }
    }
    if let Some(speed) = &inputs.speed {
        render_speed(w, speed, benchmark);
    }
    Ok(out)
}

fn line(w: &mut String, text: &str) {
    w.push_str(text);
    w.push('\n');
}

fn row_name(row: &RowReport) -> String {
    format!("{}/{}", row.building, row.split)
}

fn render_benchmark(w: &mut String, report: &BenchmarkReport) {
    line(w, "## The benchmark");
    line(w, "");
    line(w, "`waymark benchmark --threads 2 --json` ([benchmark.md](benchmark.md)): each row surveys and");
    line(w, "calibrates a site from its survey walks and scores every test walk at each WiFi scan. Mean");
    line(w, "error in metres with its walk-bootstrap standard error; p75 is the IPIN competitions' score;");
    line(w, "a wrong floor adds 15 m; \"holds\" is the share of scored points within the reported 68% / 95%");
    line(w, "radius (forward-auto); time is the row's wall-clock time on two cores.");
    line(w, "");
    line(w, "| row | test walks | forward-auto | fixed-lag-auto | viterbi-auto | wifi-knn | p75 | 68% / 95% holds | floor hit | time |");
    line(w, "|---|---|---|---|---|---|---|---|---|---|");
    for row in &report.rows {
        if let Some(reason) = &row.skipped {
            line(w, &format!("| {} | skipped: {reason} | | | | | | | | |", row_name(row)));
            continue;
        }
        let mean =
            |c: &str| row.configurations.get(c).map(|f| format!("{:.2}", f.mean_m)).unwrap_or_default();
        let mut cells = vec![row_name(row), row.test_walks.to_string()];
        match row.configurations.get(SUMMARY[0]) {
            Some(f) => cells.push(match f.mean_se_m {
                Some(se) => format!("{:.2} ± {se:.2}", f.mean_m),
                None => format!("{:.2}", f.mean_m),
            }),
            None => cells.push(String::new()),
        }
        cells.extend(SUMMARY[1..].iter().map(|c| mean(c)));
        match row.configurations.get(SUMMARY[0]) {
            Some(f) => cells.extend([
                format!("{:.2}", f.p75_m),
                format!("{:.3} / {:.3}", f.accuracy_68_hit, f.accuracy_95_hit),
                format!("{:.3}", f.floor_hit),
            ]),
            None => cells.extend([String::new(), String::new(), String::new()]),
        }
        cells.push(format!("{:.0} s", row.seconds));
        line(w, &format!("| {} |", cells.join(" | ")));
    }
    line(w, "");
    if !report.mean.is_empty() {
        line(
            w,
            &format!(
                "The mean over buildings ({}), each building's rows averaged first:",
                report.buildings.join(", ")
            ),
        );
        line(w, "");
        line(w, "| configuration | mean | p75 | 68% / 95% holds | floor hit |");
        line(w, "|---|---|---|---|---|");
        for (name, m) in &report.mean {
            line(
                w,
                &format!(
                    "| `{name}` | {:.2} | {:.2} | {:.3} / {:.3} | {:.3} |",
                    m.mean_m, m.p75_m, m.accuracy_68_hit, m.accuracy_95_hit, m.floor_hit
                ),
            );
        }
        line(w, "");
    }
    let mut buildings: Vec<&str> = Vec::new();
    for row in &report.rows {
        if !buildings.contains(&row.building.as_str()) {
            buildings.push(&row.building);
        }
    }
    for building in buildings {
        let (title, about) = building_title(building);
        line(w, &format!("### {title}"));
        line(w, "");
        if !about.is_empty() {
            line(w, about);
            line(w, "");
        }
        for row in report.rows.iter().filter(|r| r.building == building && r.skipped.is_none()) {
            if row.survey_fraction < 1.0 {
                line(w, "#### Survey fraction");
                line(w, "");
                line(
                    w,
                    &format!(
                        "`{}`: the site surveyed and calibrated from a share F = {} of each floor's survey",
                        row_name(row),
                        row.survey_fraction
                    ),
                );
                line(w, "walks, kept in file-name order when ⌈(i + 1)·F⌉ > ⌈i·F⌉ (spread evenly, the first always);");
                line(w, "the test walks are the same.");
            } else {
                line(w, &format!("#### `{}`", row_name(row)));
                line(w, "");
                line(
                    w,
                    &format!(
                        "{} test walks, {} points scored per configuration.",
                        row.test_walks,
                        epochs(row)
                    ),
                );
            }
            line(w, "");
            configurations_table(w, row);
        }
    }
}

fn epochs(row: &RowReport) -> String {
    let mut counts: Vec<usize> = row.configurations.values().map(|f| f.epochs).collect();
    counts.dedup();
    match counts.as_slice() {
        [n] => n.to_string(),
        _ => "varying".to_string(),
    }
}

fn configurations_table(w: &mut String, row: &RowReport) {
    line(w, "| configuration | mean | ± SE | p75 | p90 | 68% holds | 95% holds | floor hit |");
    line(w, "|---|---|---|---|---|---|---|---|");
    for (name, f) in &row.configurations {
        line(w, &figures_row(name, f));
    }
    line(w, "");
}

fn figures_row(name: &str, f: &Figures) -> String {
    let se = f.mean_se_m.map(|se| format!("{se:.2}")).unwrap_or_default();
    format!(
        "| `{name}` | {:.2} | {se} | {:.2} | {:.2} | {:.3} | {:.3} | {:.3} |",
        f.mean_m, f.p75_m, f.p90_m, f.accuracy_68_hit, f.accuracy_95_hit, f.floor_hit
    )
}

/// A number at `path` (keys separated by '.') of a JSON object.
fn number(value: &Value, path: &str) -> Result<f64, String> {
    path.split('.')
        .try_fold(value, |v, key| v.get(key))
        .and_then(Value::as_f64)
        .ok_or_else(|| format!("no number at `{path}`"))
}

fn render_demo(w: &mut String, demo: &Value) -> Result<(), String> {
    let demo_err = |e: String| format!("demo.json: {e}");
    let n = |path: &str| number(demo, path).map_err(demo_err);
    line(w, &format!(
        "`waymark demo --json`: {} random walks of about {} m through a simulated office ({} states, {} access",
        n("walks")?, n("walk_length_m")?, n("states")?, n("access_points")?
    ));
    line(w, "points) from synthetic raw IMU at 100 Hz and a WiFi scan every 1.5 s, through the default");
    line(w, &format!("engine; {} epochs scored, seed {}. Metres; room accuracy is the share of epochs whose most likely", n("epochs")?, n("seed")?));
    line(w, "zone is the true one.");
    line(w, "");
    line(w, "| mean | median | p90 | max | RMSE | 68% radius holds | room accuracy |");
    line(w, "|---|---|---|---|---|---|---|");
    line(
        w,
        &format!(
            "| {:.2} | {:.2} | {:.2} | {:.1} | {:.2} | {:.3} | {:.3} |",
            n("mean_error_m")?,
            n("median_error_m")?,
            n("p90_error_m")?,
            n("max_error_m")?,
            n("rmse_m")?,
            n("accuracy_68_hit")?,
            n("room_accuracy")?
        ),
    );
    line(w, "");
    Ok(())
}

fn render_simulate(w: &mut String, simulate: &Value) -> Result<(), String> {
    let sim_err = |e: String| format!("simulate.json: {e}");
    let n = |path: &str| number(simulate, path).map_err(sim_err);
    line(w, "### The papers' experiments");
    line(w, "");
    line(
        w,
        &format!(
            "`waymark simulate --runs {} --json`: Hoang et al.'s Table 1 and HIPE's Table 5 scenarios on the",
            n("runs")?
        ),
    );
    line(
        w,
        &format!(
        "same {} walks of the office (seed {}, {} epochs per method). Hoang's figures are from the paper's",
        n("runs")?, n("seed")?, n("epochs")?
    ),
    );
    line(w, "own simulation, for comparison; HIPE's are from its office and are not repeated.");
    line(w, "");
    line(w, "| Hoang et al. Table 1 | mean error | paper |");
    line(w, "|---|---|---|");
    for (name, key, paper) in [
        ("RSSI only", "rssi_only", 1.74),
        ("RSSI + step detection, censoring ignored", "rssi_step_uncensored", 1.42),
        ("RSSI + step detection", "rssi_step", 1.37),
        ("RSSI + step detection + pseudo states (the default engine)", "rssi_step_pseudo", 1.02),
    ] {
        line(w, &format!("| {name} | {:.2} | {paper:.2} |", n(&format!("hoang_table1.{key}"))?));
    }
    line(w, "");
    line(w, "| HIPE Table 5 scenario | RMSE | mean | max |");
    line(w, "|---|---|---|---|");
    for (name, key) in [
        ("measured distance & heading", "distance_heading"),
        ("measured distance", "distance"),
        ("measured heading & assumed speed", "heading_speed"),
        ("assumed speed", "speed"),
        ("single-scan MLE (no HMM)", "mle"),
    ] {
        line(
            w,
            &format!(
                "| {name} | {:.2} | {:.2} | {:.1} |",
                n(&format!("hipe_table5.{key}.rmse_m"))?,
                n(&format!("hipe_table5.{key}.mean_m"))?,
                n(&format!("hipe_table5.{key}.max_m"))?
            ),
        );
    }
    line(w, "");
    let lags = simulate
        .get("fixed_lag_mean_error_m")
        .and_then(Value::as_array)
        .ok_or_else(|| sim_err("no array at `fixed_lag_mean_error_m`".into()))?;
    let lags: Vec<(f64, f64)> = lags
        .iter()
        .map(|pair| match pair.as_array().map(Vec::as_slice) {
            Some([lag, e]) => lag.as_f64().zip(e.as_f64()).ok_or(()),
            _ => Err(()),
        })
        .collect::<Result<_, _>>()
        .map_err(|()| sim_err("`fixed_lag_mean_error_m` is not a list of [lag, metres]".into()))?;
    line(w, "The default engine's fixed-lag estimate by lag (epochs), mean error in metres:");
    line(w, "");
    line(
        w,
        &format!("| lag | {} |", lags.iter().map(|(l, _)| format!("{l}")).collect::<Vec<_>>().join(" | ")),
    );
    line(w, &format!("|---|{}", "---|".repeat(lags.len())));
    line(
        w,
        &format!(
            "| mean error | {} |",
            lags.iter().map(|(_, e)| format!("{e:.3}")).collect::<Vec<_>>().join(" | ")
        ),
    );
    line(w, "");
    let rooms = simulate
        .get("room_accuracy")
        .and_then(Value::as_object)
        .ok_or_else(|| sim_err("no object at `room_accuracy`".into()))?;
    line(w, "Room accuracy (El Gemayel et al.: the share of epochs whose most likely zone, of the office's");
    line(w, "ten rooms, the aisle and the stair hall, is the true one):");
    line(w, "");
    line(w, "| method | room accuracy |");
    line(w, "|---|---|");
    for (name, hit) in rooms {
        let hit = hit.as_f64().ok_or_else(|| sim_err(format!("`room_accuracy.{name}` is not a number")))?;
        line(w, &format!("| {name} | {:.1}% |", 100.0 * hit));
    }
    line(w, "");
    Ok(())
}

fn render_speed(w: &mut String, speed: &Speed, benchmark: &BenchmarkReport) {
    line(w, "## Speed and memory");
    line(w, "");
    line(
        w,
        &format!("Measured by hand on {}; each figure with the command that measures it.", speed.machine),
    );
    let timed: f64 = benchmark.rows.iter().map(|r| r.seconds).sum();
    line(
        w,
        &format!(
            "The benchmark's rows above took {:.1} min of wall-clock time together (`seconds` in its JSON).",
            timed / 60.0
        ),
    );
    line(w, "");
    for section in &speed.sections {
        line(w, &format!("### {}", section.title));
        line(w, "");
        if !section.text.is_empty() {
            line(w, &section.text);
            line(w, "");
        }
        line(w, "| figure | measured | target | command |");
        line(w, "|---|---|---|---|");
        for row in &section.rows {
            line(w, &format!("| {} | {} | {} | `{}` |", row.figure, row.value, row.target, row.command));
        }
        line(w, "");
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeMap;
    use waymark_eval::benchmark::MeanFigures;

    fn figures(mean_m: f64) -> Figures {
        Figures {
            mean_m,
            p90_m: 2.0 * mean_m,
            p75_m: 1.5 * mean_m,
            accuracy_68_hit: 0.68,
            accuracy_95_hit: 0.95,
            floor_hit: 1.0,
            mean_se_m: Some(0.25),
            epochs: 100,
        }
    }

    fn row(split: &str, survey_fraction: f64) -> RowReport {
        RowReport {
            building: "ilc20-site1".into(),
            split: split.into(),
            survey_fraction,
            learning: false,
            skipped: None,
            test_walks: 7,
            seconds: 61.0,
            configurations: BTreeMap::from([
                ("forward-auto".to_string(), figures(4.0)),
                ("wifi-knn".to_string(), figures(8.0)),
            ]),
            walks: Vec::new(),
        }
    }

    fn inputs() -> Inputs {
        let mean = MeanFigures {
            mean_m: 4.0,
            p75_m: 6.0,
            accuracy_68_hit: 0.68,
            accuracy_95_hit: 0.95,
            floor_hit: 1.0,
        };
        let benchmark = BenchmarkReport {
            rows: vec![row("F=1", 1.0), row("F=0.5", 0.5)],
            mean: BTreeMap::from([("forward-auto".to_string(), mean)]),
            buildings: vec!["ilc20-site1".into()],
            max_walks: None,
        };
        let speed = Speed {
            machine: "a test".into(),
            sections: vec![SpeedSection {
                title: "Speed".into(),
                text: String::new(),
                rows: vec![SpeedRow {
                    figure: "an epoch".into(),
                    value: "1 ms".into(),
                    target: "≤ 2 ms".into(),
                    command: "waymark bench".into(),
                }],
            }],
        };
        Inputs { benchmark: Some(benchmark), demo: None, simulate: None, speed: Some(speed) }
    }

    #[test]
    fn renders_the_benchmark_rows_and_the_speed_table() {
        let page = render(&inputs()).unwrap();
        assert!(page.contains(
            "| ilc20-site1/F=1 | 7 | 4.00 ± 0.25 |  |  | 8.00 | 6.00 | 0.680 / 0.950 | 1.000 | 61 s |"
        ));
        assert!(page.contains("### Five floors\n"));
        assert!(page.contains("#### Survey fraction\n"));
        assert!(page.contains("| `forward-auto` | 4.00 | 0.25 | 6.00 | 8.00 | 0.680 | 0.950 | 1.000 |"));
        assert!(page.contains("## Speed and memory\n"));
        assert!(page.contains("| an epoch | 1 ms | ≤ 2 ms | `waymark bench` |"));
        assert!(page.contains("2.0 min of wall-clock time"));
        // The same inputs make the same page, whatever else: the check compares bytes.
        assert_eq!(page, render(&inputs()).unwrap());
    }

    #[test]
    fn renders_the_simulations_and_names_a_missing_field() {
        let demo = serde_json::json!({"walks": 2, "walk_length_m": 200.0, "states": 472, "access_points": 15,
            "epochs": 10, "seed": 0, "mean_error_m": 0.5, "median_error_m": 0.4, "p90_error_m": 1.0,
            "max_error_m": 3.0, "rmse_m": 0.7, "accuracy_68_hit": 0.8, "room_accuracy": 0.9});
        let row = serde_json::json!({"rmse_m": 1.0, "mean_m": 0.9, "max_m": 5.0});
        let simulate = serde_json::json!({"runs": 2, "seed": 0, "epochs": 10,
            "hoang_table1": {"rssi_only": 1.2, "rssi_step_uncensored": 1.1, "rssi_step": 1.0, "rssi_step_pseudo": 0.5},
            "hipe_table5": {"distance_heading": row, "distance": row, "heading_speed": row, "speed": row, "mle": row},
            "fixed_lag_mean_error_m": [[0, 0.5], [3, 0.4]], "room_accuracy": {"MLE": 0.86}});
        let mut inputs = inputs();
        inputs.demo = Some(demo);
        inputs.simulate = Some(simulate.clone());
        let page = render(&inputs).unwrap();
        assert!(page.contains("## Simulated office\n"));
        assert!(page.contains("| 0.50 | 0.40 | 1.00 | 3.0 | 0.70 | 0.800 | 0.900 |"));
        assert!(page.contains("| RSSI + step detection + pseudo states (the default engine) | 0.50 | 1.02 |"));
        assert!(page.contains("| mean error | 0.500 | 0.400 |"));
        assert!(page.contains("| MLE | 86.0% |"));
        let mut broken = simulate;
        broken["hoang_table1"].as_object_mut().unwrap().remove("rssi_step");
        inputs.simulate = Some(broken);
        assert_eq!(render(&inputs).unwrap_err(), "simulate.json: no number at `hoang_table1.rssi_step`");
    }
}
