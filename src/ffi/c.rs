//! The C ABI, in rustls-ffi's conventions: one `waymark_` prefix, opaque handles, a
//! `waymark_result` code from every call, out-parameters last, NULL checks, every body behind
//! a panic boundary, a thread-local last-error message, `_free` for what Waymark allocates.
//! The engine is the same `Handle` (`handle.rs`) Kotlin and Swift use; the C side only converts
//! arguments and results (`types`). This file holds the engine handle's lifetime, the panic
//! boundary and last error, the engine's inputs and reads, and setting its callbacks; `c/`
//! holds how the callbacks are called (`callbacks`), construction (`create`), geofences,
//! habits, the log callback (`log_hook`), the survey recorder and routes. The header
//! `bindings/c/waymark.h` is generated from this file and `c/` by cbindgen, functions in source
//! order, this file's first.
#![deny(clippy::undocumented_unsafe_blocks)]
#![allow(non_camel_case_types)]
// These functions are called from C, which cannot see `unsafe`: each pointer's contract is in
// the header, and each dereference carries a SAFETY comment (as rustls-ffi does).
#![allow(clippy::not_unsafe_ptr_arg_deref)]

mod callbacks;
mod create;
mod evidence;
mod geo;
mod geofence;
mod habits;
mod log_hook;
mod recorder;
mod route;
mod types;

pub use types::*;

use callbacks::{replace_callback, Callbacks};

// The engine crate is `::waymark_engine` in the C modules: `waymark_engine` is C's handle.
use super::delivery::lock;
use super::error::PositioningError;
use super::handle::{Handle, Options};
use ::waymark_engine::radio::{Reading, Scan, TransmitterId};
use ::waymark_engine::sensors::{PressureSample, SensorSample};
use ::waymark_engine::site::Site;
use ::waymark_engine::{Engine, Epoch, TransitionModel};
use std::cell::RefCell;
use std::ffi::{c_char, c_void, CStr, CString};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// An engine. Opaque; create with `waymark_engine_new_with_options`, free with
/// `waymark_engine_free`. Thread-safe: any thread may call any function on it.
pub struct waymark_engine {
    handle: Handle<Callbacks>,
    /// [`CALL`] for each call running on the engine, plus [`FREED`] once `waymark_engine_free`
    /// was called: a free while calls run (from a callback) is done by the last of them to
    /// return (docs/errors.md#callbacks).
    calls: AtomicUsize,
}

/// `::waymark_engine::calls`: `waymark_engine_free` was called.
const FREED: usize = 1;
/// `::waymark_engine::calls`: one call running.
const CALL: usize = 2;

/// A call running on an engine: frees the engine when it is the last one to return and
/// `waymark_engine_free` was called meanwhile.
struct Running(*mut waymark_engine);

impl waymark_engine {
    fn new(handle: Handle<Callbacks>) -> Self {
        Self { handle, calls: AtomicUsize::new(0) }
    }
}

impl Running {
    /// A call on `engine`, a live handle from `waymark_engine_new*` (not NULL).
    fn enter(engine: *const waymark_engine) -> Self {
        // SAFETY: the caller checked `engine` is not NULL; it is alive (the header's contract).
        unsafe { &*engine }.calls.fetch_add(CALL, Ordering::SeqCst);
        Self(engine.cast_mut())
    }
}

impl Drop for Running {
    fn drop(&mut self) {
        // SAFETY: the engine is alive: this call's CALL in `calls` keeps `waymark_engine_free`
        // from freeing it, and only the call that removes the last CALL after FREED frees it.
        let before = unsafe { &*self.0 }.calls.fetch_sub(CALL, Ordering::SeqCst);
        if before == CALL | FREED {
            // SAFETY: the engine came from `Box::into_raw` (`waymark_engine_new*`); FREED is set
            // and no call runs on it any more, so nothing else refers to it.
            drop(unsafe { Box::from_raw(self.0) });
        }
    }
}

/// `text` as a C string, each NUL in it replaced (a message never holds one in practice).
fn c_string(text: &str) -> CString {
    CString::new(text.replace('\0', " ")).unwrap_or_default()
}

thread_local! {
    static LAST_ERROR: RefCell<String> = const { RefCell::new(String::new()) };
}

fn fail(code: waymark_result, message: impl Into<String>) -> waymark_result {
    let message = message.into();
    LAST_ERROR.with(|e| *e.borrow_mut() = message);
    code
}

