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

use crate::engine::check_readings;
use crate::error::InputError;
use crate::radio::{Scan, TransmitterId};
use crate::sensors::{refuse_ahead, BatchReport, MotionConfig, SensorSample, MAX_TIMESTAMP_NS};
use std::fmt::Write as _;
use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// The header field that marks a file this recorder wrote, and what it changes for a reader:
/// times (and last-seen times) are ns, and the WiFi and beacon lines at one time are one scan.
pub const RECORDER_HEADER: &str = "Recorder:waymark\tTimeUnit:ns\tScans:grouped";

/// How often the recorder asks the OS to put what it wrote on the storage itself (`fsync`):
/// a write at least this long after the previous sync is synced, as are a file's first and
/// last lines. A power loss costs at most the calls of the last second
/// (docs/surveying.md#durability).
pub const SYNC_INTERVAL: Duration = Duration::from_secs(1);

/// Who and what is being recorded; written into every file's header.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RecorderOptions {
    /// The walk's name: files are `WALK-1.txt`, `WALK-2.txt`, ... (one per floor walked, in
    /// order). Letters, digits, `-`, `_`, `.` and inner spaces; not empty.
    pub walk_name: String,
    /// The site's id (`SiteID` in the header); may be empty.
    pub site_id: String,
    /// The phone, e.g. "Google Pixel 8" (`Brand`/`Model` in the header); may be empty.
    pub device: String,
}

/// What a recording wrote and dropped so far. Only what is in the files is counted: a call
/// that failed counts nothing.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RecordingStats {
    /// Sensor samples written.
    pub samples: u64,
    /// Samples dropped for a NaN, infinite or absurd value.
    pub samples_non_finite: u64,
    /// Samples dropped for a time not after their stream's previous sample.
    pub samples_out_of_order: u64,
    /// Samples refused for a time too far ahead of the recording's clock
    /// (docs/errors.md#timestamps-ahead-of-the-clock).
    pub samples_ahead: u64,
    /// Scans written.
    pub scans: u64,
    /// Scans rejected (as an engine would reject them, or for a hashed transmitter id).
    pub scans_rejected: u64,
    /// Waypoints written.
    pub waypoints: u64,
    /// The walk files begun, in order.
    pub files: Vec<PathBuf>,
}

/// Why a recorder call failed. A call that fails writes and counts nothing. After
/// [`RecorderError::Io`] every call but [`SurveyRecorder::resume`] and
/// [`SurveyRecorder::stats`] fails with the same error until `resume` succeeds.
#[derive(Clone, Debug, thiserror::Error)]
pub enum RecorderError {
    /// Creating or writing a walk file failed (or the file exists: a recording never
    /// overwrites one). It sticks until [`SurveyRecorder::resume`].
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
        reason: String,
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
    /// `finish` before any waypoint: nothing in the walk has a position yet, so no walk file
    /// exists. The recording goes on: mark a waypoint, then finish.
    #[error("no waypoint was marked, so the walk surveys nothing yet and no walk file was written")]
    NoWaypoints,
}

/// The three inertial streams, as the competition names their lines.
const STREAMS: [&str; 3] = ["TYPE_ACCELEROMETER", "TYPE_GYROSCOPE", "TYPE_MAGNETIC_FIELD"];

/// Where a recording's bytes go: a file, or in tests one that fails on cue.
pub(crate) trait Sink: Write + Send {
    /// Puts what was written on the storage itself (`fdatasync`).
    fn sync(&mut self) -> io::Result<()>;
    /// Cuts the file back to `len` bytes; later writes go after them.
    fn truncate(&mut self, len: u64) -> io::Result<()>;
}

impl Sink for File {
    fn sync(&mut self) -> io::Result<()> {
        self.sync_data()
    }

    fn truncate(&mut self, len: u64) -> io::Result<()> {
        self.set_len(len)
    }
}

/// Creates a new file (never an existing one) to write a recording's lines to.
type Opener = Box<dyn Fn(&Path) -> io::Result<Box<dyn Sink>> + Send>;

fn open_file(path: &Path) -> io::Result<Box<dyn Sink>> {
    // Append: after a failed write is cut back, the next one goes after the last whole line.
    Ok(Box::new(OpenOptions::new().append(true).create_new(true).open(path)?))
}

