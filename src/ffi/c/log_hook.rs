//! The C API's log hook: Waymark's `log` records to a C function.

use super::{boundary, c_string, fail, waymark_log_callback, waymark_log_level, waymark_result};
use crate::ffi::logging::{init_logging, LogLevel, LogSink};
use std::ffi::{c_char, c_void};
use std::sync::Arc;

/// Where `waymark_set_log_callback` sends log records.
struct CLogSink {
    function: unsafe extern "C" fn(
        userdata: *mut c_void,
        level: u32,
        target: *const c_char,
        message: *const c_char,
    ),
    userdata: usize,
}

impl LogSink for CLogSink {
    fn log(&self, level: LogLevel, target: String, message: String) {
        let level = match level {
            LogLevel::Error => waymark_log_level::Error,
            LogLevel::Warn => waymark_log_level::Warn,
            LogLevel::Info => waymark_log_level::Info,
            LogLevel::Debug => waymark_log_level::Debug,
            LogLevel::Trace => waymark_log_level::Trace,
        };
        let (target, message) = (c_string(&target), c_string(&message));
        // SAFETY: the function and its userdata were registered together by the caller of
        // `waymark_set_log_callback`, who guarantees they stay valid while Waymark may log; the
        // strings live until the call returns.
        unsafe {
            (self.function)(self.userdata as *mut c_void, level as u32, target.as_ptr(), message.as_ptr())
        };
    }
}

/// Sends Waymark's log records at `level` (a `waymark_log_level`) and above to `callback`, with
/// `userdata` passed back untouched; a NULL callback stops them (on Android they then go to
/// logcat, tag "waymark"). Safe to call again: the latest callback and level win. A record
/// being logged on another thread while this is called may still reach the previous callback,
/// so keep its userdata valid for the life of the process (a static). A level that does not
/// exist returns `WAYMARK_RESULT_INVALID_CONFIG`. A panic Waymark caught (`WAYMARK_RESULT_PANIC`)
/// arrives as an `ERROR` record, "Waymark panicked at FILE:LINE: MESSAGE", and is not printed
/// on stderr. When and on which thread records arrive: `waymark_log_callback`.
#[no_mangle]
pub extern "C" fn waymark_set_log_callback(
    level: u32,
    callback: waymark_log_callback,
    userdata: *mut c_void,
) -> waymark_result {
    boundary(|| {
        let level = match level {
            1 => LogLevel::Error,
            2 => LogLevel::Warn,
            3 => LogLevel::Info,
            4 => LogLevel::Debug,
            5 => LogLevel::Trace,
            l => return fail(waymark_result::InvalidConfig, format!("log level {l} does not exist")),
        };
        let sink = callback
            .map(|function| Arc::new(CLogSink { function, userdata: userdata as usize }) as Arc<dyn LogSink>);
        init_logging(sink, level);
        waymark_result::Ok
    })
}