/// The code of `e`, its message kept for `waymark_last_error`.
fn fail_with(e: &PositioningError) -> waymark_result {
    fail(e.into(), e.to_string())
}

/// Runs `body`, turning a panic into `waymark_result::Panic` (its message goes to the log
/// callback, not to stderr). The log records `body` made reach the log callback when it has
/// returned, with no lock held; what the log callback calls does not change this call's
/// `waymark_last_error` (docs/errors.md#callbacks).
fn boundary(body: impl FnOnce() -> waymark_result) -> waymark_result {
    let hold = crate::ffi::logging::hold();
    let code = super::panic::guard(body)
        .unwrap_or_else(|_| fail(waymark_result::Panic, "Waymark panicked; the call had no effect"));
    if hold.will_flush() {
        let message = LAST_ERROR.with(|e| std::mem::take(&mut *e.borrow_mut()));
        drop(hold);
        LAST_ERROR.with(|e| *e.borrow_mut() = message);
    }
    code
}

/// Writes `value` to `out` when it is not NULL.
fn write<T>(out: *mut T, value: T) {
    if !out.is_null() {
        // SAFETY: a non-NULL out-parameter points to writable storage for one `T` (the
        // header's contract for every out-parameter).
        unsafe { *out = value };
    }
}

/// Frees an engine. NULL is ignored. Call it once, when no other thread is calling the engine.
/// It may be called from inside the engine's own callbacks (position, status or log): then no
/// callback of the engine is called after it, and the engine is freed when the calls running
/// on it (the one whose callback this is) return (docs/errors.md#callbacks).
#[no_mangle]
pub extern "C" fn waymark_engine_free(engine: *mut waymark_engine) {
    let _ = boundary(|| {
        // SAFETY: a non-NULL `engine` came from `waymark_engine_new*` (Box::into_raw) and is
        // not freed yet (the header's contract), so it is alive.
        let Some(alive) = (unsafe { engine.as_ref() }) else {
            return waymark_result::Ok;
        };
        // A call of its own, so that whichever call returns last frees it, this one or one
        // that a callback freeing the engine runs inside.
        let running = Running::enter(engine);
        // No callback of it is called again (it may be freed inside one, with its userdata).
        let callbacks = alive.handle.listeners();
        *lock(&callbacks.position) = None;
        *lock(&callbacks.status) = None;
        alive.calls.fetch_or(FREED, Ordering::SeqCst);
        drop(running);
        waymark_result::Ok
    });
}

/// Borrows the handle `engine`, or fails with `NullParameter`.
fn with_handle(
    engine: *const waymark_engine,
    body: impl FnOnce(&Handle<Callbacks>) -> waymark_result,
) -> waymark_result {
    boundary(|| {
        // SAFETY: a non-NULL `engine` is a live handle from `waymark_engine_new*` (the header's
        // contract); `waymark_engine` is Sync, so a shared reference from any thread is fine.
        let Some(alive) = (unsafe { engine.as_ref() }) else {
            return fail(waymark_result::NullParameter, "engine must not be NULL");
        };
        // Keeps the engine alive should a callback free it (`waymark_engine_free`).
        let _running = Running::enter(engine);
        body(&alive.handle)
    })
}

/// Runs `f` on the engine (under its lock, behind its panic boundary: [`Handle::call`]) and
/// passes its value to `done`, or returns the error's code.
fn call<T>(
    engine: *const waymark_engine,
    f: impl FnOnce(&mut Engine) -> Result<T, PositioningError>,
    done: impl FnOnce(T) -> waymark_result,
) -> waymark_result {
    with_handle(engine, |handle| match handle.call(f) {
        Ok(value) => done(value),
        Err(e) => fail_with(&e),
    })
}

/// Reads the engine's state with `f` and passes what it read to `done`, or returns the
/// error's code.
fn read<T>(
    engine: *const waymark_engine,
    f: impl FnOnce(&Engine) -> T,
    done: impl FnOnce(T) -> waymark_result,
) -> waymark_result {
    with_handle(engine, |handle| match handle.read(f) {
        Ok(value) => done(value),
        Err(e) => fail_with(&e),
    })
}

/// Runs an epoch and writes its position to `out` (may be NULL).
fn epoch(
    engine: *mut waymark_engine,
    out: *mut waymark_position,
    f: impl FnOnce(&mut Engine) -> Result<Epoch, ::waymark_engine::InputError>,
) -> waymark_result {
    with_handle(engine, |handle| match handle.epoch(f) {
        Ok((p, site)) => {
            write(out, position(&p, &site));
            waymark_result::Ok
        }
        Err(e) => fail_with(&e),
    })
}

