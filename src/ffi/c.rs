//! The C ABI, in rustls-ffi's conventions: one `waymark_` prefix, opaque handles, a
//! `waymark_result` code from every call, out-parameters last, NULL checks, every body behind
//! a panic boundary, a thread-local last-error message, `_free` for what Waymark allocates.
//! The header `bindings/c/waymark.h` is generated from this file by cbindgen.
#![deny(clippy::undocumented_unsafe_blocks)]
#![allow(non_camel_case_types)]
// These functions are called from C, which cannot see `unsafe`: each pointer's contract is in
// the header, and each dereference carries a SAFETY comment (as rustls-ffi does).
#![allow(clippy::not_unsafe_ptr_arg_deref)]

use super::delivery::{lock, Delivery};
use crate::engine::{Engine, Position};
use crate::radio::{Reading, Scan, TransmitterId};
use crate::sensors::{MdiScenario, MotionState, SensorSample};
use crate::site::Site;
use crate::EngineConfig;
use std::cell::RefCell;
use std::ffi::{c_char, c_void, CStr};
use std::sync::{Arc, Mutex};

/// What a call did.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum waymark_result {
    /// Success.
    Ok = 0,
    /// A required pointer was NULL.
    NullParameter = 1,
    /// The site file could not be read or is malformed (see `waymark_last_error`).
    InvalidSite = 2,
    /// The configuration is invalid.
    InvalidConfig = 3,
    /// The input was rejected and the engine is unchanged; `waymark_last_error` says why. A
    /// scan, an advance or a position fix is rejected when its timestamp is not after the last
    /// epoch's (a step back in time, or a duplicate), feedback when it is before it. A
    /// position fix or a confirmed position is also rejected for a NaN or infinite coordinate,
    /// an accuracy or radius not > 0, a floor the site does not have, or a position too far
    /// from the site (for a fix, beyond its own error; for a confirmed position, no state
    /// within the radius); feedback for a zone the site does not have; a zone index out of
    /// range for `waymark_engine_zone_name`. A scan is also rejected when
    /// - it has no readings;
    /// - a reading's RSSI is NaN, infinite or below -1000 dBm;
    /// - a reading's RSSI is above +100 dBm, more than any receiver reports;
    /// - no reading is of a transmitter the site knows;
    /// - a transmitter id is malformed: a BSSID, beacon UUID or beacon address that does not
    ///   parse, or a beacon with neither a UUID nor an address.
    InputRejected = 4,
    /// No position yet.
    NoPosition = 5,
    /// A string was not UTF-8.
    InvalidUtf8 = 6,
    /// The site's transmitter ids are salted hashes and no salt, or not the salt they were
    /// hashed with, was given (`waymark_engine_new_with_salt`).
    SaltMismatch = 7,
    /// `waymark_engine_import_habits` refused the model and the engine's habits are unchanged:
    /// the JSON does not parse, is not a Waymark habit model, is of a newer layout than this
    /// build reads, was learned on another site (or another build of the site file), or holds
    /// a value out of range; `waymark_last_error` says which, with the field's path.
    HabitsRejected = 8,
    /// The caller's buffer is too small for the whole text; nothing but an empty string was
    /// written to it, and the length it needs was returned (`waymark_engine_export_habits`).
    BufferTooSmall = 9,
    /// Waymark panicked, or refused its own data (a bug); the engine stays usable. A scan or
    /// an advance that panicked half-way is undone: the engine is as it was before the call,
    /// and no callback hears of it.
    Panic = 99,
}

/// An engine. Opaque; create with `waymark_engine_new`, free with `waymark_engine_free`.
/// Thread-safe: any thread may call any function on it.
pub struct waymark_engine {
    engine: Mutex<Engine>,
    /// The callback and its userdata, as `waymark_engine_set_callback` left them.
    callback: Mutex<Option<Callback>>,
    /// Held while the callback runs, so that setting another one can wait for it to return.
    calling: Mutex<()>,
    /// Positions not yet passed to the callback.
    positions: Delivery<waymark_position>,
}

#[derive(Clone, Copy)]
struct Callback {
    function: unsafe extern "C" fn(userdata: *mut c_void, position: *const waymark_position),
    userdata: usize,
}

/// One accelerometer (m/s², gravity included), gyroscope (rad/s) or magnetometer (µT) sample
/// in the phone's frame, with a monotonic timestamp in ns.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct waymark_sample {
    /// ns on the clock shared by every input.
    pub timestamp_ns: u64,
    /// x axis.
    pub x: f64,
    /// y axis.
    pub y: f64,
    /// z axis.
    pub z: f64,
}

/// A WiFi access point heard in a scan.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct waymark_wifi_reading {
    /// NUL-terminated BSSID, any common notation.
    pub bssid: *const c_char,
    /// dBm.
    pub rssi_dbm: f64,
    /// How long before the scan it was measured, ms.
    pub age_ms: u64,
}

