//! The Indoor Location Competition 2.0 walk format: one walk per text file, tab-separated
//! `unix_ms TYPE values...` lines, `#` header lines (site, floor, phone, sensors).
//!
//! Quirks handled here rather than downstream:
//! - Lines are not in time order: every stream is sorted (stably) after reading.
//! - All `TYPE_WIFI` lines with one timestamp are one scan; each entry's last-seen time may be
//!   tens of seconds older than the scan (Android re-reports cached access points), kept as the
//!   reading's `age_ns`.
//! - `TYPE_BEACON` lines arrive one by one; they are folded into the next WiFi scan (as an app
//!   collecting ranging callbacks would), with their age, or form a beacon-only scan when no WiFi
//!   scan follows within [`EventOptions::beacon_wait_ns`].
//! - Beacons left at major = minor = 0 (unconfigured; most of this data set's beacons) cannot
//!   be told apart by iBeacon identity, so they are identified by their MAC address.
//! - Unknown line types, malformed numbers and non-finite values are skipped and counted in
//!   [`ReadStats`], never fatal: a walk with one waypoint, or none, still reads.
//!
//! A walk the SDK's survey recorder wrote (`waymark_engine::recorder`) says so in its header
//! ([`RECORDER_HEADER`]): its times are ns rather than ms, and the WiFi and beacon lines at one
//! time are one scan as the app pushed it, each reading with its own last-seen time, so nothing
//! is folded or rounded.

use std::collections::BTreeMap;
use std::path::Path;
use waymark_engine::radio::{Reading, Scan, TransmitterId};
use waymark_engine::recorder::RECORDER_HEADER;
pub use waymark_engine::sensors::PressureSample;
use waymark_engine::sensors::SensorSample;

const NS_PER_MS: u64 = 1_000_000;

/// A ground-truth position labelled by the surveyor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Waypoint {
    /// Time, ns since the Unix epoch.
    pub timestamp_ns: u64,
    /// East, m, in the floor's frame.
    pub x: f64,
    /// North, m, in the floor's frame.
    pub y: f64,
    /// The floor the walker was on, as an index into the building's floors, where the walk's
    /// format says (GetSensorData's `POSI` lines, [`super::gsd`]); `None`: the floor the walk
    /// was filed under. An index past the site's floors is a level no survey walk reached.
    pub floor: Option<usize>,
}

/// What reading a walk skipped, by reason.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReadStats {
    /// Data lines read.
    pub lines: usize,
    /// Lines of a type Waymark does not use (`TYPE_ROTATION_VECTOR`, `TYPE_BLUE`, ...).
    pub ignored: usize,
    /// Lines of a known type with a missing, malformed or non-finite field.
    pub malformed: usize,
    /// Lines not in time order within their stream (sorted, not dropped).
    pub out_of_order: usize,
    /// WiFi entries whose last-seen time is more than 2 s before their scan.
    pub cached_wifi: usize,
}

/// One recorded walk.
#[derive(Clone, Debug, Default)]
pub struct Trace {
    /// The file's stem.
    pub name: String,
    /// `SiteID` from the header.
    pub site_id: Option<String>,
    /// `FloorName` from the header.
    pub floor_name: Option<String>,
    /// `Brand Model` from the header.
    pub device: Option<String>,
    /// Ground truth, in time order.
    pub waypoints: Vec<Waypoint>,
    /// m/s², gravity included, in time order.
    pub accelerometer: Vec<SensorSample>,
    /// rad/s, in time order.
    pub gyroscope: Vec<SensorSample>,
    /// µT, in time order.
    pub magnetometer: Vec<SensorSample>,
    /// WiFi scans, in time order; readings carry their age. In a recorder's walk
    /// ([`Trace::grouped_scans`]), the scans as pushed, beacons included.
    pub wifi_scans: Vec<Scan>,
    /// Beacon readings with the time each was heard, in time order (none in a recorder's walk).
    pub beacons: Vec<(u64, Reading)>,
    /// Written by the SDK's survey recorder: scans are whole as pushed, not folded.
    pub grouped_scans: bool,
    /// Barometer readings, hPa, in time order (GetSensorData's `PRES`; none in the Indoor
    /// Location Competition's walks).
    pub pressure: Vec<PressureSample>,
    /// What was skipped.
    pub stats: ReadStats,
}

