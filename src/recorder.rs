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

use crate::engine::check_readings;
use crate::error::InputError;
use crate::radio::{Scan, TransmitterId};
use crate::sensors::{BatchReport, SensorSample};
use std::fmt::Write as _;
use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// The header field that marks a file this recorder wrote, and what it changes for a reader:
/// times (and last-seen times) are ns, and the WiFi and beacon lines at one time are one scan.
pub const RECORDER_HEADER: &str = "Recorder:waymark\tTimeUnit:ns\tScans:grouped";

/// Who and what is being recorded; written into every file's header.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RecorderOptions {
    /// The walk's name: files are `WALK-1.txt`, `WALK-2.txt`, ... (one per floor walked, in
    /// order). Letters, digits, `-`, `_` and `.`; not empty.
    pub walk_name: String,
    /// The site's id (`SiteID` in the header); may be empty.
    pub site_id: String,
    /// The phone, e.g. "Google Pixel 8" (`Brand`/`Model` in the header); may be empty.
    pub device: String,
}

/// What a recording took and dropped so far.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RecordingStats {
    /// Sensor samples written.
    pub samples: u64,
    /// Samples dropped for a NaN, infinite or absurd value.
    pub samples_non_finite: u64,
    /// Samples dropped for a time not after their stream's previous sample.
    pub samples_out_of_order: u64,
    /// Scans written.
    pub scans: u64,
    /// Scans rejected (as an engine would reject them, or for a hashed transmitter id).
    pub scans_rejected: u64,
    /// Waypoints written.
    pub waypoints: u64,
    /// The walk files begun, in order.
    pub files: Vec<PathBuf>,
}

/// Why a recorder call failed. After any of them the recording goes on, except after
/// [`RecorderError::Io`] when the disk is full or gone.
#[derive(Debug, thiserror::Error)]
pub enum RecorderError {
    /// Creating or writing a walk file failed (or the file exists: a recording never
    /// overwrites one).
    #[error("cannot write {path}: {message}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// Why.
        message: String,
    },
    /// A walk name, floor name or site id that cannot name a file or be written in a header.
    #[error("invalid {field} {value:?}: {reason}")]
    InvalidName {
        /// Which argument.
        field: &'static str,
        /// As given.
        value: String,
        /// Why.
        reason: &'static str,
    },
    /// A waypoint with a NaN or infinite coordinate, or a time before the previous waypoint's.
    #[error("waypoint rejected: {0}")]
    Waypoint(String),
    /// A scan an engine would reject (not after the previous scan, empty, an implausible RSSI),
    /// or one holding hashed transmitter ids (a survey records the transmitters' own ids).
    #[error("scan rejected: {0}")]
    Scan(String),
    /// The recording was finished.
    #[error("the recording is finished")]
    Finished,
    /// `finish` before any waypoint: without one nothing in the walk has a position, so no file
    /// was written.
    #[error("no waypoint was marked, so the walk surveys nothing and no file was written")]
    NoWaypoints,
}

/// The three inertial streams, as the competition names their lines.
const STREAMS: [&str; 3] = ["TYPE_ACCELEROMETER", "TYPE_GYROSCOPE", "TYPE_MAGNETIC_FIELD"];

/// The file of the floor being walked.
struct WalkFile {
    floor: String,
    path: PathBuf,
    out: BufWriter<File>,
}

/// A survey walk being recorded.
pub struct SurveyRecorder {
    directory: PathBuf,
    options: RecorderOptions,
    file: Option<WalkFile>,
    /// Lines taken before the first waypoint, whose floor is not known yet.
    pending: String,
    first_ns: Option<u64>,
    last_ns: u64,
    last_sample_ns: [Option<u64>; 3],
    last_scan_ns: Option<u64>,
    last_waypoint_ns: Option<u64>,
    stats: RecordingStats,
    finished: bool,
}