/// A BLE beacon heard in a scan: an iBeacon by its UUID, major and minor, or any beacon
/// (Eddystone, an iBeacon left at major = minor = 0) by its advertiser address.
///
/// With an `address`, a beacon whose `uuid` is NULL or empty, or whose major and minor are both
/// 0, is identified by the address; otherwise by UUID, major and minor (the address must still
/// be valid). Neither a UUID nor an address, or one that does not parse: `InputRejected`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct waymark_beacon_reading {
    /// NUL-terminated proximity UUID; NULL or empty for a beacon known by its address only.
    pub uuid: *const c_char,
    /// Major.
    pub major: u16,
    /// Minor.
    pub minor: u16,
    /// dBm.
    pub rssi_dbm: f64,
    /// How long before the scan it was measured, ms.
    pub age_ms: u64,
    /// NUL-terminated advertiser MAC address, any common notation; NULL or empty when unknown.
    pub address: *const c_char,
}

/// A position.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct waymark_position {
    /// Epoch time, ns.
    pub timestamp_ns: u64,
    /// x in the site frame, m.
    pub x: f64,
    /// y in the site frame, m.
    pub y: f64,
    /// Floor index in the site file.
    pub floor: u32,
    /// Probability of that floor.
    pub floor_probability: f64,
    /// The most likely zone (a room, a corridor), an index into the site file's zones
    /// (`waymark_engine_zone_name`); -1 when the site has no zones or more posterior mass lies
    /// outside every zone than in any one.
    pub zone: i32,
    /// Probability of `zone` (of being in no zone when it is -1).
    pub zone_probability: f64,
    /// Radius of the 68% circle, m.
    pub accuracy_m: f64,
    /// Radius of the 95% circle, m.
    pub accuracy_95_m: f64,
    /// Direction of travel, degrees clockwise from the site's +y axis; NaN when unknown.
    pub heading_deg: f64,
    /// One standard deviation of the heading, degrees; NaN when unknown.
    pub heading_accuracy_deg: f64,
    /// 0 unknown, 1 stationary, 2 walking.
    pub motion_state: u32,
    /// HIPE scenario: 0 distance & heading, 1 distance, 2 heading & speed, 3 speed.
    pub scenario: u32,
    /// Steps since the previous epoch.
    pub steps: u32,
    /// Distance walked since the radio last explained a scan, m: 0 while it does; above 0 the
    /// phone is probably beyond the surveyed area and both radii include this distance.
    pub beyond_radio_m: f64,
}

/// The learned error of external position fixes: subtract the bias from a fix, then widen its
/// accuracy by `spread` (the engine does both to every fix it takes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct waymark_fix_error {
    /// Mean error of the fixes along the site's x axis, m (0 before any fix was learned from).
    pub bias_x_m: f64,
    /// Mean error along the site's y axis, m.
    pub bias_y_m: f64,
    /// Factor on the fixes' own accuracy (1: they are as good as they say).
    pub spread: f64,
}

impl From<crate::habits::FixError> for waymark_fix_error {
    fn from(e: crate::habits::FixError) -> Self {
        Self { bias_x_m: e.bias_m[0], bias_y_m: e.bias_m[1], spread: e.spread }
    }
}

/// What one `waymark_engine_learn_habits` pass did.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct waymark_habit_report {
    /// Epochs of the history learned from in this pass (those learned before are skipped).
    pub epochs: usize,
    /// Runs of epochs without a long gap learned from.
    pub segments: usize,
    /// Runs skipped: a single epoch, or over too many states.
    pub segments_skipped: usize,
    /// Epochs with the user's feedback.
    pub feedback_epochs: usize,
    /// Epochs of position fixes.
    pub fix_epochs: usize,
    /// Baum-Welch iterations run.
    pub iterations: usize,
    /// Values of ln p(observations | model) computed: one before each iteration and one for
    /// the learned model; 0 when there was nothing to learn from.
    pub log_likelihood_count: usize,
    /// The first of them (before learning), nats; NaN when there is none.
    pub log_likelihood_first: f64,
    /// The last (the learned model), nats, never below the first; NaN when there is none.
    pub log_likelihood_last: f64,
    /// Feedback epochs the habits ruled out, at which learning restarted.
    pub restarts: usize,
    /// Transitions with a learned count after the pass (all passes so far).
    pub learned_transitions: usize,
    /// Epochs learned from over all passes, including those of an imported model.
    pub total_epochs: u64,
    /// The fix error after the pass.
    pub fix_error: waymark_fix_error,
    /// How strongly the learned moves are applied (a pseudo-count per reachable move); NaN
    /// when they are not (they did not yet predict held-out parts of the history).
    pub strength: f64,
}