/// Why a walk could not be read at all.
#[derive(Debug, thiserror::Error)]
pub enum TraceError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: String,
        /// Why.
        source: std::io::Error,
    },
}

/// One call an app makes, in the order it makes them.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// A batch of accelerometer samples.
    Accelerometer(Vec<SensorSample>),
    /// A batch of gyroscope samples.
    Gyroscope(Vec<SensorSample>),
    /// A batch of magnetometer samples.
    Magnetometer(Vec<SensorSample>),
    /// A batch of barometer readings.
    Pressure(Vec<PressureSample>),
    /// A WiFi and/or beacon scan.
    Scan(Scan),
}

impl Event {
    /// The time the app would make the call: the batch's last sample, or the scan.
    pub fn timestamp_ns(&self) -> u64 {
        match self {
            Event::Accelerometer(b) | Event::Gyroscope(b) | Event::Magnetometer(b) => {
                b.last().map_or(0, |s| s.timestamp_ns)
            }
            Event::Pressure(b) => b.last().map_or(0, |s| s.timestamp_ns),
            Event::Scan(s) => s.timestamp_ns,
        }
    }
}

/// How [`Trace::events`] batches sensors and beacons.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EventOptions {
    /// Sensor batch length, ns: how a replay imitates an app, not a model parameter. 200 ms,
    /// the order of Android `SensorManager`'s batching latency; the tracker buffers samples
    /// and processes them only up to each epoch, so any length works as long as the batches
    /// before a scan are pushed before it (which [`Trace::events`] guarantees).
    pub batch_ns: u64,
    /// How long beacon readings wait for a WiFi scan to ride on before they form a scan of
    /// their own, ns. 4 s: longer than nearly every gap between a walk's WiFi scans
    /// (`scan_interval_p99_s`), so a beacon rides on the next scan unless scans have stopped;
    /// a shorter wait leaves late scans' beacons to make lone-beacon epochs, which leave the
    /// floor to chance (`docs/tuning.md#beacon-wait`).
    pub beacon_wait_ns: u64,
    /// Whether beacon readings are used at all.
    pub beacons: bool,
    /// Whether WiFi scans are used at all.
    pub wifi: bool,
}

impl Default for EventOptions {
    fn default() -> Self {
        Self { batch_ns: 200 * NS_PER_MS, beacon_wait_ns: 4_000 * NS_PER_MS, beacons: true, wifi: true }
    }
}

/// `samples` in batches of `batch_ns` from each batch's first sample, none straddling a time
/// of `scan_times` (the app pushed its samples up to a scan before the scan).
fn batches<'a, T: Clone>(
    samples: &'a [T],
    time: impl Fn(&T) -> u64 + 'a,
    scan_times: &'a [u64],
    batch_ns: u64,
) -> impl Iterator<Item = Vec<T>> + 'a {
    let mut start = 0;
    std::iter::from_fn(move || {
        let first = time(samples.get(start)?);
        let mut end_ns = first.saturating_add(batch_ns);
        if let Some(&t) = scan_times.get(scan_times.partition_point(|&t| t < first)) {
            end_ns = end_ns.min(t.saturating_add(1));
        }
        // At least one sample per batch: with `batch_ns` 0 none is before `end_ns`.
        let end = start + samples[start..].partition_point(|s| time(s) < end_ns).max(1);
        let batch = samples[start..end].to_vec();
        start = end;
        Some(batch)
    })
}

impl Trace {
    /// Reads a walk from `path`.
    pub fn read(path: &Path) -> Result<Trace, TraceError> {
        let bytes = std::fs::read(path)
            .map_err(|source| TraceError::Io { path: path.display().to_string(), source })?;
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        Ok(Trace::parse(&String::from_utf8_lossy(&bytes), &name))
    }

