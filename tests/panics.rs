//! A panic in the middle of an epoch (issue 7: "a panic anywhere becomes an error, and the
//! engine stays usable"; never a corrupted engine). With the `fault-injection` feature an
//! epoch at `FAULT_INJECTION_MID_EPOCH_NS` panics after it has stepped the filter and the
//! Viterbi window, consumed the motion tracker's samples, moved the clock, raised the counters
//! and told the listeners. The engine must come out of it exactly as it was before the call
//! (its snapshot equal, counters included), and then run on as a twin engine that never saw
//! the call, on the core and across the FFI.
#![cfg(feature = "fault-injection")]

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use waymark::{
    EngineOptions, ErrorReport, MotionSample, PositionEstimate, PositionListener, PositioningEngine,
    PositioningError, RadioScan, StatusUpdate, WifiReading,
};
use waymark_engine::sensors::SensorSample;
use waymark_engine::FAULT_INJECTION_MID_EPOCH_NS as MID;
use waymark_engine::{Engine, EngineConfig, Scan, Site, TransmitterId};
use waymark_sim::{imu, Office, OfficeConfig};

/// One epoch of a walk: the inertial samples since the previous one, then the scan.
struct Epoch {
    imu: [Vec<SensorSample>; 3],
    scan: Scan,
}

/// A simulated office and a 30 s walk with its raw IMU, shifted in time so that the walk's
/// last scan falls on the fault-injection time (ordinary gaps between epochs, so the
/// panicking epoch is an ordinary one).
fn walk() -> (Site, Vec<Epoch>) {
    let office = Office::generate(&OfficeConfig { training_scans: 20, ..OfficeConfig::default() });
    let walk = office.walk(3, 30.0);
    let trace = imu::synthesize(&walk.trajectory, &imu::ImuConfig::default(), 3);
    let offset = MID - walk.epochs.last().unwrap().scan.timestamp_ns;
    let mut previous = 0;
    let epochs = walk
        .epochs
        .iter()
        .map(|e| {
            let t = e.scan.timestamp_ns;
            let slice = |v: &[SensorSample]| -> Vec<SensorSample> {
                v[v.partition_point(|s| s.timestamp_ns <= previous)
                    ..v.partition_point(|s| s.timestamp_ns <= t)]
                    .iter()
                    .map(|s| SensorSample { timestamp_ns: s.timestamp_ns + offset, ..*s })
                    .collect()
            };
            let imu = [slice(&trace.accelerometer), slice(&trace.gyroscope), slice(&trace.magnetometer)];
            previous = t;
            Epoch { imu, scan: Scan { timestamp_ns: t + offset, ..e.scan.clone() } }
        })
        .collect();
    (office.site, epochs)
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<String>()
        .cloned()
        .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_default()
}

fn feed(engine: &mut Engine, imu: &[Vec<SensorSample>; 3]) {
    engine.push_accelerometer(&imu[0]);
    engine.push_gyroscope(&imu[1]);
    engine.push_magnetometer(&imu[2]);
}

#[test]
fn a_panic_in_the_middle_of_an_epoch_leaves_the_core_engine_as_it_was() {
    let (site, epochs) = walk();
    let site = Arc::new(site);
    let (last, earlier) = epochs.split_last().unwrap();
    for advance in [false, true] {
        let mut engine = Engine::new(Arc::clone(&site), EngineConfig::default()).unwrap();
        let mut twin = Engine::new(Arc::clone(&site), EngineConfig::default()).unwrap();
        for e in earlier {
            for engine in [&mut engine, &mut twin] {
                feed(engine, &e.imu);
                let _ = engine.push_scan(&e.scan);
            }
        }
        feed(&mut engine, &last.imu);
        feed(&mut twin, &last.imu);
        let before = engine.snapshot();
        assert!(before.position.is_some() && !before.last_track.is_empty());

        let call = catch_unwind(AssertUnwindSafe(|| {
            if advance {
                engine.advance(MID)
            } else {
                engine.push_scan(&last.scan)
            }
        }));
        let payload = call.expect_err("the injected panic");
        assert!(panic_message(&*payload).contains("middle of the epoch"), "{}", panic_message(&*payload));
        // The epoch got as far as its status events and track revisions, and is undone:
        // filter, track, tracker, clock, position and counters.
        assert_eq!(engine.snapshot(), before, "advance: {advance}");

        // The engine runs on as one that never saw the call.
        let scan = Scan { timestamp_ns: MID + 2, ..last.scan.clone() };
        assert_eq!(engine.push_scan(&scan), twin.push_scan(&scan));
        let end = waymark_engine::sensors::MAX_TIMESTAMP_NS;
        assert_eq!(engine.advance(end), twin.advance(end));
        assert_eq!(engine.snapshot(), twin.snapshot());
    }
}

