//! The Kotlin/Swift surface, exercised from Rust: a simulated walk through the FFI records,
//! listeners (including one that fails), subscriptions that cancel on drop, typed errors, and
//! eight threads at once.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use waymark::{
    BeaconReading, EngineOptions, ErrorReport, FfiFixBias, FfiPositionFix, MotionSample, PositionEstimate,
    PositionListener, PositioningEngine, PositioningError, RadioScan, StatusUpdate, WifiReading,
};
use waymark_engine::radio::TransmitterId;
use waymark_sim::{imu, Office, OfficeConfig};

#[derive(Default)]
struct Counter {
    positions: AtomicUsize,
    statuses: AtomicUsize,
    errors: AtomicUsize,
    last: Mutex<Option<PositionEstimate>>,
    status_log: Mutex<Vec<StatusUpdate>>,
}

impl PositionListener for Counter {
    fn on_position(&self, position: PositionEstimate) {
        self.positions.fetch_add(1, Ordering::SeqCst);
        *self.last.lock().unwrap() = Some(position);
    }
    fn on_status(&self, status: StatusUpdate) {
        self.statuses.fetch_add(1, Ordering::SeqCst);
        self.status_log.lock().unwrap().push(status);
    }
    fn on_error(&self, _message: ErrorReport) {
        self.errors.fetch_add(1, Ordering::SeqCst);
    }
}

/// A listener that always throws, as a buggy app's might (uniffi turns a foreign exception
/// from a method that returns nothing into a panic).
struct Failing;
impl PositionListener for Failing {
    fn on_position(&self, _: PositionEstimate) {
        panic!("app bug in on_position")
    }
    fn on_status(&self, _: StatusUpdate) {
        panic!("app bug in on_status")
    }
    fn on_error(&self, _: ErrorReport) {
        panic!("app bug in on_error")
    }
}

fn to_ffi(batch: &[waymark_engine::sensors::SensorSample]) -> Vec<MotionSample> {
    batch.iter().map(|s| MotionSample { timestamp_ns: s.timestamp_ns, x: s.x, y: s.y, z: s.z }).collect()
}

/// Pushes the IMU samples after `from` up to `to`, ns, as an app's batches.
fn push_imu(engine: &PositioningEngine, trace: &imu::ImuTrace, from: u64, to: u64) {
    let batch = |v: &[waymark_engine::sensors::SensorSample]| {
        to_ffi(&v[v.partition_point(|s| s.timestamp_ns <= from)..v.partition_point(|s| s.timestamp_ns <= to)])
    };
    engine.push_accelerometer(batch(&trace.accelerometer)).unwrap();
    engine.push_gyroscope(batch(&trace.gyroscope)).unwrap();
    engine.push_magnetometer(batch(&trace.magnetometer)).unwrap();
}

fn scan(s: &waymark_engine::Scan) -> RadioScan {
    let wifi = s
        .readings
        .iter()
        .map(|r| match &r.transmitter {
            TransmitterId::Wifi { bssid } => {
                WifiReading { bssid: bssid.to_uppercase().into(), rssi_dbm: r.rssi_dbm, age_ms: 0 }
            }
            _ => unreachable!("the simulator makes WiFi only"),
        })
        .collect();
    RadioScan { timestamp_ns: s.timestamp_ns, wifi, beacons: vec![] }
}

