//! How the C callbacks are held and called: the position and status callbacks an engine's
//! `waymark_engine_set_callback` / `_set_status_callback` left, and each event of the engine
//! (`handle.rs`'s delivery) turned into the `waymark_position` or `waymark_status` they take.

use super::*;
use crate::ffi::handle::{Event, Listeners};
use crate::ffi::record::AppStatus;

/// The app's callbacks, as `waymark_engine_set_callback` and
/// `waymark_engine_set_status_callback` left them.
#[derive(Default)]
pub(super) struct Callbacks {
    pub(super) position: Mutex<Option<Callback<waymark_position>>>,
    pub(super) status: Mutex<Option<Callback<waymark_status>>>,
    /// Held while a callback runs, so that setting another one can wait for it to return.
    pub(super) calling: Mutex<()>,
}

pub(super) struct Callback<T> {
    function: unsafe extern "C" fn(userdata: *mut c_void, event: *const T),
    userdata: usize,
}

impl<T> Clone for Callback<T> {
    fn clone(&self) -> Self {
        *self
    }
}

impl<T> Copy for Callback<T> {}

impl<T> Callback<T> {
    fn call(self, event: &T) {
        // SAFETY: the function and its userdata were registered together by the caller of
        // `waymark_engine_set_callback` / `_set_status_callback`, who guarantees they stay
        // valid until replaced; a replacement waits for this call to return (`calling`).
        unsafe { (self.function)(self.userdata as *mut c_void, event) };
    }
}

impl Listeners for Callbacks {
    /// Reads the callback afresh for each event.
    fn deliver(&self, event: &Event) {
        let _calling = lock(&self.calling);
        match event {
            // Each callback is copied out before it is called: the lock must be free so the
            // callback can replace itself (a guard in the `if let` would live through the call).
            Event::Position(p, site) => {
                let callback = *lock(&self.position);
                if let Some(callback) = callback {
                    callback.call(&position(p, site));
                }
            }
            Event::Status(s) => {
                let callback = *lock(&self.status);
                if let Some(callback) = callback {
                    deliver_status(callback, s);
                }
            }
            Event::Error(e) => {
                let callback = *lock(&self.status);
                if let Some(callback) = callback {
                    let message = c_string(&e.to_string());
                    callback.call(&waymark_status {
                        error: e.into(),
                        message: message.as_ptr(),
                        ..status(waymark_status_kind::Error, 0)
                    });
                }
            }
        }
    }
}

fn status(kind: waymark_status_kind, timestamp_ns: u64) -> waymark_status {
    waymark_status {
        kind,
        timestamp_ns,
        scenario: 0,
        motion_state: 0,
        points: std::ptr::null(),
        point_count: 0,
        error: waymark_result::Ok,
        message: std::ptr::null(),
        zone: -1,
        name: std::ptr::null(),
        probability: 0.0,
    }
}

fn deliver_status(callback: Callback<waymark_status>, s: &AppStatus) {
    match s {
        &AppStatus::ScenarioChanged { timestamp_ns, scenario: to } => callback.call(&waymark_status {
            scenario: scenario(to),
            ..status(waymark_status_kind::ScenarioChanged, timestamp_ns)
        }),
        &AppStatus::MotionStateChanged { timestamp_ns, state } => callback.call(&waymark_status {
            motion_state: motion_state(state),
            ..status(waymark_status_kind::MotionStateChanged, timestamp_ns)
        }),
        &AppStatus::NoSiteCoverage { timestamp_ns } => {
            callback.call(&status(waymark_status_kind::NoSiteCoverage, timestamp_ns))
        }
        AppStatus::TrackRevised { points } => {
            let points: Vec<waymark_track_point> = points.iter().copied().map(Into::into).collect();
            callback.call(&waymark_status {
                points: points.as_ptr(),
                point_count: points.len(),
                ..status(waymark_status_kind::TrackRevised, 0)
            })
        }
        AppStatus::Zone { timestamp_ns, zone, name, entered, probability } => {
            let kind =
                if *entered { waymark_status_kind::ZoneEntered } else { waymark_status_kind::ZoneExited };
            let name = c_string(name);
            callback.call(&waymark_status {
                zone: *zone,
                name: name.as_ptr(),
                probability: *probability,
                ..status(kind, *timestamp_ns)
            })
        }
        AppStatus::Geofence { timestamp_ns, id, entered, probability } => {
            let kind = if *entered {
                waymark_status_kind::GeofenceEntered
            } else {
                waymark_status_kind::GeofenceExited
            };
            let name = c_string(id);
            callback.call(&waymark_status {
                name: name.as_ptr(),
                probability: *probability,
                ..status(kind, *timestamp_ns)
            })
        }
    }
}

/// Puts `callback` with `userdata` in the slot `slot` picks, then waits for a callback running
/// on another thread to return (not on the delivering thread itself: it would wait for itself).
pub(super) fn replace_callback<T>(
    handle: &Handle<Callbacks>,
    slot: impl FnOnce(&Callbacks) -> &Mutex<Option<Callback<T>>>,
    callback: Option<unsafe extern "C" fn(userdata: *mut c_void, event: *const T)>,
    userdata: *mut c_void,
) -> waymark_result {
    let callbacks = handle.listeners();
    *lock(slot(callbacks)) = callback.map(|function| Callback { function, userdata: userdata as usize });
    if !handle.on_delivering_thread() {
        drop(lock(&callbacks.calling));
    }
    waymark_result::Ok
}
