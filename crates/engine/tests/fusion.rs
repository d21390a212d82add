//! Motion-driven epochs through the engine: status events, the Viterbi track and its
//! revisions, and the transition models' effect, with motion given directly.

mod common;

use common::{scan, two_floor_site};
use std::sync::Arc;
use waymark_engine::sensors::{MotionScenario, MotionState, MotionUpdate};
use waymark_engine::TransitionModel;
use waymark_engine::{Engine, EngineConfig, Epoch, InputError, Position, StatusEvent, TrackPoint};

const SECOND: u64 = 1_000_000_000;

fn readings_at(f: usize, x: f64) -> Vec<(u8, f64)> {
    (0..3).map(|t| ((3 * f + t) as u8, -40.0 - 4.0 * (x - 6.0 * t as f64).abs())).collect()
}

/// Walking east along the corridor: `steps` of 0.75 m, heading +x (90°).
fn walking(steps: u32) -> MotionUpdate {
    let d = 0.75 * steps as f64;
    MotionUpdate {
        steps,
        distance_m: Some(d),
        distance_sigma_m: 0.1 * d,
        heading_rad: Some(std::f64::consts::FRAC_PI_2),
        heading_sigma_rad: 0.1,
        displacement_m: Some([d, 0.0]),
        motion_state: MotionState::Walking,
        scenario: MotionScenario::DistanceHeading,
        ..MotionUpdate::default()
    }
}

#[derive(Default)]
struct Recorder {
    positions: Vec<Position>,
    statuses: Vec<StatusEvent>,
    revisions: Vec<Vec<TrackPoint>>,
}

impl Recorder {
    /// Keeps what an epoch returned.
    fn take(&mut self, epoch: Epoch) {
        self.positions.push(epoch.position);
        self.statuses.extend(epoch.status);
        if !epoch.revised_track.is_empty() {
            self.revisions.push(epoch.revised_track);
        }
    }
}

#[test]
fn every_model_follows_a_walk_and_the_track_has_every_epoch() {
    for model in [TransitionModel::Reach, TransitionModel::Regions, TransitionModel::MovementVector] {
        let config = EngineConfig { transition: model, ..EngineConfig::default() };
        let mut engine = Engine::new(Arc::new(two_floor_site()), config).unwrap();
        for k in 0..5u64 {
            let x = 3.0 * k as f64;
            let p = engine
                .push_scan_with_motion(&scan(SECOND * (k + 1), &readings_at(0, x)), &walking(4))
                .unwrap()
                .position;
            assert!((p.x - x).abs() < 1.0 && p.floor == 0, "{model:?}: {p:?}");
            assert_eq!(p.scenario, MotionScenario::DistanceHeading);
        }
        let track = engine.track();
        assert_eq!(track.len(), 5);
        assert!(track.windows(2).all(|w| w[0].timestamp_ns < w[1].timestamp_ns));
        assert_eq!(
            track.iter().map(|p| p.x).collect::<Vec<_>>(),
            vec![0.0, 3.0, 6.0, 9.0, 12.0],
            "{model:?}"
        );
        // The fixed-lag estimate is the smoothed mass `lag` epochs back: on this clean walk it
        // sits on that epoch's track point, its mass on the state the track passed.
        let lagged = engine.fixed_lag_position().unwrap();
        let then = &track[5 - 1 - engine.config().fixed_lag_epochs];
        assert_eq!(
            (lagged.timestamp_ns, lagged.state, lagged.floor),
            (then.timestamp_ns, then.state, then.floor)
        );
        assert!((lagged.x - then.x).abs() < 1.0 && (lagged.y - then.y).abs() < 1.0, "{model:?}: {lagged:?}");
    }
}