/// Called with every new position, in the order of the epochs, never from two threads at once,
/// with no lock held, on a thread that called the engine: usually the one whose call made the
/// position. While one thread is running the callback, positions made by other threads' calls
/// are passed to it by that thread, after the current one, so such a call may return before
/// its position reaches the callback; every position has reached it by the time all calls
/// have returned. A callback may call the engine (what it makes is delivered after the current
/// call returns, by the same thread).
pub type waymark_position_callback =
    Option<unsafe extern "C" fn(userdata: *mut c_void, position: *const waymark_position)>;

thread_local! {
    static LAST_ERROR: RefCell<String> = const { RefCell::new(String::new()) };
}

fn fail(code: waymark_result, message: impl Into<String>) -> waymark_result {
    let message = message.into();
    LAST_ERROR.with(|e| *e.borrow_mut() = message);
    code
}

/// Runs `body`, turning a panic into `waymark_result::Panic`.
fn boundary(body: impl FnOnce() -> waymark_result) -> waymark_result {
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(body)) {
        Ok(code) => code,
        Err(_) => fail(waymark_result::Panic, "Waymark panicked; the call had no effect"),
    }
}

fn convert(p: &Position) -> waymark_position {
    waymark_position {
        timestamp_ns: p.timestamp_ns,
        x: p.x,
        y: p.y,
        floor: p.floor as u32,
        floor_probability: p.floor_probability,
        // At most i32::MAX zones (`site::MAX_ZONES`).
        zone: p.zone.map_or(-1, |z| i32::try_from(z).unwrap_or(-1)),
        zone_probability: p.zone_probability,
        accuracy_m: p.accuracy_m,
        accuracy_95_m: p.accuracy_95_m,
        heading_deg: p.heading_rad.map_or(f64::NAN, f64::to_degrees),
        heading_accuracy_deg: p.heading_accuracy_rad.map_or(f64::NAN, f64::to_degrees),
        motion_state: match p.motion_state {
            MotionState::Unknown => 0,
            MotionState::Stationary => 1,
            MotionState::Walking => 2,
        },
        scenario: match p.scenario {
            MdiScenario::DistanceHeading => 0,
            MdiScenario::Distance => 1,
            MdiScenario::HeadingSpeed => 2,
            MdiScenario::Speed => 3,
        },
        steps: p.steps,
        beyond_radio_m: p.beyond_radio_m,
    }
}

fn create(
    site: Result<Site, crate::SiteError>,
    salt: Option<&[u8]>,
    out: *mut *mut waymark_engine,
) -> waymark_result {
    let site = match site {
        Ok(site) => site,
        Err(e) => return fail(waymark_result::InvalidSite, e.to_string()),
    };
    let site_salt = match salt.map(crate::Salt::new).transpose() {
        Ok(salt) => salt,
        Err(m) => return fail(waymark_result::InvalidConfig, format!("salt: {m}")),
    };
    let engine = match Engine::new(Arc::new(site), EngineConfig { site_salt, ..EngineConfig::default() }) {
        Ok(engine) => engine,
        Err(e @ crate::Error::Site(crate::SiteError::SaltRequired | crate::SiteError::WrongSalt)) => {
            return fail(waymark_result::SaltMismatch, e.to_string())
        }
        Err(e @ crate::Error::Site(_)) => return fail(waymark_result::InvalidSite, e.to_string()),
        Err(e) => return fail(waymark_result::InvalidConfig, e.to_string()),
    };
    let handle = Box::new(waymark_engine {
        engine: Mutex::new(engine),
        callback: Mutex::new(None),
        calling: Mutex::new(()),
        positions: Delivery::new(),
    });
    // SAFETY: `out` was checked non-NULL by the caller of `create` and points to writable
    // storage for one pointer, as the header documents.
    unsafe { *out = Box::into_raw(handle) };
    waymark_result::Ok
}

/// The salt argument: `None` for NULL with length 0.
fn salt_arg<'a>(salt: *const u8, salt_len: usize) -> Result<Option<&'a [u8]>, waymark_result> {
    match (salt.is_null(), salt_len) {
        (true, 0) => Ok(None),
        (true, _) => Err(fail(waymark_result::NullParameter, "salt must not be NULL when salt_len > 0")),
        // SAFETY: a non-NULL `salt` points to `salt_len` readable bytes (the header's contract).
        (false, _) => Ok(Some(unsafe { std::slice::from_raw_parts(salt, salt_len) })),
    }
}

fn new_from_bytes(
    site_file: *const u8,
    len: usize,
    salt: *const u8,
    salt_len: usize,
    out: *mut *mut waymark_engine,
) -> waymark_result {
    boundary(|| {
        if site_file.is_null() || out.is_null() {
            return fail(waymark_result::NullParameter, "site_file and out must not be NULL");
        }
        let salt = match salt_arg(salt, salt_len) {
            Ok(salt) => salt,
            Err(code) => return code,
        };
        // SAFETY: the caller guarantees `site_file` points to `len` readable bytes.
        let bytes = unsafe { std::slice::from_raw_parts(site_file, len) };
        create(Site::from_bytes(bytes), salt, out)
    })
}

