//! The motion tracker on simulated phones (`waymark_sim::imu`): step detection targets at
//! every rate for both detectors, no steps when the phone lies still or is shaken, fused
//! heading better than compass-only and gyro-only past steel, the HIPE Table 1 scenario
//! chosen from what delivered, and bad input never panicking.

use waymark_engine::sensors::{
    MotionConfig, MotionScenario, MotionState, MotionTracker, SensorSample, StepDetectorKind,
};
use waymark_engine::Error;
use waymark_experiments::motion_eval::{evaluate, evaluate_with, EvalOptions, MotionReport};
use waymark_sim::imu::{shaken_in_place, synthesize, ImuConfig, ImuTrace};

/// Prints the full report: `cargo test --release -p waymark-engine --test sensors -- --ignored --nocapture`.
/// Seed and runs from WAYMARK_EVAL_SEED and WAYMARK_EVAL_RUNS (default 1 and 10); a tracker
/// configuration to try from WAYMARK_EVAL_CONFIG as JSON, missing fields at their defaults
/// (e.g. `{"confirm_steps": 3}`).
#[test]
#[ignore]
fn print_motion_report() {
    let seed = std::env::var("WAYMARK_EVAL_SEED").ok().and_then(|s| s.parse().ok()).unwrap_or(1);
    let runs = std::env::var("WAYMARK_EVAL_RUNS").ok().and_then(|s| s.parse().ok()).unwrap_or(10);
    let report = match std::env::var("WAYMARK_EVAL_CONFIG") {
        Ok(json) => {
            let config: MotionConfig =
                serde_json::from_str(&json).expect("WAYMARK_EVAL_CONFIG is a MotionConfig");
            evaluate_with(&EvalOptions { config, ..EvalOptions::new(seed, runs) })
        }
        Err(_) => evaluate(seed, runs),
    };
    println!("{}", serde_json::to_string_pretty(&report).unwrap());
}

/// Shorter walks than `evaluate`'s defaults, to keep debug builds quick.
fn short_report(seed: u64) -> MotionReport {
    let options =
        EvalOptions { walk_length_m: 80.0, in_place_s: 20.0, heading_runs: 6, ..EvalOptions::new(seed, 2) };
    evaluate_with(&options)
}

fn assert_targets(report: &MotionReport) {
    let json = serde_json::to_string_pretty(report).unwrap();
    assert_eq!(report.step_detection.len(), 8, "4 rates × 2 detectors");
    for row in &report.step_detection {
        assert!(row.true_steps > 100, "{json}");
        assert!(row.detected_share >= 0.98, "{:?} at {} Hz: {json}", row.detector, row.rate_hz);
        assert!(row.false_share <= 0.02, "{:?} at {} Hz: {json}", row.detector, row.rate_hz);
    }
    for row in &report.in_place {
        assert_eq!(row.lying_still_steps, 0, "{json}");
        assert_eq!(row.shaken_steps, 0, "{json}");
    }
    let h = &report.heading;
    assert!(h.samples > 100, "{json}");
    assert!(h.fused_rmse_deg < h.compass_only_rmse_deg, "{json}");
    assert!(h.fused_rmse_deg < h.gyro_only_rmse_deg, "{json}");
    assert!(h.fused_trusted_share > 0.95, "{json}");
}

#[test]
fn targets_hold_on_seed_1() {
    assert_targets(&short_report(1));
}

#[test]
fn targets_hold_on_seed_2() {
    assert_targets(&short_report(2));
}

#[test]
fn targets_hold_on_seed_3() {
    assert_targets(&short_report(3));
}

/// Feeds a whole trace, updating every 1.5 s; returns the updates.
fn run_trace(
    trace: &ImuTrace,
    config: MotionConfig,
    streams: [bool; 3],
) -> (MotionTracker, Vec<waymark_engine::sensors::MotionUpdate>) {
    let mut tracker = MotionTracker::new(config).unwrap();
    let all = [&trace.accelerometer, &trace.gyroscope, &trace.magnetometer];
    let start = all.iter().filter_map(|s| s.first()).map(|s| s.timestamp_ns).min().unwrap();
    let end = all.iter().filter_map(|s| s.last()).map(|s| s.timestamp_ns).max().unwrap();
    let mut cursor = [0usize; 3];
    let mut updates = Vec::new();
    let mut t = start;
    while t <= end + 1_500_000_000 {
        t += 1_500_000_000;
        for k in [1, 2, 0] {
            let samples = all[k];
            let to = cursor[k] + samples[cursor[k]..].partition_point(|s| s.timestamp_ns <= t);
            if streams[k] {
                let batch = &samples[cursor[k]..to];
                match k {
                    0 => tracker.push_accelerometer(batch),
                    1 => tracker.push_gyroscope(batch),
                    _ => tracker.push_magnetometer(batch),
                };
            }
            cursor[k] = to;
        }
        updates.push(tracker.update(t));
    }
    (tracker, updates)
}

