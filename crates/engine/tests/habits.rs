//! Habits in the live engine (issue 6; El Gemayel et al. §III-A, §II-C, §IV-C): Baum-Welch over
//! the engine's own history learns the moves a user makes and the error of external fixes;
//! the learned transitions act as a prior on the motion transition; the model is exported and
//! imported as versioned JSON, refused with a typed error when it does not fit.

mod common;

use common::{scan, two_floor_site};
use std::sync::Arc;
use waymark_engine::habits::{HabitError, HabitModel, VERSION};
use waymark_engine::{Engine, EngineConfig, PositionFix, Site};

const SECOND: u64 = 1_000_000_000;

/// What the site's transmitters predict at x on floor 0 (its training means).
fn readings_at(x: f64) -> Vec<(u8, f64)> {
    (0..3).map(|t| (t as u8, -40.0 - 4.0 * (x - 6.0 * t as f64).abs())).collect()
}

fn engine_on(site: &Arc<Site>) -> Engine {
    Engine::new(Arc::clone(site), EngineConfig::default()).unwrap()
}

/// Laps `laps` walking east along floor 0 (x = 0, 3, .., 12, a scan a second), a minute apart.
fn walk_east(engine: &mut Engine, laps: std::ops::Range<u64>) {
    for lap in laps {
        for k in 0..5 {
            let t = SECOND * (1 + lap * 60 + k);
            engine.push_scan(&scan(t, &readings_at(3.0 * k as f64))).unwrap();
        }
    }
}

/// The posterior two seconds after a scan at x = 6 m, with no motion measured (an advance
/// sooner would be held, without a step: `EngineConfig::min_motion_step_s`).
fn predicted_from_the_middle(engine: &mut Engine, t: u64) -> Vec<f64> {
    engine.push_scan(&scan(t, &readings_at(6.0))).unwrap();
    engine.advance(t + 2 * SECOND).unwrap();
    engine.posterior().to_vec()
}

#[test]
fn walking_east_teaches_the_engine_to_expect_east() {
    let site = Arc::new(two_floor_site());
    let mut engine = engine_on(&site);
    walk_east(&mut engine, 0..6);
    let report = engine.learn_habits().unwrap();
    assert_eq!((report.segments, report.epochs), (6, 30), "{report:?}");
    assert!(report.learned_transitions > 0 && report.iterations >= 1, "{report:?}");
    let ll = &report.log_likelihood;
    assert!(ll.windows(2).all(|w| w[1] >= w[0] - 1e-6), "Baum-Welch never lowers the likelihood: {ll:?}");
    let model = engine.habits();
    for i in 1..4 {
        assert!(
            model.count(i, i + 1) > 2.0 * model.count(i, i - 1),
            "state {i}: east {} west {}",
            model.count(i, i + 1),
            model.count(i, i - 1)
        );
    }
    assert_eq!(model.count(7, 8), 0.0, "floor 1 was never visited");

    // Applied: from the middle, with no motion to go by, more mass goes east than without.
    let mut plain = engine_on(&site);
    let mut habitual = engine_on(&site);
    habitual.import_habits(&engine.export_habits()).unwrap();
    let t = 1000 * SECOND;
    let without = predicted_from_the_middle(&mut plain, t);
    let with = predicted_from_the_middle(&mut habitual, t);
    let lean = |p: &[f64]| p[3] - p[1];
    assert!(lean(&without).abs() < 0.02, "symmetric without habits: {without:?}");
    assert!(lean(&with) > lean(&without) + 0.05, "with {with:?} without {without:?}");
    assert!((with.iter().sum::<f64>() - 1.0).abs() < 1e-9);
}

#[test]
fn each_epoch_is_learned_once() {
    let site = Arc::new(two_floor_site());
    let mut engine = engine_on(&site);
    walk_east(&mut engine, 0..3);
    engine.learn_habits().unwrap();
    let once = engine.export_habits();
    let again = engine.learn_habits().unwrap();
    assert_eq!(again.epochs, 0, "{again:?}");
    assert_eq!(engine.export_habits(), once);
    // New epochs are learned on top.
    walk_east(&mut engine, 3..4);
    let more = engine.learn_habits().unwrap();
    assert_eq!(more.epochs, 5, "only the lap after the last learned epoch: {more:?}");
    assert_eq!(engine.habits().epochs(), 20);
}