    /// Parses a walk's text. Never fails: what cannot be used is counted in [`Trace::stats`].
    pub fn parse(text: &str, name: &str) -> Trace {
        let mut trace = Trace { name: name.to_owned(), ..Trace::default() };
        let mut wifi: BTreeMap<u64, Vec<Reading>> = BTreeMap::new();
        let mut stats = ReadStats::default();
        // ns per unit of the file's times: ms, or ns in a recorder's walk (its header comes
        // before its data).
        let mut unit_ns = NS_PER_MS;
        for line in text.lines() {
            let line = line.trim_end_matches('\r');
            if line.is_empty() {
                continue;
            }
            if let Some(header) = line.strip_prefix('#') {
                trace.read_header(header);
                if trace.grouped_scans {
                    unit_ns = 1;
                }
                continue;
            }
            stats.lines += 1;
            let fields: Vec<&str> = line.split('\t').collect();
            let Some(time_ms) = fields.first().and_then(|t| t.trim().parse::<u64>().ok()) else {
                stats.malformed += 1;
                continue;
            };
            let t = time_ms.saturating_mul(unit_ns);
            let kind = fields.get(1).copied().unwrap_or("");
            let values = &fields[fields.len().min(2)..];
            let ok = match kind {
                "TYPE_WAYPOINT" => numbers::<2>(values)
                    .map(|[x, y]| trace.waypoints.push(Waypoint { timestamp_ns: t, x, y, floor: None })),
                "TYPE_ACCELEROMETER" => push_sample(&mut trace.accelerometer, t, values),
                "TYPE_GYROSCOPE" => push_sample(&mut trace.gyroscope, t, values),
                "TYPE_MAGNETIC_FIELD" => push_sample(&mut trace.magnetometer, t, values),
                "TYPE_WIFI" => {
                    wifi_reading(t, unit_ns, values, &mut stats).map(|r| wifi.entry(t).or_default().push(r))
                }
                "TYPE_BEACON" if trace.grouped_scans => {
                    beacon_reading(t, unit_ns, values).map(|r| wifi.entry(t).or_default().push(r))
                }
                "TYPE_BEACON" => beacon_reading(t, 0, values).map(|r| trace.beacons.push((t, r))),
                _ => {
                    stats.ignored += 1;
                    Some(())
                }
            };
            if ok.is_none() {
                stats.malformed += 1;
            }
        }
        stats.out_of_order += sort_by_time(&mut trace.waypoints, |w| w.timestamp_ns);
        for stream in [&mut trace.accelerometer, &mut trace.gyroscope, &mut trace.magnetometer] {
            stats.out_of_order += sort_by_time(stream, |s| s.timestamp_ns);
        }
        stats.out_of_order += sort_by_time(&mut trace.beacons, |b| b.0);
        trace.wifi_scans =
            wifi.into_iter().map(|(timestamp_ns, readings)| Scan { timestamp_ns, readings }).collect();
        trace.stats = stats;
        trace
    }

    fn read_header(&mut self, header: &str) {
        if header.trim_start_matches('\t').starts_with(RECORDER_HEADER) {
            self.grouped_scans = true;
        }
        let mut brand = None;
        let mut model = None;
        for field in header.split('\t') {
            let Some((key, value)) = field.split_once(':') else { continue };
            let value = value.trim().to_owned();
            match key.trim() {
                "SiteID" => self.site_id = Some(value),
                "FloorName" => self.floor_name = Some(value),
                "Brand" => brand = Some(value),
                "Model" => model = Some(value),
                _ => {}
            }
        }
        if brand.is_some() || model.is_some() {
            self.device = Some(format!("{} {}", brand.unwrap_or_default(), model.unwrap_or_default()));
        }
    }

    /// First and last time with any data, ns.
    pub fn time_span_ns(&self) -> Option<(u64, u64)> {
        let firsts = [
            self.accelerometer.first().map(|s| s.timestamp_ns),
            self.wifi_scans.first().map(|s| s.timestamp_ns),
            self.beacons.first().map(|b| b.0),
            self.waypoints.first().map(|w| w.timestamp_ns),
        ];
        let lasts = [
            self.accelerometer.last().map(|s| s.timestamp_ns),
            self.wifi_scans.last().map(|s| s.timestamp_ns),
            self.beacons.last().map(|b| b.0),
            self.waypoints.last().map(|w| w.timestamp_ns),
        ];
        Some((firsts.into_iter().flatten().min()?, lasts.into_iter().flatten().max()?))
    }

