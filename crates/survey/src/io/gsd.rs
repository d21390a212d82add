//! The GetSensorData logfile format of the IPIN competitions' smartphone tracks: one walk per
//! text file, `;`-separated `TYPE;AppTimestamp(s);...` lines after a `%` header that names the
//! phone and describes every line type.
//!
//! Clocks: `AppTimestamp` is when the app read a value, seconds from the file's start, one
//! clock for every stream. Sensors also carry `SensorTimestamp`, the sensor's own clock, which
//! the header advises for integrating inertial data: each stream with one is mapped onto the
//! app clock by a constant offset, the least `AppTimestamp − SensorTimestamp` of the stream (a
//! value is read after it is measured, so the least delay is the one closest to none). Beacons
//! and ground truth have the app clock only.
//!
//! What becomes what:
//! - `ACCE`, `GYRO`, `MAGN` → the inertial streams (`MAGN` may carry an empty field between X
//!   and Y, as its header line shows); `PRES` → [`Trace::pressure`].
//! - `WIFI` lines read in one callback (one `AppTimestamp`) are one scan, as the phone reported
//!   it; the scan's time is its newest reading, and each reading's age is how much older than
//!   that its own `SensorTimestamp` is.
//! - `BLE4` iBeacon lines → beacon readings, by UUID, major and minor; Eddystone lines by
//!   address. They ride on the next WiFi scan as in the competition walks ([`Trace::scans`]).
//! - `POSI` → [`GeoFix`]es: WGS84 ground truth with a floor number, placed in a site frame by
//!   [`GsdWalk::trace`].
//! - Every other type (`AHRS`, `GNSS`, `LIGH`, `SOUN`...) is counted as ignored; malformed
//!   lines are counted as malformed, never fatal.

use super::ilc::{sort_by_time, PressureSample, ReadStats, Trace, TraceError, Waypoint};
use std::collections::BTreeMap;
use std::path::Path;
use waymark_engine::radio::{Reading, Scan, TransmitterId};
use waymark_engine::sensors::SensorSample;
use waymark_engine::site::{Anchor, LatLon};

const NS_PER_S: f64 = 1e9;

/// The first line the GetSensorData app writes.
pub const GSD_HEADER: &str = "% LogFile created by the 'GetSensorData' App";

/// A ground-truth point: where the walker was at a time, in WGS84, and on which floor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GeoFix {
    /// Time, ns, on the walk's clock.
    pub timestamp_ns: u64,
    /// Where.
    pub position: LatLon,
    /// The floor number the file gives (0 ground, negative below).
    pub level: i32,
}

/// One GetSensorData walk: everything but the ground truth as a [`Trace`], the truth as fixes.
#[derive(Clone, Debug, Default)]
pub struct GsdWalk {
    /// The walk without waypoints; [`GsdWalk::trace`] adds them in a site frame.
    pub trace: Trace,
    /// `POSI` lines, in time order.
    pub fixes: Vec<GeoFix>,
    /// The phone model from the header (`% Model:`).
    pub model: Option<String>,
}

/// Whether `text` is a GetSensorData logfile: its header says so, or its first data line is
/// of one of the format's sensor types.
pub fn is_gsd(text: &str) -> bool {
    let mut lines = text.lines().map(str::trim).filter(|l| !l.is_empty());
    match lines.next() {
        Some(first) if first.starts_with(GSD_HEADER) => true,
        Some(first) if first.starts_with('%') => {
            lines.find(|l| !l.starts_with('%')).is_some_and(|l| l.split(';').count() > 2 && is_type(l))
        }
        Some(first) => first.split(';').count() > 2 && is_type(first),
        None => false,
    }
}

fn is_type(line: &str) -> bool {
    matches!(
        line.split(';').next(),
        Some("ACCE" | "GYRO" | "MAGN" | "PRES" | "WIFI" | "BLE4" | "POSI" | "AHRS" | "GNSS")
    )
}

/// Readings with their sensor times, s.
type SensorTimed = Vec<(f64, Reading)>;

