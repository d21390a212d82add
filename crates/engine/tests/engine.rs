//! The engine as an app uses it: scans in, positions out, bad input rejected and counted with
//! the engine unchanged.

mod common;

use common::{scan, two_floor_site};
use std::sync::Arc;
use waymark_engine::{Engine, EngineConfig, InputError, Site};

const SECOND: u64 = 1_000_000_000;

fn engine() -> Engine {
    Engine::new(Arc::new(two_floor_site()), EngineConfig::default()).unwrap()
}

/// What a transmitter layout predicts at x on floor f (the site's training means).
fn readings_at(f: usize, x: f64) -> Vec<(u8, f64)> {
    (0..3).map(|t| ((3 * f + t) as u8, -40.0 - 4.0 * (x - 6.0 * t as f64).abs())).collect()
}

#[test]
fn finds_the_floor_and_the_place() {
    let mut engine = engine();
    for k in 0..3 {
        let p = engine.push_scan(&scan(SECOND * (k + 1), &readings_at(1, 9.0))).unwrap().position;
        assert_eq!(p.floor, 1);
        assert!(p.floor_probability > 0.99, "{p:?}");
        assert!((p.x - 9.0).abs() < 1.0 && p.y.abs() < 1e-9, "{p:?}");
        assert!(p.accuracy_m > 0.0 && p.accuracy_m < 3.0, "{p:?}");
    }
    assert_eq!(engine.stats().scans_accepted, 3);
    let sum: f64 = engine.posterior().iter().sum();
    assert!((sum - 1.0).abs() < 1e-12);
}

#[test]
fn rejected_input_leaves_the_engine_unchanged_and_is_counted() {
    let mut engine = engine();
    let first = engine.push_scan(&scan(10 * SECOND, &readings_at(0, 3.0))).unwrap().position;
    let posterior = engine.posterior().to_vec();

    let back = engine.push_scan(&scan(9 * SECOND, &readings_at(1, 3.0)));
    assert_eq!(back, Err(InputError::OutOfOrder { timestamp_ns: 9 * SECOND, last_ns: 10 * SECOND }));
    let same = engine.push_scan(&scan(10 * SECOND, &readings_at(1, 3.0)));
    assert!(matches!(same, Err(InputError::OutOfOrder { .. })));
    assert_eq!(engine.push_scan(&scan(11 * SECOND, &[])), Err(InputError::EmptyScan));
    let nan = engine.push_scan(&scan(11 * SECOND, &[(0, -60.0), (1, f64::NAN)]));
    assert!(matches!(nan, Err(InputError::NonFiniteRssi { index: 1, .. })));
    let inf = engine.push_scan(&scan(11 * SECOND, &[(0, f64::NEG_INFINITY)]));
    assert!(matches!(inf, Err(InputError::NonFiniteRssi { index: 0, .. })));
    let unknown = engine.push_scan(&scan(11 * SECOND, &[(77, -60.0), (78, -70.0)]));
    assert_eq!(unknown, Err(InputError::NoKnownTransmitter { unknown: 2, stale: 0 }));
    // An advance back in time, or to the last epoch's time, is counted apart from scans.
    let advance = engine.advance(9 * SECOND);
    assert_eq!(advance, Err(InputError::OutOfOrder { timestamp_ns: 9 * SECOND, last_ns: 10 * SECOND }));
    assert!(matches!(engine.advance(10 * SECOND), Err(InputError::OutOfOrder { .. })));

    assert_eq!(engine.posterior(), &posterior[..]);
    assert_eq!(engine.position(), Some(&first));
    let stats = engine.stats();
    assert_eq!(
        (
            stats.scans_accepted,
            stats.scans_out_of_order,
            stats.scans_empty,
            stats.scans_non_finite,
            stats.scans_no_known_transmitter,
            stats.advances_rejected,
            stats.motion_epochs,
        ),
        (1, 2, 1, 2, 1, 2, 0)
    );

    // Unknown and duplicate readings inside a good scan are dropped and counted, not fatal.
    let mut mixed = readings_at(0, 3.0);
    mixed.push((77, -50.0));
    mixed.push((0, -90.0));
    engine.push_scan(&scan(12 * SECOND, &mixed)).unwrap();
    assert_eq!((engine.stats().readings_unknown, engine.stats().readings_duplicate), (1, 1));
}

/// A site that keeps its survey's reading-age limit has engines apply it by default, as the
/// survey and its calibration did: an app gets the positions that were evaluated. The
/// configuration can still set its own limit, or keep every reading.
#[test]
fn the_sites_reading_age_limit_applies_unless_the_config_sets_one() {
    let aged = |ages: [u64; 3]| {
        let mut s = scan(10 * SECOND, &readings_at(1, 9.0));
        for (r, age) in s.readings.iter_mut().zip(ages) {
            r.age_ns = age;
        }
        s
    };
    let site = Arc::new(two_floor_site().with_max_reading_age_ns(Some(2 * SECOND)));
    let stale_after = |site: &Arc<Site>, config: EngineConfig, ages: [u64; 3]| {
        let mut engine = Engine::new(Arc::clone(site), config).unwrap();
        let result = engine.push_scan(&aged(ages)).map(|_| ());
        (result, engine.stats().readings_stale)
    };
    let default = EngineConfig::default;
    assert_eq!(stale_after(&site, default(), [0, 2 * SECOND, 5 * SECOND]), (Ok(()), 1));
    assert_eq!(
        stale_after(&site, default(), [3 * SECOND; 3]),
        (Err(InputError::NoKnownTransmitter { unknown: 0, stale: 3 }), 0),
        "every reading stale: the scan says nothing"
    );
    let own = EngineConfig { max_reading_age_ns: Some(SECOND), ..default() };
    assert_eq!(stale_after(&site, own, [0, 2 * SECOND, 5 * SECOND]), (Ok(()), 2));
    let every = EngineConfig { max_reading_age_ns: Some(u64::MAX), ..default() };
    assert_eq!(stale_after(&site, every, [0, 2 * SECOND, 5 * SECOND]), (Ok(()), 0));
    // A site without a limit (files before format version 4) keeps every reading.
    let unlimited = Arc::new(two_floor_site());
    assert_eq!(stale_after(&unlimited, default(), [0, 2 * SECOND, 5 * SECOND]), (Ok(()), 0));
    // The limit survives the site file.
    let reloaded = Site::from_bytes(&site.to_binary()).unwrap();
    assert_eq!(reloaded.max_reading_age_ns(), Some(2 * SECOND));
}

