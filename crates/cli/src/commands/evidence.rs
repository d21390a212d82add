//! `waymark evidence`: map evidence files (docs/evidence.md) merged and summarised.

use crate::shared::fail;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use waymark_engine::evidence::{Evidence, EVIDENCE_FORMAT_VERSION, MAX_EVIDENCE_BYTES};

#[derive(clap::Args)]
pub struct EvidenceArgs {
    #[command(subcommand)]
    command: EvidenceCommand,
}

#[derive(clap::Subcommand)]
enum EvidenceCommand {
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
        EvidenceCommand::Merge { out, inputs } => merge(out, inputs),
        EvidenceCommand::Show { input, json } => show(input, *json),
    };
    result.unwrap_or_else(|e| fail("evidence", e))
}

fn read(path: &Path) -> Result<Evidence, String> {
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
        let evidence = read(path)?;
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
    let e = read(path)?;
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