/// A value on a sensor's clock, before it is mapped onto the app clock.
struct Timed<T> {
    app_s: f64,
    sensor_s: f64,
    value: T,
}

/// A stream's values mapped onto the app clock by its least app − sensor delay, seconds.
fn on_app_clock<T>(stream: Vec<Timed<T>>) -> Vec<(f64, T)> {
    let offset = stream.iter().map(|t| t.app_s - t.sensor_s).fold(f64::INFINITY, f64::min);
    stream.into_iter().map(|t| (t.sensor_s + offset, t.value)).collect()
}

impl GsdWalk {
    /// Reads a logfile.
    pub fn read(path: &Path) -> Result<GsdWalk, TraceError> {
        let bytes = std::fs::read(path)
            .map_err(|source| TraceError::Io { path: path.display().to_string(), source })?;
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        Ok(GsdWalk::parse(&String::from_utf8_lossy(&bytes), &name))
    }

    /// Parses a logfile's text. Never fails: what cannot be used is counted in the trace's
    /// [`ReadStats`].
    pub fn parse(text: &str, name: &str) -> GsdWalk {
        let mut stats = ReadStats::default();
        let mut model = None;
        let mut manufacturer = None;
        let mut inertial: [Vec<Timed<[f64; 3]>>; 3] = [Vec::new(), Vec::new(), Vec::new()];
        let mut pressure: Vec<Timed<f64>> = Vec::new();
        // Per callback (its AppTimestamp, as text): the readings with their sensor times.
        let mut wifi: Vec<(String, SensorTimed)> = Vec::new();
        let mut wifi_delays: Vec<Timed<()>> = Vec::new();
        let mut beacons: Vec<(f64, Reading)> = Vec::new();
        let mut fixes: Vec<(f64, LatLon, i32)> = Vec::new();
        for line in text.lines() {
            let line = line.trim_end_matches('\r');
            if line.trim().is_empty() {
                continue;
            }
            if let Some(header) = line.strip_prefix('%') {
                if let Some((key, value)) = header.split_once(':') {
                    match key.trim() {
                        "Model" => model = Some(value.trim().to_owned()),
                        "Manufacturer" => manufacturer = Some(value.trim().to_owned()),
                        _ => {}
                    }
                }
                continue;
            }
            stats.lines += 1;
            let fields: Vec<&str> = line.split(';').map(str::trim).collect();
            let number =
                |i: usize| fields.get(i).and_then(|f| f.parse::<f64>().ok()).filter(|v| v.is_finite());
            let Some(app_s) = number(1).filter(|t| *t >= 0.0) else {
                stats.malformed += 1;
                continue;
            };
            let ok = match fields[0] {
                kind @ ("ACCE" | "GYRO" | "MAGN") => (|| {
                    let sensor_s = number(2)?;
                    // Numbers after the sensor time, empty fields skipped (MAGN's X;;Y).
                    let values: Vec<f64> = fields[3..]
                        .iter()
                        .filter(|f| !f.is_empty())
                        .take(3)
                        .map(|f| f.parse::<f64>().ok().filter(|v| v.is_finite()))
                        .collect::<Option<_>>()?;
                    let value: [f64; 3] = values.try_into().ok()?;
                    let stream = match kind {
                        "ACCE" => 0,
                        "GYRO" => 1,
                        _ => 2,
                    };
                    inertial[stream].push(Timed { app_s, sensor_s, value });
                    Some(())
                })(),
                "PRES" => (|| {
                    pressure.push(Timed {
                        app_s,
                        sensor_s: number(2)?,
                        value: number(3).filter(|p| *p > 0.0)?,
                    });
                    Some(())
                })(),
                "WIFI" => (|| {
                    let sensor_s = number(2)?;
                    // SSID;BSSID;frequency;RSS, counted from the end: an SSID may hold a `;`.
                    let n = fields.len();
                    if n < 7 {
                        return None;
                    }
                    let (bssid, rssi) = if fields[n - 1].is_empty() {
                        (fields.get(n - 4)?, fields.get(n - 2)?)
                    } else {
                        (fields.get(n - 3)?, fields.get(n - 1)?)
                    };
                    let transmitter = TransmitterId::wifi(bssid).ok()?;
                    let rssi_dbm = rssi.parse::<f64>().ok().filter(|r| r.is_finite())?;
                    let reading = Reading { transmitter, rssi_dbm, age_ns: 0 };
                    match wifi.last_mut() {
                        Some((key, readings)) if key == fields[1] => readings.push((sensor_s, reading)),
                        _ => wifi.push((fields[1].to_owned(), vec![(sensor_s, reading)])),
                    }
                    wifi_delays.push(Timed { app_s, sensor_s, value: () });
                    Some(())
                })(),
                "BLE4" => (|| {
                    // iBeacon;MAC;RSSI;Power;Major;Minor;UUID, or Eddystone;MAC;RSSI;...
                    let mac = fields.get(3)?;
                    let rssi_dbm = number(4)?;
                    let transmitter = match *fields.get(2)? {
                        "iBeacon" => {
                            let major = fields.get(6)?.parse::<u16>().ok()?;
                            let minor = fields.get(7)?.parse::<u16>().ok()?;
                            TransmitterId::ble(fields.get(8)?, major, minor).ok()?
                        }
                        _ => TransmitterId::ble_address(mac).ok()?,
                    };
                    beacons.push((app_s, Reading { transmitter, rssi_dbm, age_ns: 0 }));
                    Some(())
                })(),
                "POSI" => (|| {
                    let position = LatLon::new(number(3)?, number(4)?).ok()?;
                    let level = fields.get(5)?.parse::<i32>().ok()?;
                    fixes.push((app_s, position, level));
                    Some(())
                })(),
                _ => {
                    stats.ignored += 1;
                    Some(())
                }
            };
            if ok.is_none() {
                stats.malformed += 1;
            }
        }

        // Every time on the app clock, s, then shifted so that none is before 0.
        let [acce, gyro, magn] = inertial.map(on_app_clock);
        let pressure = on_app_clock(pressure);
        let wifi_offset = wifi_delays.iter().map(|t| t.app_s - t.sensor_s).fold(f64::INFINITY, f64::min);
        let scans: Vec<(f64, SensorTimed)> = wifi
            .into_iter()
            .map(|(_, readings)| {
                let readings: SensorTimed =
                    readings.into_iter().map(|(sensor_s, r)| (sensor_s + wifi_offset, r)).collect();
                let newest = readings.iter().map(|r| r.0).fold(f64::NEG_INFINITY, f64::max);
                (newest, readings)
            })
            .collect();
        let earliest = [acce.first(), gyro.first(), magn.first()]
            .into_iter()
            .flatten()
            .map(|s| s.0)
            .chain(pressure.first().map(|p| p.0))
            .chain(scans.iter().flat_map(|s| s.1.iter().map(|r| r.0)))
            .fold(0.0, f64::min);
        let ns = |t: f64| ((t - earliest) * NS_PER_S).round() as u64;
        let samples = |stream: Vec<(f64, [f64; 3])>| -> Vec<SensorSample> {
            stream.into_iter().map(|(t, [x, y, z])| SensorSample { timestamp_ns: ns(t), x, y, z }).collect()
        };
        let mut trace = Trace {
            name: name.to_owned(),
            device: match (&manufacturer, &model) {
                (None, None) => None,
                (m, n) => Some(format!("{} {}", m.as_deref().unwrap_or(""), n.as_deref().unwrap_or("")))
                    .map(|d| d.trim().to_owned()),
            },
            accelerometer: samples(acce),
            gyroscope: samples(gyro),
            magnetometer: samples(magn),
            pressure: pressure
                .into_iter()
                .map(|(t, hpa)| PressureSample { timestamp_ns: ns(t), hpa })
                .collect(),
            beacons: beacons.into_iter().map(|(t, r)| (ns(t), r)).collect(),
            ..Trace::default()
        };
        let mut by_time: BTreeMap<u64, Vec<Reading>> = BTreeMap::new();
        for (newest, readings) in scans {
            let at = ns(newest);
            let entry = by_time.entry(at).or_default();
            entry
                .extend(readings.into_iter().map(|(t, r)| Reading { age_ns: at.saturating_sub(ns(t)), ..r }));
        }
        trace.wifi_scans =
            by_time.into_iter().map(|(timestamp_ns, readings)| Scan { timestamp_ns, readings }).collect();
        for stream in [&mut trace.accelerometer, &mut trace.gyroscope, &mut trace.magnetometer] {
            stats.out_of_order += sort_by_time(stream, |s| s.timestamp_ns);
        }
        stats.out_of_order += sort_by_time(&mut trace.pressure, |p| p.timestamp_ns);
        stats.out_of_order += sort_by_time(&mut trace.beacons, |b| b.0);
        let mut fixes: Vec<GeoFix> = fixes
            .into_iter()
            .map(|(t, position, level)| GeoFix { timestamp_ns: ns(t), position, level })
            .collect();
        stats.out_of_order += sort_by_time(&mut fixes, |f| f.timestamp_ns);
        trace.stats = stats;
        GsdWalk { trace, fixes, model }
    }