    /// Ground truth at `timestamp_ns`, linear between waypoints; `None` outside the first and
    /// last waypoint (the surveyor's path there is unknown).
    pub fn position_at(&self, timestamp_ns: u64) -> Option<(f64, f64)> {
        let w = &self.waypoints;
        let k = w.partition_point(|p| p.timestamp_ns <= timestamp_ns);
        match (k.checked_sub(1).map(|i| &w[i]), w.get(k)) {
            (Some(a), _) if a.timestamp_ns == timestamp_ns => Some((a.x, a.y)),
            (Some(a), Some(b)) => {
                let f = (timestamp_ns - a.timestamp_ns) as f64 / (b.timestamp_ns - a.timestamp_ns) as f64;
                Some((a.x + f * (b.x - a.x), a.y + f * (b.y - a.y)))
            }
            _ => None,
        }
    }

    /// The floor index the walk's truth gives at `timestamp_ns` ([`Waypoint::floor`]): that of
    /// the waypoint nearer in time, within the waypoints' span; `None` outside it or where the
    /// format gives no floor.
    pub fn floor_at(&self, timestamp_ns: u64) -> Option<usize> {
        let w = &self.waypoints;
        let k = w.partition_point(|p| p.timestamp_ns <= timestamp_ns);
        match (k.checked_sub(1).map(|i| &w[i]), w.get(k)) {
            (Some(a), _) if a.timestamp_ns == timestamp_ns => a.floor,
            (Some(a), Some(b)) => {
                if timestamp_ns - a.timestamp_ns <= b.timestamp_ns - timestamp_ns {
                    a.floor
                } else {
                    b.floor
                }
            }
            _ => None,
        }
    }

    /// The part of the walk from `from_ns` to `to_ns` (both included): every stream and the
    /// waypoints cut to that span, the rest as it was.
    pub fn between(&self, from_ns: u64, to_ns: u64) -> Trace {
        fn cut<T: Clone>(items: &[T], time: impl Fn(&T) -> u64, from_ns: u64, to_ns: u64) -> Vec<T> {
            let start = items.partition_point(|i| time(i) < from_ns);
            let end = items.partition_point(|i| time(i) <= to_ns).max(start);
            items[start..end].to_vec()
        }
        let sample = |s: &SensorSample| s.timestamp_ns;
        Trace {
            waypoints: cut(&self.waypoints, |w| w.timestamp_ns, from_ns, to_ns),
            accelerometer: cut(&self.accelerometer, sample, from_ns, to_ns),
            gyroscope: cut(&self.gyroscope, sample, from_ns, to_ns),
            magnetometer: cut(&self.magnetometer, sample, from_ns, to_ns),
            wifi_scans: cut(&self.wifi_scans, |s| s.timestamp_ns, from_ns, to_ns),
            beacons: cut(&self.beacons, |b| b.0, from_ns, to_ns),
            pressure: cut(&self.pressure, |p| p.timestamp_ns, from_ns, to_ns),
            name: self.name.clone(),
            site_id: self.site_id.clone(),
            floor_name: self.floor_name.clone(),
            device: self.device.clone(),
            grouped_scans: self.grouped_scans,
            stats: self.stats,
        }
    }

    /// Length of the waypoint polyline, m.
    pub fn path_length_m(&self) -> f64 {
        self.waypoints.windows(2).map(|p| (p[1].x - p[0].x).hypot(p[1].y - p[0].y)).sum()
    }

