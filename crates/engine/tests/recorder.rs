//! The survey recorder against the reader `waymark survey` uses: whatever calls an app makes,
//! the files read back as the samples, scans and waypoints the recorder took, bit for bit; and a
//! recorded walk replayed from its file positions exactly as the calls did.

use proptest::prelude::*;
use std::sync::Arc;
use waymark_engine::recorder::{RecorderOptions, SurveyRecorder};
use waymark_engine::sensors::SensorSample;
use waymark_engine::{Engine, EngineConfig, Reading, Scan, TransmitterId};
use waymark_sim::{imu, Office, OfficeConfig};
use waymark_survey::io::ilc::{EventOptions, Trace, Waypoint};

#[derive(Clone, Debug)]
enum Call {
    Samples { stream: usize, batch: Vec<(u64, f64, f64, f64)> },
    Scan { dt: u64, readings: Vec<(usize, f64, u64)> },
    Waypoint { dt: u64, x: f64, y: f64, floor: usize },
}

/// WiFi access points, iBeacons (one at major = minor = 0 without an address) and beacons known
/// by their address.
fn transmitter(k: usize) -> TransmitterId {
    match k % 6 {
        0 => TransmitterId::wifi("AA:BB:CC:DD:EE:01").unwrap(),
        1 => TransmitterId::wifi("aa-bb-cc-dd-ee-02").unwrap(),
        2 => TransmitterId::ble("fda50693-a4e2-4fb1-afcf-c6eb07647825", 10073, 61418).unwrap(),
        3 => TransmitterId::ble("FDA50693A4E24FB1AFCFC6EB07647825", 0, 0).unwrap(),
        4 => TransmitterId::ble_address("e0:78:a3:3d:b5:d6").unwrap(),
        _ => TransmitterId::ble("fda50693-a4e2-4fb1-afcf-c6eb07647825", 0, 9).unwrap(),
    }
}

fn value() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -20.0..20.0f64,
        1 => prop::num::f64::ANY,
        1 => Just(-0.0),
        1 => prop::num::f64::SUBNORMAL,
    ]
}

fn call() -> impl Strategy<Value = Call> {
    let sample = (0u64..30_000_000, value(), value(), value());
    prop_oneof![
        4 => (0usize..3, prop::collection::vec(sample, 0..20)).prop_map(|(stream, batch)| Call::Samples { stream, batch }),
        2 => (0u64..2_000_000_000, prop::collection::vec((0usize..6, prop_oneof![4 => -110.0..-20.0f64, 1 => prop::num::f64::ANY], 0u64..5_000_000_000), 0..6))
            .prop_map(|(dt, readings)| Call::Scan { dt, readings }),
        1 => (0u64..3_000_000_000, -50.0..50.0f64, -50.0..50.0f64, 0usize..3)
            .prop_map(|(dt, x, y, floor)| Call::Waypoint { dt, x, y, floor }),
    ]
}

const FLOORS: [&str; 3] = ["B1", "F1", "F2"];

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn what_is_recorded_reads_back_bit_for_bit(
        start in 0u64..1_000_000_000_000_000_000,
        calls in prop::collection::vec(call(), 1..80),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let options = RecorderOptions { walk_name: "prop".into(), site_id: "site".into(), device: "Test Phone".into() };
        let mut recorder = SurveyRecorder::new(dir.path(), options).unwrap();
        // What the recorder took, by its own word; checked against the reader below.
        let mut streams: [Vec<SensorSample>; 3] = Default::default();
        let mut scans = Vec::new();
        let mut waypoints: Vec<(String, Waypoint)> = Vec::new();
        let (mut sample_clock, mut scan_clock, mut waypoint_clock) = ([start; 3], start, start);
        for call in calls {
            match call {
                Call::Samples { stream, batch } => {
                    let batch: Vec<SensorSample> = batch.iter().map(|&(dt, x, y, z)| {
                        sample_clock[stream] += dt;
                        SensorSample { timestamp_ns: sample_clock[stream], x, y, z }
                    }).collect();
                    let taken = match stream {
                        0 => recorder.push_accelerometer(&batch),
                        1 => recorder.push_gyroscope(&batch),
                        _ => recorder.push_magnetometer(&batch),
                    }.unwrap();
                    let mut last = streams[stream].last().map(|s| s.timestamp_ns);
                    let kept: Vec<SensorSample> = batch.into_iter().filter(|s| {
                        let keep = s.is_plausible() && last.is_none_or(|l| s.timestamp_ns > l);
                        if keep { last = Some(s.timestamp_ns); }
                        keep
                    }).collect();
                    prop_assert_eq!(taken.accepted, kept.len());
                    streams[stream].extend(kept);
                }
                Call::Scan { dt, readings } => {
                    scan_clock += dt;
                    let readings = readings.iter().map(|&(k, rssi_dbm, age_ns)| Reading { transmitter: transmitter(k), rssi_dbm, age_ns: age_ns.min(scan_clock) }).collect();
                    let scan = Scan { timestamp_ns: scan_clock, readings };
                    if recorder.push_scan(&scan).is_ok() {
                        scans.push(scan);
                    }
                }
                Call::Waypoint { dt, x, y, floor } => {
                    waypoint_clock += dt;
                    recorder.mark_waypoint(waypoint_clock, x, y, FLOORS[floor]).unwrap();
                    waypoints.push((FLOORS[floor].to_owned(), Waypoint { timestamp_ns: waypoint_clock, x, y, floor: None }));
                }
            }
        }
        let stats = match recorder.finish() {
            Ok(stats) => stats,
            Err(waymark_engine::RecorderError::NoWaypoints) => {
                prop_assert!(waypoints.is_empty());
                // No walk file: what was pushed waits in the spool for a waypoint.
                let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
                prop_assert!(names.iter().all(|n| n == ".prop.pending"), "{:?}", names);
                return Ok(());
            }
            Err(e) => panic!("{e}"),
        };
        prop_assert_eq!(stats.scans as usize, scans.len());
        let mut read: [Vec<SensorSample>; 3] = Default::default();
        let (mut read_scans, mut read_waypoints) = (Vec::new(), Vec::new());
        for path in &stats.files {
            let trace = Trace::read(path).unwrap();
            prop_assert!(trace.grouped_scans);
            prop_assert_eq!(trace.stats.malformed + trace.stats.out_of_order + trace.stats.ignored, 0);
            prop_assert_eq!(trace.site_id.as_deref(), Some("site"));
            read_scans.extend(trace.scans(&EventOptions::default()));
            read[0].extend(trace.accelerometer);
            read[1].extend(trace.gyroscope);
            read[2].extend(trace.magnetometer);
            let floor = trace.floor_name.unwrap();
            read_waypoints.extend(trace.waypoints.into_iter().map(|w| (floor.clone(), w)));
        }
        // Bit for bit: -0.0 stays -0.0, subnormals stay.
        for (taken, back) in streams.iter().zip(&read) {
            prop_assert_eq!(taken.len(), back.len());
            for (a, b) in taken.iter().zip(back) {
                prop_assert_eq!(a.timestamp_ns, b.timestamp_ns);
                prop_assert_eq!([a.x.to_bits(), a.y.to_bits(), a.z.to_bits()], [b.x.to_bits(), b.y.to_bits(), b.z.to_bits()]);
            }
        }
        prop_assert_eq!(&scans, &read_scans);
        prop_assert_eq!(&waypoints, &read_waypoints);
        let floors_walked = waypoints.windows(2).filter(|w| w[0].0 != w[1].0).count() + 1;
        prop_assert_eq!(stats.files.len(), floors_walked);
    }
}

