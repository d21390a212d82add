//! What a recording is told (who and what is recorded), what it counts, and the names it
//! accepts for files and folders.

use super::RecorderError;
use std::path::PathBuf;

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

/// A name used as a file or folder name: letters, digits, `-`, `_`, `.` and spaces, not
/// empty, not `.` or `..`, at most 100 characters, with no space at either end and no `.` at
/// the end (Windows drops those, so "F1 " and "F1" would name one folder there).
pub(super) fn check_name(field: &'static str, value: &str) -> Result<(), RecorderError> {
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
pub(super) fn check_header_text(field: &'static str, value: &str) -> Result<(), RecorderError> {
    if value.chars().any(char::is_control) {
        return Err(RecorderError::InvalidName {
            field,
            value: value.to_owned(),
            reason: "no tabs, line breaks or control characters".to_owned(),
        });
    }
    Ok(())
}
