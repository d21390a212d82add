//! Where tests and tools find the competition's site-1 floors (docs/testing.md#real-data):
//! unpacked under the workspace's `target/ilc/site1/`, else unpacked there from the archive
//! `ilc20-site1/<floor>.tar.xz` in the folder `WAYMARK_DATA` names or, without it, in `data/`
//! of a folder beside the checkout.

use std::path::{Path, PathBuf};

/// `floor` of site 1 (`B1`, `F1` ... `F4`) unpacked under `<workspace>/target/ilc/site1/`, or
/// `None`, saying why on stderr, when the data is not there or cannot be unpacked.
pub fn site1_floor(workspace: &Path, floor: &str) -> Option<PathBuf> {
    let unpacked = workspace.join("target/ilc/site1").join(floor);
    if unpacked.join("path_data_files").is_dir() {
        return Some(unpacked);
    }
    let Some(archive) = archive(workspace, floor) else {
        eprintln!("skipping: ilc20-site1/{floor}.tar.xz not found (docs/testing.md#real-data)");
        return None;
    };
    let into = workspace.join("target/ilc");
    std::fs::create_dir_all(&into).ok()?;
    let status = std::process::Command::new("tar").arg("-xJf").arg(&archive).arg("-C").arg(&into).status();
    match status {
        Ok(s) if s.success() => Some(unpacked),
        _ => {
            eprintln!("skipping: could not unpack {}", archive.display());
            None
        }
    }
}

/// The archive of one floor: in `$WAYMARK_DATA/ilc20-site1/`, or without that variable in
/// `data/ilc20-site1/` of a folder beside the checkout.
fn archive(workspace: &Path, floor: &str) -> Option<PathBuf> {
    let relative = Path::new("ilc20-site1").join(format!("{floor}.tar.xz"));
    if let Some(data) = std::env::var_os("WAYMARK_DATA") {
        return Some(Path::new(&data).join(relative)).filter(|a| a.is_file());
    }
    let beside = workspace.canonicalize().ok()?.parent()?.read_dir().ok()?;
    beside.flatten().map(|e| e.path().join("data").join(&relative)).find(|a| a.is_file())
}