#[test]
fn the_sites_calibrated_m_applies_unless_the_config_sets_one() {
    let calibrated = |m: Option<u32>| {
        let calibration = waymark_engine::site::Calibration { estimate_states: m, ..Default::default() };
        Arc::new(two_floor_site().with_calibration(calibration).unwrap())
    };
    // Between two states' fingerprints, so that the M most likely states average to
    // different places.
    let position_after = |site: &Arc<Site>, config: EngineConfig| {
        let mut engine = Engine::new(Arc::clone(site), config).unwrap();
        let p = engine.push_scan(&scan(SECOND, &readings_at(1, 7.3))).unwrap().position;
        let by_m: Vec<[f64; 2]> = engine.positions_by_states(&[1, 3]);
        ([p.x, p.y], by_m)
    };
    let default = EngineConfig::default;
    let (p, by_m) = position_after(&calibrated(Some(1)), default());
    assert_ne!(by_m[0], by_m[1], "M must matter on this scan: {by_m:?}");
    assert_eq!(p, by_m[0], "the site's M");
    let (p, by_m) =
        position_after(&calibrated(Some(1)), EngineConfig { estimate_states: Some(3), ..default() });
    assert_eq!(p, by_m[1], "the configuration's M");
    let (p, by_m) =
        position_after(&calibrated(Some(3)), EngineConfig { estimate_states: Some(1), ..default() });
    assert_eq!(p, by_m[0], "the configuration's M");
    let (p, by_m) =
        position_after(&calibrated(Some(1)), EngineConfig { site_calibration: false, ..default() });
    assert_eq!(p, by_m[1], "without the site's calibration, the default M");
    assert_eq!(waymark_engine::DEFAULT_ESTIMATE_STATES, 3);
    let (p, by_m) = position_after(&calibrated(None), default());
    assert_eq!(p, by_m[1], "a site without one: the default M");
    // M survives the site file, and 0 is refused.
    let reloaded = Site::from_bytes(&calibrated(Some(30)).to_binary()).unwrap();
    assert_eq!(reloaded.calibration().estimate_states, Some(30));
    let zero = waymark_engine::site::Calibration { estimate_states: Some(0), ..Default::default() };
    assert!(two_floor_site().with_calibration(zero).is_err());
}

#[test]
fn each_epoch_returns_its_position_and_a_rejected_one_returns_nothing() {
    let mut engine = engine();
    let first = engine.push_scan(&scan(SECOND, &readings_at(0, 0.0))).unwrap();
    assert_eq!(engine.position(), Some(&first.position));
    assert!(first.status.is_empty() && first.revised_track.is_empty(), "nothing came before it: {first:?}");
    let second = engine.push_scan(&scan(2 * SECOND, &readings_at(0, 3.0))).unwrap();
    assert_eq!(second.position.timestamp_ns, 2 * SECOND);
    assert!(engine.push_scan(&scan(SECOND, &readings_at(0, 3.0))).is_err());
    assert_eq!(engine.position(), Some(&second.position), "the rejected scan changed nothing");
}

#[test]
fn a_long_silence_restarts_from_the_prior_and_recovers() {
    let mut engine = engine();
    engine.push_scan(&scan(SECOND, &readings_at(0, 0.0))).unwrap();
    // Ten minutes later, on the other floor.
    let p = engine.push_scan(&scan(601 * SECOND, &readings_at(1, 12.0))).unwrap().position;
    assert_eq!(engine.stats().filter_restarts, 1);
    assert_eq!(p.floor, 1);
    assert!((p.x - 12.0).abs() < 1.5, "{p:?}");
}