/// The fixed-lag estimate smooths over the filter's steps since it last started over: feedback
/// pins an epoch without a step, so the lag starts again from it and grows back to the
/// configured one.
#[test]
fn the_fixed_lag_estimate_starts_again_at_feedback_and_grows_back() {
    let mut engine = Engine::new(Arc::new(two_floor_site()), EngineConfig::default()).unwrap();
    let lag = engine.config().fixed_lag_epochs;
    assert_eq!(engine.fixed_lag_position(), None);
    let mut times = Vec::new();
    for k in 0..5u64 {
        let t = SECOND * (k + 1);
        engine.push_scan_with_motion(&scan(t, &readings_at(0, 3.0 * k as f64)), &walking(4)).unwrap();
        times.push(t);
        // Until the filter has taken `lag` steps, the estimate is of its first epoch.
        assert_eq!(
            engine.fixed_lag_position().unwrap().timestamp_ns,
            times[k.saturating_sub(lag as u64) as usize]
        );
    }
    let latest = *times.last().unwrap();
    engine.confirm_position(latest, 12.0, 0.0, 0, 1.0).unwrap();
    let pinned = engine.fixed_lag_position().unwrap();
    assert_eq!(pinned.timestamp_ns, latest);
    assert!((pinned.x - 12.0).abs() < 1.0, "{pinned:?}");
    assert_eq!(engine.smoothed_position(1), None);
    for k in 5..5 + lag as u64 + 2 {
        let t = SECOND * (k + 1);
        engine.push_scan_with_motion(&scan(t, &readings_at(0, 12.0)), &MotionUpdate::default()).unwrap();
        times.push(t);
        let back = (k as usize - 4).min(lag);
        assert_eq!(engine.fixed_lag_position().unwrap().timestamp_ns, times[k as usize - back], "epoch {k}");
    }
    assert!(engine.smoothed_position(lag + 1).is_none(), "beyond the configured lag");
}

#[test]
fn scenario_and_motion_changes_are_announced() {
    let mut engine = Engine::new(Arc::new(two_floor_site()), EngineConfig::default()).unwrap();
    let mut r = Recorder::default();
    r.take(engine.push_scan(&scan(SECOND, &readings_at(0, 0.0))).unwrap());
    r.take(engine.push_scan_with_motion(&scan(2 * SECOND, &readings_at(0, 3.0)), &walking(4)).unwrap());
    r.take(engine.push_scan_with_motion(&scan(3 * SECOND, &readings_at(0, 6.0)), &walking(4)).unwrap());
    assert_eq!(r.positions.len(), 3);
    assert_eq!(
        r.statuses,
        vec![
            StatusEvent::ScenarioChanged {
                timestamp_ns: 2 * SECOND,
                from: MotionScenario::Speed,
                to: MotionScenario::DistanceHeading
            },
            StatusEvent::MotionStateChanged {
                timestamp_ns: 2 * SECOND,
                from: MotionState::Unknown,
                to: MotionState::Walking
            },
        ]
    );
}

/// A corridor of five states 3 m apart whose one transmitter is symmetric: -50 dBm at both
/// ends, -70 dBm in the middle. Only the direction of walking tells the ends apart.
fn symmetric_corridor() -> waymark_engine::Site {
    use waymark_engine::site::{BuildOptions, SiteBuilder};
    let mut b = SiteBuilder::new("symmetric");
    let f = b.floor("G", 0.0);
    let mut previous = None;
    for k in 0..5 {
        let x = 3.0 * k as f64;
        let mean = -50.0 - 10.0 * (x.min(12.0 - x) / 3.0);
        let scans = (0..20).map(|n| scan(n, &[(0, mean + if n % 2 == 0 { 2.0 } else { -2.0 })])).collect();
        let id = b.state(f, nalgebra::Point2::new(x, 0.0), scans);
        if let Some(p) = previous {
            b.edge(p, id, None);
        }
        previous = Some(id);
    }
    b.build(BuildOptions::default()).unwrap()
}

#[test]
fn a_later_epoch_revises_an_ambiguous_past() {
    let mut engine = Engine::new(Arc::new(symmetric_corridor()), EngineConfig::default()).unwrap();
    let mut r = Recorder::default();
    // At an end: which one, the radio cannot say.
    r.take(engine.push_scan(&scan(SECOND, &[(0, -50.0)])).unwrap());
    let first_guess = engine.track()[0].x;
    // Four steps east, and the signal fades: only the west end fits.
    r.take(engine.push_scan_with_motion(&scan(2 * SECOND, &[(0, -60.0)]), &walking(4)).unwrap());
    let track = engine.track();
    assert_eq!(track.iter().map(|p| p.x).collect::<Vec<_>>(), vec![0.0, 3.0]);
    if first_guess != 0.0 {
        assert_eq!(r.revisions.len(), 1, "{:?}", r.revisions);
        assert_eq!(r.revisions[0], vec![track[0].clone()]);
    } else {
        assert!(r.revisions.is_empty());
    }
}

