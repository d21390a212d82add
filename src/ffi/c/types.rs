//! The C API's types: the result codes, the `repr(C)` structs passed in and out, and their
//! conversions from the core's types. cbindgen writes them into `bindings/c/waymark.h`.

use crate::ffi::error::{ErrorCode, PositioningError};
use crate::ffi::record::{AppFixBias, AppHabitReport, AppPosition, AppTrackPoint};
use ::waymark_engine::sensors::{MotionScenario, MotionState};
use ::waymark_engine::site::Site;
use ::waymark_engine::{self as engine, Position};
use std::ffi::{c_char, c_void};

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
    /// The configuration is invalid: a field of `waymark_engine_options` out of range, or a
    /// log level that does not exist.
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
    /// hashed with, was given (`waymark_engine_options.site_salt`).
    SaltMismatch = 7,
    /// `waymark_engine_import_habits` refused the model and the engine's habits are unchanged:
    /// the JSON does not parse, is not a Waymark habit model, is of a newer layout than this
    /// build reads, was learned on another site (or another build of the site file), or holds
    /// a value out of range; `waymark_last_error` says which, with the field's path.
    HabitsRejected = 8,
    /// The caller's buffer is too small for the whole text; nothing but an empty string was
    /// written to it, and the length it needs was returned (`waymark_engine_export_habits`).
    BufferTooSmall = 9,
    /// A route's destination names a zone the site does not have (`waymark_engine_route_to_zone`).
    UnknownZone = 10,
    /// A point is off the site's walkable graph: its floor does not exist, a coordinate or the
    /// accuracy is NaN or infinite, or no walkable place is near enough (docs/routes.md).
    OffGraph = 11,
    /// No walkable path joins a route's start to its destination.
    Unreachable = 12,
    /// A survey recorder could not create or write a walk file, or the file exists already (a
    /// recording never overwrites one); `waymark_last_error` names it.
    Io = 13,
    /// `waymark_recorder_finish` before any waypoint: nothing had a position, no file was
    /// written.
    NoWaypoints = 14,
    /// The recording was finished.
    Finished = 15,
    /// Waymark panicked, or refused its own data (a bug). An epoch (a scan, an advance, a fix,
    /// feedback) or a read that panicked had no effect: the engine is as it was before the
    /// call, no callback hears of it, and it stays usable. Any other call that panicked may
    /// have left the engine half-changed: every later call on it returns `PANIC` too (free it
    /// and create another). A getter that fails writes nothing to its out-parameters.
    Panic = 99,
}

impl From<ErrorCode> for waymark_result {
    fn from(code: ErrorCode) -> Self {
        match code {
            ErrorCode::InvalidSite => waymark_result::InvalidSite,
            ErrorCode::InvalidConfig => waymark_result::InvalidConfig,
            ErrorCode::InputRejected => waymark_result::InputRejected,
            ErrorCode::SaltMismatch => waymark_result::SaltMismatch,
            ErrorCode::HabitsRejected => waymark_result::HabitsRejected,
            ErrorCode::Internal => waymark_result::Panic,
        }
    }
}

impl From<&PositioningError> for waymark_result {
    fn from(e: &PositioningError) -> Self {
        e.code().into()
    }
}

/// Values of `waymark_engine_options.transition`: which transition model the engine uses.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum waymark_transition {
    /// The default (Hoang's).
    Default = 0,
    /// Radio only: uniform over the states reachable at the maximum speed.
    Reach = 1,
    /// HIPE's high/low regions from distance and heading.
    Hipe = 2,
    /// Hoang's Gaussian on the movement vector.
    Hoang = 3,
}