/// The file being written: the floor's walk file, or before the first waypoint (`floor`
/// `None`) the spool `DIR/.WALK.pending`, whose lines go into the first walk file.
struct Output {
    floor: Option<String>,
    path: PathBuf,
    sink: Box<dyn Sink>,
    /// Bytes of whole lines in the file: what a failed write is cut back to.
    len: u64,
    /// Whether the file may hold bytes after `len` (a failed write that could not be cut back).
    dirty: bool,
}

impl Output {
    /// Appends `lines` whole, or fails leaving the file as it was (or `dirty`).
    fn append(&mut self, lines: &[u8]) -> io::Result<()> {
        if let Err(e) = self.sink.write_all(lines).and_then(|()| self.sink.flush()) {
            self.cut_back();
            return Err(e);
        }
        self.len += lines.len() as u64;
        Ok(())
    }

    /// As [`append`](Self::append), then syncs; lines that cannot be synced are cut back too.
    fn append_synced(&mut self, lines: &[u8]) -> io::Result<()> {
        let before = self.len;
        self.append(lines)?;
        self.sink.sync().inspect_err(|_| {
            self.len = before;
            self.cut_back();
        })
    }

    fn cut_back(&mut self) {
        self.dirty = self.sink.truncate(self.len).is_err();
    }
}

/// A survey walk being recorded.
///
/// Each call that returns `Ok` has written its lines to the OS before it returns (a killed app
/// loses none of them), and every [`SYNC_INTERVAL`] they are synced to storage; files only ever
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

    /// Appends whole lines to the floor's file, or before the first waypoint to the spool;
    /// syncs when [`SYNC_INTERVAL`] has passed. Fails writing nothing.
    fn write(&mut self, lines: &str) -> Result<(), RecorderError> {
        if lines.is_empty() {
            return Ok(());
        }
        let out = match self.out.take() {
            Some(out) => out,
            None => self.open_spool()?,
        };
        let out = self.out.insert(out);
        let written = match self.last_sync.elapsed() >= SYNC_INTERVAL {
            true => out.append_synced(lines.as_bytes()).inspect(|()| self.last_sync = Instant::now()),
            false => out.append(lines.as_bytes()),
        };
        written.map_err(|e| io_error(&out.path, &e)).map_err(|e| self.fail(e))
    }

    /// The spool for what comes before the first waypoint, whose floor is not known yet:
    /// `DIR/.WALK.pending`, on disk like the walk files so that memory stays bounded and a
    /// killed app leaves it.
    fn open_spool(&mut self) -> Result<Output, RecorderError> {
        let path = self.directory.join(format!(".{}.pending", self.options.walk_name));
        let opened = std::fs::create_dir_all(&self.directory)
            .map_err(|e| io_error(&self.directory, &e))
            .and_then(|()| (self.open)(&path).map_err(|e| io_error(&path, &e)));
        match opened {
            Ok(sink) => Ok(Output { floor: None, path, sink, len: 0, dirty: false }),
            Err(e) => Err(self.fail(e)),
        }
    }

    /// Refuses a floor whose folder would collide with another's on case-insensitive storage.
    fn check_floor_folder(&self, floor: &str) -> Result<(), RecorderError> {
        let Ok(entries) = std::fs::read_dir(&self.directory) else { return Ok(()) };
        let folded = floor.to_lowercase();
        for name in entries.filter_map(|e| e.ok()?.file_name().into_string().ok()) {
            if name != floor && name.to_lowercase() == folded {
                return Err(RecorderError::InvalidName {
                    field: "floor",
                    value: floor.to_owned(),
                    reason: format!(
                        "the folder {name:?} differs from it only in case, and case-insensitive \
                         storage would merge the two"
                    ),
                });
            }
        }
        Ok(())
    }

    /// Begins `floor`'s walk file with its header, what was spooled before the first waypoint
    /// and `first_line`, then ends the previous floor's file. All or nothing: on a failure the
    /// new file is removed and the previous one is as it was.
    fn begin_file(&mut self, floor: &str, timestamp_ns: u64, first_line: &str) -> Result<(), RecorderError> {
        let folder = self.directory.join(floor).join("path_data_files");
        if let Err(e) = std::fs::create_dir_all(&folder) {
            return Err(self.fail(io_error(&folder, &e)));
        }
        let path = folder.join(format!("{}-{}.txt", self.options.walk_name, self.stats.files.len() + 1));
        let sink = match (self.open)(&path) {
            Ok(sink) => sink,
            Err(e) => return Err(self.fail(io_error(&path, &e))),
        };
        let mut next = Output { floor: Some(floor.to_owned()), path, sink, len: 0, dirty: false };
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
        let spool = self.out.as_ref().filter(|out| out.floor.is_none()).map(|out| out.path.clone());
        let mut begun = next.append(header.as_bytes());
        if let (Ok(()), Some(spool)) = (&begun, &spool) {
            begun = copy_spool(spool, &mut next);
        }
        begun = begun.and_then(|()| next.append_synced(first_line.as_bytes()));
        // The previous floor's file ends once the next one holds its first line.
        let end = self.end_line();
        if let (Ok(()), Some(previous)) = (&begun, self.out.as_mut().filter(|out| out.floor.is_some())) {
            if let Err(e) = previous.append_synced(end.as_bytes()) {
                let e = io_error(&previous.path, &e);
                drop(next.sink);
                let _ = std::fs::remove_file(&next.path);
                return Err(self.fail(e));
            }
        }
        if let Err(e) = begun {
            let e = io_error(&next.path, &e);
            drop(next.sink);
            let _ = std::fs::remove_file(&next.path);
            return Err(self.fail(e));
        }
        self.last_sync = Instant::now();
        self.stats.files.push(next.path.clone());
        self.out = Some(next);
        if let Some(spool) = spool {
            // Its lines are in the walk file now; one left behind only repeats them.
            if let Err(e) = std::fs::remove_file(&spool) {
                log::warn!("cannot remove {}: {e}", spool.display());
            }
        }
        Ok(())
    }
}