#[test]
fn standing_still_holds_the_estimate_that_walking_would_move() {
    let still = MotionUpdate {
        distance_m: Some(0.0),
        distance_sigma_m: 0.0,
        displacement_m: Some([0.0, 0.0]),
        motion_state: MotionState::Stationary,
        scenario: MotionScenario::Distance,
        ..MotionUpdate::default()
    };
    let run = |motion: &MotionUpdate| {
        let config = EngineConfig { transition: TransitionModel::Regions, ..EngineConfig::default() };
        let mut engine = Engine::new(Arc::new(two_floor_site()), config).unwrap();
        engine.push_scan(&scan(SECOND, &readings_at(0, 6.0))).unwrap();
        // The radio now leans towards x = 9 by about 3.6 nats.
        engine.push_scan_with_motion(&scan(2 * SECOND, &readings_at(0, 7.6)), motion).unwrap().position
    };
    let held = run(&still);
    assert!((held.x - 6.0).abs() < 0.5, "{held:?}");
    let unknown = run(&MotionUpdate::default());
    assert!(unknown.x > 8.0, "{unknown:?}");
}

#[test]
fn motion_epochs_move_the_estimate_without_radio() {
    let config = EngineConfig { transition: TransitionModel::MovementVector, ..EngineConfig::default() };
    let mut engine = Engine::new(Arc::new(two_floor_site()), config).unwrap();
    engine.push_scan(&scan(SECOND, &readings_at(0, 0.0))).unwrap();
    let mut p = None;
    // 1.5 m/s: every other advance is held, its motion carried into the next.
    for k in 0..4u64 {
        p = Some(engine.advance_with_motion(SECOND * (k + 2), &walking(2)).unwrap().position);
    }
    let p = p.unwrap();
    assert!(p.radio_log_evidence.is_none());
    assert!(p.x > 4.5 && p.floor == 0, "{p:?}");
    assert_eq!(engine.stats().motion_epochs, 4);
    assert!(engine.advance_with_motion(SECOND, &walking(1)).is_err());
}

#[test]
fn motion_with_a_nan_or_negative_field_is_rejected_and_changes_nothing() {
    // Found by fuzzing (`engine_calls`): a NaN heading given with a scan came out as the
    // position's heading.
    let mut engine = Engine::new(Arc::new(two_floor_site()), EngineConfig::default()).unwrap();
    let first = engine.push_scan(&scan(SECOND, &readings_at(0, 0.0))).unwrap().position;
    let posterior = engine.posterior().to_vec();
    let bad = [
        MotionUpdate { heading_rad: Some(f64::NAN), ..walking(4) },
        MotionUpdate { heading_sigma_rad: f64::INFINITY, ..walking(4) },
        MotionUpdate { heading_sigma_rad: -0.25, ..walking(4) },
        MotionUpdate { distance_m: Some(-1.0), ..walking(4) },
        MotionUpdate { distance_sigma_m: f64::NAN, ..walking(4) },
        MotionUpdate { displacement_m: Some([f64::NEG_INFINITY, 0.0]), ..walking(4) },
    ];
    for (k, motion) in bad.iter().enumerate() {
        let scanned = engine.push_scan_with_motion(&scan(2 * SECOND, &readings_at(0, 3.0)), motion);
        assert!(matches!(scanned, Err(InputError::InvalidMotion { .. })), "{k}: {scanned:?}");
        let advanced = engine.advance_with_motion(2 * SECOND, motion);
        assert!(matches!(advanced, Err(InputError::InvalidMotion { .. })), "{k}: {advanced:?}");
    }
    assert_eq!(engine.stats().scans_invalid_motion, bad.len() as u64);
    assert_eq!(engine.posterior(), &posterior[..]);
    assert_eq!(engine.position(), Some(&first));
    let p =
        engine.push_scan_with_motion(&scan(2 * SECOND, &readings_at(0, 3.0)), &walking(4)).unwrap().position;
    assert!(p.heading_rad.is_some_and(f64::is_finite));
}

