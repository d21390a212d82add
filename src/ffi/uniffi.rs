//! The Kotlin and Swift API, through uniffi proc-macros. Every exported type lives here; a
//! change in this file is a possible breaking change for apps (CHANGELOG, "Breaking changes").

use super::delivery::{lock, Delivery};
use crate::config::{EngineConfig, TransitionModel};
use crate::engine::{self, Engine, PositionListener as CoreListener};
use crate::radio::{Reading, Scan, TransmitterId};
use crate::sensors::{self, SensorSample};
use crate::site::Site;
use std::sync::{Arc, Mutex, Weak};

/// Errors an app can act on.
#[derive(Debug, thiserror::Error, uniffi::Error)]
pub enum PositioningError {
    /// The site file could not be read or is malformed; `reason` says what and where.
    #[error("invalid site: {reason}")]
    InvalidSite {
        /// What is wrong and where.
        reason: String,
    },
    /// A configuration value is out of range.
    #[error("invalid configuration: {reason}")]
    InvalidConfig {
        /// Which field and why.
        reason: String,
    },
    /// An input was rejected; the engine is unchanged and goes on. A scan, an advance or a
    /// position fix whose time is not after the last epoch's, or feedback whose time is before
    /// it; a scan with no readings, with an RSSI that is NaN, infinite, below -1000 dBm or
    /// above +100 dBm, with no transmitter the site knows, or with a malformed transmitter id:
    /// a BSSID, UUID or address that does not parse (in Kotlin, one holding a lone UTF-16
    /// surrogate too), a beacon with neither a UUID nor an address; a position fix or a
    /// confirmed position with a NaN or infinite coordinate, an accuracy or radius not > 0, a
    /// floor the site does not have, or too far from the site; feedback naming a zone the
    /// site does not have.
    #[error("input rejected: {reason}")]
    InputRejected {
        /// Why.
        reason: String,
    },
    /// The site's transmitter ids are salted hashes and `EngineOptions.siteSalt` is missing or
    /// is not the salt they were hashed with: get the venue's salt for this site file.
    #[error("salt mismatch: {reason}")]
    SaltMismatch {
        /// Missing or wrong (the salt itself is never in the message).
        reason: String,
    },
    /// `importHabits` refused the model: the JSON does not parse, is not a Waymark habit
    /// model, is of a newer layout than this build reads, was learned on another site (or
    /// another build of the site file), or holds a value out of range. `reason` says which,
    /// with the field's path. The engine's habits are unchanged. A stored model refused for
    /// its site or its content will never be accepted by this engine: learn afresh.
    #[error("habit model rejected: {reason}")]
    HabitsRejected {
        /// Why.
        reason: String,
    },
    /// A bug in Waymark or in a listener: the call had no effect (a scan or an advance that
    /// panicked half-way is undone, and no listener hears its position).
    #[error("internal error: {reason}")]
    Internal {
        /// What happened.
        reason: String,
    },
}

impl From<uniffi::UnexpectedUniFFICallbackError> for PositioningError {
    fn from(e: uniffi::UnexpectedUniFFICallbackError) -> Self {
        PositioningError::Internal { reason: format!("listener failed: {}", e.reason) }
    }
}

impl From<crate::Error> for PositioningError {
    fn from(e: crate::Error) -> Self {
        match e {
            crate::Error::InvalidConfig(reason) => PositioningError::InvalidConfig { reason },
            crate::Error::Site(s @ (crate::SiteError::SaltRequired | crate::SiteError::WrongSalt)) => {
                PositioningError::SaltMismatch { reason: s.to_string() }
            }
            crate::Error::Site(s) => PositioningError::InvalidSite { reason: s.to_string() },
            crate::Error::Input(i) => PositioningError::InputRejected { reason: i.to_string() },
        }
    }
}

/// Which transition model the engine uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, uniffi::Enum)]
pub enum TransitionKind {
    /// Radio only: uniform over the states reachable at the maximum speed.
    Reach,
    /// HIPE's high/low regions from distance and heading.
    Hipe,
    /// Hoang's Gaussian on the movement vector (the default).
    Hoang,
}

