//! The records and enums of the Kotlin and Swift API, and their conversions from the core's
//! types. A change here is a possible breaking change for apps (CHANGELOG, "Breaking changes").

use crate::ffi::handle::Options;
use crate::ffi::record::{AppFixBias, AppHabitReport, AppPosition, AppStatus, AppTrackPoint};
use waymark_engine as engine;
use waymark_engine::sensors::SensorSample;
use waymark_engine::site::Site;
use waymark_engine::TransitionModel;

/// Which transition model the engine uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, uniffi::Enum)]
pub enum TransitionKind {
    /// Radio only: uniform over the states reachable at the maximum speed.
    Reach,
    /// High/low probability regions from the walked distance and heading (HIPE eqs. 5-11).
    Regions,
    /// A Gaussian on the movement vector between states, the default (Hoang eq. 11).
    MovementVector,
}

/// Engine settings an app may change; every field has a default.
#[derive(Clone, PartialEq, uniffi::Record)]
pub struct EngineOptions {
    /// Transition model; `null` / `nil` for the default (Hoang's).
    #[uniffi(default = None)]
    pub transition: Option<TransitionKind>,
    /// The user's own step length in metres, used in place of the step length model the site
    /// was surveyed with (for an app that knows its user's stride). `null` / `nil`: the
    /// site's surveyed model, or 0.7 m on a site without one. Outside 0.1-2.5 m:
    /// `InvalidConfig`.
    #[uniffi(default = None)]
    pub step_length_m: Option<f64>,
    /// How many epochs behind the newest the fixed-lag estimate is.
    #[uniffi(default = 3)]
    pub fixed_lag_epochs: u32,
    /// Whether the engine keeps the Viterbi track (`track()`, `TrackRevised`). `false`: an app
    /// that shows only the live position (and maybe `fixedLagPosition()`) saves each epoch's
    /// Viterbi step and the track's memory (docs/results.md#speed); `track()` is then empty
    /// and no `TrackRevised` comes. The positions are the same either way.
    #[uniffi(default = true)]
    pub track: bool,
    /// Magnetic declination at the site, degrees east, within ±180; `null` / `nil`: the site
    /// file's.
    #[uniffi(default = None)]
    pub declination_deg: Option<f64>,
    /// True azimuth of the site's +y axis, degrees, within ±360; `null` / `nil`: the site
    /// file's.
    #[uniffi(default = None)]
    pub site_rotation_deg: Option<f64>,
    /// The salt of a site file whose transmitter ids are hashed (docs/privacy.md): the bytes
    /// the salt file's hex digits stand for, at least 16. Scans are hashed with it before
    /// matching. `null` / `nil` for a site with raw ids. A hashed site without it, or with
    /// another salt, throws `SaltMismatch`. Keep it out of the site file's download and out of
    /// logs.
    #[uniffi(default = None)]
    pub site_salt: Option<Vec<u8>>,
}

/// By hand, so the salt never reaches a log.
impl std::fmt::Debug for EngineOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EngineOptions")
            .field("transition", &self.transition)
            .field("step_length_m", &self.step_length_m)
            .field("fixed_lag_epochs", &self.fixed_lag_epochs)
            .field("track", &self.track)
            .field("declination_deg", &self.declination_deg)
            .field("site_rotation_deg", &self.site_rotation_deg)
            .field("site_salt", &self.site_salt.as_ref().map(|s| format!("<{} bytes, redacted>", s.len())))
            .finish()
    }
}

impl Default for EngineOptions {
    fn default() -> Self {
        let core = waymark_engine::EngineConfig::default();
        Self {
            transition: None,
            step_length_m: None,
            fixed_lag_epochs: core.fixed_lag_epochs as u32,
            track: core.track,
            declination_deg: None,
            site_rotation_deg: None,
            site_salt: None,
        }
    }
}

impl EngineOptions {
    /// The options both FFIs share.
    pub(crate) fn to_options(&self) -> Options {
        Options {
            transition: self.transition.map(|t| match t {
                TransitionKind::Reach => TransitionModel::Reach,
                TransitionKind::Regions => TransitionModel::Regions,
                TransitionKind::MovementVector => TransitionModel::MovementVector,
            }),
            fixed_lag_epochs: Some(self.fixed_lag_epochs as usize),
            track: Some(self.track),
            declination_deg: self.declination_deg,
            site_rotation_deg: self.site_rotation_deg,
            site_salt: self.site_salt.clone(),
            step_length_m: self.step_length_m,
        }
    }
}

