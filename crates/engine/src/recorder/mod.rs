//! Recording a survey with the SDK. The surveyor's phone pushes the sensor batches and scans it
//! would push to an engine, and taps waypoints (where the surveyor stands on the floor plan, and
//! on which floor); the recorder writes them as Indoor Location Competition 2.0 walk files, one
//! per floor walked, in the folders `waymark survey` reads: `DIR/FLOOR/path_data_files/WALK-K.txt`
//! (docs/surveying.md).
//!
//! Nothing is lost: times are written in ns (`TimeUnit:ns` in the header, where the competition
//! writes ms), numbers in Rust's shortest form that reads back to the same `f64`, and each scan's
//! readings under the scan's time with their own last-seen times (`Scans:grouped`), so the file
//! reads back as the samples, scans and waypoints that were taken, in order. Inputs are checked
//! as an engine checks them: implausible or out-of-order samples are dropped and counted, a scan
//! an engine would reject is rejected.
//!
//! Nothing that returned is lost either: each call's whole lines reach the OS before it returns,
//! files are synced once a second, what comes before the first waypoint is spooled to disk, a
//! failed write is cut back to the last whole line, and an I/O error sticks until
//! [`SurveyRecorder::resume`] (docs/surveying.md#durability).

mod error;
mod options;
mod output;

pub use error::RecorderError;
pub use options::{RecorderOptions, RecordingStats};

use error::io_error;
use options::{check_header_text, check_name};
use output::{open_file, Opener, Output};

use crate::error::InputError;
use crate::radio::{check_readings, Scan, TransmitterId};
use crate::sensors::{refuse_ahead, BatchReport, MotionConfig, SensorSample, MAX_TIMESTAMP_NS};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// The header field that marks a file this recorder wrote, and what it changes for a reader:
/// times (and last-seen times) are ns, and the WiFi and beacon lines at one time are one scan.
pub const RECORDER_HEADER: &str = "Recorder:waymark\tTimeUnit:ns\tScans:grouped";

/// The three inertial streams, as the competition names their lines.
const STREAMS: [&str; 3] = ["TYPE_ACCELEROMETER", "TYPE_GYROSCOPE", "TYPE_MAGNETIC_FIELD"];

/// A survey walk being recorded.
///
/// Each call that returns `Ok` has written its lines to the OS before it returns (a killed app
/// loses none of them), and every second they are synced to storage; files only ever
/// hold whole lines (docs/surveying.md#durability).
pub struct SurveyRecorder {
    directory: PathBuf,
    options: RecorderOptions,
    open: Opener,
    out: Option<Output>,
    first_ns: Option<u64>,
    last_ns: Option<u64>,
    last_sample_ns: [Option<u64>; 3],
    /// Each stream's last sample refused as ahead of the clock, which the next may confirm.
    refused_ahead_ns: [Option<u64>; 3],
    last_scan_ns: Option<u64>,
    last_waypoint_ns: Option<u64>,
    stats: RecordingStats,
    failure: Option<RecorderError>,
    last_sync: Instant,
    finished: bool,
}

impl SurveyRecorder {
    /// A recording into `directory` (created if missing). Fails on a walk name or site id that
    /// cannot be used; nothing is written until the first call with something to write.
    pub fn new(directory: impl Into<PathBuf>, options: RecorderOptions) -> Result<Self, RecorderError> {
        Self::with_opener(directory.into(), options, Box::new(open_file))
    }

    pub(crate) fn with_opener(
        directory: PathBuf,
        options: RecorderOptions,
        open: Opener,
    ) -> Result<Self, RecorderError> {
        check_name("walk name", &options.walk_name)?;
        check_header_text("site id", &options.site_id)?;
        check_header_text("device", &options.device)?;
        Ok(Self {
            directory,
            options,
            open,
            out: None,
            first_ns: None,
            last_ns: None,
            last_sample_ns: [None; 3],
            refused_ahead_ns: [None; 3],
            last_scan_ns: None,
            last_waypoint_ns: None,
            stats: RecordingStats::default(),
            failure: None,
            last_sync: Instant::now(),
            finished: false,
        })
    }

    /// Accelerometer samples (m/s², gravity included), oldest first; samples an engine would
    /// drop are dropped and counted.
    pub fn push_accelerometer(&mut self, batch: &[SensorSample]) -> Result<BatchReport, RecorderError> {
        self.push_samples(0, batch)
    }

    /// Gyroscope samples (rad/s), as [`push_accelerometer`](Self::push_accelerometer).
    pub fn push_gyroscope(&mut self, batch: &[SensorSample]) -> Result<BatchReport, RecorderError> {
        self.push_samples(1, batch)
    }

