//! The C API's survey recorder (docs/surveying.md): the same sensor and scan calls as an
//! engine's, plus waypoint taps, written as walk files `waymark survey` reads.

use super::{
    boundary, copy_string, fail, readings, samples, sensor_samples, string_arg, waymark_beacon_reading,
    waymark_result, waymark_sample, waymark_wifi_reading, write, Rejected,
};
use crate::ffi::delivery::lock;
use ::waymark_engine::radio::Scan;
use ::waymark_engine::recorder::{RecorderError, RecorderOptions, RecordingStats, SurveyRecorder};
use ::waymark_engine::sensors::{BatchReport, SensorSample};
use std::ffi::c_char;
use std::sync::Mutex;

/// A survey walk being recorded. Opaque; create with `waymark_recorder_new`, free with
/// `waymark_recorder_free` (after `waymark_recorder_finish`, or the last file has no end
/// line). Thread-safe.
pub struct waymark_recorder {
    inner: Mutex<SurveyRecorder>,
}

/// What a recording wrote and dropped (`waymark_recorder_get_summary`, `_finish`). Only what
/// is in the files is counted: a call that failed counts nothing.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct waymark_recording_summary {
    /// Sensor samples written.
    pub samples: u64,
    /// Samples dropped for a NaN, infinite or absurd value, a time not after their stream's
    /// previous sample, or a time too far ahead of the recording's clock (more than 10 s after
    /// the latest input written, unless the stream's next sample confirms the jump, or above
    /// INT64_MAX).
    pub samples_dropped: u64,
    /// Scans written.
    pub scans: u64,
    /// Scans rejected (each call returned `INPUT_REJECTED`).
    pub scans_rejected: u64,
    /// Waypoints written.
    pub waypoints: u64,
    /// Walk files begun: `DIR/FLOOR/path_data_files/WALK-K.txt`, K from 1.
    pub files: u64,
}

fn summary(s: &RecordingStats) -> waymark_recording_summary {
    waymark_recording_summary {
        samples: s.samples,
        samples_dropped: s.samples_non_finite + s.samples_out_of_order + s.samples_ahead,
        scans: s.scans,
        scans_rejected: s.scans_rejected,
        waypoints: s.waypoints,
        files: s.files.len() as u64,
    }
}

fn recorder_error(e: &RecorderError) -> waymark_result {
    let code = match e {
        RecorderError::Io { .. } => waymark_result::Io,
        RecorderError::InvalidName { .. } | RecorderError::Waypoint(_) | RecorderError::Scan(_) => {
            waymark_result::InputRejected
        }
        RecorderError::NoWaypoints => waymark_result::NoWaypoints,
        RecorderError::Finished => waymark_result::Finished,
    };
    fail(code, e.to_string())
}

/// Begins a recording into the folder `directory` (created if missing). `walk_name` names its
/// files (letters, digits, `-`, `_`, `.`, inner spaces); `site_id` and `device` (may be NULL)
/// go into their headers. On success `*out` holds the recorder. Fails with `INPUT_REJECTED`
/// for a name that cannot be used.
///
/// Every call that returns `OK` has handed its lines to the OS before it returns, so a killed
/// app loses none of them; they are synced to storage at least once a second while calls come,
/// and at each new file and at `_finish`. Before the first waypoint the lines go to
/// `DIRECTORY/.WALK.pending`, then into the first walk file. Files only ever hold whole lines.
/// A call that returns `IO` wrote nothing, and every later call returns `IO` too until
/// `waymark_recorder_resume` succeeds (docs/surveying.md#durability).
#[no_mangle]
pub extern "C" fn waymark_recorder_new(
    directory: *const c_char,
    walk_name: *const c_char,
    site_id: *const c_char,
    device: *const c_char,
    out: *mut *mut waymark_recorder,
) -> waymark_result {
    boundary(|| {
        if out.is_null() {
            return fail(waymark_result::NullParameter, "out must not be NULL");
        }
        let text = |p: *const c_char, what| if p.is_null() { Ok(String::new()) } else { string_arg(p, what) };
        let args = (
            string_arg(directory, "directory"),
            string_arg(walk_name, "walk_name"),
            text(site_id, "site_id"),
            text(device, "device"),
        );
        let (directory, walk_name, site_id, device) = match args {
            (Ok(d), Ok(w), Ok(s), Ok(v)) => (d, w, s, v),
            (Err(code), ..) | (_, Err(code), ..) | (_, _, Err(code), _) | (.., Err(code)) => return code,
        };
        match SurveyRecorder::new(directory, RecorderOptions { walk_name, site_id, device }) {
            Ok(recorder) => {
                write(out, Box::into_raw(Box::new(waymark_recorder { inner: Mutex::new(recorder) })));
                waymark_result::Ok
            }
            Err(e) => recorder_error(&e),
        }
    })
}

