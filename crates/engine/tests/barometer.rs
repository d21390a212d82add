//! The barometer as a motion input for floor changes (docs/accuracy.md#barometer).

mod common;

use common::scan;
use nalgebra::Point2;
use std::sync::Arc;
use waymark_engine::sensors::{pressure_height_m, PressureSample};
use waymark_engine::site::Calibration;
use waymark_engine::site::{BuildOptions, Site, SiteBuilder};
use waymark_engine::{Engine, EngineConfig, Position};

const SECOND: u64 = 1_000_000_000;

/// Two floors 4 m apart, each a corridor of five states 3 m apart joined by a staircase at
/// x = 0. Transmitters 0-2 sound the same on both floors; transmitter 9 is 30 dB stronger on
/// the ground floor. A scan with 9 half way between cannot tell the floors apart.
fn twin_floors() -> Site {
    twin_floors_at(None)
}

/// [`twin_floors`] with these levels, if any.
fn twin_floors_at(levels: Option<[i32; 2]>) -> Site {
    twin_floors_with(levels, true)
}

/// [`twin_floors_at`], with or without the staircase.
fn twin_floors_with(levels: Option<[i32; 2]>, stairs: bool) -> Site {
    let mut b = SiteBuilder::new("twin floors");
    let floors = [b.floor("G", 0.0), b.floor("1", 4.0)];
    let mut first = Vec::new();
    for (f, &floor) in floors.iter().enumerate() {
        let mut previous = None;
        for k in 0..5 {
            let x = 3.0 * k as f64;
            let scans = (0..20)
                .map(|n| {
                    let jitter = if n % 2 == 0 { 2.0 } else { -2.0 };
                    let mut readings: Vec<(u8, f64)> = (0..3)
                        .map(|t| (t as u8, -40.0 - 4.0 * (x - 6.0 * t as f64).abs() + jitter))
                        .collect();
                    readings.push((9, if f == 0 { -45.0 } else { -75.0 } + jitter));
                    scan(n, &readings)
                })
                .collect();
            let id = b.state(floor, Point2::new(x, 0.0), scans);
            match previous {
                Some(p) => b.edge(p, id, None),
                None => first.push(id),
            }
            previous = Some(id);
        }
    }
    if stairs {
        b.edge(first[0], first[1], Some(6.0));
    }
    for (floor, level) in floors.iter().zip(levels.into_iter().flatten()) {
        b.floor_geo(*floor, Some(level), [0.0, 0.0]);
    }
    b.build(BuildOptions::default()).unwrap()
}

/// The pressure at `height_m` above a ground floor at 1000 hPa (the inverse of
/// `pressure_height_m`).
fn hpa_at(height_m: f64) -> f64 {
    let h0 = pressure_height_m(1000.0);
    1013.25 * (1.0 - (h0 + height_m) / 44_330.8).powf(1.0 / 0.190_263)
}

/// Readings at 10 Hz over `[from_s, to_s)` of the height `height(t)`.
fn pressure(from_s: f64, to_s: f64, height: impl Fn(f64) -> f64) -> Vec<PressureSample> {
    let n = ((to_s - from_s) * 10.0).round() as u64;
    (0..n)
        .map(|i| {
            let t = from_s + i as f64 * 0.1;
            PressureSample { timestamp_ns: (t * 1e9).round() as u64, hpa: hpa_at(height(t)) }
        })
        .collect()
}

/// A walk: 10 s on the ground floor at x = 0 (transmitter 9 as there), then a climb of `climb_m`
/// between 10 and 16 s, then 10 s more at x = 0 with scans that cannot tell the floors apart.
/// Returns the floor of the last position and its probability.
fn walk(config: EngineConfig, climb_m: f64) -> (usize, f64) {
    let p = walk_on(twin_floors(), config, climb_m);
    (p.floor, p.floor_probability)
}

/// [`walk`] on `site`, returning the last position.
fn walk_on(site: Site, config: EngineConfig, climb_m: f64) -> Position {
    let (positions, _) = walk_heights(site, config, 26, |t| climb_m * ((t - 10.0) / 6.0).clamp(0.0, 1.0));
    positions.last().cloned().unwrap()
}

/// [`walk`]'s scans for `seconds` on `site` at the height `height(t)`: every position, and the
/// engine after them.
fn walk_heights(
    site: Site,
    config: EngineConfig,
    seconds: u64,
    height: impl Fn(f64) -> f64,
) -> (Vec<Position>, Engine) {
    walk_heights_heard(site, config, seconds, height, |_| -60.0)
}

