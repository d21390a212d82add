//! `engine_calls`: a sequence of calls decoded from the input, made on the core `Engine` and on
//! the FFI `PositioningEngine` over the same site: inertial batches (any timestamps, NaN, ±inf,
//! huge values, up to 4096 samples), scans (empty, duplicated and unknown transmitters, NaN or
//! infinite RSSI, any age), advances, motion given from outside, queries, FFI subscriptions.
//!
//! After every call: the posterior is a distribution; every position and track point that
//! leaves either engine is finite with a radius > 0; a scan or advance is taken exactly when
//! the documented rules say so, and a rejected one leaves the core engine as it was. When the
//! two engines run the same configuration they must agree bit for bit. At the end a valid scan
//! must still be taken.

use super::checks;
use super::cursor::{Cursor, Writer};
use std::sync::{Arc, OnceLock, Weak};
use waymark as ffi;
use waymark_engine::sensors::{MotionScenario, MotionState, MotionUpdate, SensorSample};
use waymark_engine::TransitionModel;
use waymark_engine::TransmitterId;
use waymark_engine::{Engine, EngineConfig, Epoch, InputError, Position, Reading, Scan, Site};
use waymark_sim::{imu, Office, OfficeConfig};

/// Calls decoded from one input, at most.
const MAX_CALLS: usize = 256;
/// Inertial samples in one input, at most (over all batches), so one input stays fast.
const MAX_SAMPLES: usize = 1 << 15;

/// A site both engines run on.
pub struct Fixture {
    site: Arc<Site>,
    json: String,
    floor_names: Vec<String>,
}

impl Fixture {
    fn new(json: String) -> Self {
        let site = Site::from_json(json.as_bytes()).expect("the fixture site loads");
        let floor_names = site.floors().iter().map(|f| f.name.clone()).collect();
        Self { site: Arc::new(site), json, floor_names }
    }

    fn transmitters(&self) -> &[TransmitterId] {
        self.site.radio().transmitters()
    }

    fn knows(&self, t: &TransmitterId) -> bool {
        self.transmitters().contains(t)
    }
}

/// The simulated office (81 states; 8 access points and 60 training scans per state, enough
/// for fingerprints and fast to fit once per process).
fn office() -> &'static Office {
    static OFFICE: OnceLock<Office> = OnceLock::new();
    OFFICE.get_or_init(|| {
        Office::generate(&OfficeConfig { access_points: 8, training_scans: 60, ..OfficeConfig::default() })
    })
}