/// Engine settings an app may change; every field has a default.
#[derive(Clone, PartialEq, uniffi::Record)]
pub struct EngineOptions {
    /// Transition model; `null` / `nil` for the default (Hoang's).
    #[uniffi(default = None)]
    pub transition: Option<TransitionKind>,
    /// The user's step length in metres (HIPE: 0.7 m).
    #[uniffi(default = 0.7)]
    pub step_length_m: f64,
    /// How many epochs behind the newest the fixed-lag estimate is.
    #[uniffi(default = 3)]
    pub fixed_lag_epochs: u32,
    /// Magnetic declination at the site, degrees east; `null` / `nil`: the site file's.
    #[uniffi(default = None)]
    pub declination_deg: Option<f64>,
    /// True azimuth of the site's +y axis, degrees; `null` / `nil`: the site file's.
    #[uniffi(default = None)]
    pub site_rotation_deg: Option<f64>,
    /// The salt of a site file whose transmitter ids are hashed (`waymark survey --salt-file`,
    /// `waymark site hash`): the bytes the salt file's hex digits stand for, at least 16.
    /// Scans are hashed with it before matching. `null` / `nil` for a site with raw ids. A
    /// hashed site without it, or with another salt, throws `SaltMismatch`. Keep it out of the
    /// site file's download and out of logs.
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
            .field("declination_deg", &self.declination_deg)
            .field("site_rotation_deg", &self.site_rotation_deg)
            .field("site_salt", &self.site_salt.as_ref().map(|s| format!("<{} bytes, redacted>", s.len())))
            .finish()
    }
}

impl Default for EngineOptions {
    fn default() -> Self {
        let core = EngineConfig::default();
        Self {
            transition: None,
            step_length_m: 0.7,
            fixed_lag_epochs: core.fixed_lag_epochs as u32,
            declination_deg: None,
            site_rotation_deg: None,
            site_salt: None,
        }
    }
}

