//! Map evidence from the engine's own session and a refitted site loaded in place
//! (docs/evidence.md#from-a-session, #loading-a-refitted-site), on the simulated office.

use std::collections::BTreeMap;
use std::sync::Arc;
use waymark_engine::evidence::{most_probable, Evidence, EvidenceOptions, TransmitterKey};
use waymark_engine::geofence::{Geofence, GeofenceShape};
use waymark_engine::radio::Scan;
use waymark_engine::{Engine, EngineConfig};
use waymark_sim::{Office, OfficeConfig};

/// Seeds 61-69 are used nowhere else.
fn office(clip_dbm: f64) -> Office {
    Office::generate(&OfficeConfig { seed: 61, clip_dbm, ..OfficeConfig::default() })
}

/// The walk's inputs, in time order: each scan, a timer epoch halfway to the next, and a gap
/// of ten minutes halfway through the walk (the filter bridges or restarts: the smoother's
/// steps are forgotten there).
enum Input {
    Scan(Scan),
    Advance(u64),
}

fn inputs(office: &Office, seed: u64) -> Vec<Input> {
    let epochs = office.walk(seed, 150.0).epochs;
    let half = epochs.len() / 2;
    let mut out = Vec::new();
    for (k, epoch) in epochs.iter().enumerate() {
        let shift = if k >= half { 600_000_000_000 } else { 0 };
        let scan = Scan { timestamp_ns: epoch.scan.timestamp_ns + shift, ..epoch.scan.clone() };
        let next = epochs.get(k + 1).map(|e| e.scan.timestamp_ns + shift);
        out.push(Input::Scan(scan.clone()));
        if let Some(next) = next.filter(|_| k + 1 != half) {
            out.push(Input::Advance((scan.timestamp_ns + next) / 2));
        }
    }
    out
}

fn keyed(scan: &Scan) -> (Vec<(TransmitterKey, f64)>, [bool; 2]) {
    let mut radios = [false; 2];
    let readings = (scan.readings.iter())
        .map(|r| {
            radios[usize::from(r.transmitter.is_ble())] = true;
            (TransmitterKey::of(&r.transmitter), r.rssi_dbm)
        })
        .collect();
    (readings, radios)
}

#[test]
fn each_scan_weighs_its_epochs_posterior_smoothed_by_the_lag() {
    let office = office(-100.0);
    let site = Arc::new(office.site.clone());
    let whole = EvidenceOptions { mass: 1.0, states: 0 };
    for (lag, options) in [(0, whole), (3, whole), (12, whole), (3, EvidenceOptions::default())] {
        let config = EngineConfig { fixed_lag_epochs: lag, ..EngineConfig::default() };
        let mut gathering = Engine::new(Arc::clone(&site), config.clone()).unwrap();
        let mut reference = Engine::new(Arc::clone(&site), config).unwrap();
        gathering.start_evidence_with(options);
        assert!(gathering.is_gathering_evidence() && !reference.is_gathering_evidence());
        // The reference: each epoch's posterior as the last sweep that held it smoothed it,
        // the most epochs after it that the smoother ever held.
        let mut last_seen: BTreeMap<u64, Vec<(u32, f64)>> = BTreeMap::new();
        let mut scans = Vec::new();
        for input in inputs(&office, 62) {
            let (a, b) = match &input {
                Input::Scan(scan) => (gathering.push_scan(scan), reference.push_scan(scan)),
                Input::Advance(t) => (gathering.advance(*t), reference.advance(*t)),
            };
            assert_eq!(a, b, "gathering evidence changes no position (lag {lag})");
            if let (Input::Scan(scan), Ok(_)) = (&input, &b) {
                scans.push(scan.clone());
            }
            reference.smoothed_posteriors(|t, posterior| {
                last_seen.insert(t, posterior.to_vec());
            });
        }
        let mut expected = Evidence::new(&site);
        let mut kept = Vec::new();
        for scan in &scans {
            let (readings, radios) = keyed(scan);
            most_probable(&last_seen[&scan.timestamp_ns], options.mass, options.states, &mut kept);
            expected.add_scan(&kept, &readings, radios).unwrap();
        }
        expected.add_walk();
        let taken = gathering.take_evidence().unwrap();
        assert_eq!(taken.scans, scans.len() as u64, "lag {lag}");
        assert_eq!(taken.scans_dropped, 0, "lag {lag}");
        assert!(scans.len() > 50, "{} scans", scans.len());
        assert_eq!(taken.evidence, expected, "lag {lag}");
        assert_eq!(taken.evidence.walks(), 1);
    }
}