    /// The walk as an app would feed it: sensor batches of [`EventOptions::batch_ns`], each
    /// scan after every batch that ends at or before it, beacons folded into scans.
    pub fn events(&self, options: &EventOptions) -> Vec<Event> {
        let mut events: Vec<Event> = Vec::new();
        type Make = fn(Vec<SensorSample>) -> Event;
        let streams: [(&[SensorSample], Make); 3] = [
            (&self.accelerometer, Event::Accelerometer),
            (&self.gyroscope, Event::Gyroscope),
            (&self.magnetometer, Event::Magnetometer),
        ];
        // A recorder's walk replays as the app pushed it: each stream's samples up to a scan
        // before the scan. Elsewhere a batch may straddle a scan, as an app's would.
        let scans = self.scans(options);
        let scan_times: Vec<u64> =
            if self.grouped_scans { scans.iter().map(|s| s.timestamp_ns).collect() } else { Vec::new() };
        for (samples, make) in streams {
            events.extend(batches(samples, |s| s.timestamp_ns, &scan_times, options.batch_ns).map(make));
        }
        events.extend(
            batches(&self.pressure, |s| s.timestamp_ns, &scan_times, options.batch_ns).map(Event::Pressure),
        );
        events.extend(scans.into_iter().map(Event::Scan));
        // Stable: at equal times sensors (pushed first) precede the scan.
        events.sort_by_key(Event::timestamp_ns);
        events
    }

    /// The radio epochs: WiFi scans with the beacons heard since the previous one, and
    /// beacon-only scans where no WiFi scan followed within the wait.
    pub fn scans(&self, options: &EventOptions) -> Vec<Scan> {
        if self.grouped_scans {
            return self.grouped(options);
        }
        let wifi: &[Scan] = if options.wifi { &self.wifi_scans } else { &[] };
        let beacons: &[(u64, Reading)] = if options.beacons { &self.beacons } else { &[] };
        let mut out = Vec::with_capacity(wifi.len());
        let mut pending: Vec<&(u64, Reading)> = Vec::new();
        let mut b = 0;
        let flush = |pending: &mut Vec<&(u64, Reading)>, at: u64, mut readings: Vec<Reading>| {
            readings.extend(pending.drain(..).map(|(t, r)| Reading { age_ns: at - t, ..r.clone() }));
            Scan { timestamp_ns: at, readings }
        };
        for scan in wifi {
            while b < beacons.len() && beacons[b].0 <= scan.timestamp_ns {
                if let Some(first) = pending.first() {
                    if beacons[b].0 > first.0.saturating_add(options.beacon_wait_ns) {
                        let at = pending.last().map_or(first.0, |p| p.0);
                        out.push(flush(&mut pending, at, Vec::new()));
                    }
                }
                pending.push(&beacons[b]);
                b += 1;
            }
            // Beacons that waited too long go out on their own, strictly before the WiFi scan.
            let stale =
                pending.partition_point(|p| p.0.saturating_add(options.beacon_wait_ns) < scan.timestamp_ns);
            if stale > 0 {
                let at = pending[stale - 1].0;
                let mut rest = pending.split_off(stale);
                out.push(flush(&mut pending, at, Vec::new()));
                pending.append(&mut rest);
            }
            out.push(flush(&mut pending, scan.timestamp_ns, scan.readings.clone()));
        }
        for beacon in &beacons[b..] {
            if pending.first().is_some_and(|p| beacon.0 > p.0.saturating_add(options.beacon_wait_ns)) {
                let at = pending.last().map_or(0, |p| p.0);
                out.push(flush(&mut pending, at, Vec::new()));
            }
            pending.push(beacon);
        }
        if let Some(last) = pending.last() {
            let at = last.0;
            out.push(flush(&mut pending, at, Vec::new()));
        }
        debug_assert!(out.windows(2).all(|w| w[0].timestamp_ns < w[1].timestamp_ns));
        out
    }
}

impl Trace {
    /// A recorder's scans as pushed, less the kinds of reading `options` leaves out.
    fn grouped(&self, options: &EventOptions) -> Vec<Scan> {
        let keep = |r: &Reading| if r.transmitter.is_ble() { options.beacons } else { options.wifi };
        self.wifi_scans
            .iter()
            .map(|s| Scan {
                timestamp_ns: s.timestamp_ns,
                readings: s.readings.iter().filter(|r| keep(r)).cloned().collect(),
            })
            .filter(|s| !s.readings.is_empty())
            .collect()
    }
}