#[test]
fn a_site_file_round_trip_gives_the_same_track() {
    let site = two_floor_site();
    let reloaded = Site::from_json(site.to_json().as_bytes()).unwrap();
    let run = |site: Site| {
        let mut engine = Engine::new(Arc::new(site), EngineConfig::default()).unwrap();
        (0..5)
            .map(|k| {
                engine.push_scan(&scan(SECOND * (k + 1), &readings_at(0, 3.0 * k as f64))).unwrap().position
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(run(site), run(reloaded));
}

#[test]
fn without_the_track_the_positions_are_the_same() {
    let run = |track: bool| {
        let config = EngineConfig { track, ..EngineConfig::default() };
        let mut engine = Engine::new(Arc::new(two_floor_site()), config).unwrap();
        // Walking along floor 0, a gap the walking-distance table does not cover, then floor 1.
        let times = [1, 2, 3, 4, 5, 40, 41, 42];
        let epochs: Vec<_> = (times.iter().enumerate())
            .map(|(k, &t)| {
                let readings = if t < 40 { readings_at(0, 3.0 * k as f64) } else { readings_at(1, 12.0) };
                engine.push_scan(&scan(SECOND * t, &readings)).unwrap()
            })
            .collect();
        (epochs, engine.track(), engine.track_memory_bytes())
    };
    let (with, track, bytes) = run(true);
    let (without, no_track, no_bytes) = run(false);
    let positions =
        |epochs: &[waymark_engine::Epoch]| epochs.iter().map(|e| e.position.clone()).collect::<Vec<_>>();
    assert_eq!(positions(&with), positions(&without));
    assert_eq!(track.len(), 8);
    assert!(bytes > 0);
    assert!(no_track.is_empty() && no_bytes == 0);
    assert!(without.iter().all(|e| e.revised_track.is_empty()));
}

#[test]
fn invalid_config_is_refused() {
    let config = EngineConfig { estimate_states: Some(0), ..EngineConfig::default() };
    let err = Engine::new(Arc::new(two_floor_site()), config).err().unwrap();
    assert!(err.to_string().contains("estimate_states"));
}

#[test]
fn an_rssi_no_receiver_reports_rejects_the_scan() {
    // Found by fuzzing (`engine_calls`): at f64::MAX dBm every state's log-likelihood was -inf,
    // the filter restarted, and the position carried a radio_log_evidence of -inf.
    let mut engine = engine();
    let first = engine.push_scan(&scan(10 * SECOND, &readings_at(0, 3.0))).unwrap().position;
    for rssi in [f64::MAX, 1e300, 100.5] {
        let high = engine.push_scan(&scan(11 * SECOND, &[(0, -60.0), (1, rssi)]));
        assert!(matches!(high, Err(InputError::RssiTooHigh { index: 1, .. })), "{rssi}: {high:?}");
    }
    assert_eq!(engine.stats().scans_rssi_too_high, 3);
    assert_eq!(engine.position(), Some(&first));
    let loud = engine.push_scan(&scan(11 * SECOND, &[(0, waymark_engine::MAX_RSSI_DBM)])).unwrap().position;
    assert!(loud.radio_log_evidence.is_some_and(f64::is_finite));
}

/// Hoang eq. 14 per floor: an epoch runs at the γ of the floor of the latest estimate (the
/// site-wide γ before there is one, and for a floor without its own), one γ for every state;
/// an explicit γ in the configuration overrides every floor.
#[test]
fn each_epoch_weighs_the_radio_by_the_gamma_of_the_floor_it_is_on() {
    use waymark_engine::site::Calibration;
    let (site_wide, floor_1) = (0.3, 0.05);
    let with = |floors: [Option<f64>; 2]| {
        let calibration = Calibration { rssi_weight: Some(site_wide), ..Calibration::default() };
        let site = two_floor_site().with_calibration(calibration).unwrap();
        Arc::new(site.with_floor_rssi_weights(&floors.map(|g| [g, None])).unwrap())
    };
    let per_floor = with([None, Some(floor_1)]);
    let everywhere = with([Some(floor_1), Some(floor_1)]);
    let none = with([None, None]);
    let run = |site: &Arc<Site>, rssi_weight: Option<f64>, f: usize| {
        let config = EngineConfig { rssi_weight, ..EngineConfig::default() };
        let mut engine = Engine::new(Arc::clone(site), config).unwrap();
        // Both floors' transmitters, so that both floors keep mass.
        let mut posteriors = Vec::new();
        for k in 1..=2 {
            let readings: Vec<(u8, f64)> = readings_at(f, 3.0)
                .into_iter()
                .chain(readings_at(1 - f, 9.0).into_iter().map(|(t, v)| (t, v - 20.0)))
                .collect();
            let p = engine.push_scan(&scan(k * SECOND, &readings)).unwrap().position;
            assert_eq!(p.floor, f);
            posteriors.push(engine.posterior().to_vec());
        }
        posteriors
    };
    // On floor 1: the first epoch at the site-wide γ, the second at floor 1's.
    let on_1 = run(&per_floor, None, 1);
    assert_eq!(on_1[0], run(&none, None, 1)[0]);
    assert_eq!(on_1[1], run(&everywhere, None, 1)[1]);
    assert_ne!(on_1[1], run(&none, None, 1)[1]);
    // On floor 0, which has no γ of its own: the site-wide γ throughout.
    assert_eq!(run(&per_floor, None, 0), run(&none, None, 0));
    assert_ne!(run(&everywhere, None, 0)[1], run(&none, None, 0)[1]);
    // An explicit γ overrides the floors'.
    assert_eq!(run(&per_floor, Some(0.5), 1), run(&none, Some(0.5), 1));
}

/// The radius factors follow the epoch's motion scenario: a scan with no motion before it is a
/// speed-only epoch, so it gets `speed`'s factors, and the site-wide ones when the scenario has
/// none of its own. A bad factor is refused with its path.
#[test]
fn radius_factors_follow_the_epochs_scenario() {
    use waymark_engine::sensors::MotionScenario;
    use waymark_engine::site::{Calibration, ScenarioScales};
    let radius = |calibration: Calibration| {
        let site = Arc::new(two_floor_site().with_calibration(calibration).unwrap());
        let mut engine = Engine::new(site, EngineConfig::default()).unwrap();
        let p = engine.push_scan(&scan(SECOND, &readings_at(0, 3.0))).unwrap().position;
        assert_eq!(p.scenario, MotionScenario::Speed);
        (p.accuracy_m, p.accuracy_95_m)
    };
    let plain = radius(Calibration::default());
    let site_wide = Calibration { accuracy_scale: Some([2.0, 3.0]), ..Calibration::default() };
    let scaled = radius(site_wide);
    assert!((scaled.0 - 2.0 * plain.0).abs() < 1e-9, "{plain:?} {scaled:?}");
    let mut by_scenario = ScenarioScales::default();
    by_scenario.set(MotionScenario::Speed, Some([5.0, 7.0]));
    let own = radius(Calibration { accuracy_scale_by_scenario: by_scenario, ..site_wide });
    assert!((own.0 - 5.0 * plain.0).abs() < 1e-9, "{plain:?} {own:?}");
    assert!((own.1 - (7.0 * plain.1).max(own.0)).abs() < 1e-9, "{plain:?} {own:?}");
    // Another scenario's factors leave a speed-only epoch at the site-wide ones.
    let mut other = ScenarioScales::default();
    other.set(MotionScenario::DistanceHeading, Some([5.0, 7.0]));
    let fallback = radius(Calibration { accuracy_scale_by_scenario: other, ..site_wide });
    assert!((fallback.0 - scaled.0).abs() < 1e-12);

    let mut bad = ScenarioScales::default();
    bad.set(MotionScenario::Distance, Some([f64::NAN, 2.0]));
    let refused =
        two_floor_site().with_calibration(Calibration { accuracy_scale_by_scenario: bad, ..site_wide });
    let message = format!("{:?}", refused.err());
    assert!(message.contains("calibration.accuracy_scale_by_scenario.distance"), "{message}");
}

/// An epoch without the movement vector's likelihood takes its scenario's γ when the site has
/// one (a distance-only epoch the site's `distance` γ), else the γ without movement; the first
/// epoch, which has no transition at all, takes the γ without movement; an explicit γ in the
/// configuration overrides both, and a γ out of (0, 1] is refused with its path.
#[test]
fn an_epoch_without_movement_takes_its_scenarios_gamma() {
    use waymark_engine::sensors::{MotionScenario, MotionState, MotionUpdate};
    use waymark_engine::site::{Calibration, PerScenario};
    let (without, distance_only) = (0.3, 0.05);
    let site = |by_scenario: Option<f64>, without: f64| {
        let mut rssi_weight_by_scenario = PerScenario::default();
        rssi_weight_by_scenario.set(MotionScenario::Distance, by_scenario);
        let calibration = Calibration {
            rssi_weight_without_movement: Some(without),
            rssi_weight_by_scenario,
            ..Calibration::default()
        };
        Arc::new(two_floor_site().with_calibration(calibration).unwrap())
    };
    // Two scans, each after a metre walked with no heading, or with no motion
    // at all (speed only).
    let run = |site: &Arc<Site>, config: EngineConfig, walked: bool| {
        let mut engine = Engine::new(Arc::clone(site), config).unwrap();
        let mut posteriors = Vec::new();
        for k in 1..=2u64 {
            let s = scan(k * SECOND, &readings_at(0, 3.0 + k as f64));
            let p = if walked {
                let motion = MotionUpdate {
                    start_ns: (k - 1) * SECOND,
                    end_ns: k * SECOND,
                    steps: 1,
                    distance_m: Some(1.0),
                    distance_sigma_m: 0.1,
                    motion_state: MotionState::Walking,
                    scenario: MotionScenario::Distance,
                    ..MotionUpdate::default()
                };
                engine.push_scan_with_motion(&s, &motion).unwrap().position
            } else {
                engine.push_scan(&s).unwrap().position
            };
            assert_eq!(p.scenario, if walked { MotionScenario::Distance } else { MotionScenario::Speed });
            posteriors.push(engine.posterior().to_vec());
        }
        posteriors
    };
    let default = EngineConfig::default;
    let own = site(Some(distance_only), without);
    let (walked, reference) = (run(&own, default(), true), run(&site(None, without), default(), true));
    assert_eq!(walked[0], reference[0], "the first epoch weighs the radio as without movement");
    assert_ne!(walked[1], reference[1], "a distance-only epoch takes the distance γ");
    // With the distance γ as the γ without movement too, only the first epoch differs.
    assert_ne!(walked[0], run(&site(None, distance_only), default(), true)[0]);
    // A speed-only epoch on the same site: the γ without movement.
    assert_eq!(run(&own, default(), false), run(&site(None, without), default(), false));
    // An explicit γ overrides the scenario's.
    let explicit = EngineConfig { rssi_weight_without_movement: Some(0.5), ..default() };
    assert_eq!(run(&own, explicit.clone(), true), run(&site(None, without), explicit, true));
    let refused = two_floor_site().with_calibration(Calibration {
        rssi_weight_by_scenario: PerScenario { heading_speed: Some(0.0), ..PerScenario::default() },
        ..Calibration::default()
    });
    let message = format!("{:?}", refused.err());
    assert!(message.contains("calibration.rssi_weight_by_scenario.heading_speed"), "{message}");
}

/// Second k of a walk: `distance_m` walked in two steps, no heading.
fn walking(k: u64, distance_m: f64) -> waymark_engine::sensors::MotionUpdate {
    use waymark_engine::sensors::{MotionScenario, MotionState, MotionUpdate};
    MotionUpdate {
        start_ns: (k - 1) * SECOND,
        end_ns: k * SECOND,
        steps: 2,
        distance_m: Some(distance_m),
        distance_sigma_m: 0.1,
        motion_state: MotionState::Walking,
        scenario: MotionScenario::Distance,
        ..MotionUpdate::default()
    }
}

/// Beyond the surveyed area. A scan the map does not explain (a radio fit below the site's
/// floor) leaves the estimate to the motion alone, as an epoch without a scan would, and both
/// radii grow by the distance walked since the radio last explained a scan, motion-only epochs
/// included; a scan it explains brings them back. The first scan is used whatever its fit, and
/// an engine told not to take the site's calibration has no floor.
#[test]
fn beyond_the_map_the_radii_grow_with_the_distance_walked() {
    use waymark_engine::site::Calibration;
    let walked = |k: u64| walking(k, 1.5);
    let explained = readings_at(0, 3.0);
    // Floor 0's transmitters all faint, as nowhere on the map: a state that never heard them
    // does about as well as any.
    let unexplained: Vec<(u8, f64)> = (0..3).map(|t| (t, -92.0)).collect();
    let fit = |readings: &[(u8, f64)]| {
        engine().push_scan(&scan(SECOND, readings)).unwrap().position.radio_fit.unwrap()
    };
    let (good, bad) = (fit(&explained), fit(&unexplained));
    assert!(good > bad + 2.0, "{good} {bad}");
    let site = |floor: f64| {
        let calibration = Calibration { radio_fit_floor: Some(floor), ..Calibration::default() };
        Arc::new(two_floor_site().with_calibration(calibration).unwrap())
    };
    let site = site(0.5 * (good + bad));

    // `twin` gets the same input, but no scan where `engine`'s is unexplained; its filter steps
    // at every advance, as `engine`'s does at every scan.
    let mut engine = Engine::new(Arc::clone(&site), EngineConfig::default()).unwrap();
    let every_advance = EngineConfig { min_motion_step_s: 0.0, ..EngineConfig::default() };
    let mut twin = Engine::new(Arc::clone(&site), every_advance).unwrap();
    // The first scan is all there is to go on.
    let first = engine.push_scan_with_motion(&scan(SECOND, &unexplained), &walked(1)).unwrap().position;
    assert_eq!((first.beyond_radio_m, engine.stats().scans_unexplained), (0.0, 0));
    twin.push_scan_with_motion(&scan(SECOND, &unexplained), &walked(1)).unwrap();
    assert_eq!(engine.posterior(), twin.posterior());
    let p = engine.push_scan_with_motion(&scan(2 * SECOND, &explained), &walked(2)).unwrap().position;
    assert_eq!(p.beyond_radio_m, 0.0);
    twin.push_scan_with_motion(&scan(2 * SECOND, &explained), &walked(2)).unwrap();
    // Three unexplained scans: each moves the estimate as the motion alone would.
    for k in 3..=5u64 {
        twin.advance_with_motion(k * SECOND, &walked(k)).unwrap();
        let p = engine.push_scan_with_motion(&scan(k * SECOND, &unexplained), &walked(k)).unwrap().position;
        assert!(p.radio_fit.is_some_and(|f| f < 0.5 * (good + bad)), "{p:?}");
        assert_eq!(engine.posterior(), twin.posterior());
        let beyond = 1.5 * (k - 2) as f64;
        assert!((p.beyond_radio_m - beyond).abs() < 1e-9, "{p:?}");
        assert!(p.accuracy_m > beyond && p.accuracy_95_m >= p.accuracy_m, "{p:?}");
    }
    assert_eq!(engine.stats().scans_unexplained, 3);
    // No scan since an unexplained one: still growing.
    let p = engine.advance_with_motion(6 * SECOND, &walked(6)).unwrap().position;
    assert!((p.beyond_radio_m - 6.0).abs() < 1e-9, "{p:?}");
    // Explained again.
    let p = engine.push_scan_with_motion(&scan(7 * SECOND, &explained), &walked(7)).unwrap().position;
    assert_eq!(p.beyond_radio_m, 0.0);
    assert!(p.accuracy_m < 3.0, "{p:?}");

    let config = EngineConfig { site_calibration: false, ..EngineConfig::default() };
    let mut plain = Engine::new(site, config).unwrap();
    plain.push_scan_with_motion(&scan(SECOND, &explained), &walked(1)).unwrap();
    let p = plain.push_scan_with_motion(&scan(2 * SECOND, &unexplained), &walked(2)).unwrap().position;
    assert_eq!((p.beyond_radio_m, plain.stats().scans_unexplained), (0.0, 0));
}

/// A corridor surveyed from x = 0 to 12 m that carries on, unsurveyed, to 24 m: while the radio
/// explains the scans the unsurveyed states hold no mass at all; when it stops explaining them
/// the walker's measured movement carries the estimate out along the unsurveyed corridor, where
/// a site without those states pins it to the map's end; an explained scan brings it back.
#[test]
fn beyond_the_map_the_motion_carries_the_estimate_onto_unsurveyed_states() {
    use common::wifi;
    use nalgebra::Point2;
    use waymark_engine::radio::{Reading, Scan};
    use waymark_engine::sensors::{MotionScenario, MotionUpdate};
    use waymark_engine::site::{BuildOptions, Calibration, SiteBuilder, StateKind};
    let level = |t: u8, x: f64| -40.0 - 4.0 * (x - 6.0 * f64::from(t)).abs();
    let site = |unsurveyed: bool| {
        let mut b = SiteBuilder::new("corridor");
        let floor = b.floor("G", 0.0);
        let mut previous: Option<u32> = None;
        for k in 0..9 {
            let x = 3.0 * k as f64;
            let id = if k <= 4 {
                let scans = (0..20)
                    .map(|n| {
                        let jitter = if n % 2 == 0 { 2.0 } else { -2.0 };
                        let readings = (0..3)
                            .map(|t| Reading {
                                transmitter: wifi(t),
                                rssi_dbm: level(t, x) + jitter,
                                age_ns: 0,
                            })
                            .collect();
                        Scan { timestamp_ns: n, readings }
                    })
                    .collect();
                b.state(floor, Point2::new(x, 0.0), scans)
            } else if unsurveyed {
                b.unsurveyed_state(floor, Point2::new(x, 0.0))
            } else {
                break;
            };
            if let Some(p) = previous {
                b.edge(p, id, None);
            }
            previous = Some(id);
        }
        let site = b.build(BuildOptions::default()).unwrap();
        let calibration = Calibration { radio_fit_floor: Some(1.0), ..Calibration::default() };
        Arc::new(site.with_calibration(calibration).unwrap())
    };
    let (open, closed) = (site(true), site(false));
    assert_eq!(open.states().iter().filter(|s| s.kind == StateKind::Unsurveyed).count(), 4);
    let walked_east = |k: u64| MotionUpdate {
        heading_rad: Some(std::f64::consts::FRAC_PI_2),
        heading_sigma_rad: 0.1,
        displacement_m: Some([3.0, 0.0]),
        scenario: MotionScenario::DistanceHeading,
        ..walking(k, 3.0)
    };
    let explained_at = |x: f64| -> Vec<(u8, f64)> { (0..3).map(|t| (t, level(t, x))).collect() };
    let unexplained: Vec<(u8, f64)> = (0..3).map(|t| (t, -92.0)).collect();
    let unsurveyed_mass = |engine: &Engine| -> f64 {
        let states = engine.site().states();
        engine
            .posterior()
            .iter()
            .zip(states)
            .filter(|(_, s)| s.kind == StateKind::Unsurveyed)
            .map(|(p, _)| p)
            .sum()
    };
    let mut engine = Engine::new(Arc::clone(&open), EngineConfig::default()).unwrap();
    let mut pinned = Engine::new(closed, EngineConfig::default()).unwrap();
    for (k, x) in [(1, 6.0), (2, 9.0), (3, 12.0)] {
        let p = engine
            .push_scan_with_motion(&scan(k * SECOND, &explained_at(x)), &walked_east(k))
            .unwrap()
            .position;
        pinned.push_scan_with_motion(&scan(k * SECOND, &explained_at(x)), &walked_east(k)).unwrap();
        assert_eq!(unsurveyed_mass(&engine), 0.0, "{p:?}");
        assert!((p.x - x).abs() < 1.5, "{p:?}");
    }
    // Walking on past the map's end, hearing nothing the map explains. One such scan could be
    // a bad one on the map: the estimate stays on it, moved by the motion alone.
    let p = engine.push_scan_with_motion(&scan(4 * SECOND, &unexplained), &walked_east(4)).unwrap().position;
    let q = pinned.push_scan_with_motion(&scan(4 * SECOND, &unexplained), &walked_east(4)).unwrap().position;
    // The fit is the fingerprinted map's: unsurveyed states, which score the no-fingerprint
    // baseline, neither raise it to 0 nor keep a site whose floor is 0 from finding it out.
    assert_eq!(p.radio_fit, q.radio_fit);
    assert!(p.radio_fit.is_some_and(|f| f < 0.0), "{p:?}");
    assert_eq!(unsurveyed_mass(&engine), 0.0, "{p:?}");
    let same =
        engine.posterior()[..5].iter().zip(&pinned.posterior()[..5]).all(|(a, b)| (a - b).abs() <= 1e-12);
    assert!(same, "{:?} {:?}", engine.posterior(), pinned.posterior());
    // From the second in a row the motion carries it off the map, a scan behind the walker.
    let mut last_x = p.x;
    for k in 5..=7u64 {
        let p =
            engine.push_scan_with_motion(&scan(k * SECOND, &unexplained), &walked_east(k)).unwrap().position;
        let q =
            pinned.push_scan_with_motion(&scan(k * SECOND, &unexplained), &walked_east(k)).unwrap().position;
        let truth = 3.0 * k as f64 + 3.0;
        // About 2.7 m of each 3 m walked (measured 14.4, 17.1, 19.9 m), behind the truth.
        assert!(p.x > last_x + 2.0 && p.x < truth, "{truth} {p:?}");
        assert!(q.x <= 12.0 + 1e-9, "{q:?}");
        assert!(p.beyond_radio_m > 0.0 && p.accuracy_m > p.beyond_radio_m, "{p:?}");
        last_x = p.x;
    }
    assert!(unsurveyed_mass(&engine) > 0.99);
    // A motion-only epoch out there moves it on.
    let p = engine.advance_with_motion(8 * SECOND, &walked_east(8)).unwrap().position;
    assert!(p.x > last_x + 2.0, "{p:?}");
    // The radio explains a scan again: back on the map, the unsurveyed states emptied.
    let p = engine
        .push_scan_with_motion(&scan(9 * SECOND, &explained_at(12.0)), &walked_east(9))
        .unwrap()
        .position;
    assert_eq!(unsurveyed_mass(&engine), 0.0);
    assert!((p.x - 12.0).abs() < 1.5 && p.beyond_radio_m == 0.0, "{p:?}");
}

/// Scans far apart, as under Android 9+'s throttling (`SparseScans`): after a sparse scan the
/// radii take the factors of the band of time since it, and the epochs with a movement
/// likelihood its γ; in a steady stream of scans (2 s apart) neither applies, except after
/// the first scan, whose posterior holds one scan as after a sparse one.
#[test]
fn sparse_scans_take_their_own_radius_factors_and_gamma() {
    use waymark_engine::sensors::{MotionScenario, MotionState, MotionUpdate};
    use waymark_engine::site::{Calibration, FloorReliability, SparseScans, SPARSE_BANDS};
    let mut accuracy_scale_by_since = [None; SPARSE_BANDS];
    accuracy_scale_by_since[0] = Some([3.0, 4.0]);
    accuracy_scale_by_since[1] = Some([5.0, 6.0]);
    let base = Calibration { rssi_weight: Some(0.3), ..Calibration::default() };
    let site = |sparse_scans: SparseScans| {
        Arc::new(two_floor_site().with_calibration(Calibration { sparse_scans, ..base }).unwrap())
    };
    let (plain, scales, gamma) = (
        site(SparseScans::default()),
        site(SparseScans { accuracy_scale_by_since, ..SparseScans::default() }),
        site(SparseScans { rssi_weight: Some(0.05), ..SparseScans::default() }),
    );
    // An epoch every 2 s from 1 s to 41 s, 0.3 m east each with steps and heading measured;
    // a scan where `scan_at` says, else a timer epoch.
    let run = |site: &Arc<Site>, config: EngineConfig, scan_at: &dyn Fn(u64) -> bool| {
        let mut engine = Engine::new(Arc::clone(site), config).unwrap();
        (0..21u64)
            .map(|k| {
                let t = (1 + 2 * k) * SECOND;
                let x = 3.0 + 0.3 * k as f64;
                let motion = MotionUpdate {
                    start_ns: t.saturating_sub(2 * SECOND),
                    end_ns: t,
                    steps: 1,
                    distance_m: Some(0.3),
                    distance_sigma_m: 0.1,
                    heading_rad: Some(std::f64::consts::FRAC_PI_2),
                    heading_sigma_rad: 0.1,
                    displacement_m: Some([0.3, 0.0]),
                    motion_state: MotionState::Walking,
                    scenario: MotionScenario::DistanceHeading,
                    ..MotionUpdate::default()
                };
                let p = if scan_at(t / SECOND) {
                    engine.push_scan_with_motion(&scan(t, &readings_at(0, x)), &motion)
                } else {
                    engine.advance_with_motion(t, &motion)
                };
                (p.unwrap(), engine.posterior().to_vec())
            })
            .collect::<Vec<_>>()
    };
    let throttled = |s: u64| s == 1 || s == 31;
    let steady = |_: u64| true;
    let default = EngineConfig::default;
    // Radii: the band's factors where it has some, else the scenario's (none here: 1).
    let (a, b) = (run(&plain, default(), &throttled), run(&scales, default(), &throttled));
    let ratios: Vec<f64> =
        a.iter().zip(&b).map(|(a, b)| b.0.position.accuracy_m / a.0.position.accuracy_m).collect();
    let expected = |s: u64| match s {
        1 | 31 => 3.0,
        3 | 5 | 33 | 35 => 5.0,
        _ => 1.0,
    };
    for (k, ratio) in ratios.iter().enumerate() {
        assert!((ratio - expected(1 + 2 * k as u64)).abs() < 1e-9, "epoch {k}: {ratios:?}");
        assert_eq!(a[k].1, b[k].1, "the factors change the radii only");
    }
    let (a, b) = (run(&plain, default(), &steady), run(&scales, default(), &steady));
    assert!(
        (b[0].0.position.accuracy_m / a[0].0.position.accuracy_m - 3.0).abs() < 1e-9,
        "the first scan is sparse"
    );
    assert!(a.iter().zip(&b).skip(1).all(|(a, b)| a.0 == b.0), "a steady stream keeps the site's factors");
    // γ: the first epoch has no movement likelihood; from the second on, the sparse γ.
    let (a, b) = (run(&plain, default(), &throttled), run(&gamma, default(), &throttled));
    assert_eq!(a[0].1, b[0].1);
    assert_ne!(a[1].1, b[1].1);
    let (a, b) = (run(&plain, default(), &steady), run(&gamma, default(), &steady));
    assert!(a.iter().zip(&b).all(|(a, b)| a.1 == b.1), "no sparse scan, no sparse γ");
    // An explicit γ overrides the sparse one.
    let explicit = || EngineConfig { rssi_weight: Some(0.3), ..default() };
    let (a, b) = (run(&plain, explicit(), &throttled), run(&gamma, explicit(), &throttled));
    assert!(a.iter().zip(&b).all(|(a, b)| a.1 == b.1));
    // The floor probability: the band's share of the sparse table in the sparse regime (every
    // epoch when throttled, the first when steady), else of the steady table; the posterior's
    // own mass without the site's calibration, and the steady table when no sparse one is fitted.
    let steady_table = FloorReliability([0.11, 0.22, 0.33, 0.44, 0.55].map(Some));
    let sparse_table = FloorReliability([0.61, 0.62, 0.63, 0.64, 0.65].map(Some));
    let with_tables = |sparse: FloorReliability| {
        let sparse_scans = SparseScans { floor_reliability: sparse, ..SparseScans::default() };
        Arc::new(
            two_floor_site()
                .with_calibration(Calibration { floor_reliability: steady_table, sparse_scans, ..base })
                .unwrap(),
        )
    };
    let (both, steady_only) = (with_tables(sparse_table), with_tables(FloorReliability::default()));
    let p = |epochs: &[(waymark_engine::Epoch, Vec<f64>)]| -> Vec<f64> {
        epochs.iter().map(|e| e.0.position.floor_probability).collect()
    };
    let raw = p(&run(&plain, default(), &throttled));
    assert_eq!(
        p(&run(&both, default(), &throttled)),
        raw.iter().map(|&r| sparse_table.report(r)).collect::<Vec<_>>()
    );
    assert_eq!(
        p(&run(&steady_only, default(), &throttled)),
        raw.iter().map(|&r| steady_table.report(r)).collect::<Vec<_>>()
    );
    let uncalibrated = || EngineConfig { site_calibration: false, ..default() };
    assert_eq!(p(&run(&both, uncalibrated(), &throttled)), p(&run(&plain, uncalibrated(), &throttled)));
    let raw = p(&run(&plain, default(), &steady));
    let reported = p(&run(&both, default(), &steady));
    assert_eq!(reported[0], sparse_table.report(raw[0]), "the first scan is sparse");
    assert!(
        raw.iter().zip(&reported).skip(1).all(|(&r, &c)| c == steady_table.report(r)),
        "{raw:?} {reported:?}"
    );
}

/// Engines sharing scan likelihoods (the calibration's replays) give the positions of engines
/// computing their own, to the bit, whatever γ each runs at and on a copy of the site with
/// another calibration; a memo of another site, even an equal one, is refused.
#[test]
fn shared_scan_likelihoods_change_no_position() {
    use waymark_engine::SharedEmissions;
    let site = Arc::new(two_floor_site());
    let walk: Vec<_> = (0..12u64)
        .map(|k| scan((k + 1) * 2 * SECOND, &readings_at((k / 6) as usize, 2.0 * (k % 6) as f64)))
        .collect();
    let shared = SharedEmissions::new(&site);
    for gamma in [1.0, 0.3, 0.03] {
        let config = EngineConfig { rssi_weight: Some(gamma), ..EngineConfig::default() };
        let mut own = Engine::new(Arc::clone(&site), config.clone()).unwrap();
        let mut sharing = Engine::new(Arc::clone(&site), config).unwrap();
        sharing.share_emissions(Arc::clone(&shared)).unwrap();
        for s in walk.iter().chain(&walk[..3]) {
            // The last three scans again, later: the memo answers for them.
            let s = waymark_engine::Scan {
                timestamp_ns: s.timestamp_ns.max(own.position().map_or(0, |p| p.timestamp_ns) + SECOND),
                ..s.clone()
            };
            assert_eq!(own.push_scan(&s).map(|e| e.position), sharing.push_scan(&s).map(|e| e.position));
            assert_eq!(own.posterior(), sharing.posterior());
        }
    }
    // A copy of the site with another calibration shares its radio map, and so the memo.
    let calibration = waymark_engine::site::Calibration { radio_fit_floor: Some(1.0), ..*site.calibration() };
    let copy = Arc::new(site.as_ref().clone().with_calibration(calibration).unwrap());
    let mut own = Engine::new(Arc::clone(&copy), EngineConfig::default()).unwrap();
    let mut sharing = Engine::new(copy, EngineConfig::default()).unwrap();
    sharing.share_emissions(Arc::clone(&shared)).unwrap();
    for s in &walk {
        assert_eq!(own.push_scan(s).map(|e| e.position), sharing.push_scan(s).map(|e| e.position));
    }
    let mut other = Engine::new(Arc::new(two_floor_site()), EngineConfig::default()).unwrap();
    assert!(other.share_emissions(shared).is_err());
}

/// One sample with a time far ahead (a negative Kotlin `Long` passed as `ULong`, a clock
/// glitch) is refused and counted, not adopted as the clock every later sample would be out of
/// order against; a real jump, confirmed by the stream's next sample, is taken
/// (docs/errors.md#timestamps-ahead-of-the-clock).
#[test]
fn a_time_far_ahead_is_refused_and_counted_and_the_stream_goes_on() {
    use waymark_engine::sensors::SensorSample;
    let at = |t: u64| SensorSample { timestamp_ns: t, x: 0.1, y: 0.2, z: 9.81 };
    let ms = SECOND / 1000;
    let mut engine = engine();
    assert_eq!(
        engine.push_accelerometer(&(1..=100).map(|k| at(k * 10 * ms)).collect::<Vec<_>>()).accepted,
        100
    );
    let negative = engine.push_accelerometer(&[at(u64::MAX - 999)]);
    assert_eq!((negative.accepted, negative.ahead), (0, 1));
    let later: Vec<_> = (101..=10_200).map(|k| at(k * 10 * ms)).collect();
    assert_eq!(engine.push_accelerometer(&later).accepted, 10_100);
    // An hour ahead once, then back on time: refused, and the stream goes on.
    let hour = 3600 * SECOND;
    assert_eq!(engine.push_gyroscope(&[at(hour)]).ahead, 1);
    assert_eq!(engine.push_gyroscope(&[at(102 * SECOND)]).accepted, 1);
    // The phone slept for an hour: the stream's second sample confirms the jump.
    let woke = engine.push_gyroscope(&[at(hour + 102 * SECOND), at(hour + 102 * SECOND + 10 * ms)]);
    assert_eq!((woke.accepted, woke.ahead), (1, 1));
    // Epochs may be minutes apart, so only a time no phone's clock shows is too far ahead.
    let scan_at = |t| scan(t, &readings_at(0, 3.0));
    assert_eq!(
        engine.push_scan(&scan_at(u64::MAX - 8)),
        Err(InputError::TimeAhead { timestamp_ns: u64::MAX - 8 })
    );
    assert!(matches!(engine.advance(u64::MAX), Err(InputError::TimeAhead { .. })));
    engine.push_scan(&scan_at(hour + 103 * SECOND)).unwrap();
    engine.push_scan(&scan_at(hour + 104 * SECOND)).unwrap();
    let stats = engine.stats();
    assert_eq!(
        (stats.timestamps_ahead, stats.scans_accepted, stats.advances_rejected),
        (5, 2, 0),
        "counted once"
    );
}
