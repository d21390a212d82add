//! What matching scans against a site with hashed transmitter ids costs per scan, on scans of
//! 100 readings (the simulated office's access points heard at one place, padded with unknown
//! ones): hashing the ids with a warm cache (a transmitter heard before), with a cold one
//! (100 HMAC-SHA256), and whole engine epochs on the raw and the hashed site.
//!
//! ```sh
//! cargo run --release -p waymark-engine --example scan_hashing
//! ```

use std::hint::black_box;
use std::sync::Arc;
use std::time::Instant;
use waymark_engine::radio::ScanHasher;
use waymark_engine::{Engine, EngineConfig, Reading, Salt, Scan, Site, TransmitterId};
use waymark_sim as sim;

/// Mean time of `f` in µs over enough calls to take about a second.
fn time<T>(what: &str, mut f: impl FnMut() -> T) -> f64 {
    let start = Instant::now();
    let mut calls = 0u64;
    while start.elapsed().as_secs_f64() < 1.0 {
        for _ in 0..100 {
            black_box(f());
        }
        calls += 100;
    }
    let us = start.elapsed().as_secs_f64() * 1e6 / calls as f64;
    println!("{what:<48} {us:>9.2} µs");
    us
}

fn padded(scan: &Scan, timestamp_ns: u64) -> Scan {
    let mut readings = scan.readings.clone();
    for k in 0..100usize.saturating_sub(readings.len()) {
        let bssid = format!("0a:00:00:00:{:02x}:{:02x}", k / 256, k % 256);
        readings.push(Reading {
            transmitter: TransmitterId::wifi(&bssid).unwrap(),
            rssi_dbm: -85.0,
            age_ns: 0,
        });
    }
    Scan { timestamp_ns, readings }
}

fn main() {
    let office = sim::Office::generate(&sim::OfficeConfig::default());
    let salt = Salt::new(vec![0x5a; 32]).unwrap();
    let hashed_site = Arc::new(office.site.hashed(&salt).unwrap());
    let raw_site = Arc::new(office.site.clone());
    let walk = office.walk(1, 200.0);
    let scans: Vec<Scan> = walk.epochs.iter().map(|e| padded(&e.scan, e.scan.timestamp_ns)).collect();
    let known = walk.epochs[5].scan.readings.len();
    println!(
        "{} transmitters in the site; scans of {} readings ({known} of the site's)\n",
        raw_site.radio().transmitters().len(),
        scans[5].readings.len()
    );

    let scan = &scans[5];
    let mut hasher = ScanHasher::new(salt.clone());
    let warm = time("hash a scan's ids, warm cache", || hasher.hash_scan(scan).readings.len());
    let cold = time("hash a scan's ids, cold cache (100 HMACs)", || {
        ScanHasher::new(salt.clone()).hash_scan(scan).readings.len()
    });
    let raw_resolve = time("resolve on the raw site", || raw_site.radio().resolve(scan, None).unknown);
    let hashed_resolve = time("hash + resolve on the hashed site, warm", || {
        hashed_site.radio().resolve(hasher.hash_scan(scan), None).unknown
    });

    // Whole epochs: the same scans through an engine on each site, timestamps moving on.
    let epoch_time = |what: &str, site: &Arc<Site>, salt: Option<Salt>| {
        let config = EngineConfig { site_salt: salt, ..EngineConfig::default() };
        let mut engine = Engine::new(Arc::clone(site), config).unwrap();
        let mut t = 0u64;
        let mut k = 0usize;
        time(what, || {
            t += 1_500_000_000;
            k = (k + 1) % scans.len();
            engine.push_scan(&Scan { timestamp_ns: t, readings: scans[k].readings.clone() }).is_ok()
        })
    };
    let raw_epoch = epoch_time("an engine epoch, raw site", &raw_site, None);
    let hashed_epoch = epoch_time("an engine epoch, hashed site", &hashed_site, Some(salt));
    println!(
        "\nper 100-reading scan: hashing adds {warm:.1} µs with a warm cache ({cold:.1} µs cold); \
         resolve {raw_resolve:.1} → {hashed_resolve:.1} µs; a whole epoch {raw_epoch:.0} → {hashed_epoch:.0} µs"
    );
}