/// Frees a recorder, closing its file (without its end line if `_finish` did not succeed).
/// NULL is ignored.
#[no_mangle]
pub extern "C" fn waymark_recorder_free(recorder: *mut waymark_recorder) {
    let _ = boundary(|| {
        if !recorder.is_null() {
            // SAFETY: `recorder` came from `waymark_recorder_new` (Box::into_raw) and is freed
            // once, as the header requires.
            drop(unsafe { Box::from_raw(recorder) });
        }
        waymark_result::Ok
    });
}

/// Borrows `recorder` under its lock, or fails with `NullParameter`.
fn with_recorder(
    recorder: *const waymark_recorder,
    body: impl FnOnce(&mut SurveyRecorder) -> waymark_result,
) -> waymark_result {
    boundary(|| {
        // SAFETY: a non-NULL `recorder` is a live handle from `waymark_recorder_new` (the
        // header's contract); `waymark_recorder` is Sync, so a shared reference from any thread
        // is fine.
        match unsafe { recorder.as_ref() } {
            Some(r) => body(&mut lock(&r.inner)),
            None => fail(waymark_result::NullParameter, "recorder must not be NULL"),
        }
    })
}

fn push_samples(
    recorder: *const waymark_recorder,
    batch: *const waymark_sample,
    count: usize,
    accepted: *mut usize,
    push: fn(&mut SurveyRecorder, &[SensorSample]) -> Result<BatchReport, RecorderError>,
) -> waymark_result {
    with_recorder(recorder, |r| {
        let Some(batch) = samples(batch, count) else {
            return fail(waymark_result::NullParameter, "samples must not be NULL when count > 0");
        };
        let converted = sensor_samples(batch);
        match push(r, &converted) {
            Ok(report) => {
                write(accepted, report.accepted);
                waymark_result::Ok
            }
            Err(e) => recorder_error(&e),
        }
    })
}

/// Accelerometer samples, oldest first; as `waymark_engine_push_accelerometer` (bad samples
/// dropped and counted; `*accepted`, may be NULL, receives how many were written).
#[no_mangle]
pub extern "C" fn waymark_recorder_push_accelerometer(
    recorder: *const waymark_recorder,
    samples: *const waymark_sample,
    count: usize,
    accepted: *mut usize,
) -> waymark_result {
    push_samples(recorder, samples, count, accepted, SurveyRecorder::push_accelerometer)
}

/// Gyroscope samples; as `waymark_recorder_push_accelerometer`.
#[no_mangle]
pub extern "C" fn waymark_recorder_push_gyroscope(
    recorder: *const waymark_recorder,
    samples: *const waymark_sample,
    count: usize,
    accepted: *mut usize,
) -> waymark_result {
    push_samples(recorder, samples, count, accepted, SurveyRecorder::push_gyroscope)
}

/// Magnetometer samples; as `waymark_recorder_push_accelerometer`.
#[no_mangle]
pub extern "C" fn waymark_recorder_push_magnetometer(
    recorder: *const waymark_recorder,
    samples: *const waymark_sample,
    count: usize,
    accepted: *mut usize,
) -> waymark_result {
    push_samples(recorder, samples, count, accepted, SurveyRecorder::push_magnetometer)
}

/// A scan, as `waymark_engine_push_scan` takes it. Returns `INPUT_REJECTED` (and counts it)
/// where an engine would reject it, but for unknown transmitters: a survey records them all.
#[no_mangle]
pub extern "C" fn waymark_recorder_push_scan(
    recorder: *const waymark_recorder,
    timestamp_ns: u64,
    wifi: *const waymark_wifi_reading,
    wifi_count: usize,
    beacons: *const waymark_beacon_reading,
    beacon_count: usize,
) -> waymark_result {
    with_recorder(recorder, |r| {
        if (wifi.is_null() && wifi_count > 0) || (beacons.is_null() && beacon_count > 0) {
            return fail(waymark_result::NullParameter, "reading arrays must not be NULL when count > 0");
        }
        let readings = match readings(wifi, wifi_count, beacons, beacon_count) {
            Ok(readings) => readings,
            Err(Rejected::Code(code)) => return code,
            Err(Rejected::Input(reason)) => return recorder_error(&r.reject_scan(reason)),
        };
        match r.push_scan(&Scan { timestamp_ns, readings }) {
            Ok(()) => waymark_result::Ok,
            Err(e) => recorder_error(&e),
        }
    })
}