#[test]
fn a_walk_through_the_ffi_with_listeners() {
    let office = Office::generate(&OfficeConfig::default());
    let engine = PositioningEngine::new(office.site.to_json(), EngineOptions::default()).unwrap();
    let counter = Arc::new(Counter::default());
    let _subscription = Arc::clone(&engine).subscribe(counter.clone());
    let failing = Arc::clone(&engine).subscribe(Arc::new(Failing));
    let walk = office.walk(3, 60.0);
    let trace = imu::synthesize(&walk.trajectory, &imu::ImuConfig::default(), 3);
    let mut previous = 0;
    let mut errors = Vec::new();
    for epoch in &walk.epochs {
        let t = epoch.scan.timestamp_ns;
        push_imu(&engine, &trace, previous, t);
        previous = t;
        match engine.push_scan(scan(&epoch.scan)) {
            Ok(p) => {
                let error = ((p.x - epoch.truth.x).powi(2) + (p.y - epoch.truth.y).powi(2)).sqrt();
                errors.push(error);
                assert_eq!(p.floor_name, "office");
            }
            Err(e) => assert!(matches!(e, PositioningError::InputRejected { .. })),
        }
    }
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    assert!(mean < 1.5, "mean error {mean}");
    assert_eq!(counter.positions.load(Ordering::SeqCst), errors.len());
    assert_eq!(counter.last.lock().unwrap().clone(), engine.position().unwrap());
    assert!(!engine.track().unwrap().is_empty());
    assert!(engine.fixed_lag_position().unwrap().is_some());

    // Cancelled (here by drop) listeners hear nothing more; the failing one never broke anything.
    drop(failing);
    let before = counter.positions.load(Ordering::SeqCst);
    let last = walk.epochs.last().unwrap().scan.timestamp_ns;
    engine.advance(last + 1_500_000_000).unwrap();
    assert_eq!(counter.positions.load(Ordering::SeqCst), before + 1);
}

#[test]
fn errors_are_typed() {
    let bad = PositioningEngine::new("{\"format_version\": 1".into(), EngineOptions::default());
    assert!(matches!(bad, Err(PositioningError::InvalidSite { .. })));
    let missing = PositioningEngine::from_path("/nonexistent.json".into(), EngineOptions::default());
    assert!(matches!(missing, Err(PositioningError::InvalidSite { .. })));
    let office = Office::generate(&OfficeConfig { training_scans: 20, ..OfficeConfig::default() });
    let options = EngineOptions { fixed_lag_epochs: 1000, ..EngineOptions::default() };
    assert!(matches!(
        PositioningEngine::new(office.site.to_json(), options),
        Err(PositioningError::InvalidConfig { .. })
    ));
    let nan_north = EngineOptions { declination_deg: Some(f64::NAN), ..EngineOptions::default() };
    assert!(matches!(
        PositioningEngine::new(office.site.to_json(), nan_north),
        Err(PositioningError::InvalidConfig { .. })
    ));
    let north = EngineOptions {
        declination_deg: Some(7.7),
        site_rotation_deg: Some(12.0),
        ..EngineOptions::default()
    };
    PositioningEngine::new(office.site.to_json(), north).unwrap();
    let engine = PositioningEngine::new(office.site.to_json(), EngineOptions::default()).unwrap();
    let reading = |bssid: &str, rssi_dbm| WifiReading { bssid: bssid.into(), rssi_dbm, age_ms: 0 };
    let good =
        RadioScan { timestamp_ns: 10, wifi: vec![reading("02:00:00:00:00:00", -60.0)], beacons: vec![] };
    engine.push_scan(good.clone()).unwrap();
    for rejected in [
        good.clone(),
        RadioScan { timestamp_ns: 20, wifi: vec![], beacons: vec![] },
        RadioScan { timestamp_ns: 20, wifi: vec![reading("not a bssid", -60.0)], beacons: vec![] },
        RadioScan { timestamp_ns: 20, wifi: vec![reading("02:00:00:00:00:00", f64::NAN)], beacons: vec![] },
    ] {
        assert!(matches!(engine.push_scan(rejected), Err(PositioningError::InputRejected { .. })));
    }
    // Listeners hear rejections too, and a scan of unknown transmitters means no coverage.
    let counter = Arc::new(Counter::default());
    let _subscription = Arc::clone(&engine).subscribe(counter.clone());
    let foreign =
        RadioScan { timestamp_ns: 30, wifi: vec![reading("aa:aa:aa:aa:aa:aa", -50.0)], beacons: vec![] };
    assert!(engine.push_scan(foreign).is_err());
    assert_eq!(counter.errors.load(Ordering::SeqCst), 1);
    assert_eq!(*counter.status_log.lock().unwrap(), vec![StatusUpdate::NoSiteCoverage { timestamp_ns: 30 }]);
    // NaN and backwards samples are dropped, not fatal.
    let s = |t, x| MotionSample { timestamp_ns: t, x, y: 0.0, z: 9.81 };
    assert_eq!(
        engine.push_accelerometer(vec![s(15, 0.0), s(14, 0.0), s(16, f64::NAN), s(17, 0.1)]).unwrap(),
        2
    );
}