/// Sorts `items` by `key` (stably) and returns how many were out of order.
pub(super) fn sort_by_time<T>(items: &mut [T], key: impl Fn(&T) -> u64) -> usize {
    let out_of_order = items.windows(2).filter(|w| key(&w[1]) < key(&w[0])).count();
    if out_of_order > 0 {
        items.sort_by_key(|i| key(i));
    }
    out_of_order
}

/// The first `N` fields as finite numbers.
fn numbers<const N: usize>(values: &[&str]) -> Option<[f64; N]> {
    let mut out = [0.0; N];
    for (o, v) in out.iter_mut().zip(values.get(..N)?) {
        *o = v.trim().parse::<f64>().ok().filter(|x| x.is_finite())?;
    }
    Some(out)
}

fn push_sample(stream: &mut Vec<SensorSample>, timestamp_ns: u64, values: &[&str]) -> Option<()> {
    let [x, y, z] = numbers::<3>(values)?;
    stream.push(SensorSample { timestamp_ns, x, y, z });
    Some(())
}

/// `ssid bssid rssi frequency last_seen`; the SSID may be empty or contain anything. Times are
/// in units of `unit_ns`.
fn wifi_reading(timestamp_ns: u64, unit_ns: u64, values: &[&str], stats: &mut ReadStats) -> Option<Reading> {
    // Count from the end: an SSID could in principle contain a tab.
    let n = values.len();
    if n < 4 {
        return None;
    }
    let (bssid, rssi, last_seen) = if n >= 5 {
        (values[n - 4], values[n - 3], Some(values[n - 1]))
    } else {
        (values[0], values[1], None)
    };
    let transmitter = TransmitterId::wifi(bssid).ok()?;
    let rssi_dbm = rssi.trim().parse::<f64>().ok().filter(|r| r.is_finite())?;
    let age_ns = match last_seen.and_then(|s| s.trim().parse::<u64>().ok()) {
        Some(seen) => timestamp_ns.saturating_sub(seen.saturating_mul(unit_ns)),
        None => 0,
    };
    if age_ns > 2_000 * NS_PER_MS {
        stats.cached_wifi += 1;
    }
    Some(Reading { transmitter, rssi_dbm, age_ns })
}

/// `uuid major minor tx_power rssi distance mac [last_seen]`. A beacon at major = minor = 0 is
/// known by its address, or by its UUID when it has none. With `unit_ns` > 0 (a recorder's
/// walk) the age is the line's time less the last-seen time; otherwise 0 (the line's time is
/// when the beacon was heard).
fn beacon_reading(timestamp_ns: u64, unit_ns: u64, values: &[&str]) -> Option<Reading> {
    let uuid = values.first()?;
    let major = values.get(1)?.trim().parse::<u16>().ok()?;
    let minor = values.get(2)?.trim().parse::<u16>().ok()?;
    let rssi_dbm = values.get(4)?.trim().parse::<f64>().ok().filter(|r| r.is_finite())?;
    let mac = values.get(6).map(|m| m.trim()).unwrap_or("");
    let transmitter = if major == 0 && minor == 0 && !(mac.is_empty() && unit_ns > 0) {
        TransmitterId::ble_address(mac).ok()?
    } else {
        TransmitterId::ble(uuid, major, minor).ok()?
    };
    let age_ns = match values.get(7).and_then(|s| s.trim().parse::<u64>().ok()) {
        Some(seen) if unit_ns > 0 => timestamp_ns.saturating_sub(seen.saturating_mul(unit_ns)),
        _ => 0,
    };
    Some(Reading { transmitter, rssi_dbm, age_ns })
}

#[cfg(test)]
mod tests {
    use super::*;