/// Engine settings for `waymark_engine_new_with_options`. Fill it with
/// `waymark_engine_options_default`, then change the fields you need: a later version may add
/// fields, which the defaults function sets.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct waymark_engine_options {
    /// A `waymark_transition` value.
    pub transition: u32,
    /// How many epochs behind the newest the fixed-lag estimate is.
    pub fixed_lag_epochs: u32,
    /// The user's own step length, m, used in place of the step length model the site was
    /// surveyed with; NaN (the default): the site's surveyed model, or 0.7 m on a site
    /// without one. Outside 0.1-2.5 m: `WAYMARK_RESULT_INVALID_CONFIG`.
    pub step_length_m: f64,
    /// Magnetic declination at the site, degrees east, within ±180; NaN: the site file's.
    pub declination_deg: f64,
    /// True azimuth of the site's +y axis, degrees, within ±360; NaN: the site file's.
    pub site_rotation_deg: f64,
    /// The salt of a site file whose transmitter ids are hashed (docs/privacy.md):
    /// `site_salt_len` bytes (at least 16; the bytes the salt file's hex digits stand for),
    /// copied before the constructor returns. NULL with length 0 for a site with raw ids. A
    /// hashed site without it, or with another salt, returns `WAYMARK_RESULT_SALT_MISMATCH`; a
    /// salt given for a site with raw ids is ignored.
    pub site_salt: *const u8,
    /// Bytes at `site_salt`.
    pub site_salt_len: usize,
    /// 1 (the default): the engine keeps the Viterbi track and reports its revisions
    /// (`WAYMARK_STATUS_KIND_TRACK_REVISED`). 0: it runs without it, for an app that shows only
    /// the live position: each epoch costs less, the engine holds no track window
    /// (docs/results.md#speed), and no revision is reported. The positions are the same either
    /// way. Other values are rejected (`WAYMARK_RESULT_INVALID_CONFIG`).
    pub track: u8,
}

/// Severity of a log record (`waymark_set_log_callback`).
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum waymark_log_level {
    /// Something failed.
    Error = 1,
    /// Something unexpected (a dropped input, a filter restart).
    Warn = 2,
    /// Lifecycle.
    Info = 3,
    /// Per-epoch detail.
    Debug = 4,
    /// Everything.
    Trace = 5,
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

/// One barometer reading: air pressure in hPa (Android `Sensor.TYPE_PRESSURE`; iOS
/// `CMAltitudeData.pressure` in kPa × 10), with a monotonic timestamp in ns.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct waymark_pressure_sample {
    /// ns on the clock shared by every input.
    pub timestamp_ns: u64,
    /// Air pressure, hPa.
    pub hpa: f64,
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
    /// Probability that the floor is right: how often it was at this posterior mass on it on
    /// held-out survey walks (docs/accuracy.md#floor-probability), or the posterior's own mass
    /// when the site file has no such calibration.
    pub floor_probability: f64,
    /// Whether `floor_level` holds the floor's logical level (the site file gives one).
    pub has_floor_level: bool,
    /// The floor's logical level as the building numbers it (-1 for the first basement);
    /// 0 when `has_floor_level` is false. When `level_unmapped`, a level the site has no floor
    /// for, where the barometer places the phone (docs/accuracy.md#barometer).
    pub floor_level: i32,
    /// Whether `floor_level` is a level the site has no floor for: x, y and the radii then
    /// stand on `floor`'s plan, the nearest the map can place the phone.
    pub level_unmapped: bool,
    /// Latitude, degrees north (WGS84), when the site is geo-referenced (its file has an
    /// `anchor`); NaN otherwise.
    pub latitude_deg: f64,
    /// Longitude, degrees east (WGS84); NaN when the site is not geo-referenced.
    pub longitude_deg: f64,
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
    /// Direction of travel, degrees clockwise from true north in [0, 360); NaN when the
    /// heading is unknown or the site is not geo-referenced.
    pub bearing_deg: f64,
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

/// One point of a revised track.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct waymark_track_point {
    /// Epoch time, ns.
    pub timestamp_ns: u64,
    /// x in the site frame, m.
    pub x: f64,
    /// y in the site frame, m.
    pub y: f64,
    /// Floor index.
    pub floor: u32,
    /// Whether `floor_level` holds a level (the site file gives one, or `level_unmapped`).
    pub has_floor_level: bool,
    /// The level to show, as `waymark_position`'s: the level the live position of the same
    /// epoch reported where the site has no floor for it, else the floor's own; 0 when
    /// `has_floor_level` is false.
    pub floor_level: i32,
    /// Whether `floor_level` is a level the site has no floor for.
    pub level_unmapped: bool,
}