fn samples<'a, T>(batch: *const T, count: usize) -> Option<&'a [T]> {
    if count == 0 {
        return Some(&[]);
    }
    // SAFETY: a non-NULL `batch` points to `count` samples (the header's contract).
    (!batch.is_null()).then(|| unsafe { std::slice::from_raw_parts(batch, count) })
}

/// C samples as the core takes them (engines and survey recorders).
fn sensor_samples(batch: &[waymark_sample]) -> Vec<SensorSample> {
    batch.iter().map(|s| SensorSample { timestamp_ns: s.timestamp_ns, x: s.x, y: s.y, z: s.z }).collect()
}

fn push_samples(
    engine: *mut waymark_engine,
    batch: *const waymark_sample,
    count: usize,
    accepted: *mut usize,
    push: fn(&mut Engine, &[SensorSample]) -> ::waymark_engine::sensors::BatchReport,
) -> waymark_result {
    with_handle(engine, |handle| {
        let Some(batch) = samples(batch, count) else {
            return fail(waymark_result::NullParameter, "samples must not be NULL when count > 0");
        };
        let converted = sensor_samples(batch);
        match handle.push_samples(|e| push(e, &converted)) {
            Ok(n) => {
                write(accepted, n);
                waymark_result::Ok
            }
            Err(e) => fail_with(&e),
        }
    })
}
/// Accelerometer samples (m/s², gravity included), oldest first. Bad samples are dropped and
/// counted; `*accepted` (may be NULL) receives how many were taken. Samples whose time is too
/// far ahead of the engine's clock (more than 10 s after the latest input taken, unless the
/// stream's next sample confirms the jump, or above INT64_MAX) are refused, counted in
/// `waymark_input_stats.timestamps_ahead` and reported to the status callback as an
/// `INPUT_REJECTED` error; the call still returns `OK`.
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

/// Barometer readings (hPa), oldest first: floor changes from the height climbed
/// (docs/accuracy.md#barometer). Readings that are not a pressure (NaN, outside 300-1100 hPa)
/// or not after the previous are dropped and counted in
/// `waymark_input_stats.pressure_dropped`; times too far ahead as for
/// `waymark_engine_push_accelerometer`. `*accepted` (may be NULL) receives how many were taken.
#[no_mangle]
pub extern "C" fn waymark_engine_push_pressure(
    engine: *mut waymark_engine,
    samples: *const waymark_pressure_sample,
    count: usize,
    accepted: *mut usize,
) -> waymark_result {
    with_handle(engine, |handle| {
        let Some(batch) = self::samples(samples, count) else {
            return fail(waymark_result::NullParameter, "samples must not be NULL when count > 0");
        };
        let converted: Vec<PressureSample> =
            batch.iter().map(|s| PressureSample { timestamp_ns: s.timestamp_ns, hpa: s.hpa }).collect();
        match handle.push_samples(|e| e.push_pressure(&converted)) {
            Ok(n) => {
                write(accepted, n);
                waymark_result::Ok
            }
            Err(e) => fail_with(&e),
        }
    })
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
    with_handle(engine, |handle| {
        if (wifi.is_null() && wifi_count > 0) || (beacons.is_null() && beacon_count > 0) {
            return fail(waymark_result::NullParameter, "reading arrays must not be NULL when count > 0");
        }
        let readings = match readings(wifi, wifi_count, beacons, beacon_count) {
            Ok(readings) => readings,
            Err(Rejected::Code(code)) => return code,
            Err(Rejected::Input(reason)) => {
                return fail_with(&handle.reject(PositioningError::InputRejected { reason }))
            }
        };
        match handle.push_scan(&Scan { timestamp_ns, readings }) {
            Ok((p, site)) => {
                write(out, position(&p, &site));
                waymark_result::Ok
            }
            Err(e) => fail_with(&e),
        }
    })
}

/// Why a scan's readings could not be read.
enum Rejected {
    /// A NULL or non-UTF-8 string.
    Code(waymark_result),
    /// A malformed transmitter id.
    Input(String),
}