fn new_from_path(
    path: *const c_char,
    salt: *const u8,
    salt_len: usize,
    out: *mut *mut waymark_engine,
) -> waymark_result {
    boundary(|| {
        if path.is_null() || out.is_null() {
            return fail(waymark_result::NullParameter, "path and out must not be NULL");
        }
        let salt = match salt_arg(salt, salt_len) {
            Ok(salt) => salt,
            Err(code) => return code,
        };
        // SAFETY: the caller guarantees a NUL-terminated string at `path`.
        let Ok(path) = unsafe { CStr::from_ptr(path) }.to_str() else {
            return fail(waymark_result::InvalidUtf8, "path is not UTF-8");
        };
        create(Site::load(path), salt, out)
    })
}

/// Creates an engine from a site file's contents, `len` bytes at `site_file`: the binary
/// encoding (`waymark site pack`, what an app should ship: it loads several times faster and
/// in a third of the memory) or JSON text (not necessarily NUL-terminated). On success `*out`
/// holds the engine; free it with `waymark_engine_free`.
/// A site whose transmitter ids are hashed needs `waymark_engine_new_with_salt`.
#[no_mangle]
pub extern "C" fn waymark_engine_new(
    site_file: *const u8,
    len: usize,
    out: *mut *mut waymark_engine,
) -> waymark_result {
    new_from_bytes(site_file, len, std::ptr::null(), 0, out)
}

/// Creates an engine from the site file (binary or JSON) at the NUL-terminated `path`.
/// A site whose transmitter ids are hashed needs `waymark_engine_new_from_path_with_salt`.
#[no_mangle]
pub extern "C" fn waymark_engine_new_from_path(
    path: *const c_char,
    out: *mut *mut waymark_engine,
) -> waymark_result {
    new_from_path(path, std::ptr::null(), 0, out)
}

/// As `waymark_engine_new`, for a site file whose transmitter ids are salted hashes
/// (`waymark survey --salt-file`, `waymark site hash`): `salt` points to `salt_len` bytes (at
/// least 16; the bytes the salt file's hex digits stand for), copied before the call returns.
/// Scans are hashed with it before matching. A hashed site with no salt (`salt` NULL,
/// `salt_len` 0) or another salt returns `WAYMARK_RESULT_SALT_MISMATCH`; a salt given for a
/// site with raw ids is not needed and is ignored.
#[no_mangle]
pub extern "C" fn waymark_engine_new_with_salt(
    site_file: *const u8,
    len: usize,
    salt: *const u8,
    salt_len: usize,
    out: *mut *mut waymark_engine,
) -> waymark_result {
    new_from_bytes(site_file, len, salt, salt_len, out)
}

/// As `waymark_engine_new_from_path`, with the site's salt as in `waymark_engine_new_with_salt`.
#[no_mangle]
pub extern "C" fn waymark_engine_new_from_path_with_salt(
    path: *const c_char,
    salt: *const u8,
    salt_len: usize,
    out: *mut *mut waymark_engine,
) -> waymark_result {
    new_from_path(path, salt, salt_len, out)
}

/// Frees an engine. NULL is ignored.
#[no_mangle]
pub extern "C" fn waymark_engine_free(engine: *mut waymark_engine) {
    let _ = boundary(|| {
        if !engine.is_null() {
            // SAFETY: `engine` came from `waymark_engine_new*` (Box::into_raw) and is freed
            // once, as the header requires.
            drop(unsafe { Box::from_raw(engine) });
        }
        waymark_result::Ok
    });
}

/// Borrows the handle `engine`, or fails with `NullParameter`.
fn with_handle(
    engine: *const waymark_engine,
    body: impl FnOnce(&waymark_engine) -> waymark_result,
) -> waymark_result {
    boundary(|| {
        // SAFETY: a non-NULL `engine` is a live handle from `waymark_engine_new*` (the header's
        // contract); `waymark_engine` is Sync, so a shared reference from any thread is fine.
        let Some(handle) = (unsafe { engine.as_ref() }) else {
            return fail(waymark_result::NullParameter, "engine must not be NULL");
        };
        body(handle)
    })
}

/// Runs `body` on the engine behind `engine` under its lock, or fails with `NullParameter`.
/// The lock is taken even if a panic poisoned it: an epoch that panics is undone by the engine.
fn with_engine(
    engine: *const waymark_engine,
    body: impl FnOnce(&mut Engine) -> waymark_result,
) -> waymark_result {
    with_handle(engine, |handle| body(&mut lock(&handle.engine)))
}