/// Which kind of `waymark_status` event.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum waymark_status_kind {
    /// The motion information changed (a sensor stopped, the compass became disturbed, ...):
    /// `scenario` holds the new one.
    ScenarioChanged = 1,
    /// The person started or stopped walking: `motion_state` holds the new state.
    MotionStateChanged = 2,
    /// A scan heard no transmitter of the site: the phone is probably outside the surveyed
    /// area (or the site file is for another building).
    NoSiteCoverage = 3,
    /// Earlier positions were revised by later evidence: `points[0..point_count]`.
    TrackRevised = 4,
    /// A call failed (it also returned `error`); `message` says why.
    Error = 5,
    /// The person entered one of the site's zones: `zone`, `name` (its name), `probability`.
    ZoneEntered = 6,
    /// The person left a zone they had entered: `zone`, `name`, `probability`.
    ZoneExited = 7,
    /// The person entered a geofence (`waymark_engine_add_geofence_circle` / `_polygon`):
    /// `name` (its id), `probability`.
    GeofenceEntered = 8,
    /// The person left a geofence they had entered: `name`, `probability`.
    GeofenceExited = 9,
}

/// Something about the session changed, or a call failed. Only the fields its `kind` names are
/// set; the others are 0 or NULL. Pointers in it are valid only during the callback.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct waymark_status {
    /// What happened.
    pub kind: waymark_status_kind,
    /// When, ns (0 for `TRACK_REVISED` and `ERROR`).
    pub timestamp_ns: u64,
    /// `SCENARIO_CHANGED`: as `waymark_position.scenario`.
    pub scenario: u32,
    /// `MOTION_STATE_CHANGED`: as `waymark_position.motion_state`.
    pub motion_state: u32,
    /// `TRACK_REVISED`: the revised points, oldest first.
    pub points: *const waymark_track_point,
    /// Number of `points`.
    pub point_count: usize,
    /// `ERROR`: the code the failed call returned.
    pub error: waymark_result,
    /// `ERROR`: NUL-terminated message (as `waymark_last_error` gives it to that call's thread).
    pub message: *const c_char,
    /// `ZONE_ENTERED`, `ZONE_EXITED`: the zone's index into the site's zones; -1 otherwise.
    pub zone: i32,
    /// `ZONE_*`: the zone's name; `GEOFENCE_*`: the geofence's id. NUL-terminated UTF-8.
    pub name: *const c_char,
    /// `ZONE_*`, `GEOFENCE_*`: the posterior probability of being inside it then.
    pub probability: f64,
}

/// The learned error of external position fixes: subtract the bias from a fix, then widen its
/// accuracy by `spread` (the engine does both to every fix it takes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct waymark_fix_bias {
    /// Mean error of the fixes along the site's x axis, m (0 before any fix was learned from).
    pub bias_x_m: f64,
    /// Mean error along the site's y axis, m.
    pub bias_y_m: f64,
    /// Factor on the fixes' own accuracy (1: they are as good as they say).
    pub spread: f64,
}

impl From<AppFixBias> for waymark_fix_bias {
    fn from(e: AppFixBias) -> Self {
        Self { bias_x_m: e.bias_x_m, bias_y_m: e.bias_y_m, spread: e.spread }
    }
}

/// What one `waymark_engine_learn_habits` pass did.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct waymark_habit_report {
    /// Epochs of the history learned from in this pass (those learned before are skipped); 0
    /// when there was nothing new to learn from.
    pub epochs: usize,
    /// Epochs learned from over all passes, including those of an imported model.
    pub total_epochs: u64,
    /// Moves between places with a learned count after the pass (all passes so far).
    pub learned_transitions: usize,
    /// Whether the learned moves now weigh on the positions: they do once they predict parts
    /// of the history they were not learned from better than the motion alone.
    pub applied: bool,
}

