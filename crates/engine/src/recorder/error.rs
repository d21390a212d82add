//! Why a recorder call fails.

use std::path::{Path, PathBuf};

/// Why a recorder call failed. A call that fails writes and counts nothing. After
/// [`RecorderError::Io`] every call but [`SurveyRecorder::resume`](super::SurveyRecorder::resume)
/// and [`SurveyRecorder::stats`](super::SurveyRecorder::stats) fails with the same error until
/// `resume` succeeds.
#[derive(Clone, Debug, thiserror::Error)]
pub enum RecorderError {
    /// Creating or writing a walk file failed (or the file exists: a recording never
    /// overwrites one). It sticks until [`SurveyRecorder::resume`](super::SurveyRecorder::resume).
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

/// The recording's error for an I/O failure `e` on `path`.
pub(super) fn io_error(path: &Path, e: &std::io::Error) -> RecorderError {
    RecorderError::Io { path: path.to_owned(), message: e.to_string() }
}