/// One accelerometer (m/s², gravity included), gyroscope (rad/s) or magnetometer (µT) sample
/// in the phone's frame, with its monotonic timestamp in nanoseconds (Android
/// `SensorEvent.timestamp`; iOS `CMLogItem.timestamp` × 1e9).
#[derive(Clone, Copy, Debug, PartialEq, uniffi::Record)]
pub struct MotionSample {
    /// Nanoseconds on the monotonic clock shared by every input.
    pub timestamp_ns: u64,
    /// x axis.
    pub x: f64,
    /// y axis.
    pub y: f64,
    /// z axis.
    pub z: f64,
}

/// One barometer reading with its monotonic timestamp in nanoseconds: Android's
/// `Sensor.TYPE_PRESSURE` (`values[0]`, hPa), iOS's `CMAltitudeData.pressure` (kPa) × 10.
#[derive(Clone, Copy, Debug, PartialEq, uniffi::Record)]
pub struct PressureReading {
    /// Nanoseconds on the monotonic clock shared by every input.
    pub timestamp_ns: u64,
    /// Air pressure, hPa.
    pub hpa: f64,
}

/// A transmitter's id as an app gives it: a BSSID, a beacon's proximity UUID or its advertiser
/// address. Kotlin and Swift see a `String`.
///
/// A Kotlin `String` can hold a lone UTF-16 surrogate (`"\uD800"`), which is not text: uniffi's
/// generated code refuses to encode it and throws `CharacterCodingException` before the call
/// reaches Waymark (and, for a method, leaks the engine's handle). This type's Kotlin
/// conversion (`uniffi.toml`) encodes such an id with each lone surrogate replaced by `?`
/// instead, so it reaches Waymark, parses as no id, and the scan throws
/// `PositioningException.InputRejected` like any malformed id. A valid id is never changed.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TransmitterIdString(pub String);

uniffi::custom_newtype!(TransmitterIdString, String);

impl std::ops::Deref for TransmitterIdString {
    type Target = str;
    fn deref(&self) -> &str {
        &self.0
    }
}

impl From<&str> for TransmitterIdString {
    fn from(id: &str) -> Self {
        Self(id.to_owned())
    }
}

impl From<String> for TransmitterIdString {
    fn from(id: String) -> Self {
        Self(id)
    }
}

/// A WiFi access point heard in a scan.
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
pub struct WifiReading {
    /// BSSID, any common notation. One that does not parse (in Kotlin, one holding a lone
    /// UTF-16 surrogate too) makes `push_scan` throw `InputRejected`.
    pub bssid: TransmitterIdString,
    /// Signal strength, dBm.
    pub rssi_dbm: f64,
    /// How long before the scan this reading was measured, ms (0 if fresh).
    #[uniffi(default = 0)]
    pub age_ms: u64,
}

/// A BLE beacon heard in a scan: an iBeacon by its UUID, major and minor, or any beacon
/// (Eddystone, an iBeacon left at major = minor = 0) by its advertiser address.
///
/// Which one it is: with an `address`, a beacon whose `uuid` is empty or whose major and
/// minor are both 0 is identified by the address; otherwise by UUID, major and minor (the
/// address must still be valid). A reading with neither a UUID nor an address, or with one
/// that does not parse (in Kotlin, one holding a lone UTF-16 surrogate too), makes
/// `push_scan` throw `InputRejected`.
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
pub struct BeaconReading {
    /// Proximity UUID, with or without hyphens; empty for a beacon known by its address only.
    #[uniffi(default = "")]
    pub uuid: TransmitterIdString,
    /// Major number.
    #[uniffi(default = 0)]
    pub major: u16,
    /// Minor number.
    #[uniffi(default = 0)]
    pub minor: u16,
    /// Signal strength, dBm.
    pub rssi_dbm: f64,
    /// How long before the scan this reading was measured, ms (0 if fresh).
    #[uniffi(default = 0)]
    pub age_ms: u64,
    /// The advertiser's MAC address (Android `ScanResult.getDevice().getAddress()`), any common
    /// notation; `null` / `nil` or empty when unknown (iOS never reports it).
    #[uniffi(default = None)]
    pub address: Option<TransmitterIdString>,
}

