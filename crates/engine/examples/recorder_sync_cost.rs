//! What the survey recorder's durability costs (docs/surveying.md#durability): records in real
//! time, as a phone would, three inertial streams at 100 Hz in 100 ms batches, a WiFi scan every
//! 3 s and a tap every 5 s, into a temporary folder, and prints the bytes written and how long
//! the calls took: each call hands its lines to the OS, and one a second also syncs them.
//!
//! `cargo run --release -p waymark-engine --example recorder_sync_cost [seconds, default 10] [folder]`

use std::time::{Duration, Instant};
use waymark_engine::recorder::{RecorderOptions, SurveyRecorder};
use waymark_engine::sensors::SensorSample;
use waymark_engine::{Reading, Scan, TransmitterId};

fn main() {
    let mut args = std::env::args().skip(1);
    let seconds: u64 = args.next().map_or(10, |s| s.parse().expect("seconds"));
    let parent = args.next().map_or_else(std::env::temp_dir, Into::into);
    let dir = tempfile::tempdir_in(parent).expect("a temporary folder");
    let options = RecorderOptions { walk_name: "cost".into(), ..RecorderOptions::default() };
    let mut recorder = SurveyRecorder::new(dir.path(), options).expect("a recorder");
    let ms = 1_000_000u64;
    let mut calls = Vec::new();
    let start = Instant::now();
    let mut timed = |f: &mut dyn FnMut()| {
        let t = Instant::now();
        f();
        calls.push(t.elapsed());
    };
    for tick in 0..seconds * 10 {
        let t0 = tick * 100 * ms;
        let batch: Vec<SensorSample> = (0..10)
            .map(|k| SensorSample {
                timestamp_ns: t0 + k * 10 * ms + 1,
                x: 0.123_456_789,
                y: -0.987_65,
                z: 9.812_34,
            })
            .collect();
        timed(&mut || {
            recorder.push_accelerometer(&batch).expect("accelerometer");
        });
        timed(&mut || {
            recorder.push_gyroscope(&batch).expect("gyroscope");
        });
        timed(&mut || {
            recorder.push_magnetometer(&batch).expect("magnetometer");
        });
        if tick % 30 == 0 {
            let readings = (0..20)
                .map(|k| Reading {
                    transmitter: TransmitterId::wifi(&format!("02:00:00:00:00:{k:02x}")).expect("a BSSID"),
                    rssi_dbm: -60.0 - k as f64,
                    age_ns: 0,
                })
                .collect();
            let scan = Scan { timestamp_ns: t0 + 99 * ms, readings };
            timed(&mut || recorder.push_scan(&scan).expect("scan"));
        }
        if tick % 50 == 0 {
            timed(&mut || recorder.mark_waypoint(t0 + 99 * ms, 1.0, 2.0, "F1").expect("tap"));
        }
        let due = Duration::from_millis(100 * (tick + 1));
        std::thread::sleep(due.saturating_sub(start.elapsed()));
    }
    let stats = recorder.finish().expect("finish");
    let bytes = std::fs::metadata(&stats.files[0]).expect("the walk file").len();
    calls.sort();
    let busy: Duration = calls.iter().sum();
    let at = |q: f64| calls[((calls.len() - 1) as f64 * q) as usize];
    println!(
        "{seconds} s: {} calls, {} bytes ({:.1} KB/s); call time median {:?}, p99 {:?}, max {:?}; \
         {:.2} % of the wall time in calls",
        calls.len(),
        bytes,
        bytes as f64 / seconds as f64 / 1000.0,
        at(0.5),
        at(0.99),
        at(1.0),
        100.0 * busy.as_secs_f64() / start.elapsed().as_secs_f64()
    );
}
