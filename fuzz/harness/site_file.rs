//! `site_file`: any bytes through `Site::from_bytes`, so both encodings: JSON, and the binary
//! one when the input starts with its signature. A site that loads must write JSON and binary
//! that reload to the same site, and must make an engine (core and FFI) that takes scans and
//! an advance without panicking and with sane positions.

use super::checks;
use std::sync::Arc;
use waymark as ffi;
use waymark_engine::{Engine, EngineConfig, Error, InputError, Reading, Scan, Site, SiteError};

/// One fuzz input.
pub fn run(data: &[u8]) {
    let parsed = Site::from_bytes(data);
    // A site that loads but whose tables are over the site budget makes no engine
    // (docs/errors.md#site-limits).
    let over_budget = parsed.as_ref().is_ok_and(|site| {
        matches!(site.reach_tables(EngineConfig::default().reach_radius_m), Err(SiteError::OverLimit { .. }))
    });
    // The FFI constructors must agree with the core on what loads: the text one on JSON (text
    // never starts with the binary signature, which is not UTF-8), the bytes one on anything.
    let agree = |created: Result<_, ffi::PositioningError>| match created {
        Ok(_) => assert!(parsed.is_ok() && !over_budget, "the FFI made an engine the core refuses"),
        Err(ffi::PositioningError::InvalidSite { .. }) => assert!(parsed.is_err() || over_budget),
        Err(ffi::PositioningError::InvalidConfig { .. }) => assert!(parsed.is_ok()),
        Err(e) => panic!("unexpected FFI error: {e}"),
    };
    if let Ok(text) = std::str::from_utf8(data) {
        agree(ffi::PositioningEngine::new(text.to_owned(), ffi::EngineOptions::default()));
    }
    agree(ffi::PositioningEngine::from_site_bytes(data.to_vec(), ffi::EngineOptions::default()));
    let site = match parsed {
        Ok(site) => site,
        Err(e) => {
            let _ = e.to_string();
            return;
        }
    };
    let json = site.to_json();
    let again = Site::from_json(json.as_bytes()).unwrap_or_else(|e| panic!("to_json does not reload: {e}"));
    assert_eq!(again.to_json(), json, "a reloaded site writes different JSON");
    assert_eq!(again.states(), site.states());
    let binary = site.to_binary();
    let unpacked = Site::from_bytes(&binary).unwrap_or_else(|e| panic!("to_binary does not reload: {e}"));
    assert_eq!(unpacked.to_json(), json, "the binary encoding loads as another site");
    assert_eq!(unpacked.to_binary(), binary, "a reloaded site writes different binary");
    let site = Arc::new(site);
    match Engine::new(Arc::clone(&site), EngineConfig::default()) {
        Ok(engine) => exercise(engine),
        // The site's calibration may hold a step-length model the tracker refuses.
        Err(Error::InvalidConfig(_)) => {}
        Err(Error::Site(SiteError::OverLimit { .. })) => assert!(over_budget),
        Err(e) => panic!("unexpected engine error: {e}"),
    }
}

/// Scans of the site's first transmitters (a typical RSSI, a weak one, the highest accepted)
/// and an advance after the first.
fn exercise(mut engine: Engine) {
    let site = Arc::clone(engine.site());
    let (states, floors) = (site.states().len(), site.floors().len());
    let transmitters = site.radio().transmitters();
    let scan = |timestamp_ns: u64, rssi_dbm: f64| Scan {
        timestamp_ns,
        readings: transmitters
            .iter()
            .take(4)
            .map(|t| Reading { transmitter: t.clone(), rssi_dbm, age_ns: 0 })
            .collect(),
    };
    for (k, rssi) in [(1u64, -60.0), (4, -85.0), (5, waymark_engine::MAX_RSSI_DBM)] {
        match engine.push_scan(&scan(k * 1_000_000_000, rssi)) {
            Ok(e) => checks::position(&e.position, floors),
            Err(InputError::EmptyScan) => assert!(transmitters.is_empty()),
            Err(e) => panic!("a scan of the site's own transmitters was rejected: {e}"),
        }
        checks::posterior(engine.posterior(), states);
        if k == 1 {
            let p = engine.advance(2_500_000_000).expect("an advance in time order is taken").position;
            checks::position(&p, floors);
            checks::posterior(engine.posterior(), states);
        }
    }
    checks::track(&engine.track(), states, floors);
    if let Some(p) = engine.fixed_lag_position() {
        checks::track(&[p], states, floors);
    }
}