/// Everything heard at one moment.
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
pub struct RadioScan {
    /// Nanoseconds on the monotonic clock shared by every input.
    pub timestamp_ns: u64,
    /// WiFi access points.
    pub wifi: Vec<WifiReading>,
    /// BLE beacons.
    pub beacons: Vec<BeaconReading>,
}

impl RadioScan {
    /// The scan as the core takes it, or why a transmitter id does not parse.
    pub(crate) fn to_core(&self) -> Result<waymark_engine::radio::Scan, String> {
        use waymark_engine::radio::{Reading, TransmitterId};
        let mut readings = Vec::with_capacity(self.wifi.len() + self.beacons.len());
        for w in &self.wifi {
            readings.push(Reading {
                transmitter: TransmitterId::wifi(&w.bssid)?,
                rssi_dbm: w.rssi_dbm,
                age_ns: w.age_ms.saturating_mul(crate::ffi::NS_PER_MS),
            });
        }
        for b in &self.beacons {
            readings.push(Reading {
                transmitter: crate::ffi::beacon_id(&b.uuid, b.major, b.minor, b.address.as_deref())?,
                rssi_dbm: b.rssi_dbm,
                age_ns: b.age_ms.saturating_mul(crate::ffi::NS_PER_MS),
            });
        }
        Ok(waymark_engine::radio::Scan { timestamp_ns: self.timestamp_ns, readings })
    }
}

pub use waymark_engine::sensors::{MotionScenario, MotionState};
pub use waymark_engine::site::ZoneKind;

// The core's enums, exported as they are (uniffi remote types): their variants are what an app
// sees, so there is one type and no conversion. The doc comments here are the ones Kotlin and
// Swift get.

/// Walking or not.
#[uniffi::remote(Enum)]
enum MotionState {
    /// No accelerometer data.
    Unknown,
    /// Still.
    Stationary,
    /// Walking.
    Walking,
}

/// Which motion information the engine had (HIPE's four scenarios).
#[uniffi::remote(Enum)]
enum MotionScenario {
    /// Steps and heading.
    DistanceHeading,
    /// Steps, no trustworthy heading.
    Distance,
    /// Heading, no steps.
    HeadingSpeed,
    /// Neither.
    Speed,
}

/// Where the phone is.
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
pub struct PositionEstimate {
    /// Time of the epoch, ns.
    pub timestamp_ns: u64,
    /// x in the site's metric frame, m.
    pub x: f64,
    /// y in the site's metric frame, m.
    pub y: f64,
    /// Floor index in the site file.
    pub floor: u32,
    /// Floor name.
    pub floor_name: String,
    /// The floor's logical level as the building numbers it (-1 for the first basement), as
    /// Core Location's `CLFloor.level`; `null` / `nil` when the site file gives none. When
    /// `level_unmapped`, a level the site has no floor for, where the barometer places the
    /// phone (docs/accuracy.md#barometer).
    #[uniffi(default = None)]
    pub floor_level: Option<i32>,
    /// Whether `floor_level` is a level the site has no floor for: x, y and the radii then
    /// stand on `floor`'s plan, the nearest the map can place the phone.
    #[uniffi(default = false)]
    pub level_unmapped: bool,
    /// Probability that the floor is right: how often it was at this posterior mass on it on
    /// held-out survey walks (docs/accuracy.md#floor-probability), or the posterior's own mass
    /// when the site file has no such calibration.
    pub floor_probability: f64,
    /// Latitude, degrees north (WGS84), when the site file is geo-referenced (has an
    /// `anchor`); `null` / `nil` otherwise.
    #[uniffi(default = None)]
    pub latitude_deg: Option<f64>,
    /// Longitude, degrees east (WGS84), when the site file is geo-referenced.
    #[uniffi(default = None)]
    pub longitude_deg: Option<f64>,
    /// The most likely zone's name (a room, a corridor): the zone holding the most posterior
    /// mass; `null` / `nil` when the site has no zones or more mass lies outside every zone
    /// than in any one. (The defaults here and below only keep code that builds estimates,
    /// such as tests, compiling: the engine always sets both.)
    #[uniffi(default = None)]
    pub zone: Option<String>,
    /// Probability of `zone` (of being in no zone when it is `null` / `nil`).
    #[uniffi(default = 1.0)]
    pub zone_probability: f64,
    /// Radius of the 68% circle, m, as Android's `getAccuracy()` and iOS's
    /// `horizontalAccuracy`.
    pub accuracy_m: f64,
    /// Radius of the 95% circle, m.
    pub accuracy_95_m: f64,
    /// Direction of travel, degrees clockwise from the site's +y axis, when known.
    pub heading_deg: Option<f64>,
    /// One standard deviation of the heading, degrees.
    pub heading_accuracy_deg: Option<f64>,
    /// Direction of travel, degrees clockwise from true north in [0, 360) (Android's
    /// `bearing`, iOS's `course`), when the heading is known and the site is geo-referenced.
    #[uniffi(default = None)]
    pub bearing_deg: Option<f64>,
    /// Walking or not.
    pub motion_state: MotionState,
    /// Motion information available this epoch.
    pub scenario: MotionScenario,
    /// Steps since the previous epoch.
    pub steps: u32,
    /// Distance walked since the radio last explained a scan, m: 0 while it does. Above 0 the
    /// phone is probably beyond the surveyed area (the site's map does not explain what it
    /// hears), the estimate follows the motion alone and both radii include this distance.
    #[uniffi(default = 0.0)]
    pub beyond_radio_m: f64,
}