    const WALK: &str = "#\tstartTime:1000\n\
#\tSiteID:site\tSiteName:x\tFloorId:f\tFloorName:F1\n\
#\tBrand:OPPO\tModel:PBCM10\tAndroidName:8.1.0\n\
1000\tTYPE_WAYPOINT\t10.0\t20.0\n\
1000\tTYPE_ACCELEROMETER\t0.1\t0.2\t9.8\t3\n\
1020\tTYPE_ACCELEROMETER\t0.1\t0.2\tNaN\t3\n\
1010\tTYPE_ACCELEROMETER\t0.1\t0.3\t9.7\t3\n\
1030\tTYPE_GYROSCOPE\t0.1\t0.3\t0.7\n\
1025\tTYPE_GYROSCOPE\t0.1\t0.3\t0.7\n\
1500\tTYPE_WIFI\tnet\tAA:BB:CC:DD:EE:01\t-50\t2412\t1490\n\
1500\tTYPE_WIFI\t\tAA:BB:CC:DD:EE:02\t-70\t5180\t-1\n\
1500\tTYPE_WIFI\told\taa:bb:cc:dd:ee:03\t-80\t5180\t100\n\
1200\tTYPE_BEACON\tFDA50693-A4E2-4FB1-AFCF-C6EB07647825\t10073\t61418\t-59\t-80\t3.2\tE0:78:A3:3D:B5:D6\t1200\n\
1300\tTYPE_BEACON\t9195B3AD-A9D0-4500-85FF-9FB0F65A5201\t0\t0\t-56\t-93\t45.0\tE0:78:A3:3D:B5:D7\t1300\n\
1400\tTYPE_ROTATION_VECTOR\t0.1\t0.0\t0.2\t3\n\
bogus line\n\
3000\tTYPE_WIFI\tnet\tAA:BB:CC:DD:EE:01\t-55\t2412\t3000\n\
4000\tTYPE_WAYPOINT\t13.0\t24.0\n\
#\tendTime:4000\n";

    #[test]
    fn reads_headers_streams_and_quirks() {
        let t = Trace::parse(WALK, "walk");
        assert_eq!(t.floor_name.as_deref(), Some("F1"));
        assert_eq!(t.site_id.as_deref(), Some("site"));
        assert_eq!(t.device.as_deref(), Some("OPPO PBCM10"));
        assert_eq!(t.waypoints.len(), 2);
        assert_eq!(t.accelerometer.len(), 2, "the NaN sample is dropped");
        assert_eq!(t.accelerometer[0].timestamp_ns, 1000 * NS_PER_MS);
        assert_eq!(t.accelerometer[1].timestamp_ns, 1010 * NS_PER_MS);
        assert_eq!(t.gyroscope[0].timestamp_ns, 1025 * NS_PER_MS, "sorted");
        assert_eq!(t.stats.out_of_order, 1);
        assert_eq!(t.stats.malformed, 2, "the NaN sample and the bogus line");
        assert_eq!(t.stats.ignored, 1);
        assert_eq!(t.wifi_scans.len(), 2);
        let scan = &t.wifi_scans[0];
        assert_eq!(scan.readings.len(), 3);
        assert_eq!(scan.readings[0].age_ns, 10 * NS_PER_MS);
        assert_eq!(scan.readings[1].age_ns, 0, "a last-seen of -1 is no age information");
        assert_eq!(scan.readings[2].age_ns, 1400 * NS_PER_MS);
        assert_eq!(t.stats.cached_wifi, 0, "1.4 s is not yet cached");
        assert_eq!(t.beacons.len(), 2);
        assert!(matches!(t.beacons[0].1.transmitter, TransmitterId::Ble { major: 10073, .. }));
        assert!(matches!(t.beacons[1].1.transmitter, TransmitterId::BleAddress { .. }));
        assert!((t.path_length_m() - 5.0).abs() < 1e-12);
        assert_eq!(t.position_at(2500 * NS_PER_MS), Some((11.5, 22.0)));
        assert_eq!(t.position_at(500 * NS_PER_MS), None);
        assert_eq!(t.position_at(4000 * NS_PER_MS), Some((13.0, 24.0)));
    }