fn samples<'a>(batch: *const waymark_sample, count: usize) -> Option<&'a [waymark_sample]> {
    if count == 0 {
        return Some(&[]);
    }
    // SAFETY: a non-NULL `batch` points to `count` samples (the header's contract).
    (!batch.is_null()).then(|| unsafe { std::slice::from_raw_parts(batch, count) })
}

fn push_samples(
    engine: *mut waymark_engine,
    batch: *const waymark_sample,
    count: usize,
    accepted: *mut usize,
    push: fn(&mut Engine, &[SensorSample]) -> crate::sensors::BatchReport,
) -> waymark_result {
    with_engine(engine, |inner| {
        let Some(batch) = samples(batch, count) else {
            return fail(waymark_result::NullParameter, "samples must not be NULL when count > 0");
        };
        let converted: Vec<SensorSample> = batch
            .iter()
            .map(|s| SensorSample { timestamp_ns: s.timestamp_ns, x: s.x, y: s.y, z: s.z })
            .collect();
        let report = push(inner, &converted);
        if !accepted.is_null() {
            // SAFETY: a non-NULL `accepted` points to writable storage for one size_t.
            unsafe { *accepted = report.accepted };
        }
        waymark_result::Ok
    })
}

/// Accelerometer samples (m/s², gravity included), oldest first. Bad samples are dropped and
/// counted; `*accepted` (may be NULL) receives how many were taken.
#[no_mangle]
pub extern "C" fn waymark_engine_push_accelerometer(
    engine: *mut waymark_engine,
    samples: *const waymark_sample,
    count: usize,
    accepted: *mut usize,
) -> waymark_result {
    push_samples(engine, samples, count, accepted, Engine::push_accelerometer)
}

/// Gyroscope samples (rad/s); as `waymark_engine_push_accelerometer`.
#[no_mangle]
pub extern "C" fn waymark_engine_push_gyroscope(
    engine: *mut waymark_engine,
    samples: *const waymark_sample,
    count: usize,
    accepted: *mut usize,
) -> waymark_result {
    push_samples(engine, samples, count, accepted, Engine::push_gyroscope)
}

/// Magnetometer samples (µT); as `waymark_engine_push_accelerometer`.
#[no_mangle]
pub extern "C" fn waymark_engine_push_magnetometer(
    engine: *mut waymark_engine,
    samples: *const waymark_sample,
    count: usize,
    accepted: *mut usize,
) -> waymark_result {
    push_samples(engine, samples, count, accepted, Engine::push_magnetometer)
}

fn string_arg(text: *const c_char, what: &str) -> Result<String, waymark_result> {
    if text.is_null() {
        return Err(fail(waymark_result::NullParameter, format!("{what} must not be NULL")));
    }
    // SAFETY: a non-NULL string argument is NUL-terminated (the header's contract).
    match unsafe { CStr::from_ptr(text) }.to_str() {
        Ok(s) => Ok(s.to_owned()),
        Err(_) => Err(fail(waymark_result::InvalidUtf8, format!("{what} is not UTF-8"))),
    }
}

/// As `string_arg`, with NULL as `None`.
fn optional_string_arg(text: *const c_char, what: &str) -> Result<Option<String>, waymark_result> {
    if text.is_null() {
        Ok(None)
    } else {
        string_arg(text, what).map(Some)
    }
}

/// Runs an epoch under the lock, queueing its position under it (so in the order of the
/// epochs), writes `out`, then passes the queue to the callback with no lock held.
fn epoch(
    engine: *mut waymark_engine,
    out: *mut waymark_position,
    body: impl FnOnce(&mut Engine) -> Result<Position, waymark_result>,
) -> waymark_result {
    with_handle(engine, |handle| {
        let position = {
            let mut engine = lock(&handle.engine);
            body(&mut engine).map(|p| {
                let position = convert(&p);
                handle.positions.push(position);
                position
            })
        };
        match position {
            Ok(position) => {
                if !out.is_null() {
                    // SAFETY: a non-NULL `out` points to writable storage for one
                    // waymark_position.
                    unsafe { *out = position };
                }
                deliver(handle);
                waymark_result::Ok
            }
            Err(code) => code,
        }
    })
}

/// Passes the queued positions to the callback, one thread at a time, in order ([`Delivery`]),
/// reading the callback afresh for each.
fn deliver(handle: &waymark_engine) {
    handle.positions.deliver(|position| {
        let _calling = lock(&handle.calling);
        let callback = *lock(&handle.callback);
        if let Some(Callback { function, userdata }) = callback {
            // SAFETY: the function and its userdata were registered together by the caller of
            // `waymark_engine_set_callback`, who guarantees they stay valid until replaced; a
            // replacement waits for this call to return (`calling`).
            unsafe { function(userdata as *mut c_void, &position) };
        }
    });
}