#[test]
fn the_model_round_trips_and_bad_models_are_refused() {
    let site = Arc::new(two_floor_site());
    let mut engine = engine_on(&site);
    walk_east(&mut engine, 0..3);
    engine.learn_habits().unwrap();
    let json = engine.export_habits();
    let value: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(value["format"], "waymark-habits");
    assert_eq!(value["version"], VERSION);
    let back = HabitModel::from_json(&json, &site).unwrap();
    assert_eq!(&back, engine.habits());
    assert_eq!(back.to_json(), json);

    let mut other = engine_on(&site);
    let before = other.export_habits();
    let edit = |f: &dyn Fn(&mut serde_json::Value)| {
        let mut v = value.clone();
        f(&mut v);
        v.to_string()
    };
    type Expect<'a> = &'a dyn Fn(&HabitError) -> bool;
    let cases: Vec<(String, Expect)> = vec![
        ("{".into(), &|e| matches!(e, HabitError::Json(_))),
        (edit(&|v| v["format"] = "something".into()), &|e| matches!(e, HabitError::Format(_))),
        (
            edit(&|v| v["version"] = (VERSION + 1).into()),
            &|e| matches!(e, HabitError::UnsupportedVersion { found, .. } if *found == VERSION + 1),
        ),
        (edit(&|v| v["site"]["digest"] = "00000000".into()), &|e| matches!(e, HabitError::WrongSite(_))),
        (
            edit(&|v| v["transitions"][0]["count"][0] = (-1.0).into()),
            &|e| matches!(e, HabitError::Invalid { path, .. } if path == "transitions[0].count[0]"),
        ),
        (
            edit(&|v| v["transitions"][0]["to"][0] = 99.into()),
            &|e| matches!(e, HabitError::Invalid { path, .. } if path == "transitions[0].to[0]"),
        ),
        (edit(&|v| v["fix"]["weight"] = (-1.0).into()), &|e| matches!(e, HabitError::Invalid { .. })),
        (
            edit(&|v| v["transitions"][0]["count"][0] = 1e300.into()),
            &|e| matches!(e, HabitError::Invalid { path, .. } if path == "transitions[0].count[0]"),
        ),
        (
            edit(&|v| v["strength"] = 1e300.into()),
            &|e| matches!(e, HabitError::Invalid { path, .. } if path == "strength"),
        ),
    ];
    for (json, expected) in cases {
        let e = other.import_habits(&json).unwrap_err();
        assert!(expected(&e), "{json}: {e:?}");
        assert_eq!(other.export_habits(), before, "a refused model changes nothing");
    }
    // A model of another site.
    let mut builder = waymark_engine::site::SiteBuilder::new("elsewhere");
    let f = builder.floor("G", 0.0);
    builder.state(f, nalgebra::Point2::new(0.0, 0.0), vec![scan(0, &[(0, -50.0)])]);
    let elsewhere = builder.build(waymark_engine::site::BuildOptions::default()).unwrap();
    assert!(matches!(HabitModel::from_json(&json, &elsewhere), Err(HabitError::WrongSite(_))));
    other.clear_habits();
    assert!(other.habits().is_empty());
}

#[test]
fn the_bias_of_external_fixes_is_learned_and_taken_off() {
    let site = Arc::new(two_floor_site());
    let mut engine = engine_on(&site);
    // Scans place the user; a fix half a second later reads 2.5 m east and 1 m north of them.
    let bias = [2.5, 1.0];
    for k in 0..40u64 {
        let x = 3.0 * (k % 5) as f64;
        let t = SECOND * (1 + 2 * k);
        engine.push_scan(&scan(t, &readings_at(x))).unwrap();
        let fix = PositionFix {
            timestamp_ns: t + SECOND / 2,
            x: x + bias[0],
            y: bias[1],
            floor: Some(0),
            accuracy_m: 3.0,
        };
        engine.push_fix(&fix).unwrap();
    }
    assert_eq!(engine.fix_bias().bias_m, [0.0, 0.0], "nothing learned yet");
    let report = engine.learn_habits().unwrap();
    assert_eq!(report.fix_epochs, 40, "{report:?}");
    let learned = engine.fix_bias();
    // 40 fixes against 5 pseudo-fixes at zero bias: about 40/45 of the true bias.
    assert!((learned.bias_m[0] - bias[0]).abs() < 0.8, "{learned:?}");
    assert!((learned.bias_m[1] - bias[1]).abs() < 0.5, "{learned:?}");
    assert!(learned.spread > 0.2 && learned.spread < 1.5, "{learned:?}");
    // Taken off: a fix 2.5 m east of state 2 now puts the user at state 2, not between 2 and 3.
    let t = 1000 * SECOND;
    engine.push_scan(&scan(t, &readings_at(6.0))).unwrap();
    let mut plain = engine_on(&site);
    plain.push_scan(&scan(t, &readings_at(6.0))).unwrap();
    let fix = PositionFix {
        timestamp_ns: t + SECOND,
        x: 6.0 + bias[0],
        y: bias[1],
        floor: Some(0),
        accuracy_m: 1.0,
    };
    let corrected = engine.push_fix(&fix).unwrap().position;
    let raw = plain.push_fix(&fix).unwrap().position;
    assert!((corrected.x - 6.0).abs() < (raw.x - 6.0).abs() - 0.5, "corrected {corrected:?} raw {raw:?}");
}

