//! Privacy: a site file with salted hashes of its transmitter ids positions exactly as the raw
//! one does, holds no raw id, and refuses to start without its salt.

use std::sync::Arc;
use waymark_engine::radio::Reading;
use waymark_engine::{Engine, EngineConfig, Error, Salt, Scan, Site, SiteError, TransmitterId};
use waymark_sim as sim;

const SALT_HEX: &str = "8c1d6b2a9e4f0a7753b1c0de5a11e7f00d2b6c8e9f1a3b5c7d9e0f1a2b3c4d5e";

fn office() -> sim::Office {
    sim::Office::generate(&sim::OfficeConfig::default())
}

fn engine(site: &Site, salt: Option<Salt>) -> Result<Engine, Error> {
    Engine::new(Arc::new(site.clone()), EngineConfig { site_salt: salt, ..EngineConfig::default() })
}

/// The walk's scans, each with an unknown access point, a duplicate of its first reading (in
/// another notation) and a beacon the site does not know.
fn scans(office: &sim::Office) -> Vec<Scan> {
    let walk = office.walk(3, 80.0);
    walk.epochs
        .iter()
        .map(|e| {
            let mut scan = e.scan.clone();
            let first = scan.readings[0].clone();
            let shouted = match &first.transmitter {
                TransmitterId::Wifi { bssid } => {
                    TransmitterId::wifi(&bssid.to_uppercase().replace(':', "-")).unwrap()
                }
                other => other.clone(),
            };
            scan.readings.push(Reading { transmitter: shouted, rssi_dbm: first.rssi_dbm - 3.0, age_ns: 0 });
            scan.readings.push(Reading {
                transmitter: TransmitterId::wifi("02:00:5e:00:00:01").unwrap(),
                rssi_dbm: -60.0,
                age_ns: 0,
            });
            scan.readings.push(Reading {
                transmitter: TransmitterId::ble("fda50693-a4e2-4fb1-afcf-c6eb07647825", 1, 2).unwrap(),
                rssi_dbm: -70.0,
                age_ns: 0,
            });
            scan
        })
        .collect()
}

#[test]
fn a_hashed_site_positions_exactly_as_the_raw_one() {
    let office = office();
    let salt = Salt::from_hex(SALT_HEX).unwrap();
    let hashed = Site::from_json(office.site.hashed(&salt).unwrap().to_json().as_bytes()).unwrap();
    let mut raw_engine = engine(&office.site, None).unwrap();
    let mut hashed_engine = engine(&hashed, Some(salt)).unwrap();
    let scans = scans(&office);
    assert!(scans.len() > 20);
    for scan in &scans {
        assert_eq!(hashed_engine.push_scan(scan), raw_engine.push_scan(scan));
    }
    assert_eq!(hashed_engine.stats(), raw_engine.stats());
    let stats = hashed_engine.stats();
    assert_eq!(stats.readings_unknown, 2 * scans.len() as u64, "{stats:?}");
    assert_eq!(stats.readings_duplicate, scans.len() as u64, "{stats:?}");
    assert_eq!(hashed_engine.track(), raw_engine.track());
    // A scan of transmitters the site does not know is still rejected as such, through the hash.
    let unknown = Scan {
        timestamp_ns: scans.last().unwrap().timestamp_ns + 1_000_000_000,
        readings: scans[0].readings[scans[0].readings.len() - 2..].to_vec(),
    };
    assert_eq!(hashed_engine.push_scan(&unknown), raw_engine.push_scan(&unknown));
    assert!(matches!(
        hashed_engine.push_scan(&unknown),
        Err(waymark_engine::InputError::NoKnownTransmitter { unknown: 2, .. })
    ));
}

#[test]
fn a_hashed_site_file_holds_no_raw_id() {
    let office = office();
    let text = office.site.hashed(&Salt::from_hex(SALT_HEX).unwrap()).unwrap().to_json();
    assert!(!text.contains("bssid") && !text.contains("\"mac\"") && !text.contains("uuid"));
    for id in office.site.radio().transmitters() {
        let TransmitterId::Wifi { bssid } = id else { continue };
        assert!(!text.contains(bssid.as_str()), "{bssid} in the hashed file");
        assert!(!text.contains(&bssid.replace(':', "")), "{bssid} in the hashed file");
    }
}

#[test]
fn no_salt_or_a_wrong_salt_is_a_typed_error() {
    let office = office();
    let hashed = office.site.hashed(&Salt::from_hex(SALT_HEX).unwrap()).unwrap();
    assert_eq!(engine(&hashed, None).err(), Some(Error::Site(SiteError::SaltRequired)));
    let wrong = Salt::new(*b"not the venue's salt").unwrap();
    assert_eq!(engine(&hashed, Some(wrong.clone())).err(), Some(Error::Site(SiteError::WrongSalt)));
    // A salt is not needed for raw ids; the engine starts and matches them raw.
    let mut raw = engine(&office.site, Some(wrong)).unwrap();
    assert!(raw.push_scan(&office.walk(1, 20.0).epochs[0].scan).is_ok());
}