    /// Magnetometer samples (µT), as [`push_accelerometer`](Self::push_accelerometer).
    pub fn push_magnetometer(&mut self, batch: &[SensorSample]) -> Result<BatchReport, RecorderError> {
        self.push_samples(2, batch)
    }

    fn push_samples(&mut self, stream: usize, batch: &[SensorSample]) -> Result<BatchReport, RecorderError> {
        self.check_open()?;
        // As an engine's bound: the most a stream may lead the others (docs/errors.md).
        let bound_ns = (MotionConfig::default().max_backlog_s * 1e9) as u64;
        let mut report = BatchReport::default();
        let mut lines = String::new();
        let (mut last, mut refused) = (self.last_sample_ns[stream], self.refused_ahead_ns[stream]);
        let (mut first_ns, mut clock_ns) = (self.first_ns, self.last_ns);
        for s in batch {
            let t = s.timestamp_ns;
            if !s.is_plausible() {
                report.non_finite += 1;
            } else if last.is_some_and(|last| t <= last) {
                report.out_of_order += 1;
            } else if refuse_ahead(t, clock_ns, bound_ns, refused) {
                refused = Some(t);
                report.ahead += 1;
            } else {
                (last, refused) = (Some(t), None);
                first_ns = Some(first_ns.map_or(t, |f| f.min(t)));
                clock_ns = Some(clock_ns.map_or(t, |c| c.max(t)));
                let _ = writeln!(lines, "{t}\t{}\t{}\t{}\t{}", STREAMS[stream], s.x, s.y, s.z);
                report.accepted += 1;
            }
        }
        self.write(&lines)?;
        (self.last_sample_ns[stream], self.refused_ahead_ns[stream]) = (last, refused);
        (self.first_ns, self.last_ns) = (first_ns, clock_ns);
        self.stats.samples += report.accepted as u64;
        self.stats.samples_non_finite += report.non_finite as u64;
        self.stats.samples_out_of_order += report.out_of_order as u64;
        self.stats.samples_ahead += report.ahead as u64;
        Ok(report)
    }

    /// A WiFi and/or BLE scan. Rejected, and counted, where an engine would reject it: a time
    /// not after the previous scan's or past [`MAX_TIMESTAMP_NS`], no readings, an implausible
    /// RSSI; and for hashed ids.
    pub fn push_scan(&mut self, scan: &Scan) -> Result<(), RecorderError> {
        self.check_open()?;
        let t = scan.timestamp_ns;
        let checked = match self.last_scan_ns {
            Some(last_ns) if t <= last_ns => {
                Err(InputError::OutOfOrder { timestamp_ns: t, last_ns }.to_string())
            }
            _ if t > MAX_TIMESTAMP_NS => Err(InputError::TimeAhead { timestamp_ns: t }.to_string()),
            _ => check_readings(scan).map_err(|e| e.to_string()),
        };
        let lines = checked.and_then(|()| scan_lines(scan));
        let lines = lines.map_err(|reason| self.reject_scan(reason))?;
        self.write(&lines)?;
        self.last_scan_ns = Some(t);
        self.saw(t);
        self.stats.scans += 1;
        Ok(())
    }

    /// Counts a scan refused before it reached [`push_scan`](Self::push_scan) (a binding that
    /// could not read a transmitter id) and returns the error to give the app.
    pub fn reject_scan(&mut self, reason: String) -> RecorderError {
        self.stats.scans_rejected += 1;
        RecorderError::Scan(reason)
    }

    /// The surveyor is at (`x`, `y`) m on the plan of `floor` (its name, as the site's floor
    /// folders are named: "F1", "B1") at `timestamp_ns`. A waypoint on another floor than the
    /// previous one ends that floor's file and begins the next. A floor name that differs only
    /// in case from a floor folder in the directory is refused: case-insensitive storage would
    /// merge the two.
    pub fn mark_waypoint(
        &mut self,
        timestamp_ns: u64,
        x: f64,
        y: f64,
        floor: &str,
    ) -> Result<(), RecorderError> {
        self.check_open()?;
        check_name("floor", floor)?;
        if !(x.is_finite() && y.is_finite()) {
            return Err(RecorderError::Waypoint(format!("({x}, {y}) is not a finite position")));
        }
        if timestamp_ns > MAX_TIMESTAMP_NS {
            return Err(RecorderError::Waypoint(InputError::TimeAhead { timestamp_ns }.to_string()));
        }
        if let Some(last) = self.last_waypoint_ns.filter(|&last| timestamp_ns < last) {
            return Err(RecorderError::Waypoint(format!(
                "time {timestamp_ns} ns is before the previous waypoint's, {last} ns"
            )));
        }
        let line = format!("{timestamp_ns}\tTYPE_WAYPOINT\t{x}\t{y}\n");
        match &self.out {
            Some(out) if out.floor.as_deref() == Some(floor) => self.write(&line)?,
            _ => {
                self.check_floor_folder(floor)?;
                self.begin_file(floor, timestamp_ns, &line)?;
            }
        }
        self.last_waypoint_ns = Some(timestamp_ns);
        self.saw(timestamp_ns);
        self.stats.waypoints += 1;
        Ok(())
    }

