//! `waymark`: the command-line tool for the engineer who surveys a building and measures
//! accuracy. `waymark demo` runs the engine on a built-in simulated office.

mod app_engine;
mod commands;
mod shared;

use clap::{Parser, Subcommand};
use commands::{
    bench, benchmark, demo, eval, evidence, hmm, replay, results, route, sim_export, simulate, site, survey,
    view,
};
use std::process::ExitCode;

#[derive(Parser)]
#[command(name = "waymark", version, about = "Indoor positioning engine: demo and tools")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

// One command is parsed once per run: the size of its largest arguments (eval's) costs nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Subcommand)]
enum Command {
    /// Track random walks through a simulated office from raw accelerometer, gyroscope and
    /// magnetometer samples and WiFi scans, and print the error.
    Demo(demo::DemoArgs),
    /// The papers' artificial-data experiments on the same walks: Hoang et al. Table 1 and
    /// HIPE Table 5.
    Simulate(simulate::SimulateArgs),
    /// Write a simulated site file and one walk (raw IMU batches and WiFi scans per epoch,
    /// with the truth) as JSON, for testing the engine from other languages.
    SimExport(sim_export::SimExportArgs),
    /// Build a site file from recorded survey walks (Indoor Location Competition 2.0 format),
    /// one or more floors of one building.
    Survey(survey::SurveyArgs),
    /// Replay one recorded walk through the engine as an app would, writing the track.
    Replay(replay::ReplayArgs),
    /// Survey on the survey walks of the given floors, replay the test walks through every
    /// configuration, and print the errors (split: file i is a test walk when i % 5 == 4).
    Eval(eval::EvalArgs),
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
    Site(site::SiteArgs),
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
    /// Map evidence from walks without labels (docs/evidence.md): merge evidence files of a
    /// site (`evidence merge`), summarise one (`evidence show`).
    Evidence(evidence::EvidenceArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Command::Demo(args) => demo::demo(&args),
        Command::Simulate(args) => simulate::simulate(&args),
        Command::SimExport(args) => sim_export::sim_export(&args),
        Command::Survey(args) => survey::survey(&args),
        Command::Replay(args) => replay::replay(&args),
        Command::Eval(args) => eval::eval(&args),
        Command::Bench(args) => bench::bench(&args),
        Command::Benchmark(args) => benchmark::benchmark(&args),
        Command::Results(args) => results::run(&args),
        Command::Site(args) => site::site(&args),
        Command::Hmm(args) => hmm::hmm(&args),
        Command::View(args) => view::view(&args),
        Command::Route(args) => route::route(&args),
        Command::Evidence(args) => evidence::evidence(&args),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every `waymark` command in a shell block of the guide `docs/your-building.md`, as the
    /// guide writes it: the commands a venue team copies must be ones the binary takes. The
    /// guide writes no quotes, so splitting on whitespace is the shell's own split.
    #[test]
    fn guide_commands_parse() {
        let guide = include_str!("../../../docs/your-building.md");
        let mut commands = 0;
        for block in guide.split("```sh\n").skip(1) {
            let block = block.split("```").next().unwrap_or_default();
            for line in block.lines().filter(|l| l.starts_with("waymark ")) {
                assert!(!line.contains(['"', '\'', '\\']), "quoting in a guide command: {line}");
                if let Err(e) = Cli::try_parse_from(line.split_whitespace()) {
                    panic!("docs/your-building.md: `{line}` is not a waymark command:\n{e}");
                }
                commands += 1;
            }
        }
        assert!(commands >= 4, "the guide's shell blocks hold {commands} waymark commands");
    }
}