/// A site whose survey dropped stale readings has the FFI's engine drop them too: the C,
/// Kotlin and Swift engines are the one the evaluation measures.
#[test]
fn the_sites_reading_age_limit_applies_through_the_ffi() {
    let office = Office::generate(&OfficeConfig { training_scans: 20, ..OfficeConfig::default() });
    let reading = |age_ms| WifiReading { bssid: "02:00:00:00:00:00".into(), rssi_dbm: -60.0, age_ms };
    let stale_counted = |site: &waymark_engine::Site| {
        let engine = PositioningEngine::new(site.to_json(), EngineOptions::default()).unwrap();
        let scan = RadioScan { timestamp_ns: 10, wifi: vec![reading(0), reading(5_000)], beacons: vec![] };
        // The same transmitter twice: the fresh reading is kept, the old one is stale or a
        // duplicate.
        engine.push_scan(scan).unwrap();
        let only_old = RadioScan { timestamp_ns: 20, wifi: vec![reading(5_000)], beacons: vec![] };
        let result = engine.push_scan(only_old);
        (result.is_ok(), engine.input_stats().unwrap().readings_stale)
    };
    let limited = office.site.clone().with_max_reading_age_ns(Some(2_000_000_000));
    assert_eq!(stale_counted(&limited), (false, 1), "the site's 2 s limit applies");
    assert_eq!(stale_counted(&office.site), (true, 0), "a site without a limit keeps every reading");
}

#[test]
fn a_hashed_site_needs_its_salt() {
    let office = Office::generate(&OfficeConfig { training_scans: 20, ..OfficeConfig::default() });
    let salt: Vec<u8> = (0u8..32).collect();
    let hashed = office.site.hashed(&waymark_engine::Salt::new(salt.clone()).unwrap()).unwrap().to_json();
    let with = |site_salt: Option<Vec<u8>>| EngineOptions { site_salt, ..EngineOptions::default() };
    let engine = PositioningEngine::new(hashed.clone(), with(Some(salt.clone()))).unwrap();
    let walk = office.walk(5, 20.0);
    for epoch in &walk.epochs {
        engine.push_scan(scan(&epoch.scan)).unwrap();
    }
    for options in [with(None), with(Some(vec![7; 32]))] {
        match PositioningEngine::new(hashed.clone(), options) {
            Err(PositioningError::SaltMismatch { reason }) => assert!(!reason.contains("0001"), "{reason}"),
            other => panic!("expected SaltMismatch, got {:?}", other.map(|_| ())),
        }
    }
    assert!(matches!(
        PositioningEngine::new(hashed, with(Some(vec![1; 8]))),
        Err(PositioningError::InvalidConfig { .. })
    ));
    // The salt stays out of Debug output, and a raw site takes (and ignores) one.
    assert!(!format!("{:?}", with(Some(salt.clone()))).contains("[0, 1, 2"));
    PositioningEngine::new(office.site.to_json(), with(Some(salt))).unwrap();
}