fn straight_walk() -> (waymark_sim::Trajectory, ImuTrace, ImuConfig) {
    use nalgebra::Point2;
    let points = [Point2::new(0.0, 0.0), Point2::new(30.0, 30.0)];
    let trajectory = waymark_sim::Trajectory::new(5_000_000_000, 1.2, &points, Vec::new());
    let imu = ImuConfig { rate_hz: 50.0, site_rotation_rad: 0.5, ..ImuConfig::default() };
    let trace = synthesize(&trajectory, &imu, 4);
    (trajectory, trace, imu)
}

fn walk_config(imu: &ImuConfig) -> MotionConfig {
    MotionConfig {
        declination_rad: imu.declination_rad,
        site_rotation_rad: imu.site_rotation_rad,
        ..MotionConfig::default()
    }
}

/// A straight walk north-east in the site frame (site rotated 0.5 rad from true north,
/// declination 7.7°): the displacement points the right way, is about as long as the walk,
/// and the scenario follows what delivered.
#[test]
fn walk_gives_displacement_and_scenarios_follow_the_sensors() {
    let (trajectory, trace, imu) = straight_walk();
    let (tracker, updates) = run_trace(&trace, walk_config(&imu), [true; 3]);
    let walking: Vec<_> = updates.iter().filter(|u| u.steps > 0).collect();
    assert!(walking.len() > 10);
    let mut sum = [0.0, 0.0];
    for u in &walking {
        assert_eq!(u.scenario, MotionScenario::DistanceHeading, "{u:?}");
        let d = u.displacement_m.unwrap();
        sum[0] += d[0];
        sum[1] += d[1];
        assert!(u.distance_sigma_m > 0.0);
    }
    // Within 10°: the phone is held up to 4° off the walking direction, and a sign error in
    // the declination (15°) or the site rotation (57°) would be far out.
    let direction = sum[0].atan2(sum[1]);
    assert!(
        (direction - std::f64::consts::FRAC_PI_4).abs() < 10f64.to_radians(),
        "{}",
        direction.to_degrees()
    );
    let steps: u64 = tracker.stats().steps_total;
    assert!((steps as i64 - trace.true_step_times_ns.len() as i64).abs() <= 2);
    // 0.7 m per step against the true step length (speed / cadence): within 40 %.
    let length = sum[0].hypot(sum[1]);
    assert!((length / trajectory.length_m() - 1.0).abs() < 0.4, "{length}");
    assert!(updates.iter().any(|u| u.motion_state == MotionState::Walking));
    assert!(updates.iter().any(|u| u.motion_state == MotionState::Stationary));
    // Standing at the start: distance 0, no movement.
    let first = &updates[0];
    assert_eq!(first.distance_m, Some(0.0));
    assert_eq!(first.displacement_m, Some([0.0, 0.0]));

    // No magnetometer: gyro-only, no absolute heading.
    let (_, updates) = run_trace(&trace, walk_config(&imu), [true, true, false]);
    assert!(updates.iter().filter(|u| u.steps > 0).all(|u| u.scenario == MotionScenario::Distance
        && u.heading_rad.is_none()
        && u.displacement_m.is_none()));
    // No accelerometer: heading and an assumed speed.
    let (_, updates) = run_trace(&trace, walk_config(&imu), [false, true, true]);
    assert!(updates
        .iter()
        .skip(1)
        .all(|u| u.scenario == MotionScenario::HeadingSpeed && u.distance_m.is_none()));
    assert!(updates.iter().all(|u| u.motion_state == MotionState::Unknown));
    // Only a gyroscope: nothing measured.
    let (_, updates) = run_trace(&trace, walk_config(&imu), [false, true, false]);
    assert!(updates.iter().all(|u| u.scenario == MotionScenario::Speed));
    // Compass only (no gyroscope): still a measured heading.
    let (_, updates) = run_trace(&trace, walk_config(&imu), [true, false, true]);
    let with_heading = updates.iter().filter(|u| u.scenario == MotionScenario::DistanceHeading).count();
    assert!(with_heading * 10 >= updates.len() * 9, "{with_heading} of {}", updates.len());
}