/// `site` as a site file with every number rounded to 0.01: the FFI engine parses it for every
/// input, and `Site::to_json`'s 17-digit floats made that most of an input's time.
fn compact_json(site: &Site) -> String {
    let mut fingerprints = vec![Vec::new(); site.states().len()];
    for (state, tx, g) in site.radio().fingerprints() {
        fingerprints[state as usize]
            .push(format!(r#"{{"tx":{tx},"mean_dbm":{:.2},"std_db":{:.2}}}"#, g.mean_dbm, g.std_db));
    }
    let states: Vec<String> = site
        .states()
        .iter()
        .zip(&fingerprints)
        .map(|(s, f)| {
            format!(
                r#"{{"id":{},"floor":{},"x":{:.2},"y":{:.2},"training_scans":{},"fingerprint":[{}]}}"#,
                s.id,
                s.floor,
                s.position.x,
                s.position.y,
                s.training_scans,
                f.join(",")
            )
        })
        .collect();
    let edges: Vec<String> = site
        .edges()
        .iter()
        .map(|e| {
            let (a, b) = (&site.states()[e.a as usize], &site.states()[e.b as usize]);
            format!(r#"{{"from":{},"to":{},"length_m":{:.2}}}"#, a.id, b.id, e.length_m)
        })
        .collect();
    let transmitters: Vec<String> = site
        .radio()
        .transmitters()
        .iter()
        .map(|t| match t {
            TransmitterId::Wifi { bssid } => format!(r#"{{"wifi":{{"bssid":"{bssid}"}}}}"#),
            other => panic!("the office has only access points, not {other}"),
        })
        .collect();
    let floors: Vec<String> = site
        .floors()
        .iter()
        .map(|f| format!(r#"{{"name":"{}","elevation_m":{:.2}}}"#, f.name, f.elevation_m))
        .collect();
    let (north, unheard) = (site.north(), site.radio().unheard());
    format!(
        r#"{{"format_version":1,"name":"fuzz office","north":{{"site_rotation_rad":{:.4},"declination_rad":{:.4}}},"floors":[{}],"radio":{{"clip_dbm":{:.2},"unheard":{{"mean_dbm":{:.2},"std_db":{:.2}}},"transmitters":[{}]}},"states":[{}],"edges":[{}]}}"#,
        north.site_rotation_rad,
        north.declination_rad,
        floors.join(","),
        site.radio().clip_dbm(),
        unheard.mean_dbm,
        unheard.std_db,
        transmitters.join(","),
        states.join(","),
        edges.join(",")
    )
}

/// Two floors joined by stairs, WiFi and both kinds of beacon, and a calibration (γ with and
/// without movement, radius factors, a frequency step-length model, a rotated north).
const TWO_FLOORS: &str = r#"{
  "format_version": 1, "name": "two floors",
  "north": {"site_rotation_rad": 0.5, "declination_rad": -0.1},
  "floors": [{"name": "G"}, {"name": "1", "elevation_m": 4}],
  "radio": {"clip_dbm": -100, "unheard": {"mean_dbm": -112, "std_db": 5},
    "transmitters": [{"wifi": {"bssid": "0a:00:00:00:00:01"}}, {"wifi": {"bssid": "0a:00:00:00:00:02"}},
      {"wifi": {"bssid": "0a:00:00:00:00:03"}}, {"wifi": {"bssid": "0a:00:00:00:00:04"}},
      {"ble": {"uuid": "fda50693-a4e2-4fb1-afcf-c6eb07647825", "major": 1, "minor": 7}},
      {"ble_address": {"mac": "e0:78:a3:3d:b5:d6"}}]},
  "states": [
    {"id": 0, "floor": 0, "x": 0, "y": 0, "fingerprint": [{"tx": 0, "mean_dbm": -50, "std_db": 4}, {"tx": 4, "mean_dbm": -70, "std_db": 3}]},
    {"id": 1, "floor": 0, "x": 3, "y": 0, "fingerprint": [{"tx": 0, "mean_dbm": -60, "std_db": 4}, {"tx": 1, "mean_dbm": -75, "std_db": 5}]},
    {"id": 2, "floor": 0, "x": 6, "y": 0, "fingerprint": [{"tx": 1, "mean_dbm": -55, "std_db": 4}, {"tx": 5, "mean_dbm": -80, "std_db": 6}]},
    {"id": 3, "floor": 0, "x": 6, "y": 3, "kind": "pseudo", "fingerprint": [{"tx": 1, "mean_dbm": -65, "std_db": 6}]},
    {"id": 10, "floor": 1, "x": 0, "y": 0, "fingerprint": [{"tx": 2, "mean_dbm": -50, "std_db": 4}]},
    {"id": 11, "floor": 1, "x": 3, "y": 0, "fingerprint": [{"tx": 2, "mean_dbm": -62, "std_db": 4}, {"tx": 3, "mean_dbm": -70, "std_db": 4}]},
    {"id": 12, "floor": 1, "x": 6, "y": 0, "fingerprint": [{"tx": 3, "mean_dbm": -52, "std_db": 4}, {"tx": 5, "mean_dbm": -60, "std_db": 4}]},
    {"id": 13, "floor": 1, "x": 6, "y": 3, "training_scans": 5}
  ],
  "edges": [{"from": 0, "to": 1}, {"from": 1, "to": 2}, {"from": 2, "to": 3}, {"from": 10, "to": 11},
    {"from": 11, "to": 12}, {"from": 12, "to": 13}, {"from": 0, "to": 10, "length_m": 6}],
  "calibration": {"rssi_weight": 0.6, "rssi_weight_without_movement": 0.8, "accuracy_scale": [1.2, 1.5],
    "step_length": {"linear_frequency": {"intercept_m": 0.3, "slope_m_per_hz": 0.2}}}
}"#;

/// The sites an input can pick, built once per process.
pub fn fixtures() -> &'static [Fixture; 2] {
    static FIXTURES: OnceLock<[Fixture; 2]> = OnceLock::new();
    FIXTURES.get_or_init(|| [Fixture::new(compact_json(&office().site)), Fixture::new(TWO_FLOORS.to_owned())])
}

const TRANSITIONS: [TransitionModel; 3] =
    [TransitionModel::Reach, TransitionModel::Regions, TransitionModel::MovementVector];

/// The input's running clock: timestamps are mostly read relative to the last one.
struct Clock {
    now: u64,
}

impl Clock {
    fn time(&mut self, c: &mut Cursor) -> u64 {
        let t = match c.u8() % 8 {
            0 => self.now.saturating_add(u64::from(c.u16()) * 1_000_000),
            1 => self.now.saturating_add(u64::from(c.u16()) * 1_000),
            2 => self.now,
            3 => self.now.saturating_sub(u64::from(c.u16()) * 1_000_000),
            4 => c.u64(),
            5 => u64::MAX - u64::from(c.u8()),
            6 => u64::from(c.u8()),
            _ => self.now.saturating_add(u64::from(c.u32()) * 1_000),
        };
        let t = not_fault_injection(t);
        self.now = t;
        t
    }
}

/// The times a test build (feature `fault-injection`, `cargo test --all-features`) panics at
/// on purpose: a scan at `u64::MAX - 7` inside the FFI engine
/// (`waymark::FAULT_INJECTION_TIMESTAMP_NS`) and an epoch at `MAX_TIMESTAMP_NS - 8` inside
/// either engine (`waymark_engine::FAULT_INJECTION_MID_EPOCH_NS`). Those constants exist only
/// with the feature (`tests/fuzz_corpus.rs` checks these against them); the harness never
/// makes either time, with the feature or without.
pub const INJECTED_SCAN_NS: u64 = u64::MAX - 7;
/// See [`INJECTED_SCAN_NS`].
pub const INJECTED_MID_EPOCH_NS: u64 = waymark_engine::sensors::MAX_TIMESTAMP_NS - 8;

fn not_fault_injection(t: u64) -> u64 {
    if t == INJECTED_SCAN_NS || t == INJECTED_MID_EPOCH_NS {
        INJECTED_MID_EPOCH_NS - 1
    } else {
        t
    }
}

fn options(c: &mut Cursor) -> ffi::EngineOptions {
    let first = c.u8();
    if first < 128 {
        return ffi::EngineOptions::default();
    }
    let optional = |c: &mut Cursor| if c.u8().is_multiple_of(2) { None } else { Some(c.f64()) };
    ffi::EngineOptions {
        transition: match c.u8() % 4 {
            0 => None,
            1 => Some(ffi::TransitionKind::Reach),
            2 => Some(ffi::TransitionKind::Regions),
            _ => Some(ffi::TransitionKind::MovementVector),
        },
        step_length_m: optional(c),
        fixed_lag_epochs: if c.u8().is_multiple_of(2) { u32::from(c.u8()) } else { c.u32() },
        declination_deg: optional(c),
        site_rotation_deg: optional(c),
        // The harness's sites hold raw ids; salts are fuzzed by tests/properties.rs.
        site_salt: None,
        // From the byte already read, so the corpus's inputs decode as before: off in a quarter.
        track: !first.is_multiple_of(4),
    }
}

/// Whether the FFI options make the same engine configuration as the core's `transition`.
fn same_config(options: &ffi::EngineOptions, transition: TransitionModel) -> bool {
    let ffi_transition = match options.transition {
        None | Some(ffi::TransitionKind::MovementVector) => TransitionModel::MovementVector,
        Some(ffi::TransitionKind::Reach) => TransitionModel::Reach,
        Some(ffi::TransitionKind::Regions) => TransitionModel::Regions,
    };
    let default = ffi::EngineOptions::default();
    ffi_transition == transition
        && options.step_length_m == default.step_length_m
        && options.fixed_lag_epochs == default.fixed_lag_epochs
        && options.declination_deg.is_none()
        && options.site_rotation_deg.is_none()
        && options.track == default.track
}

fn batch(c: &mut Cursor, clock: &mut Clock, budget: &mut usize) -> Vec<SensorSample> {
    let mode = c.u8() % 5;
    let wanted = match mode {
        0 | 3 | 4 => usize::from(c.u8()),
        1 => usize::from(c.u16()) % 4097,
        _ => 0,
    };
    let n = wanted.min(*budget);
    *budget -= n;
    match mode {
        // Samples one by one.
        0 => (0..n)
            .map(|_| SensorSample { timestamp_ns: clock.time(c), x: c.f64(), y: c.f64(), z: c.f64() })
            .collect(),
        // A periodic signal at a fixed interval, every k-th sample poisoned on one axis.
        1 => {
            let start = clock.time(c);
            let dt = u64::from(c.u32());
            let base = [c.f64(), c.f64(), c.f64()];
            let amplitude = c.f64();
            let period = f64::from(c.u8().max(1));
            let poison_every = usize::from(c.u8());
            let poison = c.f64();
            let samples: Vec<SensorSample> = (0..n)
                .map(|i| {
                    let phase = std::f64::consts::TAU * i as f64 / period;
                    let mut v = [
                        base[0] + amplitude * phase.sin(),
                        base[1] + amplitude * phase.cos(),
                        base[2] + amplitude * phase.sin(),
                    ];
                    if poison_every > 0 && i % poison_every == 0 {
                        v[i % 3] = poison;
                    }
                    let timestamp_ns = start.saturating_add(dt.saturating_mul(i as u64));
                    SensorSample { timestamp_ns, x: v[0], y: v[1], z: v[2] }
                })
                .collect();
            if let Some(last) = samples.last() {
                clock.now = last.timestamp_ns;
            }
            samples
        }
        2 => Vec::new(),
        // One value, going back in time.
        3 => {
            let start = clock.time(c);
            let dt = u64::from(c.u16()) * 1_000;
            let (x, y, z) = (c.f64(), c.f64(), c.f64());
            (0..n as u64)
                .map(|i| SensorSample { timestamp_ns: start.saturating_sub(dt * i), x, y, z })
                .collect()
        }
        // A recorded stream, compactly: a fixed interval, then each axis as i8 steps of 2^-shift.
        _ => {
            let start = clock.time(c);
            let dt = u64::from(c.u16()) * 1_000;
            let step = 0.5f64.powi(i32::from(c.u8() % 24));
            let mut v = [c.f64(), c.f64(), c.f64()];
            let samples: Vec<SensorSample> = (0..n as u64)
                .map(|i| {
                    for axis in &mut v {
                        *axis += f64::from(c.u8() as i8) * step;
                    }
                    SensorSample { timestamp_ns: start.saturating_add(dt * i), x: v[0], y: v[1], z: v[2] }
                })
                .collect();
            if let Some(last) = samples.last() {
                clock.now = last.timestamp_ns;
            }
            samples
        }
    }
}

fn rssi(c: &mut Cursor) -> f64 {
    match c.u8() {
        b @ 0..=191 => -20.0 - 0.5 * f64::from(b),
        _ => c.f64(),
    }
}

fn age_ms(c: &mut Cursor) -> u64 {
    match c.u8() % 8 {
        0..=4 => 0,
        5 => u64::from(c.u8()),
        6 => u64::from(c.u16()),
        _ => c.u64(),
    }
}

fn transmitter(c: &mut Cursor, fixture: &Fixture, previous: Option<&TransmitterId>) -> TransmitterId {
    let known = fixture.transmitters();
    let id = match c.u8() {
        tag @ 0..=159 => Ok(known[usize::from(tag) % known.len()].clone()),
        160..=199 => TransmitterId::wifi(&format!("02:ff:00:00:{:02x}:{:02x}", c.u8(), c.u8())),
        200..=229 => Ok(previous.unwrap_or(&known[0]).clone()),
        230..=244 => TransmitterId::ble("fda50693-a4e2-4fb1-afcf-c6eb07647825", c.u16(), c.u16()),
        _ => TransmitterId::ble_address(&format!("e0:78:a3:3d:{:02x}:{:02x}", c.u8(), c.u8())),
    };
    id.expect("a well-formed identifier")
}

/// A scan, as the core and the FFI take it; with `mangled`, the FFI's copy has an identifier
/// that does not parse.
struct ScanInput {
    core: Scan,
    ffi: ffi::RadioScan,
    mangled: bool,
}

fn scan(c: &mut Cursor, fixture: &Fixture, clock: &mut Clock) -> ScanInput {
    let timestamp_ns = clock.time(c);
    let mut readings: Vec<(Reading, u64)> = Vec::new();
    let reading = |transmitter: TransmitterId, rssi_dbm: f64, age_ms: u64| {
        (Reading { transmitter, rssi_dbm, age_ns: age_ms.saturating_mul(1_000_000) }, age_ms)
    };
    match c.u8() % 4 {
        0 | 1 => {
            for _ in 0..c.below(24) {
                let t = transmitter(c, fixture, readings.last().map(|r| &r.0.transmitter));
                let r = reading(t, rssi(c), age_ms(c));
                readings.push(r);
            }
        }
        2 => {}
        // Many readings from a pattern: duplicates once the transmitters run out.
        _ => {
            let n = usize::from(c.u16()) % 2048;
            let (first, stride, rssi0) = (usize::from(c.u8()), usize::from(c.u8()), rssi(c));
            let known = fixture.transmitters();
            for i in 0..n {
                let t = known[(first + i * stride) % known.len()].clone();
                readings.push(reading(t, rssi0 - (i % 64) as f64, 0));
            }
        }
    }
    let mangled = c.u8() == 0xff && !readings.is_empty();
    let mut wifi = Vec::new();
    let mut beacons = Vec::new();
    for (k, (r, age_ms)) in readings.iter().enumerate() {
        let rssi_dbm = r.rssi_dbm;
        let age_ms = *age_ms;
        let broken = mangled && k == 0;
        match &r.transmitter {
            TransmitterId::Wifi { bssid } => wifi.push(ffi::WifiReading {
                bssid: if broken { "not a bssid".into() } else { bssid.clone().into() },
                rssi_dbm,
                age_ms,
            }),
            TransmitterId::Ble { uuid, major, minor } => beacons.push(ffi::BeaconReading {
                uuid: if broken { "".into() } else { uuid.clone().into() },
                major: *major,
                minor: *minor,
                rssi_dbm,
                age_ms,
                address: None,
            }),
            TransmitterId::BleAddress { mac } => beacons.push(ffi::BeaconReading {
                uuid: "".into(),
                major: 0,
                minor: 0,
                rssi_dbm,
                age_ms,
                address: Some(if broken { "nope".into() } else { mac.clone().into() }),
            }),
            // Readings are drawn from the harness's sites, which hold raw ids.
            TransmitterId::HashedWifi { .. } | TransmitterId::HashedBle { .. } => {}
        }
    }
    // The FFI puts WiFi readings before beacons; the core gets the same order.
    let (w, b): (Vec<Reading>, Vec<Reading>) =
        readings.into_iter().map(|r| r.0).partition(|r| matches!(r.transmitter, TransmitterId::Wifi { .. }));
    let core = Scan { timestamp_ns, readings: w.into_iter().chain(b).collect() };
    ScanInput { core, ffi: ffi::RadioScan { timestamp_ns, wifi, beacons }, mangled }
}

fn motion(c: &mut Cursor, clock: &mut Clock) -> MotionUpdate {
    let optional = |c: &mut Cursor| if c.u8().is_multiple_of(3) { None } else { Some(c.f64()) };
    MotionUpdate {
        start_ns: clock.time(c),
        end_ns: clock.time(c),
        steps: if c.u8().is_multiple_of(4) { c.u32() } else { u32::from(c.u8()) },
        distance_m: optional(c),
        distance_sigma_m: c.f64(),
        heading_rad: optional(c),
        heading_sigma_rad: c.f64(),
        displacement_m: if c.u8().is_multiple_of(3) { None } else { Some([c.f64(), c.f64()]) },
        motion_state: [MotionState::Unknown, MotionState::Stationary, MotionState::Walking][c.below(3)],
        scenario: [
            MotionScenario::DistanceHeading,
            MotionScenario::Distance,
            MotionScenario::HeadingSpeed,
            MotionScenario::Speed,
        ][c.below(4)],
        compass_disturbed: c.u8() % 2 == 1,
    }
}

/// Whether a motion given from outside is a measurement: finite, distances and spreads ≥ 0.
fn valid_motion(m: &MotionUpdate) -> bool {
    let non_negative = |v: f64| v.is_finite() && v >= 0.0;
    m.distance_m.is_none_or(non_negative)
        && non_negative(m.distance_sigma_m)
        && m.heading_rad.is_none_or(f64::is_finite)
        && non_negative(m.heading_sigma_rad)
        && m.displacement_m.is_none_or(|d| d.iter().all(|v| v.is_finite()))
}

/// Why a scan must be rejected, by the documented rules, in the order the engine checks them;
/// `None` if it must be taken. `motion_valid` is false for an invalid motion given with it.
fn rejection(
    scan: &Scan,
    last_epoch: Option<u64>,
    fixture: &Fixture,
    motion_valid: bool,
) -> Option<&'static str> {
    if scan.timestamp_ns > waymark_engine::sensors::MAX_TIMESTAMP_NS {
        Some("time ahead")
    } else if last_epoch.is_some_and(|last| scan.timestamp_ns <= last) {
        Some("out of order")
    } else if !motion_valid {
        Some("invalid motion")
    } else if scan.readings.is_empty() {
        Some("empty")
    } else if scan.readings.iter().any(|r| !(r.rssi_dbm.is_finite() && r.rssi_dbm >= -1000.0)) {
        // NaN, ±inf, or below -1000 dBm, which no receiver reports.
        Some("non-finite")
    } else if scan.readings.iter().any(|r| r.rssi_dbm > waymark_engine::MAX_RSSI_DBM) {
        Some("rssi too high")
    } else if !scan.readings.iter().any(|r| fixture.knows(&r.transmitter)) {
        Some("no known transmitter")
    } else {
        None
    }
}

fn error_kind(e: &InputError) -> &'static str {
    match e {
        InputError::TimeAhead { .. } => "time ahead",
        InputError::OutOfOrder { .. } => "out of order",
        InputError::EmptyScan => "empty",
        InputError::NonFiniteRssi { .. } => "non-finite",
        InputError::RssiTooHigh { .. } => "rssi too high",
        InputError::NoKnownTransmitter { .. } => "no known transmitter",
        InputError::InvalidMotion { .. } => "invalid motion",
        // Position fixes and user feedback, which this harness does not make.
        InputError::UnknownZone { .. } => "unknown zone",
        InputError::UnknownFloor { .. } => "unknown floor",
        InputError::InvalidValue { .. } => "invalid value",
        InputError::OutsideSite { .. } => "outside the site",
    }
}

/// Checks what the FFI delivers; may call back into the engine, or fail.
struct FfiChecker {
    floor_names: Vec<String>,
    engine: Weak<ffi::PositioningEngine>,
    reenter: bool,
    fail: bool,
}

impl ffi::PositionListener for FfiChecker {
    fn on_position(&self, position: ffi::PositionEstimate) {
        checks::estimate(&position, &self.floor_names);
        if self.reenter {
            if let Some(engine) = self.engine.upgrade() {
                if let Some(latest) = engine.position().expect("a read never fails") {
                    checks::estimate(&latest, &self.floor_names);
                }
                checks::ffi_track(&engine.track().expect("a read never fails"), self.floor_names.len());
            }
        }
        if self.fail {
            // What a Kotlin or Swift listener that throws is on the Rust side.
            panic!("a failing listener");
        }
    }

    fn on_status(&self, status: ffi::StatusUpdate) {
        if let ffi::StatusUpdate::TrackRevised { points } = status {
            assert!(!points.is_empty(), "an empty revision");
            checks::ffi_track(&points, self.floor_names.len());
        }
    }

    fn on_error(&self, _error: ffi::ErrorReport) {}
}

fn motion_samples(batch: &[SensorSample]) -> Vec<ffi::MotionSample> {
    batch.iter().map(|s| ffi::MotionSample { timestamp_ns: s.timestamp_ns, x: s.x, y: s.y, z: s.z }).collect()
}

fn same_position(core: &Position, e: &ffi::PositionEstimate) {
    assert_eq!(core.timestamp_ns, e.timestamp_ns);
    assert_eq!(core.floor, e.floor as usize);
    assert_eq!((core.x.to_bits(), core.y.to_bits()), (e.x.to_bits(), e.y.to_bits()), "core and FFI disagree");
    assert_eq!(core.accuracy_m.to_bits(), e.accuracy_m.to_bits());
    assert_eq!(core.steps, e.steps);
}

/// The two engines and what the harness knows about them.
struct Session<'f> {
    fixture: &'f Fixture,
    core: Engine,
    ffi: Option<Arc<ffi::PositioningEngine>>,
    /// Both engines have the same configuration and have had the same calls.
    lockstep: bool,
    core_last: Option<u64>,
    ffi_last: Option<u64>,
    ffi_subscriptions: Vec<Arc<ffi::Subscription>>,
}

impl Session<'_> {
    fn states(&self) -> usize {
        self.fixture.site.states().len()
    }

    fn floors(&self) -> usize {
        self.fixture.site.floors().len()
    }

    fn check(&self) {
        checks::posterior(self.core.posterior(), self.states());
        if let Some(p) = self.core.position() {
            checks::position(p, self.floors());
            assert_eq!(Some(p.timestamp_ns), self.core_last);
        }
    }

    fn queries(&self) {
        let track = self.core.track();
        checks::track(&track, self.states(), self.floors());
        if let Some(p) = self.core.fixed_lag_position() {
            checks::track(&[p], self.states(), self.floors());
        }
        let Some(ffi) = &self.ffi else { return };
        let latest = ffi.position().expect("a read never fails");
        if let Some(p) = &latest {
            checks::estimate(p, &self.fixture.floor_names);
        }
        let ffi_track = ffi.track().expect("a read never fails");
        checks::ffi_track(&ffi_track, self.floors());
        if let Some(p) = ffi.fixed_lag_position().expect("a read never fails") {
            checks::ffi_track(&[p], self.floors());
        }
        if self.lockstep {
            match (self.core.position(), &latest) {
                (Some(c), Some(e)) => same_position(c, e),
                (None, None) => {}
                _ => panic!("one engine has a position, the other not"),
            }
            assert_eq!(track.len(), ffi_track.len());
            for (c, e) in track.iter().zip(&ffi_track) {
                assert_eq!(
                    (c.timestamp_ns, c.x.to_bits(), c.y.to_bits()),
                    (e.timestamp_ns, e.x.to_bits(), e.y.to_bits())
                );
            }
        }
    }

    fn batch(&mut self, kind: u8, batch: &[SensorSample]) {
        let report = match kind {
            0 => self.core.push_accelerometer(batch),
            1 => self.core.push_gyroscope(batch),
            _ => self.core.push_magnetometer(batch),
        };
        let dropped = report.non_finite + report.out_of_order + report.ahead;
        assert_eq!(report.accepted + dropped, batch.len(), "{report:?}");
        let Some(ffi) = &self.ffi else { return };
        let samples = motion_samples(batch);
        let taken = match kind {
            0 => ffi.push_accelerometer(samples),
            1 => ffi.push_gyroscope(samples),
            _ => ffi.push_magnetometer(samples),
        };
        let taken = taken.unwrap_or_else(|e| panic!("a sensor batch failed: {e}"));
        if self.lockstep {
            assert_eq!(taken as usize, report.accepted);
        }
    }

    /// A core epoch (a scan or an advance, with or without motion): taken iff `rejection` is
    /// `None`, and a rejected one changes nothing but the counters, which it raises.
    fn core_epoch(
        &mut self,
        timestamp_ns: u64,
        rejection: Option<&'static str>,
        call: impl FnOnce(&mut Engine) -> Result<Epoch, InputError>,
    ) -> Option<Position> {
        let before = (self.core.posterior().to_vec(), self.core.position().cloned(), self.core.track());
        let stats = self.core.stats().clone();
        match (call(&mut self.core), rejection) {
            (Ok(Epoch { position, revised_track, .. }), None) => {
                assert_eq!(position.timestamp_ns, timestamp_ns);
                checks::position(&position, self.floors());
                checks::track(&revised_track, self.states(), self.floors());
                self.core_last = Some(timestamp_ns);
                Some(position)
            }
            (Err(e), Some(why)) => {
                assert_eq!(error_kind(&e), why, "rejected for the wrong reason: {e}");
                let _ = e.to_string();
                let after = (self.core.posterior(), self.core.position(), self.core.track());
                let bits = |p: &[f64]| p.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&before.0), bits(after.0), "a rejected epoch changed the posterior");
                assert_eq!(before.1.as_ref(), after.1, "a rejected epoch changed the position");
                assert_eq!(before.2, after.2, "a rejected epoch changed the track");
                assert_ne!(&stats, self.core.stats(), "a rejected epoch was not counted");
                None
            }
            (Ok(_), Some(why)) => panic!("an epoch that should be rejected ({why}) was taken"),
            (Err(e), None) => panic!("an epoch that should be taken was rejected: {e}"),
        }
    }

    fn ffi_epoch(
        &mut self,
        timestamp_ns: u64,
        rejected: bool,
        core: Option<&Position>,
        call: impl FnOnce(&ffi::PositioningEngine) -> Result<ffi::PositionEstimate, ffi::PositioningError>,
    ) {
        let Some(ffi) = &self.ffi else { return };
        match (call(ffi), rejected) {
            (Ok(e), false) => {
                assert_eq!(e.timestamp_ns, timestamp_ns);
                checks::estimate(&e, &self.fixture.floor_names);
                self.ffi_last = Some(timestamp_ns);
                if self.lockstep {
                    same_position(core.expect("the core took it too"), &e);
                }
            }
            (Err(e), true) => {
                checks::not_internal(&e);
                assert!(matches!(e, ffi::PositioningError::InputRejected { .. }), "{e}");
            }
            (Ok(_), true) => panic!("the FFI took an epoch it should reject"),
            (Err(e), false) => panic!("the FFI rejected an epoch it should take: {e}"),
        }
    }

    fn scan(&mut self, input: &ScanInput) {
        let core = if input.mangled {
            None
        } else {
            let why = rejection(&input.core, self.core_last, self.fixture, true);
            self.core_epoch(input.core.timestamp_ns, why, |e| e.push_scan(&input.core))
        };
        let ffi_rejected =
            input.mangled || rejection(&input.core, self.ffi_last, self.fixture, true).is_some();
        let ffi_scan = input.ffi.clone();
        self.ffi_epoch(input.core.timestamp_ns, ffi_rejected, core.as_ref(), |e| e.push_scan(ffi_scan));
    }

    fn advance(&mut self, timestamp_ns: u64) {
        let ahead = timestamp_ns > waymark_engine::sensors::MAX_TIMESTAMP_NS;
        let rejected = |last: Option<u64>| ahead || last.is_some_and(|last| timestamp_ns <= last);
        let why = rejected(self.core_last).then_some(if ahead { "time ahead" } else { "out of order" });
        let core = self.core_epoch(timestamp_ns, why, |e| e.advance(timestamp_ns));
        let ffi_rejected = rejected(self.ffi_last);
        self.ffi_epoch(timestamp_ns, ffi_rejected, core.as_ref(), |e| e.advance(timestamp_ns));
    }

    /// A valid scan after everything: taken if time allows, otherwise rejected as out of order.
    fn still_usable(&mut self) {
        let known = self.fixture.transmitters();
        let readings: Vec<Reading> = known
            .iter()
            .take(3)
            .map(|t| Reading { transmitter: t.clone(), rssi_dbm: -60.0, age_ns: 0 })
            .collect();
        let last = self.core_last.max(self.ffi_last);
        let timestamp_ns = last.map_or(Some(1_500_000_000), |t| t.checked_add(1_500_000_000));
        let timestamp_ns = not_fault_injection(timestamp_ns.unwrap_or(u64::MAX));
        let core = Scan { timestamp_ns, readings };
        let wifi = core
            .readings
            .iter()
            .filter_map(|r| match &r.transmitter {
                TransmitterId::Wifi { bssid } => {
                    Some(ffi::WifiReading { bssid: bssid.clone().into(), rssi_dbm: r.rssi_dbm, age_ms: 0 })
                }
                _ => None,
            })
            .collect();
        let input = ScanInput {
            ffi: ffi::RadioScan { timestamp_ns, wifi, beacons: Vec::new() },
            core,
            mangled: false,
        };
        self.scan(&input);
        self.check();
    }
}