/// The demo office's walk pushed to an engine directly, and recorded and replayed from its
/// file: the same positions, bit for bit.
#[test]
fn a_recorded_walk_replays_as_the_calls_did() {
    let office = Office::generate(&OfficeConfig { training_scans: 30, ..OfficeConfig::default() });
    let walk = office.walk(4, 120.0);
    let sim = imu::synthesize(&walk.trajectory, &imu::ImuConfig::default(), 4);
    let site = Arc::new(office.site.clone());
    let dir = tempfile::tempdir().unwrap();
    let options = RecorderOptions { walk_name: "office".into(), ..RecorderOptions::default() };
    let mut recorder = SurveyRecorder::new(dir.path(), options).unwrap();
    let mut direct = Engine::new(Arc::clone(&site), EngineConfig::default()).unwrap();
    let mut positions = Vec::new();
    let mut previous = 0;
    let first = &walk.epochs[0];
    recorder.mark_waypoint(first.scan.timestamp_ns, first.truth.x, first.truth.y, "F1").unwrap();
    for epoch in &walk.epochs {
        let t = epoch.scan.timestamp_ns;
        let batch = |v: &[SensorSample]| {
            v[v.partition_point(|s| s.timestamp_ns <= previous)..v.partition_point(|s| s.timestamp_ns <= t)]
                .to_vec()
        };
        let (a, g, m) = (batch(&sim.accelerometer), batch(&sim.gyroscope), batch(&sim.magnetometer));
        direct.push_accelerometer(&a);
        direct.push_gyroscope(&g);
        direct.push_magnetometer(&m);
        recorder.push_accelerometer(&a).unwrap();
        recorder.push_gyroscope(&g).unwrap();
        recorder.push_magnetometer(&m).unwrap();
        if let Ok(e) = direct.push_scan(&epoch.scan) {
            positions.push(e.position);
        }
        recorder.push_scan(&epoch.scan).unwrap();
        previous = t;
    }
    let last = walk.epochs.last().unwrap();
    recorder.mark_waypoint(last.scan.timestamp_ns, last.truth.x, last.truth.y, "F1").unwrap();
    let stats = recorder.finish().unwrap();
    assert_eq!(stats.files.len(), 1);
    assert!(positions.len() > 50);

    let trace = Trace::read(&stats.files[0]).unwrap();
    let mut replayed = Engine::new(site, EngineConfig::default()).unwrap();
    let mut again = Vec::new();
    for event in trace.events(&EventOptions::default()) {
        match event {
            waymark_survey::io::ilc::Event::Accelerometer(b) => _ = replayed.push_accelerometer(&b),
            waymark_survey::io::ilc::Event::Gyroscope(b) => _ = replayed.push_gyroscope(&b),
            waymark_survey::io::ilc::Event::Magnetometer(b) => _ = replayed.push_magnetometer(&b),
            waymark_survey::io::ilc::Event::Pressure(b) => _ = replayed.push_pressure(&b),
            waymark_survey::io::ilc::Event::Scan(s) => {
                if let Ok(e) = replayed.push_scan(&s) {
                    again.push(e.position);
                }
            }
        }
    }
    assert_eq!(positions, again);
}