/// Appends the spool's lines to `out`, a block at a time.
fn copy_spool(spool: &Path, out: &mut Output) -> io::Result<()> {
    let mut from = File::open(spool)?;
    let mut block = vec![0; 64 * 1024];
    loop {
        let n = io::Read::read(&mut from, &mut block)?;
        if n == 0 {
            return Ok(());
        }
        out.append(&block[..n])?;
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
/// empty, not `.` or `..`, at most 100 characters, with no space at either end and no `.` at
/// the end (Windows drops those, so "F1 " and "F1" would name one folder there).
fn check_name(field: &'static str, value: &str) -> Result<(), RecorderError> {
    let invalid = |reason: &str| {
        Err(RecorderError::InvalidName { field, value: value.to_owned(), reason: reason.to_owned() })
    };
    if value.trim().is_empty() {
        return invalid("it is empty");
    }
    if value == "." || value == ".." || value.chars().count() > 100 {
        return invalid("it cannot name a folder");
    }
    if !value.chars().all(|c| c.is_alphanumeric() || matches!(c, '-' | '_' | '.' | ' ')) {
        return invalid("only letters, digits, '-', '_', '.' and spaces");
    }
    if value.trim() != value || value.ends_with('.') {
        return invalid("no space at either end and no '.' at the end");
    }
    Ok(())
}

/// Text in a header field: no tab, line break or other control character.
fn check_header_text(field: &'static str, value: &str) -> Result<(), RecorderError> {
    if value.chars().any(char::is_control) {
        return Err(RecorderError::InvalidName {
            field,
            value: value.to_owned(),
            reason: "no tabs, line breaks or control characters".to_owned(),
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

    /// A disk that fills up on cue: writes succeed while `space` lasts (the last one in part,
    /// as a real full disk does), then fail with ENOSPC; truncation and opening can be made to
    /// fail too. The files are real, so tests read what a reader would.
    #[derive(Default)]
    struct Faults {
        space: u64,
        truncate_fails: bool,
        open_fails: bool,
        sync_fails: bool,
        syncs: u64,
    }

    struct FaultySink {
        file: File,
        faults: std::sync::Arc<std::sync::Mutex<Faults>>,
    }

    impl Write for FaultySink {
        fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
            let mut faults = self.faults.lock().unwrap();
            if faults.space == 0 {
                return Err(io::Error::from_raw_os_error(28));
            }
            let n = buf.len().min(faults.space as usize);
            faults.space -= n as u64;
            self.file.write(&buf[..n])
        }

        fn flush(&mut self) -> io::Result<()> {
            Ok(())
        }
    }

    impl Sink for FaultySink {
        fn sync(&mut self) -> io::Result<()> {
            let mut faults = self.faults.lock().unwrap();
            if faults.sync_fails {
                return Err(io::Error::from_raw_os_error(5));
            }
            faults.syncs += 1;
            self.file.sync_data()
        }

        fn truncate(&mut self, len: u64) -> io::Result<()> {
            match self.faults.lock().unwrap().truncate_fails {
                true => Err(io::Error::from_raw_os_error(5)),
                false => self.file.set_len(len),
            }
        }
    }

    fn faulty(dir: &Path) -> (SurveyRecorder, std::sync::Arc<std::sync::Mutex<Faults>>) {
        let faults =
            std::sync::Arc::new(std::sync::Mutex::new(Faults { space: u64::MAX, ..Faults::default() }));
        let shared = faults.clone();
        let open: Opener = Box::new(move |path| {
            if shared.lock().unwrap().open_fails {
                return Err(io::Error::from_raw_os_error(13));
            }
            let file = OpenOptions::new().append(true).create_new(true).open(path)?;
            Ok(Box::new(FaultySink { file, faults: shared.clone() }) as Box<dyn Sink>)
        });
        (SurveyRecorder::with_opener(dir.to_owned(), options(), open).unwrap(), faults)
    }

    fn data_lines(path: &Path) -> Vec<String> {
        let text = std::fs::read_to_string(path).unwrap();
        assert!(text.is_empty() || text.ends_with('\n'), "a file ends mid-line: {text:?}");
        text.lines().filter(|l| !l.starts_with('#')).map(str::to_owned).collect()
    }

    fn batch(from: u64, n: u64) -> Vec<SensorSample> {
        (from..from + n).map(|k| sample(k * 10_000_000, 0.5)).collect()
    }

    #[test]
    fn a_full_disk_fails_every_call_until_resumed_and_loses_nothing_that_returned_ok() {
        let dir = tempfile::tempdir().unwrap();
        let (mut r, faults) = faulty(dir.path());
        r.push_accelerometer(&batch(0, 10)).unwrap();
        r.mark_waypoint(100_000_000, 1.0, 2.0, "F1").unwrap();
        r.push_accelerometer(&batch(11, 10)).unwrap();
        let before = r.stats().clone();
        faults.lock().unwrap().space = 40; // a line and a half
        assert!(matches!(r.push_accelerometer(&batch(21, 10)), Err(RecorderError::Io { .. })));
        let path = r.stats().files[0].clone();
        assert_eq!(data_lines(&path).len(), 21, "the failed call's partial line was cut back");
        assert_eq!(r.stats(), &before, "a failed call counts nothing");
        // Space again, but the error sticks until the app acknowledges it.
        faults.lock().unwrap().space = u64::MAX;
        assert!(matches!(r.push_accelerometer(&batch(21, 10)), Err(RecorderError::Io { .. })));
        assert!(matches!(r.mark_waypoint(400_000_000, 1.0, 2.0, "F1"), Err(RecorderError::Io { .. })));
        assert!(matches!(r.finish(), Err(RecorderError::Io { .. })), "not finished, so it can be retried");
        assert_eq!(r.stats(), &before);
        r.resume().unwrap();
        assert_eq!(r.push_accelerometer(&batch(21, 10)).unwrap().accepted, 10, "the failed batch again");
        r.mark_waypoint(400_000_000, 1.0, 2.0, "F1").unwrap();
        let stats = r.finish().unwrap();
        assert_eq!((stats.samples, stats.waypoints), (30, 2));
        let lines = data_lines(&path);
        assert_eq!(lines.len(), 32);
        let times: Vec<u64> = lines.iter().map(|l| l.split('\t').next().unwrap().parse().unwrap()).collect();
        let mut sorted = times.clone();
        sorted.dedup();
        assert_eq!(sorted.len(), times.len(), "no line twice");
        assert!(std::fs::read_to_string(&path).unwrap().ends_with("#\tendTime:400000000\n"));
    }

    #[test]
    fn a_partial_line_that_could_not_be_cut_back_is_cut_at_resume() {
        let dir = tempfile::tempdir().unwrap();
        let (mut r, faults) = faulty(dir.path());
        r.mark_waypoint(0, 1.0, 2.0, "F1").unwrap();
        {
            let mut f = faults.lock().unwrap();
            (f.space, f.truncate_fails) = (15, true);
        }
        assert!(matches!(r.push_gyroscope(&batch(1, 3)), Err(RecorderError::Io { .. })));
        let path = r.stats().files[0].clone();
        assert!(!std::fs::read_to_string(&path).unwrap().ends_with('\n'), "the fault left half a line");
        faults.lock().unwrap().space = u64::MAX;
        assert!(matches!(r.resume(), Err(RecorderError::Io { .. })), "still cannot cut it back");
        assert!(matches!(r.push_gyroscope(&batch(1, 3)), Err(RecorderError::Io { .. })));
        faults.lock().unwrap().truncate_fails = false;
        r.resume().unwrap();
        assert_eq!(data_lines(&path).len(), 1);
        r.push_gyroscope(&batch(1, 3)).unwrap();
        r.finish().unwrap();
        assert_eq!(data_lines(&path).len(), 4);
    }

    #[test]
    fn lines_that_cannot_be_synced_are_cut_back_and_finish_can_be_retried() {
        let dir = tempfile::tempdir().unwrap();
        let (mut r, faults) = faulty(dir.path());
        r.mark_waypoint(0, 1.0, 2.0, "F1").unwrap();
        r.push_accelerometer(&batch(1, 5)).unwrap();
        faults.lock().unwrap().sync_fails = true;
        assert!(matches!(r.finish(), Err(RecorderError::Io { .. })));
        let path = r.stats().files[0].clone();
        assert!(!std::fs::read_to_string(&path).unwrap().contains("endTime"), "the unsynced end line is cut");
        faults.lock().unwrap().sync_fails = false;
        r.resume().unwrap();
        r.finish().unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text.matches("endTime").count(), 1);
        assert_eq!(data_lines(&path).len(), 6);
    }

    #[test]
    fn a_floor_change_that_fails_leaves_the_previous_file_current() {
        let dir = tempfile::tempdir().unwrap();
        let (mut r, faults) = faulty(dir.path());
        r.mark_waypoint(0, 1.0, 2.0, "F1").unwrap();
        faults.lock().unwrap().open_fails = true;
        assert!(matches!(r.mark_waypoint(10, 1.0, 2.0, "F2"), Err(RecorderError::Io { .. })));
        assert!(matches!(r.push_magnetometer(&batch(2, 1)), Err(RecorderError::Io { .. })));
        faults.lock().unwrap().open_fails = false;
        r.resume().unwrap();
        r.push_magnetometer(&batch(2, 1)).unwrap();
        // The new file cannot be written in full: it is removed, the old one goes on.
        faults.lock().unwrap().space = 100;
        let header_and_first = r.mark_waypoint(30_000_000, 1.0, 2.0, "F2");
        assert!(matches!(header_and_first, Err(RecorderError::Io { .. })));
        assert!(!dir.path().join("F2/path_data_files/walk-2.txt").exists());
        faults.lock().unwrap().space = u64::MAX;
        r.resume().unwrap();
        r.mark_waypoint(30_000_000, 1.0, 2.0, "F2").unwrap();
        let stats = r.finish().unwrap();
        assert_eq!(stats.files.len(), 2);
        assert_eq!(data_lines(&stats.files[0]).len(), 2);
        assert_eq!(data_lines(&stats.files[1]).len(), 1);
        let first = std::fs::read_to_string(&stats.files[0]).unwrap();
        assert_eq!(first.matches("endTime").count(), 1);
    }

    #[test]
    fn input_before_the_first_waypoint_is_spooled_to_disk_and_files_are_synced() {
        let dir = tempfile::tempdir().unwrap();
        let (mut r, faults) = faulty(dir.path());
        r.push_accelerometer(&batch(0, 100)).unwrap();
        let spool = dir.path().join(".walk.pending");
        assert_eq!(data_lines(&spool).len(), 100, "on disk, not in memory");
        assert!(matches!(r.finish(), Err(RecorderError::NoWaypoints)));
        r.push_accelerometer(&batch(100, 1)).unwrap();
        let syncs = faults.lock().unwrap().syncs;
        r.mark_waypoint(2_000_000_000, 0.0, 0.0, "F1").unwrap();
        assert!(faults.lock().unwrap().syncs > syncs, "a new file is synced");
        assert!(!spool.exists(), "its lines are in the walk file");
        let syncs = faults.lock().unwrap().syncs;
        let stats = r.finish().unwrap();
        assert!(faults.lock().unwrap().syncs > syncs, "the end is synced");
        assert_eq!(data_lines(&stats.files[0]).len(), 102);
        assert!(std::fs::read_to_string(&stats.files[0]).unwrap().starts_with("#\tstartTime:0\n"));
    }

    #[test]
    fn an_unusable_directory_fails_the_first_write_and_every_call_after() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("a file");
        std::fs::write(&file, "").unwrap();
        let mut r = SurveyRecorder::new(file.join("walks"), options()).unwrap();
        assert!(matches!(r.push_accelerometer(&[sample(1, 0.0)]), Err(RecorderError::Io { .. })));
        assert!(matches!(r.push_accelerometer(&[sample(2, 0.0)]), Err(RecorderError::Io { .. })));
        assert!(matches!(r.mark_waypoint(3, 0.0, 0.0, "F1"), Err(RecorderError::Io { .. })));
        assert!(matches!(r.finish(), Err(RecorderError::Io { .. })));
        r.resume().unwrap();
        assert!(matches!(r.push_accelerometer(&[sample(4, 0.0)]), Err(RecorderError::Io { .. })), "still");
        assert_eq!(r.stats().samples, 0);
    }

    #[test]
    fn floor_names_that_would_share_a_folder_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut r = SurveyRecorder::new(dir.path(), options()).unwrap();
        for bad in ["F1 ", " F1", "F1."] {
            let refused = r.mark_waypoint(1, 0.0, 0.0, bad);
            assert!(matches!(refused, Err(RecorderError::InvalidName { .. })), "{bad:?}");
        }
        r.mark_waypoint(1, 0.0, 0.0, "F1").unwrap();
        let refused = r.mark_waypoint(2, 0.0, 0.0, "f1");
        assert!(matches!(refused, Err(RecorderError::InvalidName { .. })), "only the case differs");
        r.mark_waypoint(3, 0.0, 0.0, "F2").unwrap();
        r.mark_waypoint(4, 0.0, 0.0, "F1").unwrap();
        let stats = r.finish().unwrap();
        assert_eq!(stats.files.len(), 3);
        let mut other =
            SurveyRecorder::new(dir.path(), RecorderOptions { walk_name: "b".into(), ..options() }).unwrap();
        let refused = other.mark_waypoint(1, 0.0, 0.0, "f2");
        assert!(matches!(refused, Err(RecorderError::InvalidName { .. })), "a folder of another walk");
    }

    #[test]
    fn a_time_far_ahead_is_refused_and_counted_and_the_stream_goes_on() {
        let dir = tempfile::tempdir().unwrap();
        let mut r = SurveyRecorder::new(dir.path(), options()).unwrap();
        r.push_accelerometer(&batch(0, 10)).unwrap();
        let negative = sample(u64::MAX - 999, 0.5);
        let report = r.push_accelerometer(&[negative]).unwrap();
        assert_eq!((report.accepted, report.ahead), (0, 1));
        assert_eq!(r.push_accelerometer(&batch(10, 100)).unwrap().accepted, 100);
        let hour = 3_600_000_000_000;
        let report = r.push_accelerometer(&[sample(hour, 0.5)]).unwrap();
        assert_eq!(report.ahead, 1, "more than 10 s ahead of the clock");
        assert_eq!(r.push_accelerometer(&batch(110, 1)).unwrap().accepted, 1);
        // A real jump (the phone slept): the next sample confirms the first.
        let report = r.push_accelerometer(&[sample(2 * hour, 0.5), sample(2 * hour + 10, 0.5)]).unwrap();
        assert_eq!((report.accepted, report.ahead), (1, 1));
        let scan = Scan { timestamp_ns: u64::MAX - 8, readings: vec![wifi("aa:bb:cc:dd:ee:01", -70.0, 0)] };
        assert!(matches!(r.push_scan(&scan), Err(RecorderError::Scan(_))));
        let scan = Scan { timestamp_ns: 2 * hour + 20, readings: vec![wifi("aa:bb:cc:dd:ee:01", -70.0, 0)] };
        r.push_scan(&scan).unwrap();
        assert!(matches!(r.mark_waypoint(u64::MAX, 0.0, 0.0, "F1"), Err(RecorderError::Waypoint(_))));
        r.mark_waypoint(2 * hour + 30, 0.0, 0.0, "F1").unwrap();
        let stats = r.finish().unwrap();
        assert_eq!((stats.samples, stats.samples_ahead, stats.scans_rejected), (112, 3, 1));
    }
}