fn readings(
    wifi: *const waymark_wifi_reading,
    wifi_count: usize,
    beacons: *const waymark_beacon_reading,
    beacon_count: usize,
) -> Result<Vec<Reading>, Rejected> {
    // Counts that no array can have are refused before any memory is touched or reserved.
    let fits = |count: usize, size: usize| count.checked_mul(size).is_some_and(|b| b <= isize::MAX as usize);
    let total = wifi_count.checked_add(beacon_count);
    let mut readings = Vec::new();
    let reserved = total.is_some_and(|n| readings.try_reserve_exact(n).is_ok());
    if !reserved
        || !fits(wifi_count, std::mem::size_of::<waymark_wifi_reading>())
        || !fits(beacon_count, std::mem::size_of::<waymark_beacon_reading>())
    {
        return Err(Rejected::Input(format!(
            "{wifi_count} WiFi and {beacon_count} beacon readings cannot be held in memory"
        )));
    }
    if wifi_count > 0 {
        // SAFETY: checked non-NULL by the caller; the app guarantees `wifi_count` elements.
        for w in unsafe { std::slice::from_raw_parts(wifi, wifi_count) } {
            let bssid = string_arg(w.bssid, "bssid").map_err(Rejected::Code)?;
            let transmitter = TransmitterId::wifi(&bssid).map_err(Rejected::Input)?;
            readings.push(Reading {
                transmitter,
                rssi_dbm: w.rssi_dbm,
                age_ns: w.age_ms.saturating_mul(crate::ffi::NS_PER_MS),
            });
        }
    }
    if beacon_count > 0 {
        // SAFETY: checked non-NULL by the caller; the app guarantees `beacon_count` elements.
        for b in unsafe { std::slice::from_raw_parts(beacons, beacon_count) } {
            let uuid = optional_string_arg(b.uuid, "uuid").map_err(Rejected::Code)?.unwrap_or_default();
            let address = optional_string_arg(b.address, "address").map_err(Rejected::Code)?;
            let transmitter =
                super::beacon_id(&uuid, b.major, b.minor, address.as_deref()).map_err(Rejected::Input)?;
            readings.push(Reading {
                transmitter,
                rssi_dbm: b.rssi_dbm,
                age_ns: b.age_ms.saturating_mul(crate::ffi::NS_PER_MS),
            });
        }
    }
    Ok(readings)
}

/// An epoch without radio at `timestamp_ns`, from the motion since the last epoch. Sooner
/// than 2 s after the filter's last step it is held: the position is the prediction by the
/// motion since, and the next epoch steps over it. A `timestamp_ns` not after the last
/// epoch's returns `InputRejected` and changes nothing.
#[no_mangle]
pub extern "C" fn waymark_engine_advance(
    engine: *mut waymark_engine,
    timestamp_ns: u64,
    out: *mut waymark_position,
) -> waymark_result {
    epoch(engine, out, |engine| engine.advance(timestamp_ns))
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
        let fix = ::waymark_engine::PositionFix {
            timestamp_ns,
            x,
            y,
            floor: usize::try_from(floor).ok(),
            accuracy_m,
        };
        engine.push_fix(&fix)
    })
}

