//! The C API's map evidence from the session (docs/evidence.md#from-a-session) and a refitted
//! site loaded in place (docs/evidence.md#loading-a-refitted-site).

use super::{boundary, call, fail, fail_with, waymark_engine, waymark_result, with_handle, write};
use crate::ffi::error::PositioningError;
use ::waymark_engine::site::Site;
use ::waymark_engine::SessionEvidence;
use std::sync::Arc;

/// Map evidence a session gathered: the evidence file's bytes (docs/evidence.md#file-format),
/// ready to upload, and what went into it. Filled by `waymark_engine_take_evidence` and
/// `waymark_engine_replace_site`; free the bytes with `waymark_evidence_free`. `bytes` is NULL
/// and `len` 0 when there was nothing to take (the engine was not gathering).
#[repr(C)]
#[derive(Debug)]
pub struct waymark_evidence {
    /// The evidence file, `len` bytes, owned by Waymark until `waymark_evidence_free`.
    pub bytes: *mut u8,
    /// Its length in bytes.
    pub len: usize,
    /// Scans in it.
    pub scans: u64,
    /// Accepted scans left out of it (their posterior could not be had or added).
    pub scans_dropped: u64,
}

impl waymark_evidence {
    const NONE: waymark_evidence =
        waymark_evidence { bytes: std::ptr::null_mut(), len: 0, scans: 0, scans_dropped: 0 };

    fn of(taken: Option<SessionEvidence>) -> waymark_evidence {
        let Some(taken) = taken else { return Self::NONE };
        let bytes = taken.evidence.to_bytes().into_boxed_slice();
        let len = bytes.len();
        let bytes = Box::into_raw(bytes).cast::<u8>();
        waymark_evidence { bytes, len, scans: taken.scans, scans_dropped: taken.scans_dropped }
    }
}

/// Starts gathering map evidence from the session's scans, for the app to upload to whoever
/// refits the venue's site: state indices and hashed transmitter ids, no time and no track
/// (docs/privacy.md#evidence). Discards what was being gathered.
#[no_mangle]
pub extern "C" fn waymark_engine_start_evidence(engine: *mut waymark_engine) -> waymark_result {
    call(
        engine,
        |e| {
            e.start_evidence();
            Ok(())
        },
        |()| waymark_result::Ok,
    )
}

/// Stops gathering map evidence and discards what was gathered and not taken.
#[no_mangle]
pub extern "C" fn waymark_engine_stop_evidence(engine: *mut waymark_engine) -> waymark_result {
    call(
        engine,
        |e| {
            e.stop_evidence();
            Ok(())
        },
        |()| waymark_result::Ok,
    )
}

/// Writes into `*out` the map evidence gathered since `waymark_engine_start_evidence` or the
/// last take, as one walk; gathering goes on from nothing. `out->bytes` is NULL when the engine
/// is not gathering. Free it with `waymark_evidence_free`.
#[no_mangle]
pub extern "C" fn waymark_engine_take_evidence(
    engine: *mut waymark_engine,
    out: *mut waymark_evidence,
) -> waymark_result {
    if out.is_null() {
        return fail(waymark_result::NullParameter, "out must not be NULL");
    }
    call(
        engine,
        |e| Ok(e.take_evidence()),
        |taken| {
            write(out, waymark_evidence::of(taken));
            waymark_result::Ok
        },
    )
}

/// Loads the site file of `len` bytes at `site_file` (binary or JSON, a site refitted from
/// evidence, say) in place of the engine's own, with the engine's options, without ending the
/// session: with the same states and zones the position, track and history carry on;
/// otherwise the estimate starts afresh, keeping the motion, the phone's RSSI offset, the
/// barometer and the geofences. `*out` (may be NULL: it is then freed) receives the evidence
/// gathered on the old site and not taken yet (NULL bytes when there is none). A file that is
/// not a valid site, or one the engine's options do not fit (a hashed site without its salt),
/// returns the site's error and changes nothing.
#[no_mangle]
pub extern "C" fn waymark_engine_replace_site(
    engine: *mut waymark_engine,
    site_file: *const u8,
    len: usize,
    out: *mut waymark_evidence,
) -> waymark_result {
    if site_file.is_null() {
        return fail(waymark_result::NullParameter, "site_file must not be NULL");
    }
    with_handle(engine, |handle| {
        // SAFETY: the caller guarantees `site_file` points to `len` readable bytes.
        let bytes = unsafe { std::slice::from_raw_parts(site_file, len) };
        let site = match Site::from_bytes(bytes) {
            Ok(site) => Arc::new(site),
            // Reported to the callbacks as the engine's own failures are.
            Err(e) => return fail_with(&handle.reject(PositioningError::from(e))),
        };
        match handle.replace_site(site) {
            Ok(taken) => {
                // Without `out` the evidence is dropped here, never allocated for nobody.
                if !out.is_null() {
                    write(out, waymark_evidence::of(taken));
                }
                waymark_result::Ok
            }
            Err(e) => fail_with(&e),
        }
    })
}

/// Frees the bytes of `evidence` (filled by `waymark_engine_take_evidence` or
/// `waymark_engine_replace_site`) and sets them to NULL and 0, so that freeing it again does
/// nothing. NULL does nothing.
#[no_mangle]
pub extern "C" fn waymark_evidence_free(evidence: *mut waymark_evidence) {
    let _ = boundary(|| {
        // SAFETY: a non-NULL `evidence` points to a `waymark_evidence` Waymark filled (the
        // header's contract), readable and writable.
        let Some(evidence) = (unsafe { evidence.as_mut() }) else {
            return waymark_result::Ok;
        };
        if !evidence.bytes.is_null() {
            let slice = std::ptr::slice_from_raw_parts_mut(evidence.bytes, evidence.len);
            // SAFETY: non-NULL bytes came from `Box::into_raw` of a boxed slice of `len` bytes
            // in `waymark_evidence::of` and were not freed since (freeing sets them to NULL).
            drop(unsafe { Box::from_raw(slice) });
        }
        *evidence = waymark_evidence::NONE;
        waymark_result::Ok
    });
}
