//! The survey recorder as Kotlin and Swift see it (docs/surveying.md).

use super::records::{samples, MotionSample, RadioScan};
use crate::ffi::delivery::lock;
use std::sync::Mutex;
use waymark_engine::recorder::{self as core, RecorderError};

/// Who and what is being recorded; written into every walk file's header.
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
pub struct SurveyOptions {
    /// The walk's name: its files are `WALK-1.txt`, `WALK-2.txt`, ... (one per floor walked).
    /// Letters, digits, `-`, `_`, `.` and spaces.
    pub walk_name: String,
    /// The site's id, for the header; may be empty.
    #[uniffi(default = "")]
    pub site_id: String,
    /// The phone, e.g. "Google Pixel 8", for the header; may be empty.
    #[uniffi(default = "")]
    pub device: String,
}

/// What a recording wrote and dropped, and the files it wrote. Only what is in the files is
/// counted: a call that threw counts nothing.
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
pub struct SurveySummary {
    /// Sensor samples written.
    pub samples: u64,
    /// Samples dropped for a NaN, infinite or absurd value, a time not after their stream's
    /// previous sample, or a time too far ahead of the recording's clock (more than 10 s after
    /// the latest input written, unless the stream's next sample confirms the jump, or a
    /// negative `Long` passed as unsigned).
    pub samples_dropped: u64,
    /// Scans written.
    pub scans: u64,
    /// Scans rejected (each call threw `InputRejected`).
    pub scans_rejected: u64,
    /// Waypoints written.
    pub waypoints: u64,
    /// The walk files, in order: `DIR/FLOOR/path_data_files/WALK-K.txt`.
    pub files: Vec<String>,
}

/// Why a recorder call failed. A call that throws writes nothing. After `Io` every call throws
/// `Io` until `resume` succeeds.
#[derive(Clone, Debug, PartialEq, thiserror::Error, uniffi::Error)]
pub enum SurveyError {
    /// A walk file could not be created or written, or exists already (a recording never
    /// overwrites one). It sticks until `resume` succeeds.
    #[error("storage: {reason}")]
    Io {
        /// Which file and why.
        reason: String,
    },
    /// A scan or waypoint was refused, as an engine refuses input (a time running backwards,
    /// an empty scan, an implausible RSSI, a malformed transmitter id, a NaN coordinate), or a
    /// walk name, floor name or site id cannot be used.
    #[error("input rejected: {reason}")]
    InputRejected {
        /// Why.
        reason: String,
    },
    /// `finish` was called before any waypoint: nothing in the walk has a position yet, so no
    /// walk file exists. The recording goes on: mark a waypoint, then finish.
    #[error("no waypoint was marked; no walk file was written yet")]
    NoWaypoints,
    /// The recording was finished.
    #[error("the recording is finished")]
    Finished,
    /// A bug in Waymark; the files may lack what the failed call pushed.
    #[error("internal error: {reason}")]
    Internal {
        /// What happened.
        reason: String,
    },
}

impl From<RecorderError> for SurveyError {
    fn from(e: RecorderError) -> Self {
        match e {
            RecorderError::Io { .. } => SurveyError::Io { reason: e.to_string() },
            RecorderError::InvalidName { .. } | RecorderError::Waypoint(_) | RecorderError::Scan(_) => {
                SurveyError::InputRejected { reason: e.to_string() }
            }
            RecorderError::NoWaypoints => SurveyError::NoWaypoints,
            RecorderError::Finished => SurveyError::Finished,
        }
    }
}

/// Records a survey walk: push the same sensor batches and scans as to a `PositioningEngine`,
/// and `markWaypoint` where the surveyor stands; `finish` closes the files, which
/// `waymark survey` turns into a site file (docs/surveying.md). Thread-safe.
///
/// Every call that returns has handed its lines to the OS, so a killed app loses none of them;
/// they are synced to storage at least once a second while calls come, and at each new file
/// and at `finish`. Files only ever hold whole lines. After an `Io` error every call throws
/// until `resume` succeeds (docs/surveying.md#durability).
#[derive(uniffi::Object)]
#[uniffi(name = "SurveyRecorder")]
pub struct FfiSurveyRecorder {
    inner: Mutex<core::SurveyRecorder>,
}

