//! `ilc_trace`: any text through the competition-walk reader, then everything a replay asks of
//! a walk: scans and events under several batching options, ground truth, path length.

use waymark_engine::radio::Scan;
use waymark_survey::io::ilc::{Event, EventOptions, Trace};

/// Batching options, from the replay's default to the extremes of each field.
const OPTIONS: [EventOptions; 4] = [
    EventOptions { batch_ns: 200_000_000, beacon_wait_ns: 2_000_000_000, beacons: true, wifi: true },
    EventOptions { batch_ns: 0, beacon_wait_ns: 0, beacons: true, wifi: true },
    EventOptions { batch_ns: u64::MAX, beacon_wait_ns: u64::MAX, beacons: true, wifi: true },
    EventOptions { batch_ns: 1, beacon_wait_ns: 1, beacons: true, wifi: false },
];

/// One fuzz input.
pub fn run(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let trace = Trace::parse(&text, "fuzz");
    let sorted = |times: &mut dyn Iterator<Item = u64>| {
        let times: Vec<u64> = times.collect();
        assert!(times.windows(2).all(|w| w[0] <= w[1]), "a stream is not in time order");
    };
    sorted(&mut trace.waypoints.iter().map(|w| w.timestamp_ns));
    for stream in [&trace.accelerometer, &trace.gyroscope, &trace.magnetometer] {
        sorted(&mut stream.iter().map(|s| s.timestamp_ns));
        assert!(stream.iter().all(|s| s.x.is_finite() && s.y.is_finite() && s.z.is_finite()));
    }
    sorted(&mut trace.beacons.iter().map(|b| b.0));
    assert!(trace.waypoints.iter().all(|w| w.x.is_finite() && w.y.is_finite()));
    let readings = |scans: &[Scan]| scans.iter().map(|s| s.readings.len()).sum::<usize>();
    for options in &OPTIONS {
        let scans = trace.scans(options);
        assert!(scans.windows(2).all(|w| w[0].timestamp_ns < w[1].timestamp_ns), "scans out of order");
        assert!(scans
            .iter()
            .all(|s| !s.readings.is_empty() && s.readings.iter().all(|r| r.rssi_dbm.is_finite())));
        let wifi = if options.wifi { readings(&trace.wifi_scans) } else { 0 };
        let beacons = if options.beacons { trace.beacons.len() } else { 0 };
        assert_eq!(readings(&scans), wifi + beacons, "a reading was lost or duplicated");
        let events = trace.events(options);
        assert!(events.windows(2).all(|w| w[0].timestamp_ns() <= w[1].timestamp_ns()), "events out of order");
        let samples: usize = events
            .iter()
            .map(|e| match e {
                Event::Accelerometer(b) | Event::Gyroscope(b) | Event::Magnetometer(b) => {
                    assert!(!b.is_empty(), "an empty sensor batch");
                    b.len()
                }
                Event::Pressure(b) => {
                    assert!(!b.is_empty(), "an empty pressure batch");
                    b.len()
                }
                Event::Scan(_) => 0,
            })
            .sum();
        let sensors = trace.accelerometer.len() + trace.gyroscope.len() + trace.magnetometer.len();
        assert_eq!(samples, sensors + trace.pressure.len());
        assert_eq!(events.iter().filter(|e| matches!(e, Event::Scan(_))).count(), scans.len());
    }
    if let Some((first, last)) = trace.time_span_ns() {
        assert!(first <= last);
    }
    let w = &trace.waypoints;
    let bounds = |f: fn(&waymark_survey::io::ilc::Waypoint) -> f64| {
        w.iter().map(f).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)))
    };
    let ((x0, x1), (y0, y1)) = (bounds(|p| p.x), bounds(|p| p.y));
    // Coordinates this large overflow when interpolated; a floor is not that big.
    let modest = [x0, x1, y0, y1].iter().all(|v| v.abs() < 1e300);
    let probes = w.iter().take(64).flat_map(|p| [p.timestamp_ns, p.timestamp_ns.saturating_add(1)]);
    for t in probes.chain([0, u64::MAX]) {
        match trace.position_at(t) {
            Some((x, y)) if modest => {
                let slack = 1e-9 * (1.0 + x0.abs().max(x1.abs()).max(y0.abs()).max(y1.abs()));
                assert!(
                    x >= x0 - slack && x <= x1 + slack && y >= y0 - slack && y <= y1 + slack,
                    "({x}, {y})"
                );
            }
            Some(_) => {}
            None => assert!(w.is_empty() || t < w[0].timestamp_ns || t > w[w.len() - 1].timestamp_ns),
        }
    }
    let length = trace.path_length_m();
    assert!(length >= 0.0 && !length.is_nan(), "path length {length}");
}