impl EngineOptions {
    fn to_config(&self, site: &Site) -> Result<EngineConfig, PositioningError> {
        let mut config = EngineConfig {
            transition: match self.transition {
                None => TransitionModel::default(),
                Some(TransitionKind::Reach) => TransitionModel::Reach,
                Some(TransitionKind::Hipe) => TransitionModel::Hipe,
                Some(TransitionKind::Hoang) => TransitionModel::Hoang,
            },
            fixed_lag_epochs: self.fixed_lag_epochs as usize,
            ..EngineConfig::default()
        };
        config.motion.step_length = sensors::StepLengthModel::Constant { length_m: self.step_length_m };
        if self.declination_deg.is_some() || self.site_rotation_deg.is_some() {
            let from_site = site.north();
            config.north = Some(crate::site::North {
                declination_rad: self.declination_deg.map_or(from_site.declination_rad, f64::to_radians),
                site_rotation_rad: self
                    .site_rotation_deg
                    .map_or(from_site.site_rotation_rad, f64::to_radians),
            });
        }
        config.site_salt = match &self.site_salt {
            None => None,
            Some(bytes) => Some(
                crate::Salt::new(bytes.clone())
                    .map_err(|m| PositioningError::InvalidConfig { reason: format!("site_salt: {m}") })?,
            ),
        };
        Ok(config)
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

/// Walking or not.
#[derive(Clone, Copy, Debug, PartialEq, Eq, uniffi::Enum)]
pub enum MotionState {
    /// No accelerometer data.
    Unknown,
    /// Still.
    Stationary,
    /// Walking.
    Walking,
}

/// Which motion information the engine had (HIPE's four scenarios).
#[derive(Clone, Copy, Debug, PartialEq, Eq, uniffi::Enum)]
pub enum MotionScenario {
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
    /// Probability of that floor.
    pub floor_probability: f64,
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

/// A position from another positioning system: GNSS near an entrance, WiFi RTT, UWB.
#[derive(Clone, Copy, Debug, PartialEq, uniffi::Record)]
pub struct PositionFix {
    /// When it was measured, ns, on the clock of every other input.
    pub timestamp_ns: u64,
    /// x in the site's metric frame, m.
    pub x: f64,
    /// y in the site's metric frame, m.
    pub y: f64,
    /// Floor index in the site file, when the other system knows it (UWB, an RTT access
    /// point's floor); `null` / `nil` for GNSS.
    #[uniffi(default = None)]
    pub floor: Option<u32>,
    /// Radius of the 68% circle, m, as Android's `Location.getAccuracy()`; must be > 0.
    pub accuracy_m: f64,
}

/// What kind of place a zone is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, uniffi::Enum)]
pub enum ZoneKind {
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

fn zone_kind(k: crate::site::ZoneKind) -> ZoneKind {
    match k {
        crate::site::ZoneKind::Room => ZoneKind::Room,
        crate::site::ZoneKind::Corridor => ZoneKind::Corridor,
        crate::site::ZoneKind::Hall => ZoneKind::Hall,
        crate::site::ZoneKind::Stairs => ZoneKind::Stairs,
        crate::site::ZoneKind::Lift => ZoneKind::Lift,
        crate::site::ZoneKind::Entrance => ZoneKind::Entrance,
        crate::site::ZoneKind::Other => ZoneKind::Other,
    }
}

/// One point of the smoothed track.
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
pub struct TrackPoint {
    /// Epoch time, ns.
    pub timestamp_ns: u64,
    /// x, m.
    pub x: f64,
    /// y, m.
    pub y: f64,
    /// Floor index.
    pub floor: u32,
}

/// The learned error of external position fixes (`pushFix`): subtract the bias from a fix,
/// then widen its accuracy by `spread`. The engine does both to every fix it takes.
#[derive(Clone, Copy, Debug, PartialEq, uniffi::Record)]
pub struct FixError {
    /// Mean error of the fixes along the site's x axis, m (0 before any fix was learned from).
    pub bias_x_m: f64,
    /// Mean error of the fixes along the site's y axis, m.
    pub bias_y_m: f64,
    /// Factor on the fixes' own accuracy: 1 when they are as good as they say, 2 when their
    /// errors are twice what they report.
    pub spread: f64,
}

impl From<crate::habits::FixError> for FixError {
    fn from(e: crate::habits::FixError) -> Self {
        Self { bias_x_m: e.bias_m[0], bias_y_m: e.bias_m[1], spread: e.spread }
    }
}

/// What one `learnHabits` pass did.
#[derive(Clone, Debug, PartialEq, uniffi::Record)]
pub struct HabitReport {
    /// Epochs of the history learned from in this pass (those learned before are skipped).
    pub epochs: u32,
    /// Runs of epochs without a long gap learned from.
    pub segments: u32,
    /// Runs skipped: a single epoch, or over too many states.
    pub segments_skipped: u32,
    /// Epochs with the user's feedback (`confirmZone`, `confirmPosition`).
    pub feedback_epochs: u32,
    /// Epochs of position fixes (`pushFix`).
    pub fix_epochs: u32,
    /// Baum-Welch iterations run.
    pub iterations: u32,
    /// ln p(observations | model) before each iteration and for the learned model, in nats;
    /// it never decreases. Empty when there was nothing to learn from.
    pub log_likelihood: Vec<f64>,
    /// Feedback epochs the habits ruled out, at which learning restarted.
    pub restarts: u32,
    /// Transitions between places with a learned count, after the pass (all passes so far).
    pub learned_transitions: u64,
    /// Epochs learned from over all passes, including those of an imported model.
    pub total_epochs: u64,
    /// The fix error after the pass.
    pub fix_error: FixError,
    /// How strongly the learned moves are applied, as a pseudo-count per reachable move;
    /// `null` / `nil` when they are not (they did not predict held-out parts of the history
    /// well enough yet, or there was only one part).
    pub strength: Option<f64>,
}

fn count(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

fn habit_report(r: &crate::habits::HabitReport, model: &crate::habits::HabitModel) -> HabitReport {
    HabitReport {
        epochs: count(r.epochs),
        segments: count(r.segments),
        segments_skipped: count(r.segments_skipped),
        feedback_epochs: count(r.feedback_epochs),
        fix_epochs: count(r.fix_epochs),
        iterations: count(r.iterations),
        log_likelihood: if r.segments == 0 { Vec::new() } else { r.log_likelihood.clone() },
        restarts: count(r.restarts),
        learned_transitions: r.learned_transitions as u64,
        total_epochs: model.epochs(),
        fix_error: r.fix_error.into(),
        strength: model.strength(),
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
        points: Vec<TrackPoint>,
    },
}

/// Receives positions and status after the engine's lock is released, in the order they
/// happened, on a thread that called the engine (usually the one that pushed the input; while
/// one thread is delivering, input pushed by others is delivered by it). Never called from two
/// threads at once. A listener may call the engine, subscribe and cancel from its methods.
/// Throwing from a method is reported, never fatal.
#[uniffi::export(with_foreign)]
pub trait PositionListener: Send + Sync {
    /// A new position.
    fn on_position(&self, position: PositionEstimate) -> Result<(), PositioningError>;
    /// A status change.
    fn on_status(&self, status: StatusUpdate) -> Result<(), PositioningError>;
    /// An input was rejected (the call that pushed it also returned the error): for apps that
    /// push from sensor callbacks and want failures in one place.
    fn on_error(&self, message: String) -> Result<(), PositioningError>;
}

fn scenario(s: sensors::MdiScenario) -> MotionScenario {
    match s {
        sensors::MdiScenario::DistanceHeading => MotionScenario::DistanceHeading,
        sensors::MdiScenario::Distance => MotionScenario::Distance,
        sensors::MdiScenario::HeadingSpeed => MotionScenario::HeadingSpeed,
        sensors::MdiScenario::Speed => MotionScenario::Speed,
    }
}

fn motion_state(s: sensors::MotionState) -> MotionState {
    match s {
        sensors::MotionState::Unknown => MotionState::Unknown,
        sensors::MotionState::Stationary => MotionState::Stationary,
        sensors::MotionState::Walking => MotionState::Walking,
    }
}

fn track_point(p: &engine::TrackPoint) -> TrackPoint {
    TrackPoint { timestamp_ns: p.timestamp_ns, x: p.x, y: p.y, floor: p.floor as u32 }
}

/// What the core engine published during one call, delivered after the lock is released.
enum Event {
    Position(PositionEstimate),
    Status(StatusUpdate),
    Error(String),
}

/// Collects the core engine's publications (under the engine's lock, so in the order of the
/// epochs), held back until the call that made them returns.
struct Collector {
    events: Arc<Delivery<Event>>,
    names: Arc<Names>,
}

/// The site's floor and zone names, by index.
struct Names {
    floors: Vec<String>,
    zones: Vec<String>,
}

impl Collector {
    fn push(&self, event: Event) {
        self.events.stage(event);
    }
}

fn estimate(p: &engine::Position, names: &Names) -> PositionEstimate {
    PositionEstimate {
        timestamp_ns: p.timestamp_ns,
        x: p.x,
        y: p.y,
        floor: p.floor as u32,
        floor_name: names.floors.get(p.floor).cloned().unwrap_or_default(),
        floor_probability: p.floor_probability,
        zone: p.zone.and_then(|z| names.zones.get(z).cloned()),
        zone_probability: p.zone_probability,
        accuracy_m: p.accuracy_m,
        accuracy_95_m: p.accuracy_95_m,
        heading_deg: p.heading_rad.map(f64::to_degrees),
        heading_accuracy_deg: p.heading_accuracy_rad.map(f64::to_degrees),
        motion_state: motion_state(p.motion_state),
        scenario: scenario(p.scenario),
        steps: p.steps,
        beyond_radio_m: p.beyond_radio_m,
    }
}

impl CoreListener for Collector {
    fn on_position(&mut self, p: &engine::Position) {
        self.push(Event::Position(estimate(p, &self.names)));
    }

    fn on_status(&mut self, status: &engine::StatusEvent) {
        let update = match status {
            engine::StatusEvent::ScenarioChanged { to, .. } => {
                StatusUpdate::ScenarioChanged { scenario: scenario(*to) }
            }
            engine::StatusEvent::MotionStateChanged { to, .. } => {
                StatusUpdate::MotionStateChanged { state: motion_state(*to) }
            }
        };
        self.push(Event::Status(update));
    }

    fn on_track_revised(&mut self, revised: &[engine::TrackPoint]) {
        self.push(Event::Status(StatusUpdate::TrackRevised {
            points: revised.iter().map(track_point).collect(),
        }));
    }
}

struct Inner {
    engine: Engine,
    names: Arc<Names>,
    /// The last position, in FFI form.
    latest: Option<PositionEstimate>,
}

/// The positioning engine. Thread-safe: sensor threads and the scan receiver may call it at
/// once. Create it from a site file; feed it sensor batches and scans with timestamps on one
/// monotonic clock; read positions by polling or by subscribing a listener.
///
/// Kotlin: a `String` argument holding a lone UTF-16 surrogate (`"\uD800"`, not text) cannot
/// be encoded by uniffi's generated code. In a transmitter id it is replaced by `?` on the way
/// in, so the scan throws `PositioningException.InputRejected`; in a constructor's `siteJson`
/// or `path` it throws `java.nio.charset.CharacterCodingException` (a
/// `MalformedInputException`) before the call reaches Waymark: no engine is made.
#[derive(uniffi::Object)]
pub struct PositioningEngine {
    inner: Mutex<Inner>,
    events: Arc<Delivery<Event>>,
    listeners: Mutex<Vec<(u64, Arc<dyn PositionListener>)>>,
    next_listener: Mutex<u64>,
}

/// Cancels its listener's subscription when dropped (or when `cancel` is called).
#[derive(uniffi::Object)]
pub struct Subscription {
    engine: Weak<PositioningEngine>,
    id: u64,
}

#[uniffi::export]
impl Subscription {
    /// Stops the listener now.
    pub fn cancel(&self) {
        if let Some(engine) = self.engine.upgrade() {
            if let Ok(mut listeners) = engine.listeners.lock() {
                listeners.retain(|(id, _)| *id != self.id);
            }
        }
    }
}

impl Drop for Subscription {
    fn drop(&mut self) {
        self.cancel();
    }
}

fn samples(batch: &[MotionSample]) -> Vec<SensorSample> {
    batch.iter().map(|s| SensorSample { timestamp_ns: s.timestamp_ns, x: s.x, y: s.y, z: s.z }).collect()
}

/// With the `fault-injection` feature (test builds only), a scan at this timestamp panics
/// inside the engine call, to show that a panic comes out as an error, not an abort.
pub const FAULT_INJECTION_TIMESTAMP_NS: u64 = u64::MAX - 7;

/// Panics on the magic timestamp in test builds; nothing otherwise.
pub(crate) fn fault_injection(timestamp_ns: u64) {
    if cfg!(feature = "fault-injection") && timestamp_ns == FAULT_INJECTION_TIMESTAMP_NS {
        panic!("fault injected at timestamp {timestamp_ns}");
    }
}

fn internal(what: &str) -> PositioningError {
    PositioningError::Internal { reason: format!("{what}: a previous call panicked") }
}

impl PositioningEngine {
    fn create(site: Site, options: EngineOptions) -> Result<Arc<Self>, PositioningError> {
        let names = Arc::new(Names {
            floors: site.floors().iter().map(|f| f.name.clone()).collect(),
            zones: site.zones().iter().map(|z| z.name.clone()).collect(),
        });
        let config = options.to_config(&site)?;
        let mut engine = Engine::new(Arc::new(site), config)?;
        let events = Arc::new(Delivery::new());
        engine.subscribe(Box::new(Collector { events: Arc::clone(&events), names: Arc::clone(&names) }));
        Ok(Arc::new(Self {
            inner: Mutex::new(Inner { engine, names, latest: None }),
            events,
            listeners: Mutex::new(Vec::new()),
            next_listener: Mutex::new(0),
        }))
    }

    /// Runs `f` on the engine under its lock, then delivers what it published to the
    /// listeners with no lock held. A panic inside becomes `Internal`: the engine undoes an
    /// epoch that panics, and what the call published is dropped, so the call had no effect.
    fn with_engine<T>(
        &self,
        f: impl FnOnce(&mut Inner) -> Result<T, PositioningError>,
    ) -> Result<T, PositioningError> {
        let result = {
            let mut inner = lock(&self.inner);
            let result = match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| f(&mut inner))) {
                Ok(result) => {
                    self.events.commit();
                    result
                }
                Err(_) => {
                    self.events.discard();
                    Err(internal("engine"))
                }
            };
            // Queued under the engine's lock, so listeners hear it in the order of the calls.
            if let Err(e) = &result {
                self.events.push(Event::Error(e.to_string()));
            }
            result
        };
        self.deliver();
        result
    }

    /// Input rejected before it reached the engine (a malformed transmitter id): reported to
    /// the listeners' `on_error` as the engine's own rejections are.
    fn reject(&self, reason: String) -> PositioningError {
        let error = PositioningError::InputRejected { reason };
        self.events.push(Event::Error(error.to_string()));
        self.deliver();
        error
    }

    /// Delivers what was published to the listeners, oldest event first, one thread at a time
    /// and with no lock held during a call ([`Delivery`]). A listener subscribed during an
    /// event hears the events after it; one cancelled during an event hears nothing more.
    fn deliver(&self) {
        self.events.deliver(|event| {
            let listeners = lock(&self.listeners).clone();
            for (id, listener) in &listeners {
                // Cancelled by a callback earlier in this event.
                if !lock(&self.listeners).iter().any(|(l, _)| l == id) {
                    continue;
                }
                let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| match &event {
                    Event::Position(p) => listener.on_position(p.clone()),
                    Event::Status(s) => listener.on_status(s.clone()),
                    Event::Error(m) => listener.on_error(m.clone()),
                }));
                match outcome {
                    Ok(Ok(())) => {}
                    Ok(Err(e)) => log::warn!("a position listener failed: {e}"),
                    Err(_) => log::warn!("a position listener panicked"),
                }
            }
        });
    }
}

#[uniffi::export]
impl PositioningEngine {
    /// An engine on the site file given as JSON text.
    #[uniffi::constructor]
    pub fn new(site_json: String, options: EngineOptions) -> Result<Arc<Self>, PositioningError> {
        let site = Site::from_json(site_json.as_bytes()).map_err(crate::Error::from)?;
        Self::create(site, options)
    }

