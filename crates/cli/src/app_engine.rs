//! The long run's app engine (`waymark simulate --experiment long-run`): the SDK library's
//! `PositioningEngine`, what Kotlin and Swift apps hold, driven from Rust through the same
//! records they pass, with a subscribed listener that counts the positions it hears.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use waymark_engine::radio::{Scan, TransmitterId};
use waymark_engine::sensors::SensorSample;
use waymark_experiments::longrun::AppEngine;
use waymark_sim::session::ImuSink;

/// Counts what an app's listener receives.
#[derive(Default)]
struct AppListener {
    finite: AtomicU64,
    non_finite: AtomicU64,
}

impl waymark::PositionListener for AppListener {
    fn on_position(&self, p: waymark::PositionEstimate) {
        let finite = p.x.is_finite() && p.y.is_finite() && p.accuracy_m.is_finite();
        let counter = if finite { &self.finite } else { &self.non_finite };
        counter.fetch_add(1, Ordering::Relaxed);
    }

    fn on_status(&self, _status: waymark::StatusUpdate) {}

    fn on_error(&self, _error: waymark::ErrorReport) {}
}

/// The FFI engine with its listener subscribed.
struct FfiEngine {
    engine: Arc<waymark::PositioningEngine>,
    listener: Arc<AppListener>,
    _subscription: Arc<waymark::Subscription>,
}

/// An FFI engine on the site file `site_json`, with the default options.
pub fn ffi_engine(site_json: &str) -> Result<Box<dyn AppEngine>, String> {
    let engine = waymark::PositioningEngine::new(site_json.to_owned(), waymark::EngineOptions::default())
        .map_err(|e| e.to_string())?;
    let listener = Arc::new(AppListener::default());
    let subscription = Arc::clone(&engine).subscribe(listener.clone());
    Ok(Box::new(FfiEngine { engine, listener, _subscription: subscription }))
}

fn motion_samples(batch: &[SensorSample]) -> Vec<waymark::MotionSample> {
    batch
        .iter()
        .map(|s| waymark::MotionSample { timestamp_ns: s.timestamp_ns, x: s.x, y: s.y, z: s.z })
        .collect()
}

/// The scan as an app hands it over the FFI (the simulated office has WiFi access points only).
fn radio_scan(scan: &Scan) -> waymark::RadioScan {
    let wifi = scan
        .readings
        .iter()
        .filter_map(|r| match &r.transmitter {
            TransmitterId::Wifi { bssid } => Some(waymark::WifiReading {
                bssid: bssid.clone().into(),
                rssi_dbm: r.rssi_dbm,
                age_ms: r.age_ns / 1_000_000,
            }),
            _ => None,
        })
        .collect();
    waymark::RadioScan { timestamp_ns: scan.timestamp_ns, wifi, beacons: Vec::new() }
}

impl ImuSink for FfiEngine {
    // A rejected batch is counted by the engine: the long run reads the core engine's counters.
    fn accelerometer(&mut self, batch: &[SensorSample]) {
        let _ = self.engine.push_accelerometer(motion_samples(batch));
    }

    fn gyroscope(&mut self, batch: &[SensorSample]) {
        let _ = self.engine.push_gyroscope(motion_samples(batch));
    }

    fn magnetometer(&mut self, batch: &[SensorSample]) {
        let _ = self.engine.push_magnetometer(motion_samples(batch));
    }
}

impl AppEngine for FfiEngine {
    fn push_scan(&mut self, scan: &Scan) -> Option<(f64, f64)> {
        self.engine.push_scan(radio_scan(scan)).ok().map(|p| (p.x, p.y))
    }

    fn positions_heard(&self) -> (u64, u64) {
        (self.listener.finite.load(Ordering::Relaxed), self.listener.non_finite.load(Ordering::Relaxed))
    }
}