#[test]
fn taking_goes_on_afresh_and_stopping_discards() {
    let office = office(-100.0);
    let mut engine = Engine::new(Arc::new(office.site.clone()), EngineConfig::default()).unwrap();
    assert_eq!(engine.take_evidence(), None, "nothing is gathered unless asked");
    let walk = office.walk(63, 120.0).epochs;
    let (first, second) = walk.split_at(walk.len() / 2);
    for epoch in first {
        engine.push_scan(&epoch.scan).unwrap();
    }
    engine.start_evidence();
    for epoch in second {
        engine.push_scan(&epoch.scan).unwrap();
    }
    let taken = engine.take_evidence().unwrap();
    assert_eq!(taken.scans, second.len() as u64, "only the scans after the start");
    let again = engine.take_evidence().unwrap();
    assert_eq!((again.scans, again.evidence.walks()), (0, 1));
    assert_eq!(again.evidence.states_scanned(), 0);
    engine.stop_evidence();
    assert!(!engine.is_gathering_evidence());
    assert_eq!(engine.take_evidence(), None);
}

#[test]
fn a_site_with_the_same_states_carries_the_session_over() {
    let office = office(-100.0);
    let site = Arc::new(office.site.clone());
    // The same site in another allocation (as a refitted file would be): the session must go
    // on exactly as if nothing had been replaced.
    let refitted = Arc::new(office.site.clone());
    let mut replaced = Engine::new(Arc::clone(&site), EngineConfig::default()).unwrap();
    let mut reference = Engine::new(site, EngineConfig::default()).unwrap();
    replaced.start_evidence();
    let walk = office.walk(64, 150.0).epochs;
    let half = walk.len() / 2;
    for (k, epoch) in walk.iter().enumerate() {
        if k == half {
            let before = replaced.take_evidence();
            let gathered = replaced.replace_site(Arc::clone(&refitted)).unwrap();
            assert!(before.is_some_and(|e| e.scans == half as u64));
            assert_eq!(gathered.map(|e| e.scans), Some(0), "taken just before");
            assert!(Arc::ptr_eq(replaced.site(), &refitted));
            assert_eq!(replaced.position(), reference.position());
        }
        assert_eq!(replaced.push_scan(&epoch.scan), reference.push_scan(&epoch.scan), "epoch {k}");
    }
    assert_eq!(replaced.track(), reference.track());
    assert_eq!(replaced.history(), reference.history());
    assert_eq!(replaced.stats(), reference.stats());
    let rest = replaced.take_evidence().unwrap();
    assert_eq!(rest.scans, (walk.len() - half) as u64, "gathering goes on on the new site");
}

#[test]
fn another_site_starts_afresh_and_keeps_what_is_not_of_its_states() {
    let office_a = office(-100.0);
    // Another clip level: other evidence, so another site for the session.
    let office_b = office(-95.0);
    let mut engine = Engine::new(Arc::new(office_a.site.clone()), EngineConfig::default()).unwrap();
    let fence = Geofence {
        id: "desk".into(),
        floor: 0,
        shape: GeofenceShape::Circle { x: 5.0, y: 5.0, radius_m: 4.0 },
    };
    engine.add_geofence(fence.clone()).unwrap();
    engine.start_evidence();
    let walk = office_a.walk(65, 100.0).epochs;
    for epoch in &walk {
        engine.push_scan(&epoch.scan).unwrap();
    }
    let accepted = engine.stats().scans_accepted;
    let gathered = engine.replace_site(Arc::new(office_b.site.clone())).unwrap().unwrap();
    assert_eq!(gathered.scans, walk.len() as u64);
    assert_eq!(gathered.evidence.key(), Evidence::site_key(&office_a.site), "of the old site");
    assert_eq!(engine.position(), None, "the estimate starts afresh");
    assert!(engine.history().is_empty());
    assert_eq!(engine.stats().scans_accepted, accepted, "the counters go on");
    assert_eq!(engine.geofences().cloned().collect::<Vec<_>>(), vec![fence]);
    let next = office_b.walk(66, 60.0).epochs;
    for epoch in &next {
        engine.push_scan(&epoch.scan).unwrap();
    }
    let taken = engine.take_evidence().unwrap();
    assert_eq!(taken.evidence.key(), Evidence::site_key(&office_b.site));
    assert_eq!(taken.scans, next.len() as u64);
}

#[test]
fn a_site_the_engine_cannot_take_changes_nothing() {
    let office = office(-100.0);
    let site = Arc::new(office.site.clone());
    let salt = waymark_engine::radio::Salt::new(*b"a venue's salt here!").unwrap();
    let hashed = Arc::new(office.site.hashed(&salt).unwrap());
    let mut engine = Engine::new(Arc::clone(&site), EngineConfig::default()).unwrap();
    let mut reference = Engine::new(site, EngineConfig::default()).unwrap();
    engine.start_evidence();
    let walk = office.walk(67, 80.0).epochs;
    for (k, epoch) in walk.iter().enumerate() {
        if k == walk.len() / 2 {
            assert!(engine.replace_site(Arc::clone(&hashed)).is_err(), "no salt for it");
        }
        assert_eq!(engine.push_scan(&epoch.scan), reference.push_scan(&epoch.scan));
    }
    assert_eq!(engine.take_evidence().unwrap().scans, walk.len() as u64);
}