/// One fuzz input.
pub fn run(data: &[u8]) {
    let mut c = Cursor::new(data);
    let fixture = &fixtures()[c.below(2)];
    let transition = TRANSITIONS[c.below(3)];
    let options = options(&mut c);
    let config = EngineConfig { transition, ..EngineConfig::default() };
    let core = Engine::new(Arc::clone(&fixture.site), config).expect("the default configuration is valid");
    let ffi = match ffi::PositioningEngine::new(fixture.json.clone(), options.clone()) {
        Ok(engine) => Some(engine),
        Err(ffi::PositioningError::InvalidConfig { .. }) => None,
        Err(e) => panic!("unexpected error creating the FFI engine: {e}"),
    };
    if ffi.is_none() {
        assert!(!same_config(&options, transition), "the default options were refused");
    }
    let lockstep = ffi.is_some() && same_config(&options, transition);
    let mut s = Session {
        fixture,
        core,
        ffi,
        lockstep,
        core_last: None,
        ffi_last: None,
        ffi_subscriptions: Vec::new(),
    };
    let mut clock = Clock { now: 0 };
    let mut budget = MAX_SAMPLES;
    for _ in 0..MAX_CALLS {
        if c.is_empty() {
            break;
        }
        match c.u8() % 16 {
            op @ 0..=4 => {
                let kind = [0, 0, 0, 1, 2][usize::from(op)];
                let b = batch(&mut c, &mut clock, &mut budget);
                s.batch(kind, &b);
            }
            5..=8 => {
                let input = scan(&mut c, fixture, &mut clock);
                s.scan(&input);
            }
            9 => {
                let t = clock.time(&mut c);
                s.advance(t);
            }
            10 => s.queries(),
            11 | 13 => {
                let flags = c.u8();
                if let Some(ffi) = &s.ffi {
                    let checker = FfiChecker {
                        floor_names: fixture.floor_names.clone(),
                        engine: Arc::downgrade(ffi),
                        reenter: flags & 1 == 1,
                        fail: flags & 2 == 2,
                    };
                    let subscription = Arc::clone(ffi).subscribe(Arc::new(checker));
                    s.ffi_subscriptions.push(subscription);
                }
            }
            12 | 14 => {
                if !s.ffi_subscriptions.is_empty() {
                    let k = c.below(s.ffi_subscriptions.len());
                    let subscription = s.ffi_subscriptions.remove(k);
                    if c.u8().is_multiple_of(2) {
                        subscription.cancel();
                    }
                }
            }
            _ => {
                // Motion measured outside Waymark: the core only, so the engines part ways.
                s.lockstep = false;
                let with_scan = c.u8().is_multiple_of(2);
                let m = motion(&mut c, &mut clock);
                // Checked right after the time.
                let valid = valid_motion(&m);
                if with_scan {
                    let input = scan(&mut c, fixture, &mut clock);
                    let why = rejection(&input.core, s.core_last, fixture, valid);
                    s.core_epoch(input.core.timestamp_ns, why, |e| e.push_scan_with_motion(&input.core, &m));
                } else {
                    let t = clock.time(&mut c);
                    let ahead = (t > waymark_engine::sensors::MAX_TIMESTAMP_NS).then_some("time ahead");
                    let why = ahead.or(s.core_last.is_some_and(|last| t <= last).then_some("out of order"));
                    let why = why.or((!valid).then_some("invalid motion"));
                    s.core_epoch(t, why, |e| e.advance_with_motion(t, &m));
                }
            }
        }
        s.check();
    }
    s.queries();
    s.still_usable();
}