    /// An engine on a site file's contents: the binary encoding (`waymark site pack`, what an
    /// app should ship: it loads several times faster and in a third of the memory) or JSON.
    #[uniffi::constructor]
    pub fn from_site_bytes(site: Vec<u8>, options: EngineOptions) -> Result<Arc<Self>, PositioningError> {
        let site = Site::from_bytes(&site).map_err(crate::Error::from)?;
        Self::create(site, options)
    }

    /// An engine on the site file (binary or JSON) at `path`.
    #[uniffi::constructor]
    pub fn from_path(path: String, options: EngineOptions) -> Result<Arc<Self>, PositioningError> {
        let site = Site::load(&path).map_err(crate::Error::from)?;
        Self::create(site, options)
    }

    /// Accelerometer samples, oldest first. Bad samples are dropped and counted; returns how
    /// many were taken.
    pub fn push_accelerometer(&self, batch: Vec<MotionSample>) -> Result<u32, PositioningError> {
        self.with_engine(|i| Ok(i.engine.push_accelerometer(&samples(&batch)).accepted as u32))
    }

    /// Gyroscope samples, oldest first; as `push_accelerometer`.
    pub fn push_gyroscope(&self, batch: Vec<MotionSample>) -> Result<u32, PositioningError> {
        self.with_engine(|i| Ok(i.engine.push_gyroscope(&samples(&batch)).accepted as u32))
    }