/// [`walk_heights`] with transmitter 9 at `nine(second)` dBm after the first 10 s (-45 dBm on
/// the ground floor, -75 upstairs, -60 half way).
fn walk_heights_heard(
    site: Site,
    config: EngineConfig,
    seconds: u64,
    height: impl Fn(f64) -> f64,
    nine: impl Fn(u64) -> f64,
) -> (Vec<Position>, Engine) {
    let mut engine = Engine::new(Arc::new(site), config).unwrap();
    let mut positions = Vec::new();
    for second in 1..=seconds {
        let report = engine.push_pressure(&pressure((second - 1) as f64, second as f64, &height));
        assert_eq!(report.accepted, 10);
        let nine = if second <= 10 { -45.0 } else { nine(second) };
        let readings = [(0u8, -40.0), (1, -64.0), (2, -88.0), (9, nine)];
        let p = engine.push_scan(&scan(second * SECOND, &readings)).unwrap().position;
        if second == 10 {
            assert_eq!((p.floor, p.unmapped_level), (0, None), "on the ground floor before the climb");
        }
        positions.push(p);
    }
    (positions, engine)
}

#[test]
fn a_storey_climbed_moves_the_estimate_upstairs_where_the_radio_cannot_tell() {
    let (floor, p) = walk(EngineConfig::default(), 4.0);
    assert!(floor == 1 && p > 0.9, "{floor} {p}");
    let without = EngineConfig { barometer: false, ..EngineConfig::default() };
    let (_, p) = walk(without, 4.0);
    assert!(p < 0.6, "without the barometer either floor: {p}");
}

#[test]
fn less_than_a_storey_holds_the_floor_and_a_height_no_floor_explains_leaves_it_to_the_radio() {
    let (floor, p) = walk(EngineConfig::default(), 1.0);
    assert!(floor == 0 && p > 0.9, "a metre is no storey: {floor} {p}");
    let (floor, p) = walk(EngineConfig::default(), -4.0);
    // No floor is 4 m below the ground floor: a height no floor explains leaves the floor to
    // the radio, which cannot tell here, rather than pushing it up or holding it.
    assert!(p < 0.6, "{floor} {p}");
}

#[test]
fn a_storey_climbed_to_a_level_nobody_surveyed_reports_that_level() {
    // Levels 0 and 2 surveyed: 3 m up is level 1, whose floor the site lacks.
    let levels = Some([0, 2]);
    let p = walk_on(twin_floors_at(levels), EngineConfig::default(), 3.0);
    assert_eq!(p.unmapped_level, Some(1), "{p:?}");
    // 6 m is one tall storey or two low ones: level 2 explains it nearly as well as level 1,
    // and the site has level 2.
    let p = walk_on(twin_floors_at(levels), EngineConfig::default(), 6.0);
    assert_eq!((p.floor, p.unmapped_level), (1, None), "{p:?}");
    // Without a level between the site's, or without the barometer, never.
    let p = walk_on(twin_floors_at(Some([0, 1])), EngineConfig::default(), 3.0);
    assert_eq!(p.unmapped_level, None);
    let without = EngineConfig { barometer: false, ..EngineConfig::default() };
    assert_eq!(walk_on(twin_floors_at(levels), without, 3.0).unmapped_level, None);
}

#[test]
fn climbs_through_a_level_nobody_surveyed_count_from_the_last_floor_the_site_has() {
    // Levels 0 and 2 surveyed, 3 m storeys: 20 s on level 1, then on to level 2. The radio
    // cannot tell the floors apart after the ground floor, so only the barometer can say.
    let height = |t: f64| 3.0 * ((t - 10.0) / 4.0).clamp(0.0, 1.0) + 3.0 * ((t - 34.0) / 4.0).clamp(0.0, 1.0);
    let (positions, engine) = walk_heights(twin_floors_at(Some([0, 2])), EngineConfig::default(), 50, height);
    let on_level_one = &positions[20..33];
    assert!(on_level_one.iter().all(|p| p.unmapped_level == Some(1)), "{on_level_one:?}");
    // The track carries each epoch's level as the live position reported it.
    let track = engine.track();
    let levels: Vec<Option<i32>> = on_level_one
        .iter()
        .map(|p| track.iter().find(|t| t.timestamp_ns == p.timestamp_ns).unwrap().unmapped_level)
        .collect();
    assert!(levels.iter().all(|&l| l == Some(1)), "{levels:?}");
    // Had the anchor moved to level 2 at level 1's height, 3 m more would fit no floor.
    let last = positions.last().unwrap();
    assert!(last.floor == 1 && last.floor_probability > 0.9 && last.unmapped_level.is_none(), "{last:?}");
}

#[test]
fn back_at_the_anchors_height_the_anchor_waits_for_a_posterior_still_upstairs() {
    // Levels 0 and 2, 3 m storeys: up 6 m (two storeys, or one tall one to the level the site
    // lacks, so the anchor stays on the ground floor), 14 s upstairs, then back down. The radio
    // leans upstairs until the descent has settled, then cannot tell.
    let height = |t: f64| 6.0 * ((t - 10.0) / 4.0).clamp(0.0, 1.0) - 6.0 * ((t - 28.0) / 4.0).clamp(0.0, 1.0);
    let nine = |second: u64| if second <= 40 { -63.0 } else { -60.0 };
    let site = twin_floors_at(Some([0, 2]));
    // Without the device offset, which would learn the lean as the phone's and keep it.
    let config = EngineConfig { device_offset: false, ..EngineConfig::default() };
    let (positions, _) = walk_heights_heard(site, config, 60, height, nine);
    assert!(positions[16..28].iter().all(|p| p.floor == 1), "upstairs: {:?}", &positions[16..28]);
    // Had the anchor moved to the floor above at the ground floor's height, the barometer would
    // hold the estimate upstairs from then on.
    let last = positions.last().unwrap();
    assert!(last.floor == 0 && last.floor_probability > 0.9, "{last:?}");
}

