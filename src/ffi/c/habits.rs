//! The C API's habit learning: learn, export, import, clear, and the learned fix error.

use super::{
    call, copy_string, fail, fail_with, read, string_arg, waymark_engine, waymark_fix_bias,
    waymark_habit_report, waymark_result, with_handle, write,
};
use crate::ffi::error::PositioningError;
use crate::ffi::record::{AppFixBias, AppHabitReport};
use ::waymark_engine::Engine;
use std::ffi::c_char;

/// Learns the user's habits from the epochs of the engine's history not learned from yet
/// (the last 500, with the user's feedback and position fixes): which way they usually go
/// from each place, and the error of their position fixes. From the next epoch on the learned
/// moves weigh on the motion model and fixes are corrected. Each epoch is learned from once.
/// It runs on the calling thread for up to a few hundred milliseconds on a large site; other
/// calls on the engine wait for it, and the callback is not called from it. `*out` (may be
/// NULL) receives what the pass did. Keep the result with `waymark_engine_export_habits`.
#[no_mangle]
pub extern "C" fn waymark_engine_learn_habits(
    engine: *mut waymark_engine,
    out: *mut waymark_habit_report,
) -> waymark_result {
    let learn = |e: &mut Engine| match e.learn_habits() {
        Ok(report) => Ok(waymark_habit_report::from(AppHabitReport::new(&report, e.habits()))),
        // Its input is the engine's own history and validated options: a bug.
        Err(err) => Err(PositioningError::internal(format!("learning habits: {err}"))),
    };
    call(engine, learn, |report| {
        write(out, report);
        waymark_result::Ok
    })
}

/// Writes the learned habits as versioned JSON (NUL-terminated UTF-8), to store per user and
/// site and give back to `waymark_engine_import_habits` in a later session, and their length
/// in bytes without the NUL into `*json_len` (may be NULL). The JSON is never truncated: when
/// it does not fit in `len` bytes with its NUL, `buf` receives an empty string (when `len` >
/// 0) and the call returns `WAYMARK_RESULT_BUFFER_TOO_SMALL`; call again with `*json_len` + 1
/// bytes. `buf` may be NULL with `len` 0 to ask the length. Another thread's learning or
/// import may change the model between the two calls, so loop until `WAYMARK_RESULT_OK`.
#[no_mangle]
pub extern "C" fn waymark_engine_export_habits(
    engine: *const waymark_engine,
    buf: *mut c_char,
    len: usize,
    json_len: *mut usize,
) -> waymark_result {
    if buf.is_null() && len > 0 {
        return fail(waymark_result::NullParameter, "buf must not be NULL when len > 0");
    }
    read(
        engine,
        |e| e.export_habits(),
        |json| {
            write(json_len, json.len());
            if json.len() >= len {
                copy_string("", buf, len);
                return fail(
                    waymark_result::BufferTooSmall,
                    format!(
                        "the habits' JSON needs {} bytes with its NUL, the buffer has {len}",
                        json.len() + 1
                    ),
                );
            }
            copy_string(&json, buf, len);
            waymark_result::Ok
        },
    )
}

/// Replaces the engine's habits by a model from `waymark_engine_export_habits` on the same
/// site (`json`: NUL-terminated UTF-8), learning on from where it left off. A model that does
/// not parse, is not a habit model, is of a newer layout, was learned on another site or
/// another build of the site file, or holds a value out of range returns
/// `WAYMARK_RESULT_HABITS_REJECTED` and changes nothing.
#[no_mangle]
pub extern "C" fn waymark_engine_import_habits(
    engine: *mut waymark_engine,
    json: *const c_char,
) -> waymark_result {
    with_handle(engine, |handle| {
        let json = match string_arg(json, "json") {
            Ok(json) => json,
            Err(code) => return code,
        };
        match handle.import_habits(&json) {
            Ok(()) => waymark_result::Ok,
            Err(e) => fail_with(&e),
        }
    })
}

/// Forgets every learned habit and the fix error.
#[no_mangle]
pub extern "C" fn waymark_engine_clear_habits(engine: *mut waymark_engine) -> waymark_result {
    call(
        engine,
        |e| {
            e.clear_habits();
            Ok(())
        },
        |()| waymark_result::Ok,
    )
}

/// The fix error learned so far into `*out`: zero bias and spread 1 before any fix was
/// learned from.
#[no_mangle]
pub extern "C" fn waymark_engine_fix_bias(
    engine: *const waymark_engine,
    out: *mut waymark_fix_bias,
) -> waymark_result {
    if out.is_null() {
        return fail(waymark_result::NullParameter, "out must not be NULL");
    }
    read(
        engine,
        |e| waymark_fix_bias::from(AppFixBias::from(e.fix_bias())),
        |error| {
            write(out, error);
            waymark_result::Ok
        },
    )
}