    /// Magnetometer samples, oldest first; as `push_accelerometer`.
    pub fn push_magnetometer(&self, batch: Vec<MotionSample>) -> Result<u32, PositioningError> {
        self.with_engine(|i| Ok(i.engine.push_magnetometer(&samples(&batch)).accepted as u32))
    }

    /// A WiFi / BLE scan: one positioning epoch. Push the sensor batches up to the scan's time
    /// first. Returns the new position; a rejected scan throws `InputRejected` and changes
    /// nothing.
    pub fn push_scan(&self, scan: RadioScan) -> Result<PositionEstimate, PositioningError> {
        let mut readings = Vec::with_capacity(scan.wifi.len() + scan.beacons.len());
        for w in &scan.wifi {
            let transmitter = TransmitterId::wifi(&w.bssid).map_err(|reason| self.reject(reason))?;
            readings.push(Reading {
                transmitter,
                rssi_dbm: w.rssi_dbm,
                age_ns: w.age_ms.saturating_mul(1_000_000),
            });
        }
        for b in &scan.beacons {
            let transmitter = super::beacon_id(&b.uuid, b.major, b.minor, b.address.as_deref())
                .map_err(|reason| self.reject(reason))?;
            readings.push(Reading {
                transmitter,
                rssi_dbm: b.rssi_dbm,
                age_ns: b.age_ms.saturating_mul(1_000_000),
            });
        }
        let core = Scan { timestamp_ns: scan.timestamp_ns, readings };
        let events = Arc::clone(&self.events);
        self.epoch(|engine| {
            fault_injection(core.timestamp_ns);
            let result = engine.push_scan(&core);
            if let Err(crate::InputError::NoKnownTransmitter { .. }) = result {
                events.stage(Event::Status(StatusUpdate::NoSiteCoverage { timestamp_ns: core.timestamp_ns }));
            }
            result
        })
    }