/// A scan: WiFi readings and BLE beacon readings (either array may be NULL with count 0). One
/// positioning epoch; `*out` (may be NULL) receives the new position. A rejected scan (out of
/// order, empty, an RSSI that is NaN, infinite, below -1000 or above +100 dBm, no known
/// transmitter, a malformed id: see `WAYMARK_RESULT_INPUT_REJECTED`) returns `InputRejected`
/// and changes nothing.
#[no_mangle]
pub extern "C" fn waymark_engine_push_scan(
    engine: *mut waymark_engine,
    timestamp_ns: u64,
    wifi: *const waymark_wifi_reading,
    wifi_count: usize,
    beacons: *const waymark_beacon_reading,
    beacon_count: usize,
    out: *mut waymark_position,
) -> waymark_result {
    epoch(engine, out, |engine| {
        if (wifi.is_null() && wifi_count > 0) || (beacons.is_null() && beacon_count > 0) {
            return Err(fail(
                waymark_result::NullParameter,
                "reading arrays must not be NULL when count > 0",
            ));
        }
        let mut readings = Vec::with_capacity(wifi_count + beacon_count);
        if wifi_count > 0 {
            // SAFETY: checked non-NULL above; the caller guarantees `wifi_count` elements.
            for w in unsafe { std::slice::from_raw_parts(wifi, wifi_count) } {
                let bssid = string_arg(w.bssid, "bssid")?;
                let transmitter =
                    TransmitterId::wifi(&bssid).map_err(|m| fail(waymark_result::InputRejected, m))?;
                readings.push(Reading {
                    transmitter,
                    rssi_dbm: w.rssi_dbm,
                    age_ns: w.age_ms.saturating_mul(1_000_000),
                });
            }
        }
        if beacon_count > 0 {
            // SAFETY: checked non-NULL above; the caller guarantees `beacon_count` elements.
            for b in unsafe { std::slice::from_raw_parts(beacons, beacon_count) } {
                let uuid = optional_string_arg(b.uuid, "uuid")?.unwrap_or_default();
                let address = optional_string_arg(b.address, "address")?;
                let transmitter = super::beacon_id(&uuid, b.major, b.minor, address.as_deref())
                    .map_err(|m| fail(waymark_result::InputRejected, m))?;
                readings.push(Reading {
                    transmitter,
                    rssi_dbm: b.rssi_dbm,
                    age_ns: b.age_ms.saturating_mul(1_000_000),
                });
            }
        }
        super::uniffi::fault_injection(timestamp_ns);
        engine
            .push_scan(&Scan { timestamp_ns, readings })
            .map_err(|e| fail(waymark_result::InputRejected, e.to_string()))
    })
}

/// An epoch without radio at `timestamp_ns`, from the motion since the last epoch. A
/// `timestamp_ns` not after the last epoch's returns `InputRejected` and changes nothing.
#[no_mangle]
pub extern "C" fn waymark_engine_advance(
    engine: *mut waymark_engine,
    timestamp_ns: u64,
    out: *mut waymark_position,
) -> waymark_result {
    epoch(engine, out, |engine| {
        engine.advance(timestamp_ns).map_err(|e| fail(waymark_result::InputRejected, e.to_string()))
    })
}

/// A position from another positioning system (GNSS near an entrance, WiFi RTT, UWB) in the
/// site's frame, m: one positioning epoch, with the motion since the last one, whose
/// observation is the fix. `floor` is its floor index, or negative when unknown (GNSS);
/// `accuracy_m` the radius of its 68% circle (Android's `Location.getAccuracy()`), > 0. A
/// precise fix pulls the estimate to it; a vague one barely moves it. `*out` (may be NULL)
/// receives the new position. A rejected fix (see `WAYMARK_RESULT_INPUT_REJECTED`) returns
/// `InputRejected` and changes nothing.
#[no_mangle]
pub extern "C" fn waymark_engine_push_fix(
    engine: *mut waymark_engine,
    timestamp_ns: u64,
    x: f64,
    y: f64,
    floor: i32,
    accuracy_m: f64,
    out: *mut waymark_position,
) -> waymark_result {
    epoch(engine, out, |engine| {
        let fix =
            crate::fix::PositionFix { timestamp_ns, x, y, floor: usize::try_from(floor).ok(), accuracy_m };
        engine.push_fix(&fix).map_err(|e| fail(waymark_result::InputRejected, e.to_string()))
    })
}

/// User feedback: the user says they are in the zone named `zone` (NUL-terminated UTF-8) at
/// `timestamp_ns`. The position is pinned to the zone's states: at the time of the latest
/// position it corrects that position, later it is a new epoch. `*out` (may be NULL) receives
/// the position. A time before the latest position or an unknown zone returns
/// `InputRejected` and changes nothing.
#[no_mangle]
pub extern "C" fn waymark_engine_confirm_zone(
    engine: *mut waymark_engine,
    timestamp_ns: u64,
    zone: *const c_char,
    out: *mut waymark_position,
) -> waymark_result {
    epoch(engine, out, |engine| {
        let zone = string_arg(zone, "zone")?;
        engine
            .confirm_zone_named(timestamp_ns, &zone)
            .map_err(|e| fail(waymark_result::InputRejected, e.to_string()))
    })
}