    /// The walk with its fixes as waypoints in the site frame of `anchor`, each with the
    /// index of its level in `levels` (the building's floors' levels in site order; a level
    /// not there gets `levels.len()`: no floor of the site).
    pub fn trace(&self, anchor: &Anchor, levels: &[Option<i32>]) -> Trace {
        let waypoints = self
            .fixes
            .iter()
            .map(|f| {
                let [x, y] = anchor.to_site(f.position);
                let floor = levels.iter().position(|&l| l == Some(f.level)).unwrap_or(levels.len());
                Waypoint { timestamp_ns: f.timestamp_ns, x, y, floor: Some(floor) }
            })
            .collect();
        Trace { waypoints, ..self.trace.clone() }
    }

    /// The floor levels the walk's fixes visit, in the order it visits them, each once per
    /// stay: `[0, -1, 0]` for a walk down a floor and back.
    pub fn level_runs(&self) -> Vec<(i32, u64, u64)> {
        let mut runs: Vec<(i32, u64, u64)> = Vec::new();
        for f in &self.fixes {
            match runs.last_mut() {
                Some(run) if run.0 == f.level => run.2 = f.timestamp_ns,
                _ => runs.push((f.level, f.timestamp_ns, f.timestamp_ns)),
            }
        }
        runs
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const WALK: &str = "% LogFile created by the 'GetSensorData' App for Android.\n\
% Phone used for this logfile:\n\
% Manufacturer:            \tsamsung\n\
% Model:                   \tSM-A520F\n\
% Magnetometer data:  \t'MAGN;AppTimestamp(s);SensorTimestamp(s);Mag_X(uT);;Mag_Y(uT);Mag_Z(uT);Accuracy(integer)'\n\
%\n\
MAGN;0.0527;100.0400;-2.1;;-34.1;-45.4;0\n\
ACCE;0.0542;100.0500;-1.0;8.2;6.2;3\n\
GYRO;0.0536;100.0450;-0.7;-0.5;0.09;3\n\
ACCE;0.0700;100.0600;-1.1;8.3;NaN;3\n\
ACCE;0.0800;100.0700;-1.2;8.4;6.4;3\n\
PRES;0.1198;100.1000;976.2273;3\n\
WIFI;0.651;100.6000;SSID2023_0001;20:23:00:00:00:01;2437;-60\n\
WIFI;0.651;100.6001;SSID;2023;20:23:00:00:00:15;2452;-63\n\
WIFI;0.651;98.0000;old;20:23:00:00:00:45;2412;-90\n\
BLE4;2.8313;iBeacon;BE:AC:20:23:00:01;-90;0;1;2;11111111-1111-BEAC-2023-111111111111\n\
AHRS;0.0547;100.0501;49.9;11.5;-16.5;0.42;0.03;-0.08;3\n\
WIFI;4.9166;104.9000;SSID2023_0008;20:23:00:00:00:15;2452;-62\n\
POSI;61.4235;1;49.461316433032;11.110964442580;0;100\n\
POSI;68.0502;2;49.461275602490;11.110988346746;-1;100\n\
POSI;bad;3;49.4;11.1;0;100\n\
garbage\n";

    #[test]
    fn reads_streams_clocks_scans_beacons_and_truth() {
        assert!(is_gsd(WALK));
        assert!(!is_gsd("1000\tTYPE_WAYPOINT\t1\t2\n"));
        let walk = GsdWalk::parse(WALK, "walk");
        let t = &walk.trace;
        assert_eq!(walk.model.as_deref(), Some("SM-A520F"));
        assert_eq!(t.device.as_deref(), Some("samsung SM-A520F"));
        assert_eq!(t.magnetometer.len(), 1, "the empty field between X and Y is skipped");
        assert_eq!(t.magnetometer[0].y, -34.1);
        assert_eq!(t.accelerometer.len(), 2, "the NaN sample is dropped");
        // Accelerometer offset: least app − sensor is 0.0542 − 100.05 at the first sample;
        // the second sample is then 20 ms later on the sensor clock, whatever the app says.
        let dt = t.accelerometer[1].timestamp_ns - t.accelerometer[0].timestamp_ns;
        assert!((dt as f64 - 20e6).abs() < 1e3, "{dt}");
        assert_eq!(t.pressure.len(), 1);
        assert_eq!(t.pressure[0].hpa, 976.2273);
        assert_eq!(t.wifi_scans.len(), 2, "one scan per callback");
        let scan = &t.wifi_scans[0];
        assert_eq!(scan.readings.len(), 3, "an SSID with a `;` still reads");
        assert!(
            matches!(&scan.readings[1].transmitter, TransmitterId::Wifi { bssid } if bssid == "20:23:00:00:00:15")
        );
        assert_eq!(scan.readings[1].age_ns, 0, "the newest reading sets the scan's time");
        assert!((scan.readings[2].age_ns as f64 - 2.6001e9).abs() < 1e3, "a cached entry is old");
        assert_eq!(t.beacons.len(), 1);
        assert!(matches!(t.beacons[0].1.transmitter, TransmitterId::Ble { major: 1, minor: 2, .. }));
        assert_eq!(walk.fixes.len(), 2);
        assert_eq!(walk.fixes[1].level, -1);
        assert_eq!(t.stats.ignored, 1, "AHRS");
        assert_eq!(t.stats.malformed, 3, "the NaN sample, the bad POSI and the garbage line");
        assert_eq!(walk.level_runs().iter().map(|r| r.0).collect::<Vec<_>>(), [0, -1]);
    }

    #[test]
    fn fixes_become_waypoints_in_the_anchor_frame_with_their_floor() {
        let walk = GsdWalk::parse(WALK, "walk");
        let anchor = Anchor::at(walk.fixes[0].position);
        let trace = walk.trace(&anchor, &[Some(-2), Some(0)]);
        assert_eq!(trace.waypoints.len(), 2);
        let (a, b) = (trace.waypoints[0], trace.waypoints[1]);
        assert!(a.x.abs() < 1e-6 && a.y.abs() < 1e-6);
        // 4.08e-5° of latitude south (4.54 m) and 2.39e-5° of longitude east at 49.46° N (1.73 m).
        assert!((b.y + 4.54).abs() < 0.02 && (b.x - 1.73).abs() < 0.02, "{b:?}");
        assert_eq!(a.floor, Some(1));
        assert_eq!(b.floor, Some(2), "a level the building's floors lack is past them");
        assert_eq!(trace.floor_at(a.timestamp_ns + 1), Some(1));
        assert_eq!(trace.floor_at(b.timestamp_ns - 1), Some(2));
    }

    #[test]
    fn empty_and_garbage_text_read_as_an_empty_walk() {
        for text in ["", "%\n", "\u{0};;\nPOSI\nWIFI;1;2\nACCE;-1;0;1;2;3\n"] {
            let walk = GsdWalk::parse(text, "x");
            assert!(walk.fixes.is_empty() && walk.trace.wifi_scans.is_empty());
            assert!(walk.trace.accelerometer.is_empty());
        }
    }
}