/// Shaking the phone in place is never walking, for either detector.
#[test]
fn shaking_is_not_walking() {
    for detector in [StepDetectorKind::Threshold, StepDetectorKind::PeakZeroCrossing] {
        for seed in 0..3 {
            let trace = shaken_in_place(30.0, &ImuConfig::default(), seed);
            let config = MotionConfig { step_detector: detector, ..MotionConfig::default() };
            let (tracker, updates) = run_trace(&trace, config, [true; 3]);
            assert!(updates.iter().all(|u| u.steps == 0 && u.motion_state != MotionState::Walking));
            assert_eq!(tracker.stats().steps_total, 0);
            assert!(tracker.stats().rejected_step_candidates > 0);
        }
    }
}

#[test]
fn invalid_configuration_is_named() {
    let bad = MotionConfig { max_cadence_hz: f64::NAN, ..MotionConfig::default() };
    // The sensors' own error, which the crate-wide one takes as an invalid configuration.
    let e = Error::from(MotionTracker::new(bad).unwrap_err());
    assert!(matches!(&e, Error::InvalidConfig(m) if m.contains("max_cadence_hz")), "{e}");
}

fn s(t: u64, x: f64, y: f64, z: f64) -> SensorSample {
    SensorSample { timestamp_ns: t, x, y, z }
}

/// NaN, infinities, time going backwards, duplicates, empty batches, timestamps at the end
/// of u64 and updates going backwards: dropped and counted, never a panic.
#[test]
fn bad_input_never_panics() {
    let mut m = MotionTracker::new(MotionConfig::default()).unwrap();
    let u = m.update(0);
    assert_eq!((u.steps, u.distance_m, u.scenario), (0, None, MotionScenario::Speed));
    assert_eq!(m.push_accelerometer(&[]).accepted, 0);
    let r = m.push_accelerometer(&[
        s(1_000, f64::NAN, 0.0, 9.8),
        s(2_000, 0.0, f64::NEG_INFINITY, 9.8),
        s(3_000, 0.0, 0.0, 9.8),
        s(3_000, 0.0, 0.0, 9.8),
        s(2_500, 0.0, 0.0, 9.8),
        s(u64::MAX - 1, 0.0, 0.0, 9.8),
        s(u64::MAX, 0.0, 0.0, 9.8),
        s(4_000, 0.0, 0.0, 9.8),
    ]);
    // The two at the end of u64 are far ahead of the clock: refused, not adopted, so the
    // sample after them is in order (docs/errors.md#timestamps-ahead-of-the-clock).
    assert_eq!((r.accepted, r.non_finite, r.out_of_order, r.ahead), (2, 2, 2, 2));
    m.push_gyroscope(&[s(5, 1e308, 0.0, 0.0), s(6, 0.0, 0.0, 0.0), s(u64::MAX, 0.1, 0.2, 0.3)]);
    m.push_magnetometer(&[s(7, 0.0, 20.0, -40.0), s(u64::MAX - 5, 0.0, 0.0, 0.0)]);
    let u = m.update(10_000);
    assert!(u.end_ns == 10_000);
    let u = m.update(5);
    assert_eq!((u.start_ns, u.end_ns), (10_000, 10_000));
    let u = m.update(u64::MAX);
    assert_eq!(u.end_ns, u64::MAX);
    assert!(u.distance_sigma_m.is_finite() && u.heading_sigma_rad.is_finite());
    // Everything later is out of order now.
    assert_eq!(m.push_accelerometer(&[s(20_000, 0.0, 0.0, 9.8)]).out_of_order, 1);
    let _ = m.update(u64::MAX);
    let stats = m.stats();
    // The samples far ahead were refused and counted, never buffered: nothing overflowed.
    assert_eq!((stats.accelerometer.ahead, stats.gyroscope.ahead, stats.magnetometer.ahead), (2, 1, 1));
    assert_eq!(stats.accelerometer.overflowed, 0);
    assert_eq!(stats.accelerometer.processed, 2);
    assert_eq!(stats.gyroscope.non_finite, 1);
    assert_eq!((stats.gyroscope.overflowed, stats.gyroscope.processed), (0, 1));
    assert_eq!((stats.magnetometer.overflowed, stats.magnetometer.processed), (0, 1));
}

