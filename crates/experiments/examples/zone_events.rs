//! The measurement behind the zone hysteresis (`ZoneHysteresis::default()`,
//! docs/zones.md#enter-and-exit): simulated walks through the office's rooms, tracked with
//! every inertial sensor, and the zone enter and exit events each band of thresholds reports
//! against the rooms the walker was really in.
//!
//! `cargo run --release -p waymark-experiments --example zone_events [walks]` prints one row per band:
//! the room visits (runs of scans in one room, three scans or more), the share of them during
//! which the engine reported the walker inside that room, the median delay of that report in
//! scans, the entries reported, and the entries left again within two scans (flaps).

use std::collections::HashSet;
use std::sync::Arc;
use waymark_engine::site::PSEUDO_SPACING_M;
use waymark_engine::{EngineConfig, StatusEvent, ZoneHysteresis};
use waymark_experiments::{track_walk, walk_seed, Sensors};
use waymark_sim::imu::{synthesize, ImuConfig};
use waymark_sim::{Office, OfficeConfig};

/// Visits shorter than this many scans are passages, not visits.
const MIN_VISIT_SCANS: usize = 3;

#[derive(Default)]
struct Tally {
    visits: usize,
    reported: usize,
    delays: Vec<usize>,
    entries: usize,
    flaps: usize,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let walks: usize = std::env::args().nth(1).map_or(Ok(30), |a| a.parse())?;
    let config = OfficeConfig::default();
    let office = Office::generate(&config);
    let site = Arc::new(office.site.with_pseudo_states(PSEUDO_SPACING_M));
    let band = |enter_mass, exit_mass| ZoneHysteresis { enter_mass, exit_mass };
    let bands = [
        ("0.5 / 0.5 (no band)", band(0.5, 0.5)),
        ("0.68 / 0.32 (default)", ZoneHysteresis::default()),
        ("0.9 / 0.1", band(0.9, 0.1)),
    ];
    println!("| enter / exit | visits | reported | median delay, scans | entries | flaps |");
    println!("|---|---|---|---|---|---|");
    for (name, hysteresis) in bands {
        let engine = EngineConfig { zone_hysteresis: hysteresis, ..EngineConfig::default() };
        let mut tally = Tally::default();
        for w in 0..walks {
            let seed = walk_seed(config.seed, w);
            let walk = office.walk(seed, 200.0);
            let imu = synthesize(&walk.trajectory, &ImuConfig::default(), seed);
            let tracked = track_walk(&site, &engine, Sensors::ALL, &walk, &imu, 0)?;
            // The zones the engine says the walker is in, scan by scan, and its entries.
            let mut inside = HashSet::new();
            let mut timeline = Vec::new();
            let mut entries = Vec::new();
            for (k, point) in tracked.points.iter().enumerate() {
                for event in &point.status {
                    match *event {
                        StatusEvent::ZoneEntered { zone, .. } => {
                            inside.insert(zone);
                            entries.push((k, zone));
                        }
                        StatusEvent::ZoneExited { zone, .. } => {
                            inside.remove(&zone);
                        }
                        _ => {}
                    }
                }
                timeline.push(inside.clone());
            }
            tally.entries += entries.len();
            tally.flaps += entries
                .iter()
                .filter(|&&(k, zone)| timeline[k + 1..].iter().take(2).any(|now| !now.contains(&zone)))
                .count();
            // Runs of scans in one room.
            let truth: Vec<Option<usize>> = tracked.points.iter().map(|p| p.truth_zone).collect();
            let mut start = 0;
            while start < truth.len() {
                let end = (start..truth.len()).find(|&k| truth[k] != truth[start]).unwrap_or(truth.len());
                if let (Some(zone), true) = (truth[start], end - start >= MIN_VISIT_SCANS) {
                    tally.visits += 1;
                    if let Some(delay) = (start..end).position(|k| timeline[k].contains(&zone)) {
                        tally.reported += 1;
                        tally.delays.push(delay);
                    }
                }
                start = end;
            }
        }
        tally.delays.sort_unstable();
        let median = tally.delays.get(tally.delays.len() / 2).copied().unwrap_or(0);
        println!(
            "| {name} | {} | {:.3} | {median} | {} | {} |",
            tally.visits,
            tally.reported as f64 / tally.visits.max(1) as f64,
            tally.entries,
            tally.flaps
        );
    }
    Ok(())
}
