//! Criterion benchmarks of what `waymark bench` reports as single figures: one epoch of the
//! sparse engine and of the dense reference, raw IMU ingestion, and site loading.
//!
//!     cargo bench -p waymark-engine --bench engine
//!
//! Sites come from `waymark_sim::scale` (an 8-connected 2 m grid, 100 access points heard
//! per scan), the same as `waymark bench` uses.

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use std::hint::black_box;
use std::sync::Arc;
use waymark_engine::hmm::UniformReach;
use waymark_engine::sensors::{MotionConfig, MotionTracker};
use waymark_engine::site::ReachTable;
use waymark_engine::{Engine, EngineConfig, Site};
use waymark_sim::imu::{self, ImuConfig};
use waymark_sim::scale::{DenseForward, ScaleConfig, ScaleSite, SCALE_EPOCH_NS};
use waymark_sim::Trajectory;

fn scaled(states: usize) -> (ScaleSite, Arc<Site>) {
    let scaled = ScaleSite::generate(&ScaleConfig { states, ..ScaleConfig::default() });
    let site = Arc::new(Site::from_json(scaled.json.as_bytes()).expect("a generated site loads"));
    (scaled, site)
}

/// One tracked epoch (emission, transition, Viterbi step, normalisation, estimate) after 20
/// epochs of convergence, at 1 000 and 10 000 states.
fn epoch(c: &mut Criterion) {
    let mut group = c.benchmark_group("epoch");
    group.sample_size(30);
    for states in [1_000, 10_000] {
        let (scaled, site) = scaled(states);
        let walk = scaled.walk(120, 1);
        let mut engine = Engine::new(Arc::clone(&site), EngineConfig::default()).expect("default config");
        for e in &walk[..20] {
            engine.push_scan_with_motion(&e.scan, &e.motion).expect("a good scan");
        }
        let mut k = 20;
        group.bench_function(format!("sparse/{states}"), |b| {
            b.iter_batched(
                || {
                    // Laps repeat the walk: shift time so every epoch is after the last.
                    let e = &walk[20 + k % 100];
                    let mut scan = e.scan.clone();
                    let mut motion = e.motion.clone();
                    let t = (k as u64 + 1) * SCALE_EPOCH_NS;
                    scan.timestamp_ns = t;
                    motion.start_ns = t - SCALE_EPOCH_NS;
                    motion.end_ns = t;
                    k += 1;
                    (scan, motion)
                },
                |(scan, motion)| {
                    black_box(engine.push_scan_with_motion(&scan, &motion).expect("a good scan").position)
                },
                BatchSize::SmallInput,
            )
        });
    }
    // The textbook dense step, at 1 000 states (10 000 needs 800 MB and 100 ms per step:
    // `waymark bench` times it).
    let (scaled, site) = scaled(1_000);
    let config = EngineConfig::default();
    let table = ReachTable::build(&site, config.reach_radius_m);
    let transition = UniformReach { table: &table, rho_m: 6.0, ratio: config.transition_ratio };
    let mut dense = DenseForward::new(&site, &transition);
    let observations: Vec<Vec<(u32, f64)>> =
        scaled.walk(20, 2).iter().map(|e| site.radio().resolve(&e.scan, None).observations).collect();
    let mut k = 0;
    group.bench_function("dense/1000", |b| {
        b.iter(|| {
            k += 1;
            black_box(dense.step(&observations[k % observations.len()]))
        })
    });
    group.finish();
}

/// Raw IMU through the motion tracker (step detection, heading filter): 10 minutes of three
/// sensors at 100 Hz in batches of 50, updated every 2 s.
fn ingest(c: &mut Criterion) {
    let points: Vec<nalgebra::Point2<f64>> = (0..40)
        .map(|k| nalgebra::Point2::new(if k % 2 == 0 { 0.0 } else { 30.0 }, 2.0 * (k / 2) as f64))
        .collect();
    let trace =
        imu::synthesize(&Trajectory::new(1_000_000_000, 1.2, &points, Vec::new()), &ImuConfig::default(), 7);
    let total = trace.accelerometer.len() + trace.gyroscope.len() + trace.magnetometer.len();
    let mut group = c.benchmark_group("ingest");
    group.sample_size(10);
    group.throughput(Throughput::Elements(total as u64));
    group.bench_function("imu_10_min", |b| {
        b.iter(|| {
            let mut tracker = MotionTracker::new(MotionConfig::default()).expect("default config");
            let (acc, gyro, mag) =
                (trace.accelerometer.chunks(50), trace.gyroscope.chunks(50), trace.magnetometer.chunks(50));
            let mut next_update = 2 * SCALE_EPOCH_NS;
            for ((a, g), m) in acc.zip(gyro).zip(mag) {
                tracker.push_accelerometer(a);
                tracker.push_gyroscope(g);
                tracker.push_magnetometer(m);
                let t = a.last().map_or(0, |s| s.timestamp_ns);
                if t >= next_update {
                    black_box(tracker.update(t));
                    next_update += SCALE_EPOCH_NS;
                }
            }
        })
    });
    group.finish();
}

/// Parsing and validating a site file of 1 000 states (`waymark bench` times 10 000).
fn site_load(c: &mut Criterion) {
    let scaled = ScaleSite::generate(&ScaleConfig { states: 1_000, ..ScaleConfig::default() });
    let mut group = c.benchmark_group("site_load");
    group.sample_size(20);
    group.throughput(Throughput::Bytes(scaled.json.len() as u64));
    group.bench_function("1000", |b| {
        b.iter(|| black_box(Site::from_json(scaled.json.as_bytes()).expect("loads")))
    });
    group.finish();
}

criterion_group!(benches, epoch, ingest, site_load);
criterion_main!(benches);