    /// An epoch without radio, from the motion since the last one: call it on a timer when
    /// scans are rare.
    pub fn advance(&self, timestamp_ns: u64) -> Result<PositionEstimate, PositioningError> {
        self.epoch(|engine| engine.advance(timestamp_ns))
    }

    /// A position from another positioning system (GNSS near an entrance, WiFi RTT, UWB): one
    /// positioning epoch, with the motion since the last one, whose observation is the fix. A
    /// precise fix pulls the estimate to it; a vague one barely moves it. Throws
    /// `InputRejected`, changing nothing, for a time not after the last epoch, a NaN or
    /// infinite coordinate, an accuracy not > 0, an unknown floor, or a fix too far from the
    /// site for its accuracy.
    pub fn push_fix(&self, fix: PositionFix) -> Result<PositionEstimate, PositioningError> {
        let core = crate::fix::PositionFix {
            timestamp_ns: fix.timestamp_ns,
            x: fix.x,
            y: fix.y,
            floor: fix.floor.map(|f| f as usize),
            accuracy_m: fix.accuracy_m,
        };
        self.epoch(|engine| engine.push_fix(&core))
    }

    /// The user says they are in the zone called `zone` ("I am in the kitchen"): the position
    /// is pinned to its states. At the time of the latest position it corrects that position;
    /// later, it is a new epoch. Kept for learning the user's habits. Throws `InputRejected`,
    /// changing nothing, for a time before the latest position or an unknown zone.
    pub fn confirm_zone(
        &self,
        timestamp_ns: u64,
        zone: String,
    ) -> Result<PositionEstimate, PositioningError> {
        self.epoch(|engine| engine.confirm_zone_named(timestamp_ns, &zone))
    }

