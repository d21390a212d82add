//! The heap an engine holds after replaying recorded walks as an app would (sensor batches,
//! scans, a timer epoch after 2 s without one, the fixed-lag estimate after every epoch),
//! counted by this program's allocator (`stats_alloc`): the bytes allocated and not yet freed
//! since just before the engine was made, once it is made and after the walk, less the site's
//! walking-distance tables, which the first engine builds and the site keeps. The site's own
//! heap once loaded is printed first. One engine per
//! walk, the default configuration (`--no-track`: without the Viterbi track). Heap, not
//! resident memory: `waymark bench --rss-probe SITE [--probe-walk WALK]` measures that.
//!
//! ```text
//! cargo run --release -p waymark-eval --example engine_heap -- [--no-track] mall.wmsite target/ilc/site1/F1/path_data_files/*.txt
//! ```

use stats_alloc::{Region, StatsAlloc, INSTRUMENTED_SYSTEM};
use std::alloc::System;
use std::path::Path;
use std::sync::Arc;
use waymark_engine::{Engine, EngineConfig, Site};
use waymark_survey::io::Trace;
use waymark_survey::replay::{replay, ReplayOptions};

#[global_allocator]
static ALLOCATOR: &StatsAlloc<System> = &INSTRUMENTED_SYSTEM;

fn main() {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let no_track = args.iter().position(|a| a == "--no-track").map(|i| args.remove(i)).is_some();
    let Some((site_path, walks)) = args.split_first() else {
        eprintln!("usage: engine_heap [--no-track] SITE WALK.txt...");
        std::process::exit(2);
    };
    // Bytes allocated and not freed since `region` began, MB.
    let live_mb = |region: &Region<System>| {
        let change = region.change();
        (change.bytes_allocated as f64 - change.bytes_deallocated as f64) / 1e6
    };
    let region = Region::new(ALLOCATOR);
    let site = Arc::new(Site::load(site_path).unwrap_or_else(|e| panic!("{site_path}: {e}")));
    println!("the site's heap once loaded: {:.2} MB", live_mb(&region));
    let config = EngineConfig { track: !no_track, ..EngineConfig::default() };
    let options = ReplayOptions { fixed_lag: true, ..ReplayOptions::default() };
    let mut largest = (0.0, String::new());
    for (k, walk) in walks.iter().enumerate() {
        let trace = Trace::read(Path::new(walk)).unwrap_or_else(|e| panic!("{walk}: {e}"));
        let region = Region::new(ALLOCATOR);
        let mut engine = Engine::new(Arc::clone(&site), config.clone()).expect("valid config");
        let made = live_mb(&region);
        let positions = replay(&mut engine, &trace, &options).positions.len();
        let held = live_mb(&region);
        let (track, fixed_lag) = (engine.track_memory_bytes(), engine.fixed_lag_memory_bytes());
        drop(engine);
        // The first engine builds the site's walking-distance tables, which the site keeps.
        let tables = live_mb(&region);
        if k == 0 {
            println!("the site's walking-distance tables: {tables:.2} MB (built by the first engine)");
        }
        let (made, held) = (made - tables, held - tables);
        println!(
            "{walk}: {positions} positions; engine heap {made:.2} MB made, {held:.2} MB after the walk \
             (track window {:.2}, fixed-lag steps {:.2})",
            track as f64 / 1e6,
            fixed_lag as f64 / 1e6,
        );
        if held > largest.0 {
            largest = (held, walk.clone());
        }
    }
    println!("most after a walk: {:.2} MB ({})", largest.0, largest.1);
}