/// A walk east along floor 0's corridor on a simulated phone: its inertial samples.
fn corridor_walk() -> waymark_sim::imu::ImuTrace {
    use nalgebra::Point2;
    let points = [Point2::new(0.0, 0.0), Point2::new(12.0, 0.0)];
    let trajectory = waymark_sim::Trajectory::new(3 * SECOND, 1.0, &points, Vec::new());
    waymark_sim::imu::synthesize(&trajectory, &waymark_sim::imu::ImuConfig::default(), 7)
}

/// Engines on [`two_floor_site`] with Hoang's transition, one per `min_motion_step_s`.
fn hoang_engines<const N: usize>(min_motion_step_s: [f64; N]) -> [Engine; N] {
    let site = Arc::new(two_floor_site());
    min_motion_step_s.map(|min_motion_step_s| {
        let config = EngineConfig {
            transition: TransitionModel::MovementVector,
            min_motion_step_s,
            ..EngineConfig::default()
        };
        Engine::new(Arc::clone(&site), config).unwrap()
    })
}

/// Gives `engine` the samples of `trace` up to `t` not given yet (`cursor`).
fn feed(engine: &mut Engine, trace: &waymark_sim::imu::ImuTrace, cursor: &mut [usize; 3], t: u64) {
    let streams = [&trace.accelerometer, &trace.gyroscope, &trace.magnetometer];
    for (k, samples) in streams.iter().enumerate() {
        let to = cursor[k] + samples[cursor[k]..].partition_point(|s| s.timestamp_ns <= t);
        let batch = &samples[cursor[k]..to];
        match k {
            0 => engine.push_accelerometer(batch),
            1 => engine.push_gyroscope(batch),
            _ => engine.push_magnetometer(batch),
        };
        cursor[k] = to;
    }
}

/// An app advancing every 0.5 s between scans every 2 s gets the filter of one that only
/// scans: the advances sooner than `min_motion_step_s` after the filter's last step are held,
/// their motion carried into the next scan's step, so the mass spreads no more than over one
/// step. Their positions, the prediction by the motion since the step, move with the walker
/// meanwhile, no more certain than the step, and are not in the history. With
/// `min_motion_step_s` 0 every advance is a step, and the mass spreads more.
#[test]
fn advancing_more_often_than_the_minimum_step_moves_the_mass_as_one_step() {
    let trace = corridor_walk();
    let [mut often, mut scans_only, mut every_advance] = hoang_engines([2.0, 2.0, 0.0]);
    let mut cursors = [[0usize; 3]; 3];
    let (mut held, mut moved) = (0, 0);
    for k in 1..=32u64 {
        let t = k * SECOND / 2;
        for (engine, cursor) in
            [&mut often, &mut scans_only, &mut every_advance].into_iter().zip(&mut cursors)
        {
            feed(engine, &trace, cursor, t);
        }
        if k % 4 == 0 {
            let x = (t as f64 / SECOND as f64 - 3.0).clamp(0.0, 12.0);
            let s = scan(t, &readings_at(0, x));
            let p = often.push_scan(&s).unwrap().position;
            assert_eq!(p, scans_only.push_scan(&s).unwrap().position);
            every_advance.push_scan(&s).unwrap();
            assert_eq!(often.posterior(), scans_only.posterior(), "at {t}");
            assert_eq!(often.position(), scans_only.position());
        } else if k > 4 {
            let step = scans_only.position().unwrap().clone();
            let p = often.advance(t).unwrap().position;
            every_advance.advance(t).unwrap();
            assert_eq!((p.timestamp_ns, p.radio_log_evidence, p.floor), (t, None, step.floor));
            assert!(p.accuracy_m >= step.accuracy_m - 1e-9, "{p:?} {step:?}");
            held += 1;
            if p.steps > 0 && step.x < 10.0 {
                // East with the walker, by what it walked since the step, short of the
                // corridor's end at 12 m.
                assert!(p.x > step.x && (p.y - step.y).abs() < 0.5 * (p.x - step.x), "{p:?} {step:?}");
                moved += 1;
            }
        }
    }
    assert!(held == 21 && moved >= 10, "{held} held, {moved} moved");
    assert_eq!(often.history().len(), scans_only.history().len());
    assert_eq!(often.stats().motion_epochs, 21);
    assert_eq!(every_advance.history().len(), scans_only.history().len() + 21);
    let spread = |engine: &Engine| engine.posterior().iter().filter(|&&p| p > 1e-3).count();
    assert!(spread(&every_advance) >= spread(&often), "{:?}", every_advance.posterior());
    assert_ne!(every_advance.posterior(), often.posterior());
}