/// User feedback: the user says they are within `radius_m` of (x, y) on `floor` (a tap on the
/// map), as `waymark_engine_confirm_zone` with the states within the radius. Also rejected:
/// an unknown floor, a NaN or infinite coordinate, a radius not > 0, no state within it.
#[no_mangle]
pub extern "C" fn waymark_engine_confirm_position(
    engine: *mut waymark_engine,
    timestamp_ns: u64,
    x: f64,
    y: f64,
    floor: u32,
    radius_m: f64,
    out: *mut waymark_position,
) -> waymark_result {
    epoch(engine, out, |engine| {
        engine
            .confirm_position(timestamp_ns, x, y, floor as usize, radius_m)
            .map_err(|e| fail(waymark_result::InputRejected, e.to_string()))
    })
}

/// The number of zones of the engine's site into `*count` (0 for a site without zones).
#[no_mangle]
pub extern "C" fn waymark_engine_zone_count(
    engine: *const waymark_engine,
    count: *mut usize,
) -> waymark_result {
    if count.is_null() {
        return fail(waymark_result::NullParameter, "count must not be NULL");
    }
    with_engine(engine, |inner| {
        // SAFETY: `count` was checked non-NULL and points to one writable size_t.
        unsafe { *count = inner.site().zones().len() };
        waymark_result::Ok
    })
}

/// Copies the name of zone `zone` into `buf` (NUL-terminated, truncated to `len` bytes; `buf`
/// may be NULL with `len` 0) and its full length in bytes into `*name_len` (may be NULL). A
/// zone index out of range returns `InputRejected`.
#[no_mangle]
pub extern "C" fn waymark_engine_zone_name(
    engine: *const waymark_engine,
    zone: usize,
    buf: *mut c_char,
    len: usize,
    name_len: *mut usize,
) -> waymark_result {
    if buf.is_null() && len > 0 {
        return fail(waymark_result::NullParameter, "buf must not be NULL when len > 0");
    }
    with_engine(engine, |inner| {
        let zones = inner.site().zones();
        let Some(z) = zones.get(zone) else {
            return fail(
                waymark_result::InputRejected,
                format!("zone {zone} does not exist ({} zones)", zones.len()),
            );
        };
        copy_string(&z.name, buf, len);
        if !name_len.is_null() {
            // SAFETY: a non-NULL `name_len` points to one writable size_t.
            unsafe { *name_len = z.name.len() };
        }
        waymark_result::Ok
    })
}

/// Writes the probability of being in each zone now, by zone index, into `out[0..count]`: the
/// first `count` zones when the site has more, the rest of `out` untouched when it has fewer.
/// `out` may be NULL when `count` is 0.
#[no_mangle]
pub extern "C" fn waymark_engine_zone_posterior(
    engine: *const waymark_engine,
    out: *mut f64,
    count: usize,
) -> waymark_result {
    if out.is_null() && count > 0 {
        return fail(waymark_result::NullParameter, "out must not be NULL when count > 0");
    }
    with_engine(engine, |inner| {
        let posterior = inner.zone_posterior();
        let n = posterior.len().min(count);
        if n > 0 {
            // SAFETY: `out` was checked non-NULL and points to `count` ≥ n writable doubles.
            unsafe { std::ptr::copy_nonoverlapping(posterior.as_ptr(), out, n) };
        }
        waymark_result::Ok
    })
}

