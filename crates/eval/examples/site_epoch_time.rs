//! What an engine costs on a real site file: replays recorded walks (ILC 2.0 text files) on it
//! as an app would (`eval::replay`: sensor batches, scans, timer epochs) and prints the time per
//! published position, sensor ingestion included, overall and as the median of the walks'
//! figures: on the thread's CPU clock (one core's work, whatever else the machine runs, as
//! `waymark bench`) and on the wall clock. `waymark bench` times one epoch on simulated sites; this is the same work on
//! a surveyed one, where scans hear more transmitters and each is fingerprinted at more states.
//! The first walk also pays for the site's walking-distance tables.
//!
//! ```text
//! waymark survey target/ilc/site1/{B1,F1,F2,F3,F4} --out mall.wmsite
//! # or, in a minute, the same states and fingerprints without the calibration:
//! cargo run --release -p waymark-eval --example timing_site -- mall.wmsite 8 0.03 0.1 target/ilc/site1/{B1,F1,F2,F3,F4}
//! cargo run --release -p waymark-eval --example site_epoch_time -- mall.wmsite target/ilc/site1/F1/path_data_files/*.txt
//! ```

use cpu_time::ThreadTime;
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
    // Per clock (CPU, wall): total seconds and each walk's ms per position.
    let (mut epochs, mut seconds, mut per_walk_ms) = (0usize, [0.0; 2], [Vec::new(), Vec::new()]);
    for walk in walks {
        let trace = Trace::read(Path::new(walk)).unwrap_or_else(|e| panic!("{walk}: {e}"));
        let mut engine = Engine::new(Arc::clone(&site), EngineConfig::default()).expect("default config");
        let (cpu, wall) = (ThreadTime::now(), Instant::now());
        let replayed = replay(&mut engine, &trace, &ReplayOptions::default());
        let elapsed = [cpu.elapsed().as_secs_f64(), wall.elapsed().as_secs_f64()];
        if replayed.positions.is_empty() {
            continue;
        }
        epochs += replayed.positions.len();
        for k in 0..2 {
            seconds[k] += elapsed[k];
            per_walk_ms[k].push(1e3 * elapsed[k] / replayed.positions.len() as f64);
        }
    }
    let [cpu, wall] = [0, 1].map(|k| {
        per_walk_ms[k].sort_by(f64::total_cmp);
        let median = per_walk_ms[k].get(per_walk_ms[k].len() / 2).copied().unwrap_or(f64::NAN);
        format!(
            "{:.2} ms each overall, walks' median {median:.2} ms",
            1e3 * seconds[k] / epochs.max(1) as f64
        )
    });
    println!(
        "{} states: {epochs} positions from {} walks; CPU {cpu}; wall {wall}",
        site.states().len(),
        per_walk_ms[0].len(),
    );
}