/// Counts what it hears.
#[derive(Default)]
struct Counter {
    positions: Mutex<Vec<PositionEstimate>>,
    errors: AtomicUsize,
}

impl PositionListener for Counter {
    fn on_position(&self, position: PositionEstimate) {
        self.positions.lock().unwrap().push(position);
    }
    fn on_status(&self, _: StatusUpdate) {}
    fn on_error(&self, _: ErrorReport) {
        self.errors.fetch_add(1, Ordering::SeqCst);
    }
}

fn samples(batch: &[SensorSample]) -> Vec<MotionSample> {
    batch.iter().map(|s| MotionSample { timestamp_ns: s.timestamp_ns, x: s.x, y: s.y, z: s.z }).collect()
}

fn ffi_scan(s: &Scan, timestamp_ns: u64) -> RadioScan {
    let wifi = s
        .readings
        .iter()
        .map(|r| match &r.transmitter {
            TransmitterId::Wifi { bssid } => {
                WifiReading { bssid: bssid.clone().into(), rssi_dbm: r.rssi_dbm, age_ms: 0 }
            }
            _ => unreachable!("the simulator makes WiFi only"),
        })
        .collect();
    RadioScan { timestamp_ns, wifi, beacons: vec![] }
}

fn ffi_feed(engine: &PositioningEngine, imu: &[Vec<SensorSample>; 3]) {
    engine.push_accelerometer(samples(&imu[0])).unwrap();
    engine.push_gyroscope(samples(&imu[1])).unwrap();
    engine.push_magnetometer(samples(&imu[2])).unwrap();
}

#[test]
fn a_panic_in_the_middle_of_an_epoch_is_internal_and_changes_nothing_across_the_ffi() {
    let (site, epochs) = walk();
    let json = site.to_json();
    let (last, earlier) = epochs.split_last().unwrap();
    for advance in [false, true] {
        let engine = PositioningEngine::new(json.clone(), EngineOptions::default()).unwrap();
        let twin = PositioningEngine::new(json.clone(), EngineOptions::default()).unwrap();
        let listener = Arc::new(Counter::default());
        let _subscription = Arc::clone(&engine).subscribe(listener.clone());
        for e in earlier {
            for engine in [&engine, &twin] {
                ffi_feed(engine, &e.imu);
                let _ = engine.push_scan(ffi_scan(&e.scan, e.scan.timestamp_ns));
            }
        }
        ffi_feed(&engine, &last.imu);
        ffi_feed(&twin, &last.imu);
        let before = engine.snapshot();
        let heard = listener.positions.lock().unwrap().clone();
        let errors = listener.errors.load(Ordering::SeqCst);

        let result = if advance { engine.advance(MID) } else { engine.push_scan(ffi_scan(&last.scan, MID)) };
        assert!(matches!(result, Err(PositioningError::Internal { .. })), "{result:?}");
        assert_eq!(engine.snapshot(), before, "advance: {advance}");
        assert_eq!(engine.position().unwrap(), before.1);
        // The undone epoch's position reached no listener; the error did.
        assert_eq!(*listener.positions.lock().unwrap(), heard);
        assert_eq!(listener.errors.load(Ordering::SeqCst), errors + 1);

        // The engine runs on as one that never saw the call.
        let p = engine.push_scan(ffi_scan(&last.scan, MID + 2)).unwrap();
        assert_eq!(p, twin.push_scan(ffi_scan(&last.scan, MID + 2)).unwrap());
        let end = waymark_engine::sensors::MAX_TIMESTAMP_NS;
        assert_eq!(engine.advance(end).unwrap(), twin.advance(end).unwrap());
        assert_eq!(engine.snapshot(), twin.snapshot());
        let positions = listener.positions.lock().unwrap();
        assert_eq!(positions.len(), heard.len() + 2);
        assert_eq!(positions[heard.len()], p);
    }
}
