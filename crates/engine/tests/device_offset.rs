//! The phone's RSSI offset learned online (docs/accuracy.md#device-offset): on the simulated
//! office, a phone that reads every signal 6 dB weaker than the survey's is found to, and is
//! positioned better for it; the survey's own phone is found to read as it did.

use std::sync::Arc;
use waymark_engine::radio::{Scan, DEVICE_OFFSET_PRIOR_STD_DB};
use waymark_engine::{Engine, EngineConfig};
use waymark_sim::{Office, OfficeConfig};

/// Replays walks `seeds` with every reading moved by `offset_db` (and dropped where that puts
/// it at or below the clip level, as a less sensitive receiver would); returns the mean error
/// and each walk's learned offset (mean, standard deviation).
fn replay(office: &Office, seeds: &[u64], offset_db: f64, learn: bool) -> (f64, Vec<(f64, f64)>) {
    let site = Arc::new(office.site.clone());
    let (mut sum, mut n, mut learned) = (0.0, 0usize, Vec::new());
    for &seed in seeds {
        let config = EngineConfig { device_offset: learn, ..EngineConfig::default() };
        let mut engine = Engine::new(Arc::clone(&site), config).unwrap();
        for epoch in &office.walk(seed, 200.0).epochs {
            let readings = (epoch.scan.readings.iter())
                .map(|r| waymark_engine::radio::Reading { rssi_dbm: r.rssi_dbm + offset_db, ..r.clone() })
                .filter(|r| r.rssi_dbm > office.field.clip_dbm)
                .collect();
            let scan = Scan { timestamp_ns: epoch.scan.timestamp_ns, readings };
            if let Ok(e) = engine.push_scan(&scan) {
                sum += (e.position.x - epoch.truth.x).hypot(e.position.y - epoch.truth.y);
                n += 1;
            }
        }
        if let Some(offset) = engine.device_offset() {
            learned.push(offset);
        }
    }
    (sum / n as f64, learned)
}

#[test]
fn a_weaker_phone_is_found_and_positioned_better_for_it() {
    // Seeds 41-46 are used nowhere else.
    let office = Office::generate(&OfficeConfig { seed: 41, ..OfficeConfig::default() });
    let walks = [42, 43, 44, 45, 46];
    let (learning, offsets) = replay(&office, &walks, -6.0, true);
    let (fixed, none) = replay(&office, &walks, -6.0, false);
    assert!(none.is_empty(), "no offset is reported when the option is off");
    assert_eq!(offsets.len(), walks.len());
    for (mean, std) in &offsets {
        // Most of it: readings the weaker phone loses below the clip level leave the strong
        // ones, which pull the estimate towards 0 (docs/accuracy.md#device-offset).
        assert!((mean + 6.0).abs() < 2.0, "learned {mean} ± {std}");
        assert!(*std < DEVICE_OFFSET_PRIOR_STD_DB / 4.0, "{std}");
    }
    assert!(learning < 0.9 * fixed, "with the offset {learning:.2} m, without {fixed:.2} m");
}

#[test]
fn the_surveys_own_phone_reads_as_the_map() {
    let office = Office::generate(&OfficeConfig { seed: 41, ..OfficeConfig::default() });
    let walks = [42, 43, 44];
    let (learning, offsets) = replay(&office, &walks, 0.0, true);
    let (fixed, _) = replay(&office, &walks, 0.0, false);
    for (mean, std) in &offsets {
        assert!(mean.abs() < 1.5 && mean.abs() < 3.0 * std.max(0.5), "learned {mean} ± {std}");
    }
    // Learning nothing to correct costs little.
    assert!(learning < 1.1 * fixed, "with the offset {learning:.2} m, without {fixed:.2} m");
}