    /// What was written and dropped so far, and the files begun.
    pub fn stats(&self) -> &RecordingStats {
        &self.stats
    }

    /// Acknowledges an [`RecorderError::Io`] and takes input again: cuts the file back to its
    /// last whole line if a failed write could not, and syncs it. Fails, and the error stays,
    /// when the storage still refuses; nothing is lost by calling it again later. The calls
    /// that failed wrote nothing: push their input again.
    pub fn resume(&mut self) -> Result<(), RecorderError> {
        if self.finished {
            return Err(RecorderError::Finished);
        }
        if self.failure.is_none() {
            return Ok(());
        }
        if let Some(out) = &mut self.out {
            let repaired = match out.dirty {
                true => out.sink.truncate(out.len),
                false => Ok(()),
            };
            if let Err(e) = repaired.and_then(|()| out.sink.sync()) {
                let e = io_error(&out.path, &e);
                self.failure = Some(e.clone());
                return Err(e);
            }
            out.dirty = false;
            self.last_sync = Instant::now();
        }
        self.failure = None;
        Ok(())
    }

    /// Ends the recording: writes the last file's end line, syncs and closes it, and returns
    /// what was recorded. Before any waypoint it fails with [`RecorderError::NoWaypoints`] and
    /// the recording goes on; after an [`RecorderError::Io`] with that error until
    /// [`resume`](Self::resume) succeeds. Once it succeeds, later calls fail with
    /// [`RecorderError::Finished`].
    pub fn finish(&mut self) -> Result<RecordingStats, RecorderError> {
        self.check_open()?;
        let end = self.end_line();
        let Some(out) = self.out.as_mut().filter(|out| out.floor.is_some()) else {
            return Err(RecorderError::NoWaypoints);
        };
        if let Err(e) = out.append_synced(end.as_bytes()) {
            let e = io_error(&out.path, &e);
            return Err(self.fail(e));
        }
        self.out = None;
        self.finished = true;
        Ok(self.stats.clone())
    }

    fn check_open(&self) -> Result<(), RecorderError> {
        match (&self.failure, self.finished) {
            (_, true) => Err(RecorderError::Finished),
            (Some(e), false) => Err(e.clone()),
            (None, false) => Ok(()),
        }
    }

    /// Keeps `e` as the recording's error until [`resume`](Self::resume).
    fn fail(&mut self, e: RecorderError) -> RecorderError {
        self.failure = Some(e.clone());
        e
    }

    fn saw(&mut self, timestamp_ns: u64) {
        self.first_ns = Some(self.first_ns.map_or(timestamp_ns, |f| f.min(timestamp_ns)));
        self.last_ns = Some(self.last_ns.map_or(timestamp_ns, |l| l.max(timestamp_ns)));
    }

    fn end_line(&self) -> String {
        format!("#\tendTime:{}\n", self.last_ns.unwrap_or(0))
    }
}

/// A scan's lines: WiFi as `t TYPE_WIFI ssid bssid rssi frequency last_seen` (no SSID or
/// frequency: apps do not give them), beacons as
/// `t TYPE_BEACON uuid major minor tx_power rssi distance address last_seen` (no tx power or
/// distance), each reading's last-seen time its scan's time less its age.
fn scan_lines(scan: &Scan) -> Result<String, String> {
    let t = scan.timestamp_ns;
    let mut lines = String::new();
    for r in &scan.readings {
        let seen = t.saturating_sub(r.age_ns);
        let rssi = r.rssi_dbm;
        let _ = match &r.transmitter {
            TransmitterId::Wifi { bssid } => writeln!(lines, "{t}\tTYPE_WIFI\t\t{bssid}\t{rssi}\t0\t{seen}"),
            TransmitterId::Ble { uuid, major, minor } => {
                writeln!(lines, "{t}\tTYPE_BEACON\t{uuid}\t{major}\t{minor}\t0\t{rssi}\t0\t\t{seen}")
            }
            TransmitterId::BleAddress { mac } => {
                writeln!(lines, "{t}\tTYPE_BEACON\t\t0\t0\t0\t{rssi}\t0\t{mac}\t{seen}")
            }
            TransmitterId::HashedWifi { .. } | TransmitterId::HashedBle { .. } => {
                return Err(format!("{} is a hashed id: record the transmitters' own ids", r.transmitter));
            }
        };
    }
    Ok(lines)
}

#[cfg(test)]
mod tests;
