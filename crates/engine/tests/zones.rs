//! Zones, user feedback and external position fixes (El Gemayel et al. §II-C, §IV-C):
//! the zone posterior and most likely zone in every position, feedback that pins the posterior
//! to a zone or a circle, fixes from other systems as observations, all rejected with a typed
//! error and a counter when they are bad, and kept in a bounded history for learning.

mod common;

use common::{corridor_readings as readings_at, scan, two_floor_site, zoned_site};
use nalgebra::Point2;
use std::sync::Arc;
use waymark_engine::EpochInput;
use waymark_engine::{Engine, EngineConfig, InputError, PositionFix, Site};
use waymark_sim::{Office, OfficeConfig};

const SECOND: u64 = 1_000_000_000;

fn engine_on(site: Site) -> Engine {
    Engine::new(Arc::new(site), EngineConfig::default()).unwrap()
}

fn assert_distribution(p: &[f64]) {
    assert!(p.iter().all(|v| v.is_finite() && *v >= 0.0), "{p:?}");
    assert!((p.iter().sum::<f64>() - 1.0).abs() < 1e-9, "{p:?}");
}

#[test]
fn positions_carry_the_most_likely_zone() {
    let mut engine = engine_on(zoned_site());
    let p = engine.push_scan(&scan(SECOND, &readings_at(0, 12.0))).unwrap().position;
    assert_eq!(p.zone, Some(1), "{p:?}");
    let zones = engine.zone_posterior();
    assert_eq!(zones.len(), 3);
    assert_eq!(p.zone_probability, zones[1]);
    assert!(zones[1] > 0.9 && zones.iter().sum::<f64>() <= 1.0 + 1e-12, "{zones:?}");
    // Mass outside every zone beats any one zone: no zone.
    let p = engine.push_scan(&scan(2 * SECOND, &readings_at(0, 6.0))).unwrap().position;
    let zones = engine.zone_posterior();
    let outside = 1.0 - zones.iter().sum::<f64>();
    assert!(outside > zones[0] && outside > zones[1], "{zones:?}");
    assert_eq!(p.zone, None);
    assert!((p.zone_probability - outside).abs() < 1e-12);
    let p = engine.push_scan(&scan(3 * SECOND, &readings_at(1, 3.0))).unwrap().position;
    assert_eq!(p.zone, Some(2));

    // A site without zones: always no zone, with certainty.
    let mut plain = engine_on(two_floor_site());
    let p = plain.push_scan(&scan(SECOND, &readings_at(0, 12.0))).unwrap().position;
    assert_eq!((p.zone, p.zone_probability), (None, 1.0));
    assert!(plain.zone_posterior().is_empty());
}

#[test]
fn confirming_a_zone_pins_the_posterior_to_it() {
    let mut engine = engine_on(zoned_site());
    engine.push_scan(&scan(SECOND, &readings_at(0, 12.0))).unwrap();
    assert_eq!(engine.position().unwrap().zone, Some(1));
    // The user says: west, at the time of the position they were shown. That epoch is pinned.
    let p = engine.confirm_zone_named(SECOND, "west").unwrap().position;
    assert_eq!((p.timestamp_ns, p.zone), (SECOND, Some(0)));
    assert!((p.zone_probability - 1.0).abs() < 1e-12, "{p:?}");
    assert!(p.x <= 3.0 + 1e-9, "{p:?}");
    let posterior = engine.posterior();
    assert_distribution(posterior);
    assert!(posterior.iter().enumerate().all(|(i, &v)| v == 0.0 || i <= 1), "{posterior:?}");
    assert_eq!(engine.track().last().map(|t| t.state <= 1), Some(true), "the track is pinned too");
    assert_eq!(engine.history().len(), 1);
    assert_eq!(engine.history()[0].allowed, Some(vec![0, 1]));
    assert_eq!(engine.history()[0].input, EpochInput::Scan);
    // Later feedback is an epoch of its own; by index, on another floor.
    let p = engine.confirm_zone(3 * SECOND, 2).unwrap().position;
    assert_eq!((p.timestamp_ns, p.floor, p.zone), (3 * SECOND, 1, Some(2)));
    assert_eq!(engine.history().len(), 2);
    assert_eq!(engine.history()[1].input, EpochInput::Feedback);
    assert_eq!(engine.history()[1].allowed, Some((5..10).collect()));
    // Scans go on from the pinned posterior.
    engine.push_scan(&scan(4 * SECOND, &readings_at(1, 12.0))).unwrap();
    assert_eq!(engine.history()[2].allowed, None);
    let stats = engine.stats();
    assert_eq!((stats.feedback_accepted, stats.feedback_rejected), (2, 0));
}