/// A seed: a simulated walk through the office (25 Hz inertial samples, every scan), encoded
/// as the calls an app would make, with transition model `transition` (index into
/// [Reach, Hipe, Hoang]) on fixture `fixture`.
pub fn walk_seed(fixture: u8, transition: u8, seed: u64, length_m: f64) -> Vec<u8> {
    let office = office();
    let walk = office.walk(seed, length_m);
    let config = imu::ImuConfig { rate_hz: 25.0, ..imu::ImuConfig::default() };
    let trace = imu::synthesize(&walk.trajectory, &config, seed);
    let office_aps = fixtures()[0].transmitters();
    let mut w = Writer::default();
    w.u8(fixture);
    w.u8(transition);
    w.u8(0); // default FFI options
             // Times as µs steps from the decoder's clock (mode 1), else absolute (mode 4).
    let mut clock = Clock { now: 0 };
    let time = |w: &mut Writer, clock: &mut Clock, t: u64| {
        let t = t / 1_000 * 1_000;
        let delta = t.saturating_sub(clock.now);
        if t >= clock.now && delta / 1_000 <= 65_535 {
            w.u8(1);
            w.u16((delta / 1_000) as u16);
        } else {
            w.u8(4);
            w.u64(t);
        }
        clock.now = t;
    };
    // Steps of 2^-shift: 1/16 m/s², 1/128 rad/s, 1/8 µT.
    let streams = [(0u8, &trace.accelerometer, 4u8), (3, &trace.gyroscope, 7), (4, &trace.magnetometer, 3)];
    let mut sent = [0usize; 3];
    let period_ns = (1e9 / config.rate_hz) as u64;
    for epoch in &walk.epochs {
        let t_scan = epoch.scan.timestamp_ns;
        for (k, (op, samples, shift)) in streams.iter().enumerate() {
            let upto = samples.partition_point(|s| s.timestamp_ns <= t_scan);
            for chunk in samples[sent[k]..upto].chunks(255) {
                // Resampled on the nominal grid from the chunk's first time (jitter is lost).
                w.u8(*op);
                w.u8(4); // delta-coded
                w.u8(chunk.len() as u8);
                time(&mut w, &mut clock, chunk[0].timestamp_ns);
                w.u16((period_ns / 1_000) as u16);
                w.u8(*shift);
                let step = 0.5f64.powi(i32::from(*shift));
                let first = [chunk[0].x, chunk[0].y, chunk[0].z];
                let mut v = [0.0; 3];
                for (value, start) in v.iter_mut().zip(first) {
                    // What the decoder reads back, so that the deltas below track it.
                    *value = w.f64(start);
                }
                for s in chunk {
                    for (value, target) in v.iter_mut().zip([s.x, s.y, s.z]) {
                        let d = ((target - *value) / step).round().clamp(-128.0, 127.0);
                        w.u8(d as i8 as u8);
                        *value += d * step;
                    }
                }
                clock.now += (chunk.len() as u64 - 1) * (period_ns / 1_000 * 1_000);
            }
            sent[k] = upto;
        }
        w.u8(5); // scan
        time(&mut w, &mut clock, t_scan);
        w.u8(0); // readings one by one
        w.u8(epoch.scan.readings.len().min(23) as u8);
        for r in epoch.scan.readings.iter().take(23) {
            // The decoder takes the index modulo the fixture's transmitter count, so on the
            // two-floor site the office's access points become its transmitters.
            let index = office_aps.iter().position(|t| *t == r.transmitter).expect("an office access point");
            w.u8(index as u8);
            let b = ((-20.0 - r.rssi_dbm) * 2.0).round();
            if (0.0..=191.0).contains(&b) {
                w.u8(b as u8);
            } else {
                w.u8(192);
                w.f64(r.rssi_dbm);
            }
            w.u8(0); // fresh
        }
        w.u8(0); // not mangled
    }
    w.u8(10); // queries
    w.bytes
}
