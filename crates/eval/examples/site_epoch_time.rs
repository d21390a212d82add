//! What an engine costs on a real site file: replays recorded walks (ILC 2.0 text files) on it
//! as an app would (`eval::replay`: sensor batches, scans, timer epochs) and prints the wall
//! time per published position, sensor ingestion included, overall and as the median of the
//! walks' figures. `waymark bench` times one epoch on simulated sites; this is the same work on
//! a surveyed one, where scans hear more transmitters and each is fingerprinted at more states.
//! The first walk also pays for the site's walking-distance tables.
//!
//! ```text
//! waymark survey target/ilc/site1/{B1,F1,F2,F3,F4} --out mall.wmsite
//! cargo run --release -p waymark-eval --example site_epoch_time -- mall.wmsite target/ilc/site1/F1/path_data_files/*.txt
//! ```

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;
use waymark::{Engine, EngineConfig, Site};
use waymark_survey::io::Trace;
use waymark_survey::replay::{replay, ReplayOptions};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((site_path, walks)) = args.split_first() else {
        eprintln!("usage: site_epoch_time SITE WALK.txt...");
        std::process::exit(2);
    };
    let site = Arc::new(Site::load(site_path).unwrap_or_else(|e| panic!("{site_path}: {e}")));
    let (mut epochs, mut seconds, mut per_walk_ms) = (0usize, 0.0, Vec::new());
    for walk in walks {
        let trace = Trace::read(Path::new(walk)).unwrap_or_else(|e| panic!("{walk}: {e}"));
        let mut engine = Engine::new(Arc::clone(&site), EngineConfig::default()).expect("default config");
        let start = Instant::now();
        let replayed = replay(&mut engine, &trace, &ReplayOptions::default());
        let elapsed = start.elapsed().as_secs_f64();
        if replayed.positions.is_empty() {
            continue;
        }
        epochs += replayed.positions.len();
        seconds += elapsed;
        per_walk_ms.push(1e3 * elapsed / replayed.positions.len() as f64);
    }
    per_walk_ms.sort_by(f64::total_cmp);
    let median = per_walk_ms.get(per_walk_ms.len() / 2).copied().unwrap_or(f64::NAN);
    println!(
        "{} states: {epochs} positions from {} walks, {:.2} ms each overall, walks' median {median:.2} ms",
        site.states().len(),
        per_walk_ms.len(),
        1e3 * seconds / epochs.max(1) as f64,
    );
}