/// A position from another positioning system: GNSS near an entrance, WiFi RTT, UWB. Give
/// either `x` and `y` in the site's frame, or `latitudeDeg` and `longitudeDeg` on a
/// geo-referenced site (its file has an `anchor`); anything else throws `InputRejected`.
#[derive(Clone, Copy, Debug, PartialEq, uniffi::Record)]
#[uniffi(name = "PositionFix")]
pub struct FfiPositionFix {
    /// When it was measured, ns, on the clock of every other input.
    pub timestamp_ns: u64,
    /// x in the site's metric frame, m.
    #[uniffi(default = None)]
    pub x: Option<f64>,
    /// y in the site's metric frame, m.
    #[uniffi(default = None)]
    pub y: Option<f64>,
    /// Floor index in the site file, when the other system knows it (UWB, an RTT access
    /// point's floor); `null` / `nil` for GNSS.
    #[uniffi(default = None)]
    pub floor: Option<u32>,
    /// Radius of the 68% circle, m, as Android's `Location.getAccuracy()`; must be > 0.
    pub accuracy_m: f64,
    /// Latitude, degrees north (WGS84), in place of `x` and `y`.
    #[uniffi(default = None)]
    pub latitude_deg: Option<f64>,
    /// Longitude, degrees east (WGS84), in place of `x` and `y`.
    #[uniffi(default = None)]
    pub longitude_deg: Option<f64>,
}

/// What kind of place a zone is.
#[uniffi::remote(Enum)]
enum ZoneKind {
    /// A room (an office, a kitchen, a shop).
    Room,
    /// A corridor or aisle.
    Corridor,
    /// A hall, an atrium, a concourse.
    Hall,
    /// A staircase.
    Stairs,
    /// A lift (elevator) or its lobby.
    Lift,
    /// An entrance.
    Entrance,
    /// Anything else.
    Other,
}

/// A zone of the site and how likely the phone is to be in it.
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
pub struct ZoneProbability {
    /// The zone's name, unique in the site.
    pub name: String,
    /// What kind of place it is.
    pub kind: ZoneKind,
    /// Posterior probability of being in it, now.
    pub probability: f64,
}

/// One point of the smoothed track.
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
#[uniffi(name = "TrackPoint")]
pub struct FfiTrackPoint {
    /// Epoch time, ns.
    pub timestamp_ns: u64,
    /// x, m.
    pub x: f64,
    /// y, m.
    pub y: f64,
    /// Floor index.
    pub floor: u32,
    /// The level to show, as `PositionEstimate.floor_level`: the level the live position of
    /// the same epoch reported where the site has no floor for it, else the floor's own;
    /// `None` when the site file gives no levels.
    #[uniffi(default = None)]
    pub floor_level: Option<i32>,
    /// Whether `floor_level` is a level the site has no floor for.
    #[uniffi(default = false)]
    pub level_unmapped: bool,
}

