//! What an engine costs on a real site file: replays recorded walks (ILC 2.0 text files) on it
//! as an app would (`eval::replay`: sensor batches, scans, timer epochs) and prints the time per
//! published position, sensor ingestion included, overall and as the median of the walks'
//! figures: on the thread's CPU clock (one core's work, whatever else the machine runs, as
//! `waymark bench`) and on the wall clock. `waymark bench` times one epoch on simulated sites; this is the same work on
//! a surveyed one, where scans hear more transmitters and each is fingerprinted at more states.
//! The first walk also pays for the site's walking-distance tables.
//!
//! Then each published position's own cost on the CPU clock: the calls since the previous one
//! (sensor batches, a scan or a timer epoch, the fixed-lag estimate), as the median, 90th
//! percentile and mean over every position, and the medians of scan and timer epochs apart. A
//! scan epoch scores the scan against the radio map; a timer epoch only moves the belief.
//! `--live-only` leaves the fixed-lag estimate out, as for an app that shows only the live one;
//! the last line is the most memory its smoother held (`Engine::fixed_lag_memory_bytes`).
//! `--no-track` runs the engine without its Viterbi track (`EngineConfig::track`).
//!
//! ```text
//! waymark survey target/ilc/site1/{B1,F1,F2,F3,F4} --out mall.wmsite
//! # or, in a minute, the same states and fingerprints without the calibration:
//! cargo run --release -p waymark-eval --example timing_site -- mall.wmsite 8 0.03 0.1 target/ilc/site1/{B1,F1,F2,F3,F4}
//! cargo run --release -p waymark-eval --example site_epoch_time -- [--live-only] [--no-track] mall.wmsite target/ilc/site1/F1/path_data_files/*.txt
//! ```

use cpu_time::ThreadTime;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;
use waymark_engine::{Engine, EngineConfig, Site};
use waymark_survey::io::Trace;
use waymark_survey::replay::{replay_observed, Call, ReplayOptions};

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut flag = |name: &str| {
        let given = args.iter().position(|a| a == name).map(|i| args.remove(i));
        given.is_some()
    };
    let (live_only, no_track) = (flag("--live-only"), flag("--no-track"));
    let options = ReplayOptions { fixed_lag: !live_only, ..ReplayOptions::default() };
    let config = EngineConfig { track: !no_track, ..EngineConfig::default() };
    let Some((site_path, walks)) = args.split_first() else {
        eprintln!("usage: site_epoch_time [--live-only] [--no-track] SITE WALK.txt...");
        std::process::exit(2);
    };
    let site = Arc::new(Site::load(site_path).unwrap_or_else(|e| panic!("{site_path}: {e}")));
    // Per clock (CPU, wall): total seconds and each walk's ms per position.
    let (mut epochs, mut seconds, mut per_walk_ms) = (0usize, [0.0; 2], [Vec::new(), Vec::new()]);
    // Each published position's own CPU cost, ms, by the call that published it.
    let (mut scan_ms, mut timer_ms) = (Vec::new(), Vec::new());
    // The most the fixed-lag smoother held at a walk's end, bytes.
    let mut smoother_bytes = 0;
    for walk in walks {
        let trace = Trace::read(Path::new(walk)).unwrap_or_else(|e| panic!("{walk}: {e}"));
        let mut engine = Engine::new(Arc::clone(&site), config.clone()).expect("valid config");
        let (cpu, wall) = (ThreadTime::now(), Instant::now());
        // CPU seconds at the previous call's end, and since then.
        let (mut mark, mut pending) = (0.0, 0.0);
        let mut observer = |call: Call| {
            let now = cpu.elapsed().as_secs_f64();
            pending += now - mark;
            mark = now;
            let (published, costs) = match call {
                Call::Scan { published } => (published, &mut scan_ms),
                Call::Timer { published } => (published, &mut timer_ms),
                Call::Sensors => return,
            };
            if published {
                costs.push(1e3 * pending);
                pending = 0.0;
            }
        };
        let replayed = replay_observed(&mut engine, &trace, &options, &mut observer);
        let elapsed = [cpu.elapsed().as_secs_f64(), wall.elapsed().as_secs_f64()];
        // Capacity, which the smoother's recycled steps keep: the most the walk needed.
        smoother_bytes = smoother_bytes.max(engine.fixed_lag_memory_bytes());
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
    let mut every: Vec<f64> = scan_ms.iter().chain(&timer_ms).copied().collect();
    let mean = every.iter().sum::<f64>() / every.len().max(1) as f64;
    println!(
        "per position, CPU: median {:.2} ms, 90th percentile {:.2} ms, mean {mean:.2} ms; \
         scan epochs ({}) median {:.2} ms, timer epochs ({}) median {:.2} ms",
        percentile(&mut every, 0.5),
        percentile(&mut every, 0.9),
        scan_ms.len(),
        percentile(&mut scan_ms, 0.5),
        timer_ms.len(),
        percentile(&mut timer_ms, 0.5),
    );
    println!("fixed-lag smoother: at most {:.2} MB at a walk's end", smoother_bytes as f64 / 1e6);
}

/// The `q` quantile of `values` (nearest rank), NaN when there are none.
fn percentile(values: &mut [f64], q: f64) -> f64 {
    values.sort_by(f64::total_cmp);
    let rank = ((values.len() as f64 * q).ceil() as usize).clamp(1, values.len().max(1));
    values.get(rank - 1).copied().unwrap_or(f64::NAN)
}