mod fuzz {
    use super::*;
    use proptest::prelude::*;

    fn value() -> impl Strategy<Value = f64> {
        prop_oneof![
            8 => -50.0..50.0f64,
            1 => Just(f64::NAN),
            1 => Just(f64::INFINITY),
            1 => Just(1e300),
            1 => Just(0.0),
        ]
    }

    fn batch() -> impl Strategy<Value = (u8, Vec<(u64, f64, f64, f64)>)> {
        (0u8..4, prop::collection::vec((0u64..3_000_000_000, value(), value(), value()), 0..40))
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
        /// Any interleaving of batches (random timestamps, values, updates): no panic, and
        /// every sample is accounted for.
        #[test]
        fn random_batches_never_panic(batches in prop::collection::vec(batch(), 1..30)) {
            let mut m = MotionTracker::new(MotionConfig::default()).unwrap();
            let mut pushed = 0u64;
            for (kind, samples) in batches {
                let samples: Vec<_> = samples.iter().map(|&(t, x, y, z)| s(t, x, y, z)).collect();
                pushed += samples.len() as u64;
                match kind {
                    0 => { m.push_accelerometer(&samples); }
                    1 => { m.push_gyroscope(&samples); }
                    2 => { m.push_magnetometer(&samples); }
                    _ => {
                        let until = samples.first().map_or(0, |s| s.timestamp_ns);
                        pushed -= samples.len() as u64;
                        let u = m.update(until);
                        prop_assert!(u.start_ns <= u.end_ns);
                        prop_assert!(u.heading_rad.is_none_or(|h| h.is_finite()));
                        prop_assert!(u.distance_m.is_none_or(|d| d.is_finite() && d >= 0.0));
                    }
                }
            }
            let st = m.stats();
            let total = [st.accelerometer, st.gyroscope, st.magnetometer]
                .iter()
                .map(|x| x.accepted + x.non_finite + x.out_of_order)
                .sum::<u64>();
            prop_assert_eq!(total, pushed);
        }
    }
}

/// Peeking at the interval leaves it open: updates every 2 s with peeks every 0.5 s between
/// report what updates every 2 s alone do, and each peek what an update at its time would.
#[test]
fn a_peek_leaves_the_interval_to_the_next_update() {
    let (_, trace, imu) = straight_walk();
    let all = [&trace.accelerometer, &trace.gyroscope, &trace.magnetometer];
    let mut peeking = MotionTracker::new(walk_config(&imu)).unwrap();
    let mut plain = MotionTracker::new(walk_config(&imu)).unwrap();
    let start = trace.accelerometer[0].timestamp_ns;
    let end = trace.accelerometer.last().unwrap().timestamp_ns;
    let half = 500_000_000;
    let mut cursor = [0usize; 3];
    let (mut peeks, mut walked) = (0, 0);
    let mut t = start;
    while t < end {
        t += half;
        for (k, samples) in all.iter().enumerate() {
            let to = cursor[k] + samples[cursor[k]..].partition_point(|s| s.timestamp_ns <= t);
            for tracker in [&mut peeking, &mut plain] {
                match k {
                    0 => tracker.push_accelerometer(&samples[cursor[k]..to]),
                    1 => tracker.push_gyroscope(&samples[cursor[k]..to]),
                    _ => tracker.push_magnetometer(&samples[cursor[k]..to]),
                };
            }
            cursor[k] = to;
        }
        if (t - start) % (4 * half) == 0 {
            let update = peeking.update(t);
            assert_eq!(update, plain.update(t));
            walked += update.steps;
        } else {
            let peek = peeking.peek(t);
            let mut twin = peeking.clone();
            assert_eq!(peek, twin.update(t));
            peeks += 1;
        }
    }
    assert!(peeks > 30 && walked > 20, "{peeks} peeks, {walked} steps");
    assert_eq!(peeking.stats().steps_total, plain.stats().steps_total);
}