/// The learned error of external position fixes (`pushFix`): subtract the bias from a fix,
/// then widen its accuracy by `spread`. The engine does both to every fix it takes.
#[derive(Clone, Copy, Debug, PartialEq, uniffi::Record)]
#[uniffi(name = "FixBias")]
pub struct FfiFixBias {
    /// Mean error of the fixes along the site's x axis, m (0 before any fix was learned from).
    pub bias_x_m: f64,
    /// Mean error of the fixes along the site's y axis, m.
    pub bias_y_m: f64,
    /// Factor on the fixes' own accuracy: 1 when they are as good as they say, 2 when their
    /// errors are twice what they report.
    pub spread: f64,
}

impl From<AppFixBias> for FfiFixBias {
    fn from(e: AppFixBias) -> Self {
        Self { bias_x_m: e.bias_x_m, bias_y_m: e.bias_y_m, spread: e.spread }
    }
}

/// What one `learnHabits` pass did.
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
#[uniffi(name = "HabitReport")]
pub struct FfiHabitReport {
    /// Epochs of the history learned from in this pass (those learned before are skipped); 0
    /// when there was nothing new to learn from.
    pub epochs: u32,
    /// Epochs learned from over all passes, including those of an imported model.
    pub total_epochs: u64,
    /// Moves between places with a learned count, after the pass (all passes so far).
    pub learned_transitions: u64,
    /// Whether the learned moves now weigh on the positions. They do once they predict parts
    /// of the history they were not learned from better than the motion alone; until then
    /// the engine keeps learning but positions as before.
    pub applied: bool,
}