#[test]
fn eight_threads_at_once() {
    let office = Office::generate(&OfficeConfig { training_scans: 50, ..OfficeConfig::default() });
    let engine = PositioningEngine::new(office.site.to_json(), EngineOptions::default()).unwrap();
    let walk = office.walk(5, 40.0);
    let counter = Arc::new(Counter::default());
    let accepted = Arc::new(AtomicUsize::new(0));
    std::thread::scope(|scope| {
        for thread in 0..8 {
            let engine = Arc::clone(&engine);
            let counter = Arc::clone(&counter);
            let accepted = Arc::clone(&accepted);
            let walk = &walk;
            scope.spawn(move || {
                let subscription = Arc::clone(&engine).subscribe(counter);
                for epoch in walk.epochs.iter().skip(thread).step_by(8) {
                    let t = epoch.scan.timestamp_ns;
                    let _ = engine.push_accelerometer(vec![MotionSample {
                        timestamp_ns: t - 1,
                        x: 0.0,
                        y: 0.0,
                        z: 9.81,
                    }]);
                    if engine.push_scan(scan(&epoch.scan)).is_ok() {
                        accepted.fetch_add(1, Ordering::SeqCst);
                    }
                    let _ = engine.position().unwrap();
                    let _ = engine.track().unwrap();
                }
                drop(subscription);
            });
        }
    });
    // Scans from other threads may arrive out of order and be rejected; every accepted one
    // produced a position, and the engine still works.
    assert!(accepted.load(Ordering::SeqCst) > 0);
    assert!(engine.position().unwrap().is_some());
}

#[cfg(feature = "fault-injection")]
#[test]
fn an_injected_panic_is_an_error_and_the_engine_goes_on() {
    use waymark::FAULT_INJECTION_TIMESTAMP_NS;
    let office = Office::generate(&OfficeConfig { training_scans: 20, ..OfficeConfig::default() });
    let engine = PositioningEngine::new(office.site.to_json(), EngineOptions::default()).unwrap();
    let wifi = vec![WifiReading { bssid: "02:00:00:00:00:00".into(), rssi_dbm: -60.0, age_ms: 0 }];
    let boom = RadioScan { timestamp_ns: FAULT_INJECTION_TIMESTAMP_NS, wifi: wifi.clone(), beacons: vec![] };
    assert!(matches!(engine.push_scan(boom), Err(PositioningError::Internal { .. })));
    engine.push_scan(RadioScan { timestamp_ns: 10, wifi, beacons: vec![] }).unwrap();
}