impl From<AppHabitReport> for waymark_habit_report {
    fn from(r: AppHabitReport) -> Self {
        Self {
            epochs: r.epochs,
            total_epochs: r.total_epochs,
            learned_transitions: r.learned_transitions,
            applied: r.applied,
        }
    }
}

/// What the engine took and refused since it was created, and why
/// (`waymark_engine_input_stats`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct waymark_input_stats {
    /// Scans that made a position.
    pub scans_accepted: u64,
    /// Scans refused because their time was not after the last position's.
    pub scans_out_of_order: u64,
    /// Scans refused for having no readings.
    pub scans_empty: u64,
    /// Scans refused for a NaN, infinite or impossible (below -1000 dBm) signal strength.
    pub scans_non_finite: u64,
    /// Scans refused for a signal strength above +100 dBm.
    pub scans_rssi_too_high: u64,
    /// Scans refused because none of their transmitters is in the site file.
    pub scans_no_known_transmitter: u64,
    /// Readings ignored in accepted scans: transmitter not in the site file.
    pub readings_unknown: u64,
    /// Readings ignored in accepted scans: the scan repeated their transmitter.
    pub readings_duplicate: u64,
    /// Readings ignored in accepted scans: measured too long before the scan.
    pub readings_stale: u64,
    /// Accepted scans the site's map did not explain (positions from the motion alone).
    pub scans_unexplained: u64,
    /// Positions made from the motion alone (`waymark_engine_advance`).
    pub motion_epochs: u64,
    /// Advances refused.
    pub advances_rejected: u64,
    /// Position fixes taken.
    pub fixes_accepted: u64,
    /// Position fixes refused.
    pub fixes_rejected: u64,
    /// User feedback taken.
    pub feedback_accepted: u64,
    /// User feedback refused.
    pub feedback_rejected: u64,
    /// Times the engine started over from "anywhere on the site".
    pub filter_restarts: u64,
    /// Inputs refused for a time too far ahead of the engine's clock: sensor samples more than
    /// 10 s ahead of the latest input taken (unless the stream's next sample confirms the
    /// jump, as after the phone slept), and any time above INT64_MAX ns, a negative time passed
    /// as unsigned. Each refusal also reaches the status callback as an `INPUT_REJECTED` error.
    pub timestamps_ahead: u64,
    /// Barometer readings dropped: not a pressure (NaN, outside 300-1100 hPa) or not after the
    /// previous one.
    pub pressure_dropped: u64,
}

impl From<&engine::InputStats> for waymark_input_stats {
    fn from(s: &engine::InputStats) -> Self {
        Self {
            scans_accepted: s.scans_accepted,
            scans_out_of_order: s.scans_out_of_order,
            scans_empty: s.scans_empty,
            scans_non_finite: s.scans_non_finite,
            scans_rssi_too_high: s.scans_rssi_too_high,
            scans_no_known_transmitter: s.scans_no_known_transmitter,
            readings_unknown: s.readings_unknown,
            readings_duplicate: s.readings_duplicate,
            readings_stale: s.readings_stale,
            scans_unexplained: s.scans_unexplained,
            motion_epochs: s.motion_epochs,
            advances_rejected: s.advances_rejected,
            fixes_accepted: s.fixes_accepted,
            fixes_rejected: s.fixes_rejected,
            feedback_accepted: s.feedback_accepted,
            feedback_rejected: s.feedback_rejected,
            filter_restarts: s.filter_restarts,
            timestamps_ahead: s.timestamps_ahead,
            pressure_dropped: s.pressure_dropped,
        }
    }
}