fn count(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

impl From<AppHabitReport> for FfiHabitReport {
    fn from(r: AppHabitReport) -> Self {
        Self {
            epochs: count(r.epochs),
            total_epochs: r.total_epochs,
            learned_transitions: r.learned_transitions as u64,
            applied: r.applied,
        }
    }
}

/// What the engine took and what it refused since it was created, and why: for an app's
/// diagnostics screen or logs (a phone whose scans are mostly refused is misconfigured, or
/// outside the site). Every rejected input also made its call throw.
#[derive(Clone, Debug, Default, PartialEq, Eq, uniffi::Record)]
#[uniffi(name = "InputStats")]
pub struct FfiInputStats {
    /// Scans that made a position.
    pub scans_accepted: u64,
    /// Scans refused because their time was not after the last position's.
    pub scans_out_of_order: u64,
    /// Scans refused for having no readings.
    pub scans_empty: u64,
    /// Scans refused for a NaN, infinite or impossible (below -1000 dBm) signal strength.
    pub scans_non_finite: u64,
    /// Scans refused for a signal strength above +100 dBm, which no receiver reports.
    pub scans_rssi_too_high: u64,
    /// Scans refused because none of their transmitters is in the site file: the phone is
    /// probably outside the surveyed area.
    pub scans_no_known_transmitter: u64,
    /// Readings ignored in accepted scans because the site file does not know their
    /// transmitter.
    pub readings_unknown: u64,
    /// Readings ignored in accepted scans because the scan repeated their transmitter.
    pub readings_duplicate: u64,
    /// Readings ignored in accepted scans because they were measured too long before it.
    pub readings_stale: u64,
    /// Accepted scans the site's map did not explain: their positions followed the motion
    /// alone.
    pub scans_unexplained: u64,
    /// Positions made from the motion alone (`advance`).
    pub motion_epochs: u64,
    /// `advance` calls refused (a time not after the last position's).
    pub advances_rejected: u64,
    /// Position fixes taken (`pushFix`).
    pub fixes_accepted: u64,
    /// Position fixes refused.
    pub fixes_rejected: u64,
    /// User feedback taken (`confirmZone`, `confirmPosition`).
    pub feedback_accepted: u64,
    /// User feedback refused.
    pub feedback_rejected: u64,
    /// Times the engine started over from "anywhere on the site": after a gap too long to
    /// bridge, or when nothing could explain a scan.
    pub filter_restarts: u64,
    /// Inputs refused for a time too far ahead of the engine's clock: sensor samples more than
    /// 10 s ahead of the latest input taken (unless the stream's next sample confirms the
    /// jump, as after the phone slept), and any time above 2^63 - 1 ns, a negative `Long`
    /// passed as unsigned. Each refusal also reaches the listener as an `InputRejected` error.
    pub timestamps_ahead: u64,
    /// Barometer readings dropped: not a pressure (NaN, outside 300-1100 hPa) or not after the
    /// previous one.
    pub pressure_dropped: u64,
}

impl From<&engine::InputStats> for FfiInputStats {
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

/// A habit model's JSON as an app gives it to `importHabits`. Kotlin and Swift see a `String`.
///
/// A Kotlin `String` can hold a lone UTF-16 surrogate, which is not text: uniffi's generated
/// code would throw `CharacterCodingException` before the call reaches Waymark (and leak the
/// engine's handle). This type's Kotlin conversion (`uniffi.toml`) replaces each lone
/// surrogate by `?` instead, so such JSON reaches Waymark and is refused as any malformed
/// model is (`HabitsRejected`). Valid text is never changed.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct HabitsJson(pub String);

uniffi::custom_newtype!(HabitsJson, String);

impl From<&str> for HabitsJson {
    fn from(json: &str) -> Self {
        Self(json.to_owned())
    }
}

impl From<String> for HabitsJson {
    fn from(json: String) -> Self {
        Self(json)
    }
}

/// Something about the session changed.
#[derive(Clone, Debug, PartialEq, uniffi::Enum)]
pub enum StatusUpdate {
    /// The motion information changed (a sensor stopped, the compass became disturbed, ...).
    ScenarioChanged {
        /// Now.
        scenario: MotionScenario,
    },
    /// The person started or stopped walking.
    MotionStateChanged {
        /// Now.
        state: MotionState,
    },
    /// A scan heard no transmitter of the site: the phone is probably outside the surveyed
    /// area (or the site file is for another building).
    NoSiteCoverage {
        /// The scan's time, ns.
        timestamp_ns: u64,
    },
    /// Earlier positions were revised by later evidence.
    TrackRevised {
        /// The revised points, oldest first.
        points: Vec<FfiTrackPoint>,
    },
    /// The person entered one of the site's zones (its posterior mass reached the engine's
    /// enter threshold; docs/zones.md).
    ZoneEntered {
        /// When, ns.
        timestamp_ns: u64,
        /// The zone's name.
        zone: String,
        /// The zone's posterior probability then.
        probability: f64,
    },
    /// The person left a zone they had entered.
    ZoneExited {
        /// When, ns.
        timestamp_ns: u64,
        /// The zone's name.
        zone: String,
        /// The zone's posterior probability then.
        probability: f64,
    },
    /// The person entered one of the app's geofences (`addGeofence`).
    GeofenceEntered {
        /// When, ns.
        timestamp_ns: u64,
        /// The geofence's id.
        id: String,
        /// Its posterior probability then.
        probability: f64,
    },
    /// The person left a geofence they had entered.
    GeofenceExited {
        /// When, ns.
        timestamp_ns: u64,
        /// The geofence's id.
        id: String,
        /// Its posterior probability then.
        probability: f64,
    },
}

impl From<AppTrackPoint> for FfiTrackPoint {
    fn from(p: AppTrackPoint) -> Self {
        Self {
            timestamp_ns: p.timestamp_ns,
            x: p.x,
            y: p.y,
            floor: p.floor,
            floor_level: p.floor_level,
            level_unmapped: p.level_unmapped,
        }
    }
}

impl From<AppPosition<'_>> for PositionEstimate {
    fn from(p: AppPosition<'_>) -> Self {
        Self {
            timestamp_ns: p.timestamp_ns,
            x: p.x,
            y: p.y,
            floor: p.floor,
            floor_name: p.floor_name.to_owned(),
            floor_level: p.floor_level,
            level_unmapped: p.level_unmapped,
            floor_probability: p.floor_probability,
            latitude_deg: p.latitude_deg,
            longitude_deg: p.longitude_deg,
            zone: p.zone_name.map(str::to_owned),
            zone_probability: p.zone_probability,
            accuracy_m: p.accuracy_m,
            accuracy_95_m: p.accuracy_95_m,
            heading_deg: p.heading_deg,
            heading_accuracy_deg: p.heading_accuracy_deg,
            bearing_deg: p.bearing_deg,
            motion_state: p.motion_state,
            scenario: p.scenario,
            steps: p.steps,
            beyond_radio_m: p.beyond_radio_m,
        }
    }
}

/// The position `p` of an engine on `site`.
pub(crate) fn estimate(p: &engine::Position, site: &Site) -> PositionEstimate {
    AppPosition::new(p, site).into()
}

/// The track point `p` of an engine on `site`.
pub(crate) fn track_point(p: &engine::TrackPoint, site: &Site) -> FfiTrackPoint {
    AppTrackPoint::new(p, site).into()
}

impl FfiPositionFix {
    /// The core fix: `x` and `y` as given, or the latitude/longitude in the site's frame
    /// (on the fix's floor, when the floors' frames differ). `Err` says why it is neither.
    pub(crate) fn to_core(self, site: &Site) -> Result<waymark_engine::PositionFix, String> {
        let floor = self.floor.map(|f| f as usize);
        let (x, y) = match (self.x, self.y, self.latitude_deg, self.longitude_deg) {
            (Some(x), Some(y), None, None) => (x, y),
            (None, None, Some(lat_deg), Some(lon_deg)) => {
                let p = site
                    .site_point(floor, waymark_engine::site::LatLon { lat_deg, lon_deg })
                    .map_err(|e| e.to_string())?;
                (p.x, p.y)
            }
            _ => return Err("a position fix needs x and y, or latitude and longitude (not both)".into()),
        };
        Ok(waymark_engine::PositionFix {
            timestamp_ns: self.timestamp_ns,
            x,
            y,
            floor,
            accuracy_m: self.accuracy_m,
        })
    }
}

impl From<&AppStatus> for StatusUpdate {
    fn from(status: &AppStatus) -> Self {
        match status {
            &AppStatus::ScenarioChanged { scenario, .. } => StatusUpdate::ScenarioChanged { scenario },
            &AppStatus::MotionStateChanged { state, .. } => StatusUpdate::MotionStateChanged { state },
            &AppStatus::NoSiteCoverage { timestamp_ns } => StatusUpdate::NoSiteCoverage { timestamp_ns },
            AppStatus::TrackRevised { points } => StatusUpdate::TrackRevised {
                points: points.iter().copied().map(FfiTrackPoint::from).collect(),
            },
            AppStatus::Zone { timestamp_ns, name, entered, probability, .. } => {
                let (timestamp_ns, zone, probability) = (*timestamp_ns, name.clone(), *probability);
                if *entered {
                    StatusUpdate::ZoneEntered { timestamp_ns, zone, probability }
                } else {
                    StatusUpdate::ZoneExited { timestamp_ns, zone, probability }
                }
            }
            AppStatus::Geofence { timestamp_ns, id, entered, probability } => {
                let (timestamp_ns, id, probability) = (*timestamp_ns, id.clone(), *probability);
                if *entered {
                    StatusUpdate::GeofenceEntered { timestamp_ns, id, probability }
                } else {
                    StatusUpdate::GeofenceExited { timestamp_ns, id, probability }
                }
            }
        }
    }
}

pub(crate) fn pressure_samples(batch: &[PressureReading]) -> Vec<waymark_engine::sensors::PressureSample> {
    batch
        .iter()
        .map(|s| waymark_engine::sensors::PressureSample { timestamp_ns: s.timestamp_ns, hpa: s.hpa })
        .collect()
}

pub(crate) fn samples(batch: &[MotionSample]) -> Vec<SensorSample> {
    batch.iter().map(|s| SensorSample { timestamp_ns: s.timestamp_ns, x: s.x, y: s.y, z: s.z }).collect()
}

/// Map evidence a session gathered (`PositioningEngine.takeEvidence`,
/// docs/evidence.md#from-a-session).
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
#[uniffi(name = "SessionEvidence")]
pub struct FfiSessionEvidence {
    /// The evidence file's bytes (docs/evidence.md#file-format), to upload as they are.
    pub bytes: Vec<u8>,
    /// Scans in it.
    pub scans: u64,
    /// Accepted scans left out of it (their posterior could not be had or added).
    pub scans_dropped: u64,
}

impl From<waymark_engine::SessionEvidence> for FfiSessionEvidence {
    fn from(taken: waymark_engine::SessionEvidence) -> Self {
        Self { bytes: taken.evidence.to_bytes(), scans: taken.scans, scans_dropped: taken.scans_dropped }
    }
}