#[test]
fn a_confirmed_position_pins_the_states_within_its_radius() {
    let mut engine = engine_on(zoned_site());
    engine.push_scan(&scan(SECOND, &readings_at(0, 0.0))).unwrap();
    let p = engine.confirm_position(2 * SECOND, 7.0, 0.5, 0, 2.0).unwrap().position;
    assert!((p.x - 6.0).abs() < 1e-9 && p.floor == 0, "only the state at x = 6 is within 2 m: {p:?}");
    assert_eq!(p.zone, None);
    assert_eq!(engine.posterior()[2], 1.0);
    assert_eq!(engine.history().back().unwrap().allowed, Some(vec![2]));
}

#[test]
fn bad_feedback_is_rejected_counted_and_changes_nothing() {
    let mut engine = engine_on(zoned_site());
    engine.push_scan(&scan(10 * SECOND, &readings_at(0, 3.0))).unwrap();
    let before = engine.snapshot();
    let cases: [(Result<_, InputError>, InputError); 8] = [
        (
            engine.confirm_zone_named(9 * SECOND, "west"),
            InputError::OutOfOrder { timestamp_ns: 9 * SECOND, last_ns: 10 * SECOND },
        ),
        (engine.confirm_zone_named(11 * SECOND, "cellar"), InputError::UnknownZone { zone: "cellar".into() }),
        (engine.confirm_zone(10 * SECOND, 3), InputError::UnknownZone { zone: "#3".into() }),
        (
            engine.confirm_position(11 * SECOND, 3.0, 0.0, 2, 1.0),
            InputError::UnknownFloor { floor: 2, floors: 2 },
        ),
        (
            engine.confirm_position(11 * SECOND, f64::NAN, 0.0, 0, 1.0),
            InputError::InvalidValue { field: "x", value: f64::NAN },
        ),
        (
            engine.confirm_position(11 * SECOND, 3.0, 0.0, 0, 0.0),
            InputError::InvalidValue { field: "radius_m", value: 0.0 },
        ),
        (
            engine.confirm_position(11 * SECOND, 3.0, 40.0, 0, 5.0),
            InputError::OutsideSite { distance_m: 40.0, limit_m: 5.0 },
        ),
        (
            engine.confirm_position(9 * SECOND, 3.0, 0.0, 0, 5.0),
            InputError::OutOfOrder { timestamp_ns: 9 * SECOND, last_ns: 10 * SECOND },
        ),
    ];
    for (k, (got, expected)) in cases.into_iter().enumerate() {
        match (&got, &expected) {
            // NaN is not equal to itself.
            (Err(InputError::InvalidValue { field: a, .. }), InputError::InvalidValue { field: b, .. }) => {
                assert_eq!(a, b)
            }
            _ => assert_eq!(got, Err(expected), "case {k}"),
        }
    }
    let after = engine.snapshot();
    assert_eq!(after.stats.feedback_rejected, 8);
    let reset = |mut s: waymark_engine::EngineSnapshot| {
        s.stats = Default::default();
        s
    };
    assert_eq!(reset(after), reset(before));
}

