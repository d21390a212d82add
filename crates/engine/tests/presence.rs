//! Entering and leaving the site's zones and the app's geofences: status events with
//! hysteresis in the epochs that cause them (docs/zones.md).

mod common;

use common::{corridor_readings as readings_at, scan, two_floor_site, zoned_site};
use std::sync::Arc;
use waymark_engine::{Engine, EngineConfig, Geofence, GeofenceError, GeofenceShape, StatusEvent};

const SECOND: u64 = 1_000_000_000;

/// The enter and exit events among `status`, as (entered, place).
fn presence(status: &[StatusEvent]) -> Vec<(bool, String)> {
    status
        .iter()
        .filter_map(|e| match e {
            StatusEvent::ZoneEntered { zone, .. } => Some((true, format!("zone {zone}"))),
            StatusEvent::ZoneExited { zone, .. } => Some((false, format!("zone {zone}"))),
            StatusEvent::GeofenceEntered { id, .. } => Some((true, id.clone())),
            StatusEvent::GeofenceExited { id, .. } => Some((false, id.clone())),
            _ => None,
        })
        .collect()
}

fn at(entered: bool, place: &str) -> (bool, String) {
    (entered, place.to_owned())
}

#[test]
fn walking_from_east_to_west_leaves_one_zone_before_entering_the_next() {
    let mut engine = Engine::new(Arc::new(zoned_site()), EngineConfig::default()).unwrap();
    let first = engine.push_scan(&scan(SECOND, &readings_at(0, 12.0))).unwrap();
    assert_eq!(presence(&first.status), vec![at(true, "zone 1")], "{:?}", first.status);
    let StatusEvent::ZoneEntered { timestamp_ns, probability, .. } = first.status[0] else { unreachable!() };
    assert_eq!(timestamp_ns, SECOND);
    assert!(probability >= 0.68 && (probability - engine.zone_posterior()[1]).abs() < 1e-12);
    // Staying put says nothing more.
    let again = engine.push_scan(&scan(2 * SECOND, &readings_at(0, 12.0))).unwrap();
    assert!(presence(&again.status).is_empty(), "{:?}", again.status);
    // Walk west, one state per scan: east is left before west is entered, each once.
    let mut heard = Vec::new();
    for (k, x) in [9.0, 6.0, 3.0, 0.0, 0.0].into_iter().enumerate() {
        let epoch = engine.push_scan(&scan((3 + k as u64) * SECOND, &readings_at(0, x))).unwrap();
        heard.extend(presence(&epoch.status));
    }
    assert_eq!(heard, vec![at(false, "zone 1"), at(true, "zone 0")]);
}

#[test]
fn an_exit_threshold_above_the_entry_is_refused() {
    let band = |enter_mass, exit_mass| EngineConfig {
        zone_hysteresis: waymark_engine::ZoneHysteresis { enter_mass, exit_mass },
        ..EngineConfig::default()
    };
    assert!(band(0.3, 0.6).validate().is_err());
    assert!(band(0.7, 0.0).validate().is_err());
    assert!(band(f64::NAN, 0.3).validate().is_err());
    assert!(band(0.5, 0.5).validate().is_ok(), "no band: presence follows an even chance");
}

#[test]
fn geofences_are_entered_and_left_like_zones() {
    let mut engine = Engine::new(Arc::new(two_floor_site()), EngineConfig::default()).unwrap();
    let desk = Geofence {
        id: "desk".into(),
        floor: 0,
        shape: GeofenceShape::Circle { x: 12.0, y: 0.0, radius_m: 3.5 },
    };
    let door = Geofence {
        id: "door".into(),
        floor: 0,
        shape: GeofenceShape::Polygon { vertices: vec![[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]] },
    };
    engine.add_geofence(desk.clone()).unwrap();
    engine.add_geofence(door.clone()).unwrap();
    assert_eq!(engine.geofences().cloned().collect::<Vec<_>>(), vec![desk.clone(), door]);
    assert_eq!(engine.add_geofence(desk.clone()), Err(GeofenceError::DuplicateId { id: "desk".into() }));

    let first = engine.push_scan(&scan(SECOND, &readings_at(0, 12.0))).unwrap();
    assert_eq!(presence(&first.status), vec![at(true, "desk")]);
    assert!(engine.geofence_probability("desk").unwrap() >= 0.68);
    assert!(engine.geofence_probability("door").unwrap() < 0.32);
    assert_eq!(engine.geofence_probability("nowhere"), None);
    let mut heard = Vec::new();
    for (k, x) in [9.0, 6.0, 3.0, 0.0, 0.0].into_iter().enumerate() {
        heard.extend(presence(
            &engine.push_scan(&scan((2 + k as u64) * SECOND, &readings_at(0, x))).unwrap().status,
        ));
    }
    assert_eq!(heard, vec![at(false, "desk"), at(true, "door")]);

    // Removed: no exit event, and the id is free again.
    assert!(engine.remove_geofence("door"));
    assert!(!engine.remove_geofence("door"));
    let quiet = engine.push_scan(&scan(10 * SECOND, &readings_at(0, 12.0))).unwrap();
    assert!(presence(&quiet.status).iter().all(|(_, place)| place != "door"), "{:?}", quiet.status);
}

#[test]
fn a_geofence_added_around_the_person_is_entered_at_the_next_epoch() {
    let mut engine = Engine::new(Arc::new(two_floor_site()), EngineConfig::default()).unwrap();
    engine.push_scan(&scan(SECOND, &readings_at(0, 12.0))).unwrap();
    let here = Geofence {
        id: "here".into(),
        floor: 0,
        shape: GeofenceShape::Circle { x: 12.0, y: 0.0, radius_m: 1.0 },
    };
    engine.add_geofence(here).unwrap();
    let next = engine.push_scan(&scan(2 * SECOND, &readings_at(0, 12.0))).unwrap();
    assert_eq!(presence(&next.status), vec![at(true, "here")]);
}

#[test]
fn a_refused_geofence_changes_nothing() {
    let mut engine = Engine::new(Arc::new(two_floor_site()), EngineConfig::default()).unwrap();
    engine.push_scan(&scan(SECOND, &readings_at(0, 12.0))).unwrap();
    let before = engine.snapshot();
    let far = Geofence {
        id: "far".into(),
        floor: 1,
        shape: GeofenceShape::Circle { x: 100.0, y: 0.0, radius_m: 2.0 },
    };
    assert_eq!(engine.add_geofence(far), Err(GeofenceError::NoStateInside { id: "far".into() }));
    let upstairs =
        Geofence { id: "x".into(), floor: 7, shape: GeofenceShape::Circle { x: 0.0, y: 0.0, radius_m: 2.0 } };
    assert!(matches!(engine.add_geofence(upstairs), Err(GeofenceError::UnknownFloor { .. })));
    assert_eq!(engine.geofences().count(), 0);
    assert_eq!(engine.snapshot(), before);
}
