//! Shared helpers for the integration tests.
#![allow(dead_code)]

use nalgebra::Point2;
use waymark_engine::radio::{Reading, Scan, TransmitterId};
use waymark_engine::site::{BuildOptions, Site, SiteBuilder};

pub fn wifi(k: u8) -> TransmitterId {
    TransmitterId::wifi(&format!("02:00:00:00:00:{k:02x}")).unwrap()
}

pub fn scan(timestamp_ns: u64, readings: &[(u8, f64)]) -> Scan {
    Scan {
        timestamp_ns,
        readings: readings
            .iter()
            .map(|&(k, rssi_dbm)| Reading { transmitter: wifi(k), rssi_dbm, age_ns: 0 })
            .collect(),
    }
}

/// Two floors, each a corridor of five states 3 m apart, joined by a 6 m staircase between
/// their first states. Floor 0 hears transmitters 0-2, floor 1 hears 3-5, each strongest
/// near its own end of the corridor. Training scans alternate ±2 dB around the mean.
pub fn two_floor_site() -> Site {
    let mut b = SiteBuilder::new("two floors");
    let floors = [b.floor("G", 0.0), b.floor("1", 4.0)];
    let mut first = Vec::new();
    for (f, &floor) in floors.iter().enumerate() {
        let mut previous = None;
        for k in 0..5 {
            let x = 3.0 * k as f64;
            let scans = (0..20)
                .map(|n| {
                    let jitter = if n % 2 == 0 { 2.0 } else { -2.0 };
                    let readings: Vec<(u8, f64)> = (0..3)
                        .map(|t| {
                            let ap_x = 6.0 * t as f64;
                            ((3 * f + t) as u8, -40.0 - 4.0 * (x - ap_x).abs() + jitter)
                        })
                        .collect();
                    scan(n as u64, &readings)
                })
                .collect();
            let id = b.state(floor, Point2::new(x, 0.0), scans);
            if let Some(p) = previous {
                b.edge(p, id, None);
            } else {
                first.push(id);
            }
            previous = Some(id);
        }
    }
    b.edge(first[0], first[1], Some(6.0));
    b.build(BuildOptions::default()).unwrap()
}

/// [`two_floor_site`] with zones: "west" is states 0-1, "east" 3-4 (state 2 in no zone),
/// "upstairs" all of floor 1.
pub fn zoned_site() -> Site {
    use waymark_engine::{Zone, ZoneKind};
    let zone = |name: &str, kind, states: Vec<u32>| Zone { name: name.into(), kind, states };
    two_floor_site()
        .with_zones(vec![
            zone("west", ZoneKind::Room, vec![0, 1]),
            zone("east", ZoneKind::Room, vec![3, 4]),
            zone("upstairs", ZoneKind::Hall, (5..10).collect()),
        ])
        .unwrap()
}

/// What [`two_floor_site`]'s transmitters say at x on floor f (the training means).
pub fn corridor_readings(f: usize, x: f64) -> Vec<(u8, f64)> {
    (0..3).map(|t| ((3 * f + t) as u8, -40.0 - 4.0 * (x - 6.0 * t as f64).abs())).collect()
}

/// The JSON of a small site that is costly to position on: `n` states packed on a line,
/// `8 / n` m apart, each joined to the next and with one fingerprint entry, so that every
/// state is within the default 9 m reach of every other (issue 60's reproduction: the
/// walking-distance tables of 20 000 such states asked for 2.4 GB).
pub fn dense_line_site_json(n: usize) -> String {
    use std::fmt::Write;
    let mut json = String::from(
        r#"{"format_version": 7, "name": "dense", "floors": [{"name": "G"}], "radio": {"clip_dbm": -100,
 "unheard": {"mean_dbm": -110, "std_db": 5}, "transmitters": [{"wifi": {"bssid": "02:00:00:00:00:01"}}]},
 "states": ["#,
    );
    let spacing_m = 8.0 / n as f64;
    for i in 0..n {
        let comma = if i == 0 { "" } else { "," };
        let x = i as f64 * spacing_m;
        write!(json, r#"{comma}{{"id": {i}, "floor": 0, "x": {x}, "y": 0, "fingerprint": [{{"tx": 0, "mean_dbm": -60, "std_db": 4}}]}}"#)
            .unwrap();
    }
    json.push_str(r#"], "edges": ["#);
    for i in 1..n {
        let comma = if i == 1 { "" } else { "," };
        write!(json, r#"{comma}{{"from": {}, "to": {i}}}"#, i - 1).unwrap();
    }
    json.push_str("]}");
    json
}