    #[test]
    fn beacons_ride_on_the_next_wifi_scan_and_events_are_in_time_order() {
        let t = Trace::parse(WALK, "walk");
        let scans = t.scans(&EventOptions::default());
        assert_eq!(scans.len(), 2);
        assert_eq!(scans[0].readings.len(), 5);
        assert_eq!(scans[0].readings[3].age_ns, 300 * NS_PER_MS);
        let wifi_only = t.scans(&EventOptions { beacons: false, ..EventOptions::default() });
        assert_eq!(wifi_only[0].readings.len(), 3);
        let beacons_only = t.scans(&EventOptions { wifi: false, ..EventOptions::default() });
        assert_eq!(beacons_only.len(), 1, "two beacons 100 ms apart make one scan");
        assert_eq!(beacons_only[0].timestamp_ns, 1300 * NS_PER_MS);
        let events = t.events(&EventOptions::default());
        assert!(events.windows(2).all(|w| w[0].timestamp_ns() <= w[1].timestamp_ns()));
        assert!(matches!(events[0], Event::Accelerometer(ref b) if b.len() == 2));
        assert_eq!(events.iter().filter(|e| matches!(e, Event::Scan(_))).count(), 2);
    }

    #[test]
    fn beacons_without_wifi_wait_at_most_the_window() {
        let mut text = String::new();
        for k in 0..10u64 {
            text += &format!(
                "{}\tTYPE_BEACON\tFDA50693-A4E2-4FB1-AFCF-C6EB07647825\t1\t{k}\t-59\t-80\t3.2\tE0:78:A3:3D:B5:D6\t0\n",
                1000 * k
            );
        }
        let t = Trace::parse(&text, "beacons");
        let options = EventOptions::default();
        let scans = t.scans(&options);
        // 9 s of beacons, none waiting longer than the window: at least 9 s / window scans.
        assert!(scans.len() as u64 >= 9_000 * NS_PER_MS / options.beacon_wait_ns);
        for s in &scans {
            assert!(s.readings.iter().all(|r| r.age_ns <= options.beacon_wait_ns));
        }
        assert_eq!(scans.iter().map(|s| s.readings.len()).sum::<usize>(), 10);
    }

    #[test]
    fn a_zero_batch_length_makes_one_sample_batches() {
        // Found by the `ilc_trace` fuzz harness: no batch ever ended, and `events` looped forever.
        let t = Trace::parse(WALK, "walk");
        let options = EventOptions { batch_ns: 0, ..EventOptions::default() };
        let events = t.events(&options);
        let batches = events.iter().filter(|e| !matches!(e, Event::Scan(_))).count();
        assert_eq!(batches, t.accelerometer.len() + t.gyroscope.len() + t.magnetometer.len());
    }

    #[test]
    fn beacon_waits_do_not_overflow_at_the_end_of_time() {
        // Found by the `ilc_trace` fuzz harness: the wait was added to the beacon's time unchecked, so
        // a timestamp near u64::MAX ns (or a wait of u64::MAX) overflowed.
        let beacon = |ms: &str| {
            format!("{ms}\tTYPE_BEACON\tFDA50693-A4E2-4FB1-AFCF-C6EB07647825\t1\t2\t-59\t-80\t3.2\tE0:78:A3:3D:B5:D6\t0\n")
        };
        // 18446744073709 ms is the last whole millisecond before u64::MAX ns.
        let text = beacon("1000")
            + &beacon("18446744073708")
            + &beacon("18446744073709")
            + "18446744073709\tTYPE_WIFI\tnet\tAA:BB:CC:DD:EE:01\t-50\t2412\t0\n";
        let t = Trace::parse(&text, "late");
        for options in
            [EventOptions::default(), EventOptions { beacon_wait_ns: u64::MAX, ..EventOptions::default() }]
        {
            let scans = t.scans(&options);
            assert_eq!(scans.iter().map(|s| s.readings.len()).sum::<usize>(), 4);
        }
        let long_wait = t.scans(&EventOptions { beacon_wait_ns: u64::MAX, ..EventOptions::default() });
        assert_eq!(long_wait.len(), 1, "every beacon waits for the one WiFi scan");
    }

    #[test]
    fn empty_and_garbage_text_reads_as_an_empty_walk() {
        let t = Trace::parse("", "empty");
        assert!(t.waypoints.is_empty() && t.wifi_scans.is_empty());
        assert_eq!(t.time_span_ns(), None);
        let t = Trace::parse("\u{0}\u{1}\n12\tTYPE_WIFI\n\tTYPE_WAYPOINT\t1\t2\n", "garbage");
        assert_eq!(t.stats.malformed, 3);
        assert!(t.events(&EventOptions::default()).is_empty());
    }
}
