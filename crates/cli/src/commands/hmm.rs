//! `waymark hmm decode|fit`: the HMM learning core on a JSON model, for checking against other
//! implementations (`waymark_engine::hmm::learn::json` documents the documents).

use serde::de::DeserializeOwned;
use std::io::{Read, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use waymark_engine::hmm::learn::json::{decode_json, fit_json};

/// Exit status for input that cannot be read, parsed or used (clap uses 2 for bad arguments).
const BAD_INPUT: u8 = 2;

#[derive(clap::Args)]
pub struct HmmArgs {
    #[command(subcommand)]
    verb: HmmVerb,
}

// The doc comments are `--help` text: JSON shapes in brackets, not intra-doc links.
#[allow(rustdoc::broken_intra_doc_links)]
#[derive(clap::Subcommand)]
enum HmmVerb {
    /// Forward-backward and Viterbi. Reads {"initial": [N], "transition": [[N×N]],
    /// "log_emission": [[T×N]]} (null = −∞); prints {"log_likelihood", "filtered", "smoothed",
    /// "viterbi", "viterbi_log_prob"}.
    Decode(Source),
    /// Baum-Welch, plain maximum likelihood. Reads {"initial", "transition", "means": [N][M][D],
    /// "covariances": [N][M][D][D], "observations": [[[T×D]], ...], "iterations": K}; prints
    /// the re-estimated "initial", "transition", "means", "covariances" and "log_likelihood"
    /// (K + 1 values). Zeros in "transition" stay zero.
    Fit(Source),
}

#[derive(clap::Args)]
struct Source {
    /// JSON input file; standard input when absent or `-`.
    input: Option<PathBuf>,
}

pub fn hmm(args: &HmmArgs) -> ExitCode {
    match &args.verb {
        HmmVerb::Decode(source) => run("decode", source, decode_json),
        HmmVerb::Fit(source) => run("fit", source, fit_json),
    }
}

fn run<I: DeserializeOwned, O: serde::Serialize>(
    verb: &str,
    source: &Source,
    compute: impl Fn(&I) -> Result<O, waymark_engine::hmm::learn::LearnError>,
) -> ExitCode {
    let fail = |message: String| {
        eprintln!("waymark hmm {verb}: {message}");
        ExitCode::from(BAD_INPUT)
    };
    let (text, name) = match source.input.as_deref().filter(|p| p.as_os_str() != "-") {
        Some(path) => match std::fs::read_to_string(path) {
            Ok(text) => (text, path.display().to_string()),
            Err(e) => return fail(format!("cannot read {}: {e}", path.display())),
        },
        None => {
            let mut text = String::new();
            if let Err(e) = std::io::stdin().read_to_string(&mut text) {
                return fail(format!("cannot read standard input: {e}"));
            }
            (text, "standard input".to_owned())
        }
    };
    let input: I = match serde_path_to_error::deserialize(&mut serde_json::Deserializer::from_str(&text)) {
        Ok(input) => input,
        Err(e) => {
            let path = e.path().to_string();
            return match path.as_str() {
                "." | "?" => fail(format!("{name}: {}", e.inner())),
                _ => fail(format!("{name}: {path}: {}", e.inner())),
            };
        }
    };
    let output = match compute(&input) {
        Ok(output) => output,
        Err(e) => return fail(format!("{name}: {e}")),
    };
    let mut stdout = std::io::stdout().lock();
    let written = serde_json::to_writer(&mut stdout, &output)
        .map_err(std::io::Error::from)
        .and_then(|_| writeln!(stdout));
    match written {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("waymark hmm {verb}: cannot write the result: {e}");
            ExitCode::FAILURE
        }
    }
}