#[test]
fn readings_that_are_no_pressure_are_dropped_and_counted() {
    let mut engine = Engine::new(Arc::new(twin_floors()), EngineConfig::default()).unwrap();
    let batch = [
        PressureSample { timestamp_ns: SECOND, hpa: 1000.0 },
        PressureSample { timestamp_ns: 2 * SECOND, hpa: f64::NAN },
        PressureSample { timestamp_ns: 3 * SECOND, hpa: -5.0 },
        PressureSample { timestamp_ns: SECOND, hpa: 1000.0 },
        PressureSample { timestamp_ns: 4 * SECOND, hpa: 1000.0 },
    ];
    let report = engine.push_pressure(&batch);
    assert_eq!((report.accepted, report.non_finite, report.out_of_order), (2, 2, 1));
    assert_eq!(engine.stats().pressure_dropped, 3);
    engine.push_scan(&scan(5 * SECOND, &[(0, -40.0), (9, -45.0)])).unwrap();
}

/// Where no edge joins the floors (a site built from walks), the survey's floor-change rate
/// lets a climb move the estimate upstairs once the height says so; without it the only mass
/// upstairs is the floor weight's, too little for the barometer to lift.
#[test]
fn the_surveys_floor_change_rate_moves_a_climb_upstairs_without_stairs_in_the_map() {
    let upstairs_at = |rate: Option<f64>| {
        let site = twin_floors_with(None, false)
            .with_calibration(Calibration { floor_change_rate_hz: rate, ..Calibration::default() })
            .unwrap();
        let climb = |t: f64| 4.0 * ((t - 10.0) / 6.0).clamp(0.0, 1.0);
        // Transmitter 9 half way: the radio cannot tell the floors apart.
        let (positions, _) = walk_heights_heard(site, EngineConfig::default(), 40, climb, |_| -60.0);
        positions.iter().position(|p| p.floor == 1).map(|k| k + 1)
    };
    // The rate of one floor change in 100 s of survey walks.
    let (with, without) = (upstairs_at(Some(0.01)), upstairs_at(None));
    let with = with.expect("upstairs with the rate");
    assert!(with <= 20, "upstairs by {with} s");
    assert!(without.is_none_or(|s| s > with), "{with} s with the rate, {without:?} without");
}

mod hostile {
    use super::*;
    use proptest::prelude::*;

    /// A pressure reading: any time in the 2 s before its batch's scan, in any order, and any
    /// value (NaN, ±∞, out of range, storeys apart); most are pressures, so most scans have a
    /// current height and the floor changes run.
    fn reading() -> impl Strategy<Value = PressureSample> {
        let hpa = prop_oneof![
            4 => 990.0f64..1010.0,
            1 => Just(f64::NAN),
            1 => Just(f64::INFINITY),
            1 => -2000.0f64..3000.0,
        ];
        (0u64..2_000, hpa).prop_map(|(ms, hpa)| PressureSample { timestamp_ns: ms * 1_000_000, hpa })
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]
        /// With floor changes on, any pressure batches between scans leave the posterior a
        /// distribution and every position finite, and never make the filter start again;
        /// what is not a pressure is dropped.
        #[test]
        fn pressure_of_any_kind_never_breaks_the_floor_changes(
            batches in prop::collection::vec(prop::collection::vec(reading(), 0..20), 1..30),
        ) {
            let site = twin_floors_with(None, false)
                .with_calibration(Calibration { floor_change_rate_hz: Some(0.01), ..Calibration::default() })
                .unwrap();
            let mut engine = Engine::new(Arc::new(site), EngineConfig::default()).unwrap();
            for (k, batch) in batches.iter().enumerate() {
                let at = (k as u64 + 1) * 2 * SECOND;
                let batch: Vec<PressureSample> = (batch.iter())
                    .map(|r| PressureSample { timestamp_ns: at - 2 * SECOND + r.timestamp_ns, ..*r })
                    .collect();
                let report = engine.push_pressure(&batch);
                prop_assert!(report.accepted <= batch.len());
                if let Ok(epoch) = engine.push_scan(&scan(at, &[(0, -40.0), (1, -64.0), (9, -60.0)])) {
                    let p = epoch.position;
                    prop_assert!(p.x.is_finite() && p.y.is_finite() && p.accuracy_m > 0.0, "{p:?}");
                }
                let total: f64 = engine.posterior().iter().sum();
                prop_assert!((total - 1.0).abs() < 1e-9, "{total}");
                prop_assert!(engine.posterior().iter().all(|p| p.is_finite() && *p >= 0.0));
            }
            // The filter restarts on a step that goes wrong; none here should.
            prop_assert_eq!(engine.stats().filter_restarts, 0);
        }
    }
}