#[test]
fn contradicting_feedback_at_one_epoch_ends_with_the_latest() {
    let mut engine = engine_on(zoned_site());
    engine.push_scan(&scan(SECOND, &readings_at(0, 0.0))).unwrap();
    engine.confirm_zone_named(SECOND, "west").unwrap();
    let p = engine.confirm_zone_named(SECOND, "east").unwrap().position;
    assert_eq!(p.zone, Some(1));
    assert_distribution(engine.posterior());
    assert_eq!(engine.history()[0].allowed, Some(vec![3, 4]));
    // Consistent feedback narrows it.
    engine.confirm_position(SECOND, 12.0, 0.0, 0, 1.0).unwrap();
    assert_eq!(engine.history()[0].allowed, Some(vec![4]));
    assert_eq!(engine.posterior()[4], 1.0);
}

/// The office a few scans into a walk, then a fix at the state nearest to `offset_m` east of
/// the estimate: how far the estimate was from the fix before and after it.
fn pull_of_a_fix(offset_m: f64, accuracy_m: f64) -> (f64, f64) {
    let office = Office::generate(&OfficeConfig { training_scans: 40, ..OfficeConfig::default() });
    let mut engine = Engine::new(Arc::new(office.site.clone()), EngineConfig::default()).unwrap();
    let walk = office.walk(3, 20.0);
    let mut last = None;
    for e in walk.epochs.iter().take(6) {
        last = Some(engine.push_scan(&e.scan).unwrap().position);
    }
    let before = last.unwrap();
    let east = Point2::new(before.x + offset_m, before.y);
    let target = office
        .points()
        .iter()
        .min_by(|a, b| nalgebra::distance(a, &east).total_cmp(&nalgebra::distance(b, &east)))
        .copied()
        .unwrap();
    let fix = PositionFix {
        // 10 s later: at 3 m/s, anywhere within 30 m of walking is reachable.
        timestamp_ns: before.timestamp_ns + 10 * SECOND,
        x: target.x,
        y: target.y,
        floor: None,
        accuracy_m,
    };
    let after = engine.push_fix(&fix).unwrap().position;
    assert_eq!(after.radio_log_evidence, None);
    assert_eq!(engine.history().back().unwrap().input, EpochInput::Fix(fix));
    let from_fix = |x: f64, y: f64| nalgebra::distance(&target, &Point2::new(x, y));
    (from_fix(before.x, before.y), from_fix(after.x, after.y))
}

#[test]
fn a_fix_pulls_the_estimate_as_much_as_its_accuracy_allows() {
    let runs: Vec<(f64, f64)> = [0.5, 2.0, 5.0, 20.0].iter().map(|&a| pull_of_a_fix(6.0, a)).collect();
    let (before, precise) = runs[0];
    assert!(before > 4.0, "{runs:?}");
    assert!(precise < 0.5, "a precise fix takes the estimate to it: {runs:?}");
    for w in runs.windows(2) {
        assert!(w[0].1 <= w[1].1, "the vaguer the fix, the less it pulls: {runs:?}");
    }
    assert!(before - runs[3].1 < 1.0, "{runs:?}");
    // A wildly wrong fix (30 m off) that says it is vague moves the estimate little.
    let (before, after) = pull_of_a_fix(30.0, 60.0);
    assert!((before - after).abs() < 1.0, "{before} -> {after}");
}

#[test]
fn a_fix_with_a_floor_rules_out_the_other_floors() {
    let mut engine = engine_on(zoned_site());
    engine.push_scan(&scan(SECOND, &readings_at(0, 3.0))).unwrap();
    let fix = PositionFix { timestamp_ns: 2 * SECOND, x: 3.0, y: 0.0, floor: Some(1), accuracy_m: 3.0 };
    let p = engine.push_fix(&fix).unwrap().position;
    assert_eq!(p.floor, 1);
    assert!(engine.posterior()[..5].iter().all(|&v| v == 0.0));
    assert_eq!(engine.stats().fixes_accepted, 1);
}