/// The surveyor stands at (`x`, `y`) m on the plan of the floor named `floor` ("F1", "B1": its
/// folder's name). A waypoint on another floor than the previous one begins that floor's
/// file. `INPUT_REJECTED` for a NaN or infinite coordinate, a time before the previous
/// waypoint's or a floor name that cannot name a folder; `IO` if the file cannot be created.
#[no_mangle]
pub extern "C" fn waymark_recorder_mark_waypoint(
    recorder: *const waymark_recorder,
    timestamp_ns: u64,
    x: f64,
    y: f64,
    floor: *const c_char,
) -> waymark_result {
    with_recorder(recorder, |r| {
        let floor = match string_arg(floor, "floor") {
            Ok(f) => f,
            Err(code) => return code,
        };
        match r.mark_waypoint(timestamp_ns, x, y, &floor) {
            Ok(()) => waymark_result::Ok,
            Err(e) => recorder_error(&e),
        }
    })
}

/// What was written and dropped so far, into `*out`. Works after an `IO` error too.
#[no_mangle]
pub extern "C" fn waymark_recorder_get_summary(
    recorder: *const waymark_recorder,
    out: *mut waymark_recording_summary,
) -> waymark_result {
    if out.is_null() {
        return fail(waymark_result::NullParameter, "out must not be NULL");
    }
    with_recorder(recorder, |r| {
        write(out, summary(r.stats()));
        waymark_result::Ok
    })
}

/// Writes the last file's end line, syncs and closes it; `*out` (may be NULL) receives what
/// was recorded. `NO_WAYPOINTS` when no waypoint was marked: no walk file exists yet, and the
/// recording goes on (mark a waypoint, then finish). `IO` when the end line cannot be written,
/// or after an earlier `IO` until `waymark_recorder_resume` succeeds: the recording goes on,
/// and `_finish` may be called again. Once it returned `OK`, later calls return `FINISHED`.
#[no_mangle]
pub extern "C" fn waymark_recorder_finish(
    recorder: *const waymark_recorder,
    out: *mut waymark_recording_summary,
) -> waymark_result {
    with_recorder(recorder, |r| match r.finish() {
        Ok(stats) => {
            write(out, summary(&stats));
            waymark_result::Ok
        }
        Err(e) => recorder_error(&e),
    })
}

/// Acknowledges an `IO` error and takes input again: cuts the file back to its last whole line
/// if the failed write could not, and syncs it. Returns `IO` while the storage still refuses
/// (the error stays; call it again later), `FINISHED` after `_finish`, else `OK` (also when
/// there was no error). The calls that returned `IO` wrote nothing: push their input again.
#[no_mangle]
pub extern "C" fn waymark_recorder_resume(recorder: *const waymark_recorder) -> waymark_result {
    with_recorder(recorder, |r| match r.resume() {
        Ok(()) => waymark_result::Ok,
        Err(e) => recorder_error(&e),
    })
}

/// The path of walk file `index` (0 for the first) into `buf` of `len` bytes, NUL-terminated,
/// and its length in bytes without the NUL into `*path_len` (may be NULL). Never truncated:
/// when it does not fit, `buf` receives an empty string (when `len` > 0) and the call returns
/// `BUFFER_TOO_SMALL`; `buf` may be NULL with `len` 0 to ask the length. `INPUT_REJECTED` for
/// an index past the files begun (`waymark_recording_summary.files`).
#[no_mangle]
pub extern "C" fn waymark_recorder_file_path(
    recorder: *const waymark_recorder,
    index: usize,
    buf: *mut c_char,
    len: usize,
    path_len: *mut usize,
) -> waymark_result {
    if buf.is_null() && len > 0 {
        return fail(waymark_result::NullParameter, "buf must not be NULL when len > 0");
    }
    with_recorder(recorder, |r| {
        let Some(path) = r.stats().files.get(index) else {
            return fail(waymark_result::InputRejected, format!("no walk file {index}"));
        };
        let path = path.display().to_string();
        write(path_len, path.len());
        if path.len() >= len {
            copy_string("", buf, len);
            return fail(
                waymark_result::BufferTooSmall,
                format!("the path needs {} bytes with its NUL", path.len() + 1),
            );
        }
        copy_string(&path, buf, len);
        waymark_result::Ok
    })
}
