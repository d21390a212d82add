//! Replays every committed fuzz input (`fuzz/corpus/<target>/` and the crash reproducers kept in
//! `fuzz/regressions/<target>/`) through the same harness the cargo-fuzz targets run, on stable
//! Rust, so a regression shows up in `cargo test` without nightly or libFuzzer.

#[allow(dead_code)]
#[path = "../fuzz/harness/mod.rs"]
mod harness;

use std::path::{Path, PathBuf};

fn inputs(target: &str) -> Vec<PathBuf> {
    let fuzz = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz");
    let mut files = Vec::new();
    for dir in ["corpus", "regressions"] {
        let Ok(entries) = std::fs::read_dir(fuzz.join(dir).join(target)) else { continue };
        files.extend(entries.map(|e| e.expect("a readable directory entry").path()).filter(|p| p.is_file()));
    }
    files.sort();
    files
}

fn replay(target: &str, run: fn(&[u8])) {
    let files = inputs(target);
    assert!(!files.is_empty(), "no corpus for {target}");
    let failed: Vec<String> = files
        .iter()
        .filter(|path| {
            let data = std::fs::read(path).expect("a readable corpus file");
            std::panic::catch_unwind(|| run(&data)).is_err()
        })
        .map(|path| path.display().to_string())
        .collect();
    assert!(failed.is_empty(), "{} of {} {target} inputs fail: {failed:#?}", failed.len(), files.len());
}

/// The harness steers clear of the test build's fault-injection times: the right ones.
#[cfg(feature = "fault-injection")]
#[test]
fn the_harness_avoids_the_injected_times() {
    assert_eq!(harness::engine_calls::INJECTED_SCAN_NS, waymark::FAULT_INJECTION_TIMESTAMP_NS);
    assert_eq!(harness::engine_calls::INJECTED_MID_EPOCH_NS, waymark_engine::FAULT_INJECTION_MID_EPOCH_NS);
}

#[test]
fn site_file_corpus() {
    replay("site_file", harness::site_file::run);
}

#[test]
fn site_cost_corpus() {
    replay("site_cost", harness::site_cost::run);
}

#[test]
fn ilc_trace_corpus() {
    replay("ilc_trace", harness::ilc_trace::run);
}

#[test]
fn engine_calls_corpus() {
    replay("engine_calls", harness::engine_calls::run);
}

/// Writes the `engine_calls` seeds (simulated walks encoded as calls) into
/// `fuzz/corpus/engine_calls/`: `cargo test --test fuzz_corpus -- --ignored`.
#[test]
#[ignore]
fn write_engine_calls_seeds() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus/engine_calls");
    std::fs::create_dir_all(&dir).unwrap();
    for (name, fixture, transition, seed) in [
        ("walk-reach", 0, 0, 1),
        ("walk-hipe", 0, 1, 2),
        ("walk-hoang", 0, 2, 3),
        ("walk-two-floors", 1, 2, 4),
    ] {
        let bytes = harness::engine_calls::walk_seed(fixture, transition, seed, 12.0);
        harness::engine_calls::run(&bytes);
        std::fs::write(dir.join(format!("seed-{name}")), bytes).unwrap();
    }
}