#[test]
fn bad_fixes_are_rejected_counted_and_change_nothing() {
    let mut engine = engine_on(zoned_site());
    engine.push_scan(&scan(10 * SECOND, &readings_at(0, 3.0))).unwrap();
    let before = engine.snapshot();
    let good = PositionFix { timestamp_ns: 11 * SECOND, x: 3.0, y: 0.0, floor: None, accuracy_m: 3.0 };
    let bad = [
        PositionFix { timestamp_ns: 10 * SECOND, ..good },
        PositionFix { timestamp_ns: 9 * SECOND, ..good },
        PositionFix { x: f64::NAN, ..good },
        PositionFix { y: f64::NEG_INFINITY, ..good },
        PositionFix { accuracy_m: 0.0, ..good },
        PositionFix { accuracy_m: -3.0, ..good },
        PositionFix { accuracy_m: f64::INFINITY, ..good },
        PositionFix { floor: Some(7), ..good },
        PositionFix { x: 500.0, ..good },
    ];
    for fix in &bad {
        let e = engine.push_fix(fix).unwrap_err();
        assert!(
            matches!(
                e,
                InputError::OutOfOrder { .. }
                    | InputError::InvalidValue { .. }
                    | InputError::UnknownFloor { .. }
                    | InputError::OutsideSite { .. }
            ),
            "{fix:?}: {e}"
        );
    }
    assert!(matches!(engine.push_fix(&bad[8]), Err(InputError::OutsideSite { .. })));
    let after = engine.snapshot();
    assert_eq!(after.stats.fixes_rejected, bad.len() as u64 + 1);
    assert_eq!(after.stats.fixes_accepted, 0);
    let reset = |mut s: waymark_engine::EngineSnapshot| {
        s.stats = Default::default();
        s
    };
    assert_eq!(reset(after), reset(before));
    // 500 m away with a vague enough accuracy is accepted (and barely matters).
    engine.push_fix(&PositionFix { x: 500.0, accuracy_m: 400.0, ..good }).unwrap();
}

#[test]
fn the_history_is_bounded() {
    let site = Arc::new(zoned_site());
    let config = EngineConfig { history_epochs: 4, ..EngineConfig::default() };
    let mut engine = Engine::new(Arc::clone(&site), config).unwrap();
    for k in 1..=10 {
        engine.push_scan(&scan(k * SECOND, &readings_at(0, 3.0))).unwrap();
        engine.confirm_zone_named(k * SECOND, "west").unwrap();
    }
    let times: Vec<u64> = engine.history().iter().map(|r| r.timestamp_ns / SECOND).collect();
    assert_eq!(times, [7, 8, 9, 10]);
    assert!(engine.history().iter().all(|r| r.allowed == Some(vec![0, 1])));
    let none = EngineConfig { history_epochs: 0, ..EngineConfig::default() };
    let mut engine = Engine::new(site, none).unwrap();
    engine.push_scan(&scan(SECOND, &readings_at(0, 3.0))).unwrap();
    assert!(engine.history().is_empty());
    assert_eq!(EngineConfig::default().history_epochs, 500);
}
#[test]
fn the_simulated_office_has_its_rooms_as_zones() {
    let office = Office::generate(&OfficeConfig { training_scans: 20, ..OfficeConfig::default() });
    let site = &office.site;
    let names: Vec<&str> = site.zones().iter().map(|z| z.name.as_str()).collect();
    assert_eq!(names.len(), 12);
    assert_eq!((names[0], names[1], names[11]), ("aisle", "room 1", "stair hall"));
    for (i, s) in site.states().iter().enumerate() {
        assert_eq!(site.zone_of(i), office.zone_at(s.position), "state {i} at {}", s.position);
    }
    let pseudo = site.with_pseudo_states(waymark_engine::site::PSEUDO_SPACING_M);
    assert!((0..pseudo.states().len()).all(|i| pseudo.zone_of(i).is_some()));
    // Every epoch of a walk is in some zone.
    assert!(office.walk(1, 100.0).epochs.iter().all(|e| e.zone.is_some()));
}

#[test]
fn room_level_accuracy_on_simulated_walks() {
    let experiment =
        waymark_experiments::Experiment { walks: 5, ..waymark_experiments::Experiment::default() };
    let report = waymark_experiments::run(&experiment).unwrap();
    let hit = report.summary.zone_hit.unwrap();
    assert!(hit > 0.8, "the right room in {:.1}% of epochs", 100.0 * hit);
}
