//! `waymark evidence`: map evidence files (docs/evidence.md) collected from walks, merged and
//! summarised.

use crate::shared::fail;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use waymark_engine::evidence::{Evidence, EVIDENCE_FORMAT_VERSION, MAX_EVIDENCE_BYTES};
use waymark_survey::calibrate::walk_evidence;
use waymark_survey::io::Trace;

#[derive(clap::Args)]
pub struct EvidenceArgs {
    #[command(subcommand)]
    command: EvidenceCommand,
}

#[derive(clap::Subcommand)]
enum EvidenceCommand {
    /// The map evidence of walks without labels on a site (docs/evidence.md#at-scale): each
    /// walk replayed on it as `waymark survey --unlabelled` replays its walks for soft
    /// evidence, one evidence file per walk, written as `merge` writes its output.
    Collect {
        /// The site the walks are replayed on (`waymark survey` of the labelled walks).
        #[arg(long)]
        site: PathBuf,
        /// Where to write the evidence of the one walk given.
        #[arg(long, required_unless_present = "out_dir", conflicts_with = "out_dir")]
        out: Option<PathBuf>,
        /// A folder to write each walk's evidence in, as `<walk file stem>.wmev`.
        #[arg(long)]
        out_dir: Option<PathBuf>,
        /// As `waymark survey --unsurveyed-margin-m`; the survey's options are the evidence's.
        #[arg(long, default_value_t = waymark_survey::UNSURVEYED_MARGIN_M)]
        unsurveyed_margin_m: f64,
        /// Worker threads with --out-dir (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
        /// Print one JSON object per walk: its minutes, seconds taken, bytes and entries.
        #[arg(long)]
        json: bool,
        /// Walk files in the floors' format (`waymark survey --unlabelled`); their waypoints
        /// are not read.
        #[arg(required = true)]
        walks: Vec<PathBuf>,
    },
    /// Merge evidence files of one site into one: the same bytes in whatever order they are
    /// given. The output is written to a temporary file beside it, synced and renamed, so it
    /// is either the whole merge or untouched.
    Merge {
        /// Where to write the merged evidence.
        #[arg(long)]
        out: PathBuf,
        /// The evidence files.
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
    },
    /// What an evidence file holds: its site, walks, states, transmitters and entries.
    Show {
        /// The evidence file.
        input: PathBuf,
        /// Print one JSON object.
        #[arg(long)]
        json: bool,
    },
}

pub fn evidence(args: &EvidenceArgs) -> ExitCode {
    let result = match &args.command {
        EvidenceCommand::Collect { site, out, out_dir, unsurveyed_margin_m, threads, json, walks } => {
            match (out, out_dir) {
                (Some(out), _) => {
                    collect(site, Destination::File(out), *unsurveyed_margin_m, *threads, *json, walks)
                }
                (None, Some(dir)) => {
                    collect(site, Destination::Folder(dir), *unsurveyed_margin_m, *threads, *json, walks)
                }
                (None, None) => Err("give --out or --out-dir".to_owned()),
            }
        }
        EvidenceCommand::Merge { out, inputs } => merge(out, inputs),
        EvidenceCommand::Show { input, json } => show(input, *json),
    };
    result.unwrap_or_else(|e| fail("evidence", e))
}