/// Motion given with held advances adds up ([`MotionUpdate::then`]) into the next epoch's.
/// A held advance's time is the latest epoch's: input before it is out of order, and feedback
/// at it is a step of its own over the held motion.
#[test]
fn held_motion_given_adds_up_and_a_held_epoch_orders_input() {
    let [mut held, mut once] = hoang_engines([2.0, 2.0]);
    let part = |k: u64| MotionUpdate { start_ns: (k - 1) * SECOND / 2, end_ns: k * SECOND / 2, ..walking(1) };
    for engine in [&mut held, &mut once] {
        engine.push_scan(&scan(SECOND / 2, &readings_at(0, 0.0))).unwrap();
    }
    let mut sum = part(2);
    for k in 2..=4 {
        let p = held.advance_with_motion(k * SECOND / 2, &part(k)).unwrap().position;
        assert_eq!(p.steps, (k - 1) as u32);
        if k > 2 {
            sum = sum.then(&part(k));
        }
    }
    assert_eq!(sum.distance_m, Some(2.25));
    assert_eq!(sum.displacement_m, Some([2.25, 0.0]));
    let late = held.push_scan(&scan(SECOND + SECOND / 4, &readings_at(0, 2.0)));
    assert_eq!(late, Err(InputError::OutOfOrder { timestamp_ns: SECOND + SECOND / 4, last_ns: 2 * SECOND }));
    let s = scan(5 * SECOND / 2, &readings_at(0, 3.0));
    held.push_scan_with_motion(&s, &part(5)).unwrap();
    once.push_scan_with_motion(&s, &sum.then(&part(5))).unwrap();
    assert_eq!(held.posterior(), once.posterior());
    assert_eq!(held.position(), once.position());

    held.advance_with_motion(3 * SECOND, &part(6)).unwrap();
    let steps = held.history().len();
    held.confirm_position(3 * SECOND, 6.0, 0.0, 0, 2.0).unwrap();
    assert_eq!(held.history().len(), steps + 1);
    assert_eq!(
        held.history().back().map(|r| (r.timestamp_ns, r.input.clone())),
        Some((3 * SECOND, waymark_engine::EpochInput::Feedback))
    );
}

/// An app whose timer advances 2 s after its last epoch by a clock a few milliseconds behind
/// the engine's (Android's newest sample) holds every other advance, and the next one comes
/// nearly 4 s after the filter's last step, beyond the walking-distance table's reach: the
/// filter first steps over the held motion, so the walk is followed as by an engine stepping
/// at every advance, not bridged by the speed bound alone. The held epoch is in the history.
#[test]
fn an_epoch_beyond_the_reach_of_the_last_step_steps_over_the_held_motion_first() {
    let trace = corridor_walk();
    let [mut app, mut reference] = hoang_engines([2.0, 0.0]);
    let mut cursors = [[0usize; 3]; 2];
    let mut t = 4 * SECOND;
    for (engine, cursor) in [&mut app, &mut reference].into_iter().zip(&mut cursors) {
        feed(engine, &trace, cursor, t);
        engine.push_scan(&scan(t, &readings_at(0, 1.0))).unwrap();
    }
    let mut worst: f64 = 0.0;
    for _ in 0..5 {
        t += 2 * SECOND - 5_000_000;
        for (engine, cursor) in [&mut app, &mut reference].into_iter().zip(&mut cursors) {
            feed(engine, &trace, cursor, t);
        }
        let p = app.advance(t).unwrap().position;
        let q = reference.advance(t).unwrap().position;
        worst = worst.max((p.x - q.x).hypot(p.y - q.y));
    }
    // 10 s walked at 1 m/s from x = 1: the end of the corridor.
    let end = app.position().unwrap();
    assert!(end.x > 9.0 && worst < 0.5, "{end:?}, {worst} m from the reference");
    assert_eq!(app.history().len(), reference.history().len() - 1, "the last advance is held");
}
