//! Where tests and tools find the real data (docs/testing.md#real-data): the competition's
//! site-1 floors unpacked under the workspace's `target/ilc/site1/`, and the IPIN 2023 museum's
//! logfiles under `target/ipin/ipin2023-t3/`; else unpacked there from their archives
//! (`ilc20-site1/<floor>.tar.xz`, `ipin2023-t3/ipin2023-t3.tar.xz`) in the folder
//! `WAYMARK_DATA` names or, without it, in `data/` of a folder beside the checkout.

use std::path::{Path, PathBuf};

/// The floors of the Indoor Location Competition 2.0's site 1 the evaluation uses, as one
/// site (`docs/testing.md#real-data`).
pub const SITE1_FLOORS: [&str; 5] = ["B1", "F1", "F2", "F3", "F4"];

/// Every floor of [`SITE1_FLOORS`] as [`site1_floor`] finds it, or `None` when one is missing.
pub fn site1_floors(workspace: &Path) -> Option<Vec<PathBuf>> {
    SITE1_FLOORS.iter().map(|floor| site1_floor(workspace, floor)).collect()
}

/// `floor` of site 1 (`B1`, `F1` ... `F4`) unpacked under `<workspace>/target/ilc/site1/`, or
/// `None`, saying why on stderr, when the data is not there or cannot be unpacked.
pub fn site1_floor(workspace: &Path, floor: &str) -> Option<PathBuf> {
    let unpacked = workspace.join("target/ilc/site1").join(floor);
    if unpacked.join("path_data_files").is_dir() {
        return Some(unpacked);
    }
    unpack(workspace, &Path::new("ilc20-site1").join(format!("{floor}.tar.xz")), "target/ilc")
        .then_some(unpacked)
}

/// A floor folder in `into` named as `floor`'s, holding its plan and its first `walks` walks by
/// name: for tests that survey a few walks. Returns the folder and every walk of `floor`,
/// sorted by name, so that a test can give the next ones without labels.
pub fn floor_with_first_walks(
    floor: &Path,
    into: &Path,
    walks: usize,
) -> std::io::Result<(PathBuf, Vec<PathBuf>)> {
    let small = into.join(floor.file_name().unwrap_or_default());
    std::fs::create_dir_all(small.join("path_data_files"))?;
    for plan in ["floor_info.json", "geojson_map.json"] {
        std::fs::copy(floor.join(plan), small.join(plan))?;
    }
    let mut all = std::fs::read_dir(floor.join("path_data_files"))?
        .map(|entry| entry.map(|e| e.path()))
        .collect::<std::io::Result<Vec<_>>>()?;
    all.sort();
    for walk in all.iter().take(walks) {
        std::fs::copy(walk, small.join("path_data_files").join(walk.file_name().unwrap_or_default()))?;
    }
    Ok((small, all))
}

/// The IPIN 2023 museum's logfiles (`ipin2023-t3/`, GetSensorData) unpacked under
/// `<workspace>/target/ipin/ipin2023-t3/`, or `None`, saying why on stderr.
pub fn ipin2023_t3(workspace: &Path) -> Option<PathBuf> {
    let unpacked = workspace.join("target/ipin/ipin2023-t3");
    if unpacked.join("logfiles").is_dir() {
        return Some(unpacked);
    }
    unpack(workspace, Path::new("ipin2023-t3/ipin2023-t3.tar.xz"), "target/ipin").then_some(unpacked)
}

/// What a real-data test does with the data it looked for: `found`, or `None` to skip, except
/// where the test command expects the data (`WAYMARK_REQUIRE_DATA=1`, which CI sets,
/// docs/testing.md#real-data): there a missing data set fails the test instead of passing it
/// unseen.
pub fn or_skip<T>(found: Option<T>) -> Option<T> {
    let required = std::env::var("WAYMARK_REQUIRE_DATA").is_ok_and(|v| !v.is_empty() && v != "0");
    assert!(
        found.is_some() || !required,
        "WAYMARK_REQUIRE_DATA is set but the real data is missing (the reason is above; docs/testing.md#real-data)"
    );
    found
}

/// Unpacks the data archive `relative` into `<workspace>/<into>`; false, saying why on stderr,
/// when it is not found or cannot be unpacked.
fn unpack(workspace: &Path, relative: &Path, into: &str) -> bool {
    let Some(archive) = archive(workspace, relative) else {
        eprintln!("skipping: {} not found (docs/testing.md#real-data)", relative.display());
        return false;
    };
    let into = workspace.join(into);
    if std::fs::create_dir_all(&into).is_err() {
        return false;
    }
    let status = std::process::Command::new("tar").arg("-xJf").arg(&archive).arg("-C").arg(&into).status();
    match status {
        Ok(s) if s.success() => true,
        _ => {
            eprintln!("skipping: could not unpack {}", archive.display());
            false
        }
    }
}

/// A data archive, `relative` to the data folder: `$WAYMARK_DATA`, or without that variable
/// `data/` of a folder beside the checkout.
fn archive(workspace: &Path, relative: &Path) -> Option<PathBuf> {
    if let Some(data) = std::env::var_os("WAYMARK_DATA") {
        return Some(Path::new(&data).join(relative)).filter(|a| a.is_file());
    }
    let beside = workspace.canonicalize().ok()?.parent()?.read_dir().ok()?;
    beside.flatten().map(|e| e.path().join("data").join(relative)).find(|a| a.is_file())
}