/// The simulated site with its first access point turned into a BLE beacon known by its
/// advertiser address only (as Eddystone beacons are).
fn site_with_an_address_beacon(office: &Office) -> String {
    let json = office.site.to_json();
    let wifi = r#"{"wifi":{"bssid":"02:00:00:00:00:00"}}"#;
    assert!(json.contains(wifi), "the simulator's first access point moved");
    json.replace(wifi, r#"{"ble_address":{"mac":"02:00:00:00:00:00"}}"#)
}

#[test]
fn beacons_known_by_address_only() {
    let office = Office::generate(&OfficeConfig { training_scans: 20, ..OfficeConfig::default() });
    let engine =
        PositioningEngine::new(site_with_an_address_beacon(&office), EngineOptions::default()).unwrap();
    let beacon = |uuid: &str, major, minor, address: Option<&str>| BeaconReading {
        uuid: uuid.into(),
        major,
        minor,
        rssi_dbm: -60.0,
        age_ms: 0,
        address: address.map(Into::into),
    };
    let scan = |timestamp_ns, beacons| RadioScan { timestamp_ns, wifi: vec![], beacons };
    const UUID: &str = "fda50693-a4e2-4fb1-afcf-c6eb07647825";
    // By address: no UUID, or an iBeacon left at major = minor = 0; any MAC notation.
    engine.push_scan(scan(10, vec![beacon("", 0, 0, Some("02-00-00-00-00-00"))])).unwrap();
    engine.push_scan(scan(20, vec![beacon(UUID, 0, 0, Some("02:00:00:00:00:00"))])).unwrap();
    // The same address as a WiFi BSSID, or an iBeacon with a major/minor, is another
    // transmitter, unknown here.
    let rejected = |result: Result<PositionEstimate, PositioningError>| {
        assert!(matches!(result, Err(PositioningError::InputRejected { .. })), "{result:?}")
    };
    let bssid = WifiReading { bssid: "02:00:00:00:00:00".into(), rssi_dbm: -60.0, age_ms: 0 };
    rejected(engine.push_scan(RadioScan { timestamp_ns: 30, wifi: vec![bssid], beacons: vec![] }));
    rejected(engine.push_scan(scan(30, vec![beacon(UUID, 1, 2, Some("02:00:00:00:00:00"))])));
    // Bad input is a typed error, and the engine goes on.
    rejected(engine.push_scan(scan(30, vec![beacon("", 0, 0, None)])));
    rejected(engine.push_scan(scan(30, vec![beacon("", 0, 0, Some(""))])));
    rejected(engine.push_scan(scan(30, vec![beacon("", 0, 0, Some("02:00:00:00:00"))])));
    rejected(engine.push_scan(scan(30, vec![beacon("", 0, 0, Some("not a mac address"))])));
    rejected(engine.push_scan(scan(30, vec![beacon(UUID, 1, 2, Some("zz:00:00:00:00:00"))])));
    let position = engine.push_scan(scan(30, vec![beacon("", 0, 0, Some("02:00:00:00:00:00"))])).unwrap();
    assert_eq!(position.timestamp_ns, 30);
}

#[test]
fn log_records_reach_the_sink() {
    use waymark::{init_logging, LogLevel, LogSink};
    #[derive(Default)]
    struct Sink(Mutex<Vec<String>>);
    impl LogSink for Sink {
        fn log(&self, _level: LogLevel, target: String, message: String) {
            self.0.lock().unwrap().push(format!("{target}: {message}"));
        }
    }
    let sink = Arc::new(Sink::default());
    init_logging(Some(sink.clone()), LogLevel::Debug);
    init_logging(Some(sink.clone()), LogLevel::Debug); // idempotent
    let office = Office::generate(&OfficeConfig { training_scans: 20, ..OfficeConfig::default() });
    let engine = PositioningEngine::new(office.site.to_json(), EngineOptions::default()).unwrap();
    let _ = engine.push_scan(RadioScan { timestamp_ns: 5, wifi: vec![], beacons: vec![] });
    assert!(
        sink.0.lock().unwrap().iter().any(|m| m.contains("scan rejected")),
        "{:?}",
        sink.0.lock().unwrap()
    );
    init_logging(None, LogLevel::Error);
}

/// A walk through the office with a fix 1.5 m east and 0.5 m north of the truth half a second
/// after every third scan, and the user confirming their room after every seventh. Returns
/// (fixes, confirmations) accepted.
fn walk_with_fixes_and_feedback(engine: &PositioningEngine, office: &Office, seed: u64) -> (u32, u32) {
    let walk = office.walk(seed, 60.0);
    let (mut fixes, mut confirmations) = (0, 0);
    for (k, epoch) in walk.epochs.iter().enumerate() {
        let t = epoch.scan.timestamp_ns;
        if engine.push_scan(scan(&epoch.scan)).is_err() {
            continue;
        }
        if k % 7 == 3 {
            if let Some(zone) = epoch.zone {
                let name = office.site.zones()[zone].name.clone();
                if engine.confirm_zone(t, name).is_ok() {
                    confirmations += 1;
                }
            }
        }
        if k % 3 == 1 {
            let fix = FfiPositionFix {
                timestamp_ns: t + 500_000_000,
                x: Some(epoch.truth.x + 1.5),
                y: Some(epoch.truth.y + 0.5),
                floor: Some(0),
                accuracy_m: 2.0,
                latitude_deg: None,
                longitude_deg: None,
            };
            if engine.push_fix(fix).is_ok() {
                fixes += 1;
            }
        }
    }
    (fixes, confirmations)
}

#[test]
fn habits_are_learned_exported_and_imported_through_the_ffi() {
    let office = Office::generate(&OfficeConfig { training_scans: 20, ..OfficeConfig::default() });
    let engine = PositioningEngine::new(office.site.to_json(), EngineOptions::default()).unwrap();
    let unlearned = FfiFixBias { bias_x_m: 0.0, bias_y_m: 0.0, spread: 1.0 };
    assert_eq!(engine.fix_bias().unwrap(), unlearned);
    let (fixes, confirmations) = walk_with_fixes_and_feedback(&engine, &office, 11);
    assert!(fixes > 10 && confirmations > 3, "{fixes} fixes, {confirmations} confirmations");

    let report = engine.learn_habits().unwrap();
    assert!(report.epochs > 0, "{report:?}");
    assert!(report.learned_transitions > 0, "{report:?}");
    assert_eq!(report.total_epochs, u64::from(report.epochs));
    // `applied` is whether the exported model holds a strength.
    let model: serde_json::Value = serde_json::from_str(&engine.export_habits().unwrap()).unwrap();
    assert_eq!(report.applied, model["strength"].as_f64().is_some(), "{report:?}");
    // The fixes' bias is learned (toward +x, +y).
    let learned = engine.fix_bias().unwrap();
    assert!(
        learned.bias_x_m > 0.3 && learned.bias_y_m > 0.0 && learned.bias_x_m > learned.bias_y_m,
        "{learned:?}"
    );
    // Each epoch once: a second pass has nothing to learn and changes nothing.
    let json = engine.export_habits().unwrap();
    let again = engine.learn_habits().unwrap();
    assert_eq!(again.epochs, 0, "{again:?}");
    assert_eq!(again.total_epochs, report.total_epochs);
    assert_eq!(again.applied, report.applied);
    assert_eq!(engine.export_habits().unwrap(), json);

    // Into a second engine on the same site: the same model.
    let other = PositioningEngine::new(office.site.to_json(), EngineOptions::default()).unwrap();
    let empty = other.export_habits().unwrap();
    assert_ne!(empty, json);
    other.import_habits(json.clone().into()).unwrap();
    assert_eq!(other.export_habits().unwrap(), json);
    assert_eq!(other.fix_bias().unwrap(), learned);

    // Refused models throw HabitsRejected, reach onError, and change nothing.
    let counter = Arc::new(Counter::default());
    let _subscription = Arc::clone(&other).subscribe(counter.clone());
    // Another site (the office with another seed has the same states, so the same key).
    let elsewhere = waymark_sim::scale::ScaleSite::generate(&waymark_sim::scale::ScaleConfig {
        states: 200,
        ..Default::default()
    });
    let foreign = PositioningEngine::new(elsewhere.json, EngineOptions::default()).unwrap();
    let mut value: serde_json::Value = serde_json::from_str(&json).unwrap();
    value["version"] = 999.into();
    let newer = value.to_string();
    let refused = [
        String::new(),
        "{".into(),
        "null".into(),
        "\u{0}".into(),
        json.replace("waymark-habits", "waymark-site"),
        newer,
        json.replacen("\"count\":[", "\"count\":[-1,", 1),
        foreign.export_habits().unwrap(),
    ];
    for (k, bad) in refused.iter().enumerate() {
        match other.import_habits(bad.clone().into()) {
            Err(PositioningError::HabitsRejected { reason }) => assert!(!reason.is_empty()),
            result => panic!("{}: expected HabitsRejected, got {result:?}", &bad[..bad.len().min(80)]),
        }
        assert_eq!(other.export_habits().unwrap(), json, "a refused model changed the habits");
        assert_eq!(counter.errors.load(Ordering::SeqCst), k + 1);
    }
    assert_eq!(other.fix_bias().unwrap(), learned);

    other.clear_habits().unwrap();
    assert_eq!(other.export_habits().unwrap(), empty);
    assert_eq!(other.fix_bias().unwrap(), unlearned);
}

#[test]
fn learning_while_other_threads_push_and_read() {
    let office = Office::generate(&OfficeConfig { training_scans: 20, ..OfficeConfig::default() });
    let engine = PositioningEngine::new(office.site.to_json(), EngineOptions::default()).unwrap();
    let walk = office.walk(4, 120.0);
    let counter = Arc::new(Counter::default());
    let _subscription = Arc::clone(&engine).subscribe(counter.clone());
    let learned = std::thread::scope(|scope| {
        let pusher = scope.spawn(|| {
            for epoch in &walk.epochs {
                let _ = engine.push_scan(scan(&epoch.scan));
                let _ = engine.fix_bias().unwrap();
            }
        });
        let learner = scope.spawn(|| {
            let mut epochs = 0;
            for _ in 0..20 {
                epochs += u64::from(engine.learn_habits().unwrap().epochs);
                let json = engine.export_habits().unwrap();
                engine.import_habits(json.into()).unwrap();
            }
            epochs
        });
        pusher.join().unwrap();
        learner.join().unwrap()
    });
    let last = engine.learn_habits().unwrap();
    // No epoch learned twice, and no pass lost, whichever thread got there first. (A pass
    // that finds a single new epoch skips it for good: hence at most, not exactly, every
    // accepted epoch.)
    assert_eq!(learned + u64::from(last.epochs), last.total_epochs);
    let positions = counter.positions.load(Ordering::SeqCst) as u64;
    assert!(last.total_epochs <= positions && last.total_epochs > positions / 2, "{last:?}, {positions}");
}

/// One `Site` shared by several engines: each positions exactly as an engine that loaded the
/// file itself, and a bad file is `InvalidSite` before any engine exists.
#[test]
fn one_shared_site_serves_several_engines() {
    let office = Office::generate(&OfficeConfig::default());
    let json = office.site.to_json();
    let site = waymark::FfiSite::from_bytes(office.site.to_binary()).unwrap();
    assert_eq!(site.floor_names(), vec!["office".to_string()]);
    assert_eq!(site.zone_names().len(), office.site.zones().len());
    let walk = office.walk(5, 40.0);
    let replay = |engine: Arc<PositioningEngine>| -> Vec<Option<PositionEstimate>> {
        walk.epochs.iter().map(|e| engine.push_scan(scan(&e.scan)).ok()).collect()
    };
    let own = replay(PositioningEngine::new(json, EngineOptions::default()).unwrap());
    let first = replay(PositioningEngine::with_site(Arc::clone(&site), EngineOptions::default()).unwrap());
    let second = replay(PositioningEngine::with_site(Arc::clone(&site), EngineOptions::default()).unwrap());
    assert!(own.iter().filter(|p| p.is_some()).count() > walk.epochs.len() / 2);
    assert_eq!(own, first);
    assert_eq!(own, second);
    let bad = waymark::FfiSite::from_bytes(b"{".to_vec());
    assert!(matches!(bad, Err(PositioningError::InvalidSite { .. })));
}

/// `track: false` gives the same positions, fixed-lag included, with no track and no
/// `TrackRevised`; the default engine on the same walk has both.
#[test]
fn without_the_track_through_the_ffi() {
    let office = Office::generate(&OfficeConfig::default());
    let walk = office.walk(7, 60.0);
    let trace = imu::synthesize(&walk.trajectory, &imu::ImuConfig::default(), 7);
    let run = |track: bool| {
        let options = EngineOptions { track, ..EngineOptions::default() };
        let engine = PositioningEngine::new(office.site.to_json(), options).unwrap();
        let counter = Arc::new(Counter::default());
        let _subscription = Arc::clone(&engine).subscribe(counter.clone());
        let (mut previous, mut positions) = (0, Vec::new());
        for epoch in &walk.epochs {
            let t = epoch.scan.timestamp_ns;
            push_imu(&engine, &trace, previous, t);
            previous = t;
            positions.push((engine.push_scan(scan(&epoch.scan)).ok(), engine.fixed_lag_position().unwrap()));
        }
        let revisions = counter
            .status_log
            .lock()
            .unwrap()
            .iter()
            .filter(|s| matches!(s, StatusUpdate::TrackRevised { .. }))
            .count();
        (positions, engine.track().unwrap().len(), revisions)
    };
    let (with, with_track, with_revisions) = run(true);
    let (without, without_track, without_revisions) = run(false);
    assert!(with.iter().filter(|(p, lag)| p.is_some() && lag.is_some()).count() > walk.epochs.len() / 2);
    assert_eq!(with, without);
    assert!(with_track > 0 && with_revisions > 0, "{with_track} points, {with_revisions} revisions");
    assert_eq!((without_track, without_revisions), (0, 0));
    assert!(EngineOptions::default().track);
}