    /// The user says they are within `radius_m` of (x, y) on `floor` (a tap on the map): as
    /// `confirm_zone`, pinned to the states within the radius. Throws `InputRejected`, changing
    /// nothing, for a time before the latest position, an unknown floor, a NaN or infinite
    /// coordinate, a radius not > 0, or no surveyed place within the radius.
    pub fn confirm_position(
        &self,
        timestamp_ns: u64,
        x: f64,
        y: f64,
        floor: u32,
        radius_m: f64,
    ) -> Result<PositionEstimate, PositioningError> {
        self.epoch(|engine| engine.confirm_position(timestamp_ns, x, y, floor as usize, radius_m))
    }

    /// Every zone of the site, in the site file's order, with the probability of being in it
    /// now (before the first epoch, its share of the site's states: the prior is uniform).
    /// Empty for a site without zones.
    pub fn zone_posterior(&self) -> Vec<ZoneProbability> {
        self.with_engine(|i| {
            let site = Arc::clone(i.engine.site());
            Ok(site
                .zones()
                .iter()
                .zip(i.engine.zone_posterior())
                .map(|(z, probability)| ZoneProbability {
                    name: z.name.clone(),
                    kind: zone_kind(z.kind),
                    probability,
                })
                .collect())
        })
        .unwrap_or_default()
    }

    /// Learns the user's habits from the epochs of this session not learned from yet (the
    /// engine keeps the last 500, with the user's feedback and position fixes): which way they
    /// usually go from each place, and the error of their position fixes. From the next epoch
    /// on, the learned moves weigh on the motion model (a habit only redistributes what the
    /// motion already allows) and fixes are corrected. Each epoch is learned from once, so
    /// calling it again soon costs little. It runs on the calling thread for up to a few
    /// hundred milliseconds on a large site: call it off the main thread, e.g. when a walk
    /// ends. Other calls on the engine wait for it; listeners are not called from it. Keep
    /// the result with `exportHabits`.
    pub fn learn_habits(&self) -> Result<HabitReport, PositioningError> {
        self.with_engine(|i| match i.engine.learn_habits() {
            Ok(report) => Ok(habit_report(&report, i.engine.habits())),
            // Its input is the engine's own history and validated options: a bug.
            Err(e) => Err(PositioningError::Internal { reason: format!("learning habits: {e}") }),
        })
    }