/// Called with every new position, in the order of the epochs, never from two threads at once,
/// with no lock held, on a thread that called the engine: usually the one whose call made the
/// position. While one thread is running a callback, events made by other threads' calls are
/// passed to it by that thread, after the current one, so such a call may return before its
/// position reaches the callback; every position has reached it by the time all calls have
/// returned. A callback may call the engine (what it makes is delivered after the current
/// call returns, by the same thread), replace or clear the callbacks, and free the engine: then
/// no callback of it is called again, and it is freed when the calls running on it return
/// (docs/errors.md#callbacks).
pub type waymark_position_callback =
    Option<unsafe extern "C" fn(userdata: *mut c_void, position: *const waymark_position)>;

/// Called with every status change and every failed call, as `waymark_position_callback` is
/// (in one order with the positions, from the same thread, never at the same time as it), and
/// may do what it may: call the engine, or free it (on a rejected input too).
pub type waymark_status_callback =
    Option<unsafe extern "C" fn(userdata: *mut c_void, status: *const waymark_status)>;

/// Called with each log record at the level given to `waymark_set_log_callback` or above:
/// `level` a `waymark_log_level`, `target` the Rust module it came from and `message` the
/// text, both NUL-terminated and valid only during the call. Called from any thread that
/// calls Waymark, possibly from several at once, on the thread that logged: a record logged
/// during a Waymark call is delivered when that call has released its locks, just before it
/// returns (at most 1000 records per call; then one `WARN` record counts the ones dropped). So it may call Waymark, free an engine, or set the log callback; what it calls
/// does not change the returning call's `waymark_last_error`. See docs/errors.md#callbacks.
pub type waymark_log_callback = Option<
    unsafe extern "C" fn(userdata: *mut c_void, level: u32, target: *const c_char, message: *const c_char),
>;

impl From<AppPosition<'_>> for waymark_position {
    fn from(p: AppPosition<'_>) -> Self {
        let nan = f64::NAN;
        waymark_position {
            timestamp_ns: p.timestamp_ns,
            x: p.x,
            y: p.y,
            floor: p.floor,
            floor_probability: p.floor_probability,
            has_floor_level: p.floor_level.is_some(),
            floor_level: p.floor_level.unwrap_or(0),
            level_unmapped: p.level_unmapped,
            latitude_deg: p.latitude_deg.unwrap_or(nan),
            longitude_deg: p.longitude_deg.unwrap_or(nan),
            zone: p.zone.unwrap_or(-1),
            zone_probability: p.zone_probability,
            accuracy_m: p.accuracy_m,
            accuracy_95_m: p.accuracy_95_m,
            heading_deg: p.heading_deg.unwrap_or(nan),
            heading_accuracy_deg: p.heading_accuracy_deg.unwrap_or(nan),
            bearing_deg: p.bearing_deg.unwrap_or(nan),
            motion_state: motion_state(p.motion_state),
            scenario: scenario(p.scenario),
            steps: p.steps,
            beyond_radio_m: p.beyond_radio_m,
        }
    }
}

/// The position `p` of an engine on `site`.
pub(crate) fn position(p: &Position, site: &Site) -> waymark_position {
    AppPosition::new(p, site).into()
}

pub(crate) fn motion_state(s: MotionState) -> u32 {
    match s {
        MotionState::Unknown => 0,
        MotionState::Stationary => 1,
        MotionState::Walking => 2,
    }
}

pub(crate) fn scenario(s: MotionScenario) -> u32 {
    match s {
        MotionScenario::DistanceHeading => 0,
        MotionScenario::Distance => 1,
        MotionScenario::HeadingSpeed => 2,
        MotionScenario::Speed => 3,
    }
}

impl From<AppTrackPoint> for waymark_track_point {
    fn from(p: AppTrackPoint) -> Self {
        waymark_track_point {
            timestamp_ns: p.timestamp_ns,
            x: p.x,
            y: p.y,
            floor: p.floor,
            has_floor_level: p.floor_level.is_some(),
            floor_level: p.floor_level.unwrap_or(0),
            level_unmapped: p.level_unmapped,
        }
    }
}