#[test]
fn feedback_steers_what_is_learned() {
    // The radio says "the middle" at every epoch; the user says they walked 0 → 4.
    let site = Arc::new(two_floor_site());
    let mut engine = engine_on(&site);
    for k in 0..5u64 {
        let t = SECOND * (1 + k);
        engine.push_scan(&scan(t, &readings_at(6.0))).unwrap();
        engine.confirm_position(t, 3.0 * k as f64, 0.0, 0, 1.0).unwrap();
    }
    let report = engine.learn_habits().unwrap();
    assert_eq!(report.feedback_epochs, 5, "{report:?}");
    let model = engine.habits();
    for i in 0..4 {
        assert!(model.count(i, i + 1) > 0.9, "state {i}: {}", model.count(i, i + 1));
    }
}

#[test]
fn habits_that_do_not_predict_are_not_applied() {
    let site = Arc::new(two_floor_site());
    // Consistent laps: the held-out laps are predicted, so the habits are applied.
    let mut east = engine_on(&site);
    walk_east(&mut east, 0..6);
    let report = east.learn_habits().unwrap();
    assert_eq!(report.strength_gain.len(), waymark_engine::habits::STRENGTHS.len(), "{report:?}");
    assert!(report.strength.is_some() && report.strength == east.habits().strength(), "{report:?}");
    assert!(report.strength_gain.iter().any(|g| g.gain > 2.0 * g.standard_error), "{report:?}");

    // Laps alternating east and west: the even laps say "east", the odd ones "west", so
    // neither half predicts the other and nothing is applied.
    let mut both = engine_on(&site);
    for lap in 0..6u64 {
        for k in 0..5u64 {
            let x = if lap % 2 == 0 { 3.0 * k as f64 } else { 12.0 - 3.0 * k as f64 };
            both.push_scan(&scan(SECOND * (1 + lap * 60 + k), &readings_at(x))).unwrap();
        }
    }
    let report = both.learn_habits().unwrap();
    assert!(report.learned_transitions > 0, "the moves are still counted: {report:?}");
    assert_eq!(report.strength, None, "{report:?}");
    assert!(report.strength_gain.iter().all(|g| g.gain <= 0.0), "{report:?}");
    let mut plain = engine_on(&site);
    let t = 1000 * SECOND;
    assert_eq!(predicted_from_the_middle(&mut both, t), predicted_from_the_middle(&mut plain, t));
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig { cases: 96, ..Default::default() })]

    /// A damaged model (any byte replaced, or the text cut anywhere) is refused or accepted,
    /// never a panic, and the engine goes on positioning either way.
    #[test]
    fn damaged_models_never_break_the_engine(at in 0usize..10_000, byte in 0u8..128, cut in proptest::bool::ANY) {
        let site = Arc::new(two_floor_site());
        let mut learned = engine_on(&site);
        walk_east(&mut learned, 0..3);
        learned.learn_habits().unwrap();
        let mut json = learned.export_habits().into_bytes();
        let at = at % json.len();
        if cut { json.truncate(at) } else { json[at] = byte }
        let Ok(text) = String::from_utf8(json) else { return Ok(()) };
        let mut engine = engine_on(&site);
        let before = engine.export_habits();
        match engine.import_habits(&text) {
            Ok(()) => {}
            Err(_) => proptest::prop_assert_eq!(engine.export_habits(), before),
        }
        let p = engine.push_scan(&scan(SECOND, &readings_at(6.0))).unwrap().position;
        proptest::prop_assert!(p.x.is_finite() && p.accuracy_m > 0.0);
        proptest::prop_assert!((engine.posterior().iter().sum::<f64>() - 1.0).abs() < 1e-9);
    }
}