    /// The learned habits as versioned JSON (a few kB to a few hundred kB), to store per user
    /// and site and give back to `importHabits` in a later session. An engine that learned
    /// nothing exports an empty model.
    pub fn export_habits(&self) -> String {
        self.with_engine(|i| Ok(i.engine.export_habits())).unwrap_or_default()
    }

    /// Replaces the engine's habits by a model from `exportHabits` on the same site, learning
    /// on from where it left off. Throws `HabitsRejected`, changing nothing, when the JSON
    /// does not parse, is not a habit model, is of a newer layout than this build reads, was
    /// learned on another site or another build of the site file, or holds a value out of
    /// range.
    pub fn import_habits(&self, json: HabitsJson) -> Result<(), PositioningError> {
        self.with_engine(|i| match i.engine.import_habits(&json.0) {
            Ok(()) => Ok(()),
            Err(crate::habits::HabitError::Learn(e)) => {
                Err(PositioningError::Internal { reason: format!("importing habits: {e}") })
            }
            Err(e) => Err(PositioningError::HabitsRejected { reason: e.to_string() }),
        })
    }

    /// Forgets every learned habit and the fix error (when the user asks, or signs out).
    pub fn clear_habits(&self) {
        let _ = self.with_engine(|i| {
            i.engine.clear_habits();
            Ok(())
        });
    }

    /// The fix error learned so far: zero bias and spread 1 before any fix was learned from.
    pub fn fix_error(&self) -> FixError {
        self.with_engine(|i| Ok(i.engine.fix_error().into())).unwrap_or(FixError {
            bias_x_m: 0.0,
            bias_y_m: 0.0,
            spread: 1.0,
        })
    }

    /// The latest position, if any.
    pub fn position(&self) -> Option<PositionEstimate> {
        self.with_engine(|i| Ok(i.latest.clone())).ok().flatten()
    }

    /// The most likely recent track, oldest first.
    pub fn track(&self) -> Vec<TrackPoint> {
        self.with_engine(|i| Ok(i.engine.track().iter().map(track_point).collect())).unwrap_or_default()
    }

    /// The fixed-lag position: a few epochs old, but revised by what came after.
    pub fn fixed_lag_position(&self) -> Option<TrackPoint> {
        self.with_engine(|i| Ok(i.engine.fixed_lag_position().as_ref().map(track_point))).ok().flatten()
    }

    /// Calls `listener` with every position and status change until the returned subscription
    /// is cancelled or dropped. Listeners run with no lock held, never two calls at once.
    pub fn subscribe(self: Arc<Self>, listener: Arc<dyn PositionListener>) -> Arc<Subscription> {
        let id = {
            let mut next = self.next_listener.lock().unwrap_or_else(|p| p.into_inner());
            *next += 1;
            *next
        };
        self.listeners.lock().unwrap_or_else(|p| p.into_inner()).push((id, listener));
        Arc::new(Subscription { engine: Arc::downgrade(&self), id })
    }
}

impl PositioningEngine {
    /// The core engine's state and the last position in FFI form, for tests that check a
    /// failed call changed nothing. Not part of the Kotlin / Swift API.
    #[doc(hidden)]
    pub fn snapshot(&self) -> (engine::EngineSnapshot, Option<PositionEstimate>) {
        let inner = lock(&self.inner);
        (inner.engine.snapshot(), inner.latest.clone())
    }

    fn epoch(
        &self,
        f: impl FnOnce(&mut Engine) -> Result<engine::Position, crate::InputError>,
    ) -> Result<PositionEstimate, PositioningError> {
        self.with_engine(|inner| {
            let position = f(&mut inner.engine)
                .map_err(|e| PositioningError::InputRejected { reason: e.to_string() })?;
            let estimate = estimate(&position, &inner.names);
            inner.latest = Some(estimate.clone());
            Ok(estimate)
        })
    }
}