#[uniffi::export(name = "SurveyRecorder")]
impl FfiSurveyRecorder {
    /// A recording into `directory` (created if missing); before the first waypoint the lines
    /// go to `directory/.WALK.pending`, then into the first walk file. Throws `InputRejected`
    /// for a walk name or site id that cannot be used.
    #[uniffi::constructor]
    pub fn new(directory: String, options: SurveyOptions) -> Result<std::sync::Arc<Self>, SurveyError> {
        guarded(|| {
            let options = core::RecorderOptions {
                walk_name: options.walk_name,
                site_id: options.site_id,
                device: options.device,
            };
            let inner = core::SurveyRecorder::new(directory, options)?;
            Ok(std::sync::Arc::new(Self { inner: Mutex::new(inner) }))
        })
    }

    /// Accelerometer samples, oldest first; returns how many were taken (the others are
    /// dropped and counted, as an engine drops them).
    pub fn push_accelerometer(&self, batch: Vec<MotionSample>) -> Result<u32, SurveyError> {
        self.call(|r| Ok(r.push_accelerometer(&samples(&batch))?.accepted as u32))
    }

    /// Gyroscope samples; as `pushAccelerometer`.
    pub fn push_gyroscope(&self, batch: Vec<MotionSample>) -> Result<u32, SurveyError> {
        self.call(|r| Ok(r.push_gyroscope(&samples(&batch))?.accepted as u32))
    }

    /// Magnetometer samples; as `pushAccelerometer`.
    pub fn push_magnetometer(&self, batch: Vec<MotionSample>) -> Result<u32, SurveyError> {
        self.call(|r| Ok(r.push_magnetometer(&samples(&batch))?.accepted as u32))
    }

    /// A WiFi / BLE scan. Throws `InputRejected` (and counts it) where an engine would.
    pub fn push_scan(&self, scan: RadioScan) -> Result<(), SurveyError> {
        self.call(|r| match scan.to_core() {
            Ok(core) => Ok(r.push_scan(&core)?),
            Err(reason) => Err(r.reject_scan(reason).into()),
        })
    }

    /// The surveyor stands at (`x`, `y`) m on the plan of `floor` (the floor's name, as its
    /// folder is named: "F1", "B1"). A waypoint on another floor begins that floor's file.
    /// Throws `InputRejected` for a floor name with a space at either end or a `.` at the end,
    /// or one that differs only in case from a folder in the directory ("f1" beside "F1":
    /// case-insensitive storage would merge them).
    pub fn mark_waypoint(&self, timestamp_ns: u64, x: f64, y: f64, floor: String) -> Result<(), SurveyError> {
        self.call(|r| Ok(r.mark_waypoint(timestamp_ns, x, y, &floor)?))
    }

    /// What was written and dropped so far; works after an `Io` error too.
    pub fn summary(&self) -> Result<SurveySummary, SurveyError> {
        self.call(|r| Ok(summary(r.stats())))
    }

    /// Acknowledges an `Io` error and takes input again: cuts the file back to its last whole
    /// line if the failed write could not, and syncs it. Throws `Io` while the storage still
    /// refuses (call it again later). The calls that threw wrote nothing: push their input
    /// again.
    pub fn resume(&self) -> Result<(), SurveyError> {
        self.call(|r| Ok(r.resume()?))
    }

    /// Writes the last file's end line, syncs and closes it, and returns what was recorded.
    /// Throws `NoWaypoints` before any waypoint and `Io` when the storage refuses; the recording
    /// goes on after either, and `finish` may be called again. Once it returned, later calls
    /// throw `Finished`.
    pub fn finish(&self) -> Result<SurveySummary, SurveyError> {
        self.call(|r| Ok(summary(&r.finish()?)))
    }
}

impl FfiSurveyRecorder {
    fn call<T>(
        &self,
        f: impl FnOnce(&mut core::SurveyRecorder) -> Result<T, SurveyError>,
    ) -> Result<T, SurveyError> {
        guarded(|| f(&mut lock(&self.inner)))
    }
}

fn summary(s: &core::RecordingStats) -> SurveySummary {
    SurveySummary {
        samples: s.samples,
        samples_dropped: s.samples_non_finite + s.samples_out_of_order + s.samples_ahead,
        scans: s.scans,
        scans_rejected: s.scans_rejected,
        waypoints: s.waypoints,
        files: s.files.iter().map(|p| p.display().to_string()).collect(),
    }
}

/// Runs `f`, turning a panic into `Internal` (`ffi::panic`).
fn guarded<T>(f: impl FnOnce() -> Result<T, SurveyError>) -> Result<T, SurveyError> {
    crate::ffi::panic::or_internal(f, || SurveyError::Internal { reason: "Waymark panicked".into() })
}