/// Where `collect` writes.
enum Destination<'a> {
    /// One walk's evidence to this file.
    File(&'a Path),
    /// Each walk's to `<stem>.wmev` in this folder.
    Folder(&'a Path),
}

/// What one walk's evidence cost and holds.
struct Collected {
    walk: PathBuf,
    out: PathBuf,
    minutes: f64,
    seconds: f64,
    bytes: usize,
    states: usize,
    entries: usize,
}

fn collect(
    site: &Path,
    to: Destination,
    unsurveyed_margin_m: f64,
    threads: Option<usize>,
    json: bool,
    walks: &[PathBuf],
) -> Result<ExitCode, String> {
    let outs: Vec<PathBuf> = match to {
        Destination::File(out) if walks.len() == 1 => vec![out.to_path_buf()],
        Destination::File(_) => {
            return Err(format!(
                "--out takes one walk's evidence, {} walks given: use --out-dir",
                walks.len()
            ))
        }
        Destination::Folder(dir) => {
            std::fs::create_dir_all(dir).map_err(|e| format!("cannot make {}: {e}", dir.display()))?;
            let outs: Vec<PathBuf> = walks
                .iter()
                .map(|w| {
                    let stem = w.file_stem().unwrap_or(w.as_os_str());
                    dir.join(stem).with_extension("wmev")
                })
                .collect();
            let mut seen = std::collections::HashSet::new();
            if let Some(twice) = outs.iter().find(|o| !seen.insert(*o)) {
                return Err(format!(
                    "two walks would write {}: give walk files of other names",
                    twice.display()
                ));
            }
            outs
        }
    };
    let site = std::sync::Arc::new(
        waymark_engine::Site::load(site).map_err(|e| format!("{}: {e}", site.display()))?,
    );
    // Exactly the options `waymark survey` replays its walks without labels with.
    let options = super::survey::calibration_options(unsurveyed_margin_m);
    let jobs: Vec<(&PathBuf, &PathBuf)> = walks.iter().zip(&outs).collect();
    let threads = threads.unwrap_or(options.threads).max(1);
    let results = waymark_survey::calibrate::parallel_map(&jobs, threads, |&(walk, out)| {
        let started = std::time::Instant::now();
        // Read as `waymark survey --unlabelled` reads its walks: without their waypoints.
        let trace = Trace::read(walk).map_err(|e| e.to_string())?;
        let trace = Trace { waypoints: Vec::new(), ..trace };
        let evidence =
            walk_evidence(&site, &trace, &options).map_err(|e| format!("{}: {e}", walk.display()))?;
        let bytes = evidence.to_bytes();
        write_atomically(out, &bytes)?;
        Ok(Collected {
            walk: walk.clone(),
            out: out.clone(),
            minutes: walk_minutes(&trace),
            seconds: started.elapsed().as_secs_f64(),
            bytes: bytes.len(),
            states: evidence.states_scanned(),
            entries: evidence.heard_entries(),
        })
    });
    let mut failed = None;
    for result in results {
        match result {
            Ok(c) if json => println!(
                "{}",
                serde_json::json!({
                    "walk": c.walk, "out": c.out, "walk_minutes": c.minutes, "seconds": c.seconds,
                    "bytes": c.bytes, "states": c.states, "entries": c.entries,
                })
            ),
            Ok(c) => println!(
                "{}: {:.1} min walked, {} states, {} entries, {} bytes in {:.2} s, written to {}",
                c.walk.display(),
                c.minutes,
                c.states,
                c.entries,
                c.bytes,
                c.seconds,
                c.out.display()
            ),
            Err(e) => {
                eprintln!("waymark evidence: {e}");
                failed = Some(e);
            }
        }
    }
    match failed {
        Some(e) => Err(e),
        None => Ok(ExitCode::SUCCESS),
    }
}

/// A walk's length in minutes: from its first sensor sample or scan to its last.
fn walk_minutes(trace: &Trace) -> f64 {
    let times = (trace.accelerometer.iter().map(|s| s.timestamp_ns))
        .chain(trace.wifi_scans.iter().map(|s| s.timestamp_ns))
        .chain(trace.beacons.iter().map(|b| b.0));
    let (first, last) = times.fold((u64::MAX, 0), |(a, b), t| (a.min(t), b.max(t)));
    last.saturating_sub(first) as f64 / 60e9
}

/// An evidence file, refused when over [`MAX_EVIDENCE_BYTES`] before it is read.
pub fn read_evidence(path: &Path) -> Result<Evidence, String> {
    // A file over the limit is refused before it is read into memory.
    let size = std::fs::metadata(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?.len();
    if size > MAX_EVIDENCE_BYTES as u64 {
        return Err(format!(
            "{}: {size} bytes is over the evidence limit of {MAX_EVIDENCE_BYTES}",
            path.display()
        ));
    }
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    Evidence::from_bytes(&bytes).map_err(|e| format!("{}: {e}", path.display()))
}

fn merge(out: &Path, inputs: &[PathBuf]) -> Result<ExitCode, String> {
    let mut merged: Option<Evidence> = None;
    for path in inputs {
        let evidence = read_evidence(path)?;
        match &mut merged {
            None => merged = Some(evidence),
            Some(m) => m.merge(&evidence).map_err(|e| format!("{}: {e}", path.display()))?,
        }
    }
    let merged = merged.ok_or("no evidence file given")?;
    write_atomically(out, &merged.to_bytes())?;
    println!(
        "{} walks, {} states, {} transmitters, {} entries written to {}",
        merged.walks(),
        merged.states_scanned(),
        merged.transmitters(),
        merged.heard_entries(),
        out.display()
    );
    Ok(ExitCode::SUCCESS)
}

/// Writes `bytes` to `path` through a temporary file in the same folder, synced before the
/// rename and the folder after it, so that a crash or a full disk leaves the old file or none,
/// never part of the new one.
fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), String> {
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let cannot = |e: std::io::Error| format!("cannot write {}: {e}", path.display());
    let mut file = tempfile::NamedTempFile::new_in(folder).map_err(cannot)?;
    file.write_all(bytes).map_err(cannot)?;
    file.as_file().sync_all().map_err(cannot)?;
    file.persist(path).map_err(|e| cannot(e.error))?;
    // The rename itself is durable once the folder is synced (where the platform allows it).
    if let Ok(dir) = std::fs::File::open(folder) {
        let _ = dir.sync_all();
    }
    Ok(())
}

fn show(path: &Path, json: bool) -> Result<ExitCode, String> {
    let e = read_evidence(path)?;
    if json {
        let summary = serde_json::json!({
            "format_version": EVIDENCE_FORMAT_VERSION,
            "site_key": format!("{:016x}", e.key()),
            "site_states": e.state_count(),
            "clip_dbm": e.clip_dbm(),
            "walks": e.walks(),
            "states": e.states_scanned(),
            "transmitters": e.transmitters(),
            "entries": e.heard_entries(),
        });
        println!("{summary}");
    } else {
        println!(
            "site {:016x} ({} states, clip {} dBm): {} walks; scans at {} states; {} transmitters heard in {} entries",
            e.key(),
            e.state_count(),
            e.clip_dbm(),
            e.walks(),
            e.states_scanned(),
            e.transmitters(),
            e.heard_entries()
        );
    }
    Ok(ExitCode::SUCCESS)
}