impl SurveyRecorder {
    /// A recording into `directory` (created if missing). Fails on a walk name or site id that
    /// cannot be used; nothing is written until the first waypoint.
    pub fn new(directory: impl Into<PathBuf>, options: RecorderOptions) -> Result<Self, RecorderError> {
        check_name("walk name", &options.walk_name)?;
        check_header_text("site id", &options.site_id)?;
        check_header_text("device", &options.device)?;
        Ok(Self {
            directory: directory.into(),
            options,
            file: None,
            pending: String::new(),
            first_ns: None,
            last_ns: 0,
            last_sample_ns: [None; 3],
            last_scan_ns: None,
            last_waypoint_ns: None,
            stats: RecordingStats::default(),
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
        let mut report = BatchReport::default();
        let mut lines = String::new();
        for s in batch {
            if !s.is_plausible() {
                report.non_finite += 1;
            } else if self.last_sample_ns[stream].is_some_and(|last| s.timestamp_ns <= last) {
                report.out_of_order += 1;
            } else {
                self.last_sample_ns[stream] = Some(s.timestamp_ns);
                let _ = writeln!(lines, "{}\t{}\t{}\t{}\t{}", s.timestamp_ns, STREAMS[stream], s.x, s.y, s.z);
                self.saw(s.timestamp_ns);
                report.accepted += 1;
            }
        }
        self.stats.samples += report.accepted as u64;
        self.stats.samples_non_finite += report.non_finite as u64;
        self.stats.samples_out_of_order += report.out_of_order as u64;
        self.write(&lines)?;
        Ok(report)
    }

    /// A WiFi and/or BLE scan. Rejected, and counted, where an engine would reject it: a time
    /// not after the previous scan's, no readings, an implausible RSSI; and for hashed ids.
    pub fn push_scan(&mut self, scan: &Scan) -> Result<(), RecorderError> {
        self.check_open()?;
        let t = scan.timestamp_ns;
        let checked = match self.last_scan_ns {
            Some(last_ns) if t <= last_ns => {
                Err(InputError::OutOfOrder { timestamp_ns: t, last_ns }.to_string())
            }
            _ => check_readings(scan).map_err(|e| e.to_string()),
        };
        let lines = checked.and_then(|()| scan_lines(scan));
        let lines = lines.map_err(|reason| self.reject_scan(reason))?;
        self.last_scan_ns = Some(t);
        self.saw(t);
        self.stats.scans += 1;
        self.write(&lines)
    }

    /// Counts a scan refused before it reached [`push_scan`](Self::push_scan) (a binding that
    /// could not read a transmitter id) and returns the error to give the app.
    pub fn reject_scan(&mut self, reason: String) -> RecorderError {
        self.stats.scans_rejected += 1;
        RecorderError::Scan(reason)
    }

    /// The surveyor is at (`x`, `y`) m on the plan of `floor` (its name, as the site's floor
    /// folders are named: "F1", "B1") at `timestamp_ns`. A waypoint on another floor than the
    /// previous one ends that floor's file and begins the next.
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
        if let Some(last) = self.last_waypoint_ns.filter(|&last| timestamp_ns < last) {
            return Err(RecorderError::Waypoint(format!(
                "time {timestamp_ns} ns is before the previous waypoint's, {last} ns"
            )));
        }
        if self.file.as_ref().is_none_or(|f| f.floor != floor) {
            self.begin_file(floor, timestamp_ns)?;
        }
        self.last_waypoint_ns = Some(timestamp_ns);
        self.saw(timestamp_ns);
        self.stats.waypoints += 1;
        self.write(&format!("{timestamp_ns}\tTYPE_WAYPOINT\t{x}\t{y}\n"))
    }

    /// What was taken and dropped so far, and the files begun.
    pub fn stats(&self) -> &RecordingStats {
        &self.stats
    }

    /// Ends the recording: closes the last file and returns what was recorded. Without any
    /// waypoint nothing was written ([`RecorderError::NoWaypoints`]). Later calls fail with
    /// [`RecorderError::Finished`].
    pub fn finish(&mut self) -> Result<RecordingStats, RecorderError> {
        self.check_open()?;
        self.finished = true;
        if self.file.is_none() {
            return Err(RecorderError::NoWaypoints);
        }
        self.end_file()?;
        Ok(self.stats.clone())
    }

    fn check_open(&self) -> Result<(), RecorderError> {
        if self.finished {
            Err(RecorderError::Finished)
        } else {
            Ok(())
        }
    }

    fn saw(&mut self, timestamp_ns: u64) {
        self.first_ns = Some(self.first_ns.map_or(timestamp_ns, |f| f.min(timestamp_ns)));
        self.last_ns = self.last_ns.max(timestamp_ns);
    }

    /// Writes to the floor's file, or keeps the lines until the first waypoint names it.
    fn write(&mut self, lines: &str) -> Result<(), RecorderError> {
        match &mut self.file {
            None => {
                self.pending.push_str(lines);
                Ok(())
            }
            Some(f) => f.out.write_all(lines.as_bytes()).map_err(|e| io_error(&f.path, &e)),
        }
    }

    fn begin_file(&mut self, floor: &str, timestamp_ns: u64) -> Result<(), RecorderError> {
        if self.file.is_some() {
            self.end_file()?;
        }
        let folder = self.directory.join(floor).join("path_data_files");
        std::fs::create_dir_all(&folder).map_err(|e| io_error(&folder, &e))?;
        let path = folder.join(format!("{}-{}.txt", self.options.walk_name, self.stats.files.len() + 1));
        let file =
            OpenOptions::new().write(true).create_new(true).open(&path).map_err(|e| io_error(&path, &e))?;
        let mut out = BufWriter::new(file);
        // The first file also holds what came before its waypoint.
        let start_ns = match self.stats.files.is_empty() {
            true => self.first_ns.map_or(timestamp_ns, |f| f.min(timestamp_ns)),
            false => timestamp_ns,
        };
        let (brand, model) = self.options.device.split_once(' ').unwrap_or((&self.options.device, ""));
        let header = format!(
            "#\tstartTime:{start_ns}\n#\tSiteID:{site}\tSiteName:{site}\tFloorId:{floor}\tFloorName:{floor}\n\
             #\tBrand:{brand}\tModel:{model}\n#\t{RECORDER_HEADER}\tVersion:{}\n",
            env!("CARGO_PKG_VERSION"),
            site = self.options.site_id,
        );
        out.write_all(header.as_bytes()).map_err(|e| io_error(&path, &e))?;
        // What came before the first waypoint belongs to the first floor's file.
        out.write_all(std::mem::take(&mut self.pending).as_bytes()).map_err(|e| io_error(&path, &e))?;
        self.stats.files.push(path.clone());
        self.file = Some(WalkFile { floor: floor.to_owned(), path, out });
        Ok(())
    }

    fn end_file(&mut self) -> Result<(), RecorderError> {
        let Some(mut f) = self.file.take() else { return Ok(()) };
        let end = format!("#\tendTime:{}\n", self.last_ns);
        f.out.write_all(end.as_bytes()).map_err(|e| io_error(&f.path, &e))?;
        let file = f.out.into_inner().map_err(|e| io_error(&f.path, e.error()))?;
        file.sync_all().map_err(|e| io_error(&f.path, &e))
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

/// A name used as a file or folder name: letters, digits, `-`, `_`, `.` and spaces, not
/// empty, not `.` or `..`, at most 100 characters.
fn check_name(field: &'static str, value: &str) -> Result<(), RecorderError> {
    let invalid = |reason| Err(RecorderError::InvalidName { field, value: value.to_owned(), reason });
    if value.trim().is_empty() {
        return invalid("it is empty");
    }
    if value == "." || value == ".." || value.chars().count() > 100 {
        return invalid("it cannot name a folder");
    }
    if !value.chars().all(|c| c.is_alphanumeric() || matches!(c, '-' | '_' | '.' | ' ')) {
        return invalid("only letters, digits, '-', '_', '.' and spaces");
    }
    Ok(())
}

/// Text in a header field: no tab, line break or other control character.
fn check_header_text(field: &'static str, value: &str) -> Result<(), RecorderError> {
    if value.chars().any(char::is_control) {
        return Err(RecorderError::InvalidName {
            field,
            value: value.to_owned(),
            reason: "no tabs, line breaks or control characters",
        });
    }
    Ok(())
}

fn io_error(path: &Path, e: &std::io::Error) -> RecorderError {
    RecorderError::Io { path: path.to_owned(), message: e.to_string() }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::radio::Reading;

    fn sample(t: u64, x: f64) -> SensorSample {
        SensorSample { timestamp_ns: t, x, y: -0.0, z: 9.81 }
    }

    fn wifi(bssid: &str, rssi_dbm: f64, age_ns: u64) -> Reading {
        Reading { transmitter: TransmitterId::wifi(bssid).unwrap(), rssi_dbm, age_ns }
    }

    fn options() -> RecorderOptions {
        RecorderOptions {
            walk_name: "walk".into(),
            site_id: "office".into(),
            device: "Google Pixel 8".into(),
        }
    }

    #[test]
    fn lines_before_the_first_waypoint_go_to_its_floor_and_a_floor_change_begins_a_file() {
        let dir = tempfile::tempdir().unwrap();
        let mut r = SurveyRecorder::new(dir.path(), options()).unwrap();
        r.push_accelerometer(&[sample(1_000, 0.1), sample(2_000, 0.2)]).unwrap();
        r.push_scan(&Scan { timestamp_ns: 2_500, readings: vec![wifi("aa:bb:cc:dd:ee:01", -61.5, 500)] })
            .unwrap();
        r.mark_waypoint(3_000, 1.0, 2.0, "F1").unwrap();
        r.push_gyroscope(&[sample(3_500, 0.01)]).unwrap();
        r.mark_waypoint(9_000, 4.0, 2.0, "F2").unwrap();
        let stats = r.finish().unwrap();
        assert_eq!(stats.files.len(), 2);
        assert!(stats.files[0].ends_with("F1/path_data_files/walk-1.txt"));
        assert!(stats.files[1].ends_with("F2/path_data_files/walk-2.txt"));
        let first = std::fs::read_to_string(&stats.files[0]).unwrap();
        let lines: Vec<&str> = first.lines().collect();
        assert_eq!(lines[0], "#\tstartTime:1000");
        assert!(lines[1].contains("SiteID:office") && lines[1].contains("FloorName:F1"));
        assert_eq!(lines[2], "#\tBrand:Google\tModel:Pixel 8");
        assert!(lines[3].starts_with(&format!("#\t{RECORDER_HEADER}")));
        assert_eq!(lines[4], "1000\tTYPE_ACCELEROMETER\t0.1\t-0\t9.81");
        assert_eq!(lines[6], "2500\tTYPE_WIFI\t\taa:bb:cc:dd:ee:01\t-61.5\t0\t2000");
        assert_eq!(lines[7], "3000\tTYPE_WAYPOINT\t1\t2");
        assert_eq!(lines[8], "3500\tTYPE_GYROSCOPE\t0.01\t-0\t9.81");
        assert_eq!(*lines.last().unwrap(), "#\tendTime:3500", "the last line before the floor changed");
        let second = std::fs::read_to_string(&stats.files[1]).unwrap();
        assert!(second.contains("FloorName:F2") && second.contains("9000\tTYPE_WAYPOINT\t4\t2"));
        assert!(second.starts_with("#\tstartTime:9000\n") && second.ends_with("#\tendTime:9000\n"));
    }

    #[test]
    fn bad_input_is_dropped_or_rejected_and_counted_never_written() {
        let dir = tempfile::tempdir().unwrap();
        let mut r = SurveyRecorder::new(dir.path(), options()).unwrap();
        let report = r
            .push_magnetometer(&[sample(10, 1.0), sample(10, 2.0), sample(5, 3.0), sample(20, f64::NAN)])
            .unwrap();
        assert_eq!((report.accepted, report.out_of_order, report.non_finite), (1, 2, 1));
        assert!(matches!(
            r.push_scan(&Scan { timestamp_ns: 30, readings: vec![] }),
            Err(RecorderError::Scan(_))
        ));
        let nan = Scan { timestamp_ns: 30, readings: vec![wifi("aa:bb:cc:dd:ee:01", f64::NAN, 0)] };
        assert!(matches!(r.push_scan(&nan), Err(RecorderError::Scan(_))));
        let ok = Scan { timestamp_ns: 30, readings: vec![wifi("aa:bb:cc:dd:ee:01", -70.0, 0)] };
        r.push_scan(&ok).unwrap();
        assert!(matches!(r.push_scan(&ok), Err(RecorderError::Scan(_))), "a duplicate scan");
        let hashed = Scan {
            timestamp_ns: 40,
            readings: vec![Reading {
                transmitter: TransmitterId::HashedWifi { hash: "0".repeat(32) },
                rssi_dbm: -70.0,
                age_ns: 0,
            }],
        };
        assert!(matches!(r.push_scan(&hashed), Err(RecorderError::Scan(_))));
        assert!(matches!(r.mark_waypoint(50, f64::INFINITY, 0.0, "F1"), Err(RecorderError::Waypoint(_))));
        assert!(matches!(r.mark_waypoint(50, 0.0, 0.0, "../F1"), Err(RecorderError::InvalidName { .. })));
        assert!(matches!(r.mark_waypoint(50, 0.0, 0.0, ""), Err(RecorderError::InvalidName { .. })));
        r.mark_waypoint(50, 0.0, 0.0, "F1").unwrap();
        assert!(matches!(r.mark_waypoint(49, 0.0, 0.0, "F1"), Err(RecorderError::Waypoint(_))));
        let stats = r.finish().unwrap();
        assert_eq!((stats.samples, stats.samples_out_of_order, stats.samples_non_finite), (1, 2, 1));
        assert_eq!((stats.scans, stats.scans_rejected, stats.waypoints), (1, 4, 1));
        let text = std::fs::read_to_string(&stats.files[0]).unwrap();
        assert_eq!(text.lines().filter(|l| !l.starts_with('#')).count(), 3);
        assert!(matches!(r.push_accelerometer(&[sample(60, 1.0)]), Err(RecorderError::Finished)));
        assert!(matches!(r.finish(), Err(RecorderError::Finished)));
    }

    #[test]
    fn names_that_cannot_be_files_are_refused_and_files_are_never_overwritten() {
        let dir = tempfile::tempdir().unwrap();
        for bad in ["", " ", "..", "a/b", "a\\b", "tab\there"] {
            let bad_walk = RecorderOptions { walk_name: bad.into(), ..options() };
            assert!(
                matches!(SurveyRecorder::new(dir.path(), bad_walk), Err(RecorderError::InvalidName { .. })),
                "{bad:?}"
            );
        }
        let bad_site = RecorderOptions { site_id: "a\nb".into(), ..options() };
        assert!(matches!(SurveyRecorder::new(dir.path(), bad_site), Err(RecorderError::InvalidName { .. })));
        let mut a = SurveyRecorder::new(dir.path(), options()).unwrap();
        a.mark_waypoint(1, 0.0, 0.0, "F1").unwrap();
        a.finish().unwrap();
        let mut b = SurveyRecorder::new(dir.path(), options()).unwrap();
        assert!(matches!(b.mark_waypoint(1, 0.0, 0.0, "F1"), Err(RecorderError::Io { .. })));
        let mut none =
            SurveyRecorder::new(dir.path(), RecorderOptions { walk_name: "empty".into(), ..options() })
                .unwrap();
        none.push_accelerometer(&[sample(1, 0.0)]).unwrap();
        assert!(matches!(none.finish(), Err(RecorderError::NoWaypoints)));
    }
}