/// `waymark_engine_push_fix` with the fix at a WGS84 latitude and longitude, degrees, on a
/// geo-referenced site (its file has an `anchor`). Besides what `waymark_engine_push_fix`
/// rejects, returns `InputRejected`, changing nothing, on a site that is not geo-referenced,
/// for a latitude or longitude out of range, or for a negative `floor` on a site whose floors
/// have different frames (`floors[f].origin_m`).
#[no_mangle]
pub extern "C" fn waymark_engine_push_fix_lat_lon(
    engine: *mut waymark_engine,
    timestamp_ns: u64,
    latitude_deg: f64,
    longitude_deg: f64,
    floor: i32,
    accuracy_m: f64,
    out: *mut waymark_position,
) -> waymark_result {
    with_handle(engine, |handle| {
        let floor = usize::try_from(floor).ok();
        let at = ::waymark_engine::site::LatLon { lat_deg: latitude_deg, lon_deg: longitude_deg };
        let p = match handle.site().site_point(floor, at) {
            Ok(p) => p,
            Err(e) => return fail_with(&handle.reject(PositioningError::input(e))),
        };
        let fix = ::waymark_engine::PositionFix { timestamp_ns, x: p.x, y: p.y, floor, accuracy_m };
        match handle.epoch(|e| e.push_fix(&fix)) {
            Ok((p, site)) => {
                write(out, position(&p, &site));
                waymark_result::Ok
            }
            Err(e) => fail_with(&e),
        }
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
    with_handle(engine, |handle| {
        let zone = match string_arg(zone, "zone") {
            Ok(zone) => zone,
            Err(code) => return code,
        };
        match handle.epoch(|e| e.confirm_zone_named(timestamp_ns, &zone)) {
            Ok((p, site)) => {
                write(out, position(&p, &site));
                waymark_result::Ok
            }
            Err(e) => fail_with(&e),
        }
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
    epoch(engine, out, |engine| engine.confirm_position(timestamp_ns, x, y, floor as usize, radius_m))
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
    with_handle(engine, |handle| {
        write(count, handle.site().zones().len());
        waymark_result::Ok
    })
}

/// Copies the name of zone `zone` into `buf` (NUL-terminated UTF-8; a name longer than
/// `len - 1` bytes is cut at the last whole character that fits, never inside one; `buf` may
/// be NULL with `len` 0) and its full length in bytes into `*name_len` (may be NULL): the name
/// was cut when `*name_len >= len`. A zone index out of range returns `InputRejected`.
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
    with_handle(engine, |handle| {
        let site = handle.site();
        let zones = site.zones();
        let Some(z) = zones.get(zone) else {
            return fail(
                waymark_result::InputRejected,
                format!("zone {zone} does not exist ({} zones)", zones.len()),
            );
        };
        copy_string(&z.name, buf, len);
        write(name_len, z.name.len());
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
    read(
        engine,
        |e| e.zone_posterior(),
        |posterior| {
            let n = posterior.len().min(count);
            if n > 0 {
                // SAFETY: `out` was checked non-NULL and points to `count` ≥ n writable doubles.
                unsafe { std::ptr::copy_nonoverlapping(posterior.as_ptr(), out, n) };
            }
            waymark_result::Ok
        },
    )
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
    read(
        engine,
        |e| e.position().map(|p| position(p, e.site())),
        |p| match p {
            Some(p) => {
                write(out, p);
                waymark_result::Ok
            }
            None => fail(waymark_result::NoPosition, "no epoch has run yet"),
        },
    )
}

/// What the engine took and refused since it was created, and why, into `*out`.
#[no_mangle]
pub extern "C" fn waymark_engine_input_stats(
    engine: *const waymark_engine,
    out: *mut waymark_input_stats,
) -> waymark_result {
    if out.is_null() {
        return fail(waymark_result::NullParameter, "out must not be NULL");
    }
    read(
        engine,
        |e| e.stats().into(),
        |stats| {
            write(out, stats);
            waymark_result::Ok
        },
    )
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
    with_handle(engine, |handle| replace_callback(handle, |c| &c.position, callback, userdata))
}

/// Sets (or, with a NULL callback, clears) the function called with every status change
/// (`waymark_status`: the motion scenario or state changed, a scan heard no transmitter of the
/// site, the track was revised) and every failed call (`WAYMARK_STATUS_KIND_ERROR`). It is
/// called as the position callback is, in one order with the positions; `userdata` and
/// replacing it behave as in `waymark_engine_set_callback`.
#[no_mangle]
pub extern "C" fn waymark_engine_set_status_callback(
    engine: *mut waymark_engine,
    callback: waymark_status_callback,
    userdata: *mut c_void,
) -> waymark_result {
    with_handle(engine, |handle| replace_callback(handle, |c| &c.status, callback, userdata))
}

/// Copies the calling thread's last error message into `buf` (NUL-terminated, truncated to
/// `len` at a character boundary) and returns the message's full length in bytes. `buf` may be
/// NULL to ask the length.
#[no_mangle]
pub extern "C" fn waymark_last_error(buf: *mut c_char, len: usize) -> usize {
    let message = LAST_ERROR.with(|e| e.borrow().clone());
    copy_string(&message, buf, len);
    message.len()
}

/// Copies `text` into `buf`, NUL-terminated and truncated to `len` bytes at a character
/// boundary (what it writes is always whole UTF-8); nothing when `buf` is NULL or `len` 0.
fn copy_string(text: &str, buf: *mut c_char, len: usize) {
    if !buf.is_null() && len > 0 {
        let mut n = text.len().min(len - 1);
        while !text.is_char_boundary(n) {
            n -= 1; // 0 is a boundary
        }
        // SAFETY: `buf` points to `len` writable bytes (the caller's contract, as the header
        // documents for each function taking a buffer); n < len.
        unsafe {
            std::ptr::copy_nonoverlapping(text.as_ptr(), buf as *mut u8, n);
            *buf.add(n) = 0;
        }
    }
}

/// The library's version (the crate's, as `WAYMARK_VERSION` in this header: compare them to
/// catch a header and library that do not match), a static NUL-terminated string.
#[no_mangle]
pub extern "C" fn waymark_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr() as *const c_char
}