/// The latest position into `*out`, or `NoPosition`.
#[no_mangle]
pub extern "C" fn waymark_engine_position(
    engine: *const waymark_engine,
    out: *mut waymark_position,
) -> waymark_result {
    if out.is_null() {
        return fail(waymark_result::NullParameter, "out must not be NULL");
    }
    with_engine(engine, |inner| match inner.position() {
        Some(p) => {
            // SAFETY: `out` was checked non-NULL and points to one waymark_position.
            unsafe { *out = convert(p) };
            waymark_result::Ok
        }
        None => fail(waymark_result::NoPosition, "no epoch has run yet"),
    })
}

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
    with_engine(engine, |inner| {
        let report = match inner.learn_habits() {
            Ok(report) => report,
            // Its input is the engine's own history and validated options: a bug.
            Err(e) => return fail(waymark_result::Panic, format!("learning habits: {e}")),
        };
        let learned = report.segments > 0;
        let ll = |v: Option<&f64>| v.filter(|_| learned).copied().unwrap_or(f64::NAN);
        let converted = waymark_habit_report {
            epochs: report.epochs,
            segments: report.segments,
            segments_skipped: report.segments_skipped,
            feedback_epochs: report.feedback_epochs,
            fix_epochs: report.fix_epochs,
            iterations: report.iterations,
            log_likelihood_count: if learned { report.log_likelihood.len() } else { 0 },
            log_likelihood_first: ll(report.log_likelihood.first()),
            log_likelihood_last: ll(report.log_likelihood.last()),
            restarts: report.restarts,
            learned_transitions: report.learned_transitions,
            total_epochs: inner.habits().epochs(),
            fix_error: report.fix_error.into(),
            strength: inner.habits().strength().unwrap_or(f64::NAN),
        };
        if !out.is_null() {
            // SAFETY: a non-NULL `out` points to writable storage for one waymark_habit_report.
            unsafe { *out = converted };
        }
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
    with_engine(engine, |inner| {
        let json = inner.export_habits();
        if !json_len.is_null() {
            // SAFETY: a non-NULL `json_len` points to one writable size_t.
            unsafe { *json_len = json.len() };
        }
        if json.len() >= len {
            copy_string("", buf, len);
            return fail(
                waymark_result::BufferTooSmall,
                format!("the habits' JSON needs {} bytes with its NUL, the buffer has {len}", json.len() + 1),
            );
        }
        copy_string(&json, buf, len);
        waymark_result::Ok
    })
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
    with_engine(engine, |inner| {
        let json = match string_arg(json, "json") {
            Ok(json) => json,
            Err(code) => return code,
        };
        match inner.import_habits(&json) {
            Ok(()) => waymark_result::Ok,
            Err(e @ crate::habits::HabitError::Learn(_)) => {
                fail(waymark_result::Panic, format!("importing habits: {e}"))
            }
            Err(e) => fail(waymark_result::HabitsRejected, e.to_string()),
        }
    })
}

/// Forgets every learned habit and the fix error.
#[no_mangle]
pub extern "C" fn waymark_engine_clear_habits(engine: *mut waymark_engine) -> waymark_result {
    with_engine(engine, |inner| {
        inner.clear_habits();
        waymark_result::Ok
    })
}

/// The fix error learned so far into `*out`: zero bias and spread 1 before any fix was
/// learned from.
#[no_mangle]
pub extern "C" fn waymark_engine_fix_error(
    engine: *const waymark_engine,
    out: *mut waymark_fix_error,
) -> waymark_result {
    if out.is_null() {
        return fail(waymark_result::NullParameter, "out must not be NULL");
    }
    with_engine(engine, |inner| {
        let error = inner.fix_error().into();
        // SAFETY: `out` was checked non-NULL and points to one writable waymark_fix_error.
        unsafe { *out = error };
        waymark_result::Ok
    })
}

/// Sets (or, with a NULL callback, clears) the function called with every new position (see
/// `waymark_position_callback` for when and on which thread). `userdata` is passed back
/// untouched; it must stay valid until the callback is replaced or the engine freed. When this
/// returns, the previous callback is not running on another thread and will not be called
/// again, so its userdata may be freed: if it is running, this waits for it to return (so do
/// not call this while holding a lock that callback takes). Called from inside the callback,
/// it does not wait; the current call finishes and the next position goes to the new one.
#[no_mangle]
pub extern "C" fn waymark_engine_set_callback(
    engine: *mut waymark_engine,
    callback: waymark_position_callback,
    userdata: *mut c_void,
) -> waymark_result {
    with_handle(engine, |handle| {
        *lock(&handle.callback) = callback.map(|function| Callback { function, userdata: userdata as usize });
        if !handle.positions.on_delivering_thread() {
            drop(lock(&handle.calling));
        }
        waymark_result::Ok
    })
}

/// Copies the calling thread's last error message into `buf` (NUL-terminated, truncated to
/// `len`) and returns the message's full length in bytes. `buf` may be NULL to ask the length.
#[no_mangle]
pub extern "C" fn waymark_last_error(buf: *mut c_char, len: usize) -> usize {
    let message = LAST_ERROR.with(|e| e.borrow().clone());
    copy_string(&message, buf, len);
    message.len()
}

/// Copies `text` into `buf`, NUL-terminated and truncated to `len` bytes; nothing when `buf`
/// is NULL or `len` 0.
fn copy_string(text: &str, buf: *mut c_char, len: usize) {
    if !buf.is_null() && len > 0 {
        let n = text.len().min(len - 1);
        // SAFETY: `buf` points to `len` writable bytes (the caller's contract, as the header
        // documents for each function taking a buffer); n < len.
        unsafe {
            std::ptr::copy_nonoverlapping(text.as_ptr(), buf as *mut u8, n);
            *buf.add(n) = 0;
        }
    }
}

/// The library's version, a static NUL-terminated string.
#[no_mangle]
pub extern "C" fn waymark_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr() as *const c_char
}
