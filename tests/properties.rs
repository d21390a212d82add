//! Property tests of the engine's promises (issue 7), on arbitrary sequences of calls: IMU
//! batches with any timestamps (backwards, duplicate, near `u64::MAX`) and any values (NaN,
//! ±inf, huge), scans (empty, duplicated and unknown transmitters, malformed ids, NaN and
//! extreme RSSI, huge ages), `advance`, position fixes (anywhere, any accuracy, any floor),
//! user feedback (any zone, any circle, at the latest epoch's time or later or earlier), and
//! reads. After every call, on the core [`Engine`] and on the FFI [`PositioningEngine`]:
//!
//! - the posterior is a distribution: finite, ≥ 0, sums to 1 ± 1e-9;
//! - no NaN or infinity in any position, estimate or track point that leaves the engine;
//! - the estimate is on the site: a valid floor, inside the bounding box of that floor's
//!   states grown by the site's spacing; `accuracy_m` and `accuracy_95_m` finite and > 0;
//! - the zone is one of the site's, or none, and its probability is what the zone posterior
//!   (itself a sub-distribution) says;
//! - a rejected call (one that returns `Err`) leaves the engine's state as it was;
//! - reads change nothing, and listeners hear exactly one position per accepted epoch.
//!
//! "State" is everything in [`waymark_engine::EngineSnapshot`] except `InputStats`: the
//! rejection counters are bookkeeping of rejections, so a rejected scan, advance, fix or
//! feedback must change exactly its own counter by one and nothing else (checked separately),
//! while every later answer of the engine is decided by the rest (the epoch history included),
//! which must be identical.

#[path = "../crates/engine/tests/common/mod.rs"]
mod common;

use proptest::prelude::*;
use std::sync::{Arc, LazyLock, Mutex};
use waymark::{
    BeaconReading, EngineOptions, FfiPositionFix, MotionSample, PositionEstimate,
    PositionListener as FfiListener, PositioningEngine, PositioningError, RadioScan, StatusUpdate,
    TransitionKind, WifiReading,
};
use waymark_engine::sensors::{MotionScenario, MotionState, MotionUpdate, SensorSample};
use waymark_engine::EngineSnapshot;
use waymark_engine::TransitionModel;
use waymark_engine::{
    Engine, EngineConfig, Epoch, InputError, InputStats, Position, PositionFix, Reading, Scan, Site,
    TrackPoint, TransmitterId, Zone, ZoneKind,
};
use waymark_sim::{imu, Office, OfficeConfig};

const SECOND: u64 = 1_000_000_000;

/// A site and realistic input for it.
struct Fixture {
    site: Arc<Site>,
    json: String,
    /// Per floor: (min x, max x, min y, max y) of its states, grown by the site's spacing.
    bounds: Vec<[f64; 4]>,
    /// The BSSIDs of the site's access points, as an app would write them.
    bssids: Vec<String>,
    /// Scans a phone on the site would make: (BSSID index, RSSI).
    scans: Vec<Vec<(usize, f64)>>,
}

impl Fixture {
    fn new(site: Site, scans: Vec<Vec<(usize, f64)>>) -> Self {
        let spacing = site.spacing_m();
        let mut bounds =
            vec![[f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY]; site.floors().len()];
        for s in site.states() {
            let b = &mut bounds[s.floor];
            b[0] = b[0].min(s.position.x - spacing);
            b[1] = b[1].max(s.position.x + spacing);
            b[2] = b[2].min(s.position.y - spacing);
            b[3] = b[3].max(s.position.y + spacing);
        }
        // Both sites name their access points 02:00:00:00:00:kk.
        let bssids: Vec<String> =
            (0..site.radio().transmitters().len()).map(|k| format!("02:00:00:00:00:{k:02x}")).collect();
        for b in &bssids {
            assert!(site.radio().transmitters().contains(&TransmitterId::wifi(b).unwrap()), "{b}");
        }
        Self { json: site.to_json(), site: Arc::new(site), bounds, bssids, scans }
    }
}

/// The simulated office (one floor, 81 states, 12 zones) and the two-floor corridor of
/// `tests/common` with three zones, one state in none.
static FIXTURES: LazyLock<[Fixture; 2]> = LazyLock::new(|| {
    let office = Office::generate(&OfficeConfig { training_scans: 20, ..OfficeConfig::default() });
    let walk = office.walk(11, 40.0);
    let index = |id: &TransmitterId| office.site.radio().transmitters().iter().position(|t| t == id).unwrap();
    let office_scans = walk
        .epochs
        .iter()
        .map(|e| e.scan.readings.iter().map(|r| (index(&r.transmitter), r.rssi_dbm)).collect())
        .collect();
    let zone = |name: &str, states: Vec<u32>| Zone { name: name.into(), kind: ZoneKind::Room, states };
    let two = common::two_floor_site()
        .with_zones(vec![
            zone("west", vec![0, 1]),
            zone("east", vec![3, 4]),
            zone("upstairs", (5..10).collect()),
        ])
        .unwrap();
    let two_scans = (0..2)
        .flat_map(|f| (0..5).map(move |k| (f, 3.0 * k as f64)))
        .map(|(f, x)| (0..3).map(|t| (3 * f + t, -40.0 - 4.0 * (x - 6.0 * t as f64).abs())).collect())
        .collect();
    [Fixture::new(office.site, office_scans), Fixture::new(two, two_scans)]
});

/// Raw IMU of a 40 s walk, timestamps from 0: pushed in slices, it makes steps and headings.
static TRACE: LazyLock<imu::ImuTrace> = LazyLock::new(|| {
    let office = Office::generate(&OfficeConfig { training_scans: 2, ..OfficeConfig::default() });
    let walk = office.walk(5, 40.0);
    let mut trace = imu::synthesize(&walk.trajectory, &imu::ImuConfig::default(), 5);
    let t0 = [&trace.accelerometer, &trace.gyroscope, &trace.magnetometer]
        .iter()
        .filter_map(|s| s.first().map(|s| s.timestamp_ns))
        .min()
        .unwrap_or(0);
    for stream in [&mut trace.accelerometer, &mut trace.gyroscope, &mut trace.magnetometer] {
        for s in stream.iter_mut() {
            s.timestamp_ns -= t0;
        }
    }
    trace
});

// --- Calls ----------------------------------------------------------------------------------

/// A timestamp relative to the test's clock `now` (the latest time handed out so far).
#[derive(Clone, Copy, Debug)]
enum When {
    /// `now + d`, and the clock moves there.
    After(u64),
    /// `now` again.
    Same,
    /// `now - d`.
    Before(u64),
    /// An absolute time (0, `u64::MAX`, the fault-injection times, anything).
    At(u64),
}

/// Who a reading is of.
#[derive(Clone, Debug)]
enum Who {
    /// The site's access point k (mod their number), written as `notation` says.
    Known(usize, u8),
    /// An access point the site does not know.
    Unknown(u8),
    /// A BSSID string an app should never send (the core sees an unknown transmitter).
    Garbage(String),
    /// A BLE beacon, valid or not (the core sees an unknown transmitter).
    Beacon { uuid: String, major: u16, minor: u16, address: Option<String> },
}

#[derive(Clone, Debug)]
struct ReadingSpec {
    who: Who,
    rssi_dbm: f64,
    age_ns: u64,
}

#[derive(Clone, Debug)]
enum Call {
    /// Samples for one stream (0 accelerometer, 1 gyroscope, 2 magnetometer).
    Imu { stream: usize, samples: Vec<(When, [f64; 3])> },
    /// The next `ms` of the synthetic walk's IMU, all three streams, after `now`.
    Walk { ms: u64 },
    /// A scan of arbitrary readings.
    Scan { when: When, readings: Vec<ReadingSpec> },
    /// A scan a phone on the site would make, perhaps with junk appended.
    RealisticScan { when: When, index: usize, junk: Vec<ReadingSpec> },
    /// An epoch without radio.
    Advance { when: When },
    /// A realistic scan, or an epoch without radio, with motion measured outside Waymark
    /// (`push_scan_with_motion`, `advance_with_motion`; the FFI has neither and uses the
    /// engine's own tracker).
    WithMotion { when: When, scan: Option<usize>, motion: MotionUpdate },
    /// A position fix near state `near` (mod the states), `offset` m off, or at junk
    /// coordinates.
    Fix { when: When, at: Place, floor: Option<usize>, accuracy_m: f64 },
    /// Feedback: "I am in this zone" (an index past the site's zones, or a junk name, is
    /// unknown).
    ConfirmZone { when: When, zone: ZoneRef },
    /// Feedback: "I am within `radius_m` of here".
    ConfirmPosition { when: When, at: Place, floor: usize, radius_m: f64 },
    /// Every read.
    Read,
}

/// Where a fix or a confirmed position is.
#[derive(Clone, Copy, Debug)]
enum Place {
    /// State `k` (mod the states) moved by (dx, dy) m.
    Near(usize, f64, f64),
    /// Anywhere, NaN and infinities included.
    At(f64, f64),
}

/// A zone named in feedback.
#[derive(Clone, Debug)]
enum ZoneRef {
    /// By index; past the site's zones is unknown.
    Index(usize),
    /// By a name, probably unknown.
    Name(String),
}

fn delta() -> impl Strategy<Value = u64> {
    prop_oneof![
        8 => 0..3 * SECOND,
        2 => 0..60 * SECOND,
        1 => 0..7200 * SECOND,
        1 => Just(1u64),
        1 => any::<u64>(),
    ]
}

/// The times a test build panics at on purpose (feature `fault-injection`): a scan at
/// `waymark::FAULT_INJECTION_TIMESTAMP_NS`, an epoch at
/// `waymark_engine::FAULT_INJECTION_MID_EPOCH_NS`. Those constants exist only with the
/// feature; without it these are times like any other near the top of the range.
const INJECTED_SCAN_NS: u64 = u64::MAX - 7;
const INJECTED_MID_EPOCH_NS: u64 = waymark_engine::sensors::MAX_TIMESTAMP_NS - 8;

#[cfg(feature = "fault-injection")]
#[test]
fn the_injected_times_are_the_features() {
    assert_eq!(INJECTED_SCAN_NS, waymark::FAULT_INJECTION_TIMESTAMP_NS);
    assert_eq!(INJECTED_MID_EPOCH_NS, waymark_engine::FAULT_INJECTION_MID_EPOCH_NS);
}

fn when() -> impl Strategy<Value = When> {
    prop_oneof![
        12 => delta().prop_map(When::After),
        2 => Just(When::Same),
        2 => delta().prop_map(When::Before),
        1 => prop_oneof![
            Just(0u64),
            Just(u64::MAX),
            Just(u64::MAX - 1),
            Just(INJECTED_SCAN_NS),
            Just(INJECTED_MID_EPOCH_NS),
            any::<u64>(),
        ]
        .prop_map(When::At),
    ]
}

/// Sensor values: mostly plausible, sometimes NaN, ±inf, huge, tiny or anything.
fn value() -> impl Strategy<Value = f64> {
    prop_oneof![
        30 => -30.0..30.0f64,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => Just(1e300),
        1 => Just(-1e6),
        1 => Just(-0.0),
        1 => Just(f64::MIN_POSITIVE),
        1 => any::<f64>(),
    ]
}

fn rssi() -> impl Strategy<Value = f64> {
    prop_oneof![
        30 => -100.0..-30.0f64,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(f64::NEG_INFINITY),
        1 => Just(f64::MAX),
        1 => Just(-f64::MAX),
        1 => Just(0.0),
        1 => Just(-500.0),
        1 => Just(80.0),
        1 => any::<f64>(),
    ]
}

fn age() -> impl Strategy<Value = u64> {
    prop_oneof![8 => Just(0u64), 2 => 0..10 * SECOND, 1 => Just(u64::MAX), 1 => any::<u64>()]
}

fn text() -> impl Strategy<Value = String> {
    prop_oneof![
        Just(String::new()),
        Just("fda50693-a4e2-4fb1-afcf-c6eb07647825".to_string()),
        Just("02:00:00:00:00:00".to_string()),
        Just("zz:zz:zz:zz:zz:zz".to_string()),
        Just("02:00:00:00:00:00:00:00".to_string()),
        ".{0,40}",
    ]
}

fn reading() -> impl Strategy<Value = ReadingSpec> {
    let who = prop_oneof![
        12 => (0..64usize, 0..3u8).prop_map(|(k, n)| Who::Known(k, n)),
        2 => any::<u8>().prop_map(Who::Unknown),
        1 => text().prop_map(Who::Garbage),
        1 => (text(), any::<u16>(), any::<u16>(), proptest::option::of(text()))
            .prop_map(|(uuid, major, minor, address)| Who::Beacon { uuid, major, minor, address }),
    ];
    (who, rssi(), age()).prop_map(|(who, rssi_dbm, age_ns)| ReadingSpec { who, rssi_dbm, age_ns })
}

fn place() -> impl Strategy<Value = Place> {
    prop_oneof![
        6 => (any::<usize>(), -6.0..6.0f64, -6.0..6.0f64).prop_map(|(k, dx, dy)| Place::Near(k, dx, dy)),
        1 => (value(), value()).prop_map(|(x, y)| Place::At(x, y)),
    ]
}

fn distance() -> impl Strategy<Value = f64> {
    prop_oneof![8 => 0.2..30.0f64, 1 => value(), 1 => Just(0.0), 1 => Just(1e5), 1 => Just(1e7)]
}

fn call() -> impl Strategy<Value = Call> {
    prop_oneof![
        2 => (when(), place(), proptest::option::of(0..3usize), distance())
            .prop_map(|(when, at, floor, accuracy_m)| Call::Fix { when, at, floor, accuracy_m }),
        2 => (when(), prop_oneof![4 => (0..14usize).prop_map(ZoneRef::Index), 1 => text().prop_map(ZoneRef::Name)])
            .prop_map(|(when, zone)| Call::ConfirmZone { when, zone }),
        1 => (when(), place(), 0..3usize, distance())
            .prop_map(|(when, at, floor, radius_m)| Call::ConfirmPosition { when, at, floor, radius_m }),
        3 => (0..3usize, proptest::collection::vec((when(), [value(), value(), value()]), 0..12))
            .prop_map(|(stream, samples)| Call::Imu { stream, samples }),
        3 => (0..3000u64).prop_map(|ms| Call::Walk { ms }),
        3 => (when(), proptest::collection::vec(reading(), 0..8))
            .prop_map(|(when, readings)| Call::Scan { when, readings }),
        4 => (when(), any::<usize>(), proptest::collection::vec(reading(), 0..2))
            .prop_map(|(when, index, junk)| Call::RealisticScan { when, index, junk }),
        2 => when().prop_map(|when| Call::Advance { when }),
        2 => (when(), proptest::option::of(any::<usize>()), motion_update())
            .prop_map(|(when, scan, motion)| Call::WithMotion { when, scan, motion }),
        1 => Just(Call::Read),
    ]
}

/// Motion from a platform step detector: any values, consistent or not.
fn motion_update() -> impl Strategy<Value = MotionUpdate> {
    let scenario = prop_oneof![
        Just(MotionScenario::DistanceHeading),
        Just(MotionScenario::Distance),
        Just(MotionScenario::HeadingSpeed),
        Just(MotionScenario::Speed),
    ];
    let state =
        prop_oneof![Just(MotionState::Unknown), Just(MotionState::Stationary), Just(MotionState::Walking)];
    let distance = prop_oneof![4 => 0.0..5.0f64, 1 => value()];
    let angle = prop_oneof![4 => -4.0..4.0f64, 1 => value()];
    let sigma = prop_oneof![4 => 0.0..1.0f64, 1 => value()];
    (
        (any::<u32>(), proptest::option::of(distance.clone()), sigma.clone()),
        (proptest::option::of(angle), sigma, proptest::option::of([distance.clone(), distance])),
        (state, scenario, any::<bool>()),
    )
        .prop_map(
            |(
                (steps, distance_m, distance_sigma_m),
                (heading_rad, heading_sigma_rad, displacement_m),
                (motion_state, scenario, compass_disturbed),
            )| MotionUpdate {
                start_ns: 0,
                end_ns: 0,
                steps,
                distance_m,
                distance_sigma_m,
                heading_rad,
                heading_sigma_rad,
                displacement_m,
                motion_state,
                scenario,
                compass_disturbed,
            },
        )
}

fn transition() -> impl Strategy<Value = TransitionModel> {
    prop_oneof![
        Just(TransitionModel::MovementVector),
        Just(TransitionModel::Regions),
        Just(TransitionModel::Reach)
    ]
}

/// The test's clock and the walk's IMU cursor: turns `When` into timestamps.
#[derive(Default)]
struct Clock {
    now: u64,
    /// Time into the synthetic walk already pushed, ns.
    walked_ns: u64,
}

impl Clock {
    fn at(&mut self, when: When) -> u64 {
        match when {
            When::After(d) => {
                self.now = self.now.saturating_add(d);
                self.now
            }
            When::Same => self.now,
            When::Before(d) => self.now.saturating_sub(d),
            When::At(t) => t,
        }
    }

    /// The next `ms` of the walk's samples per stream, moved to start just after `now`.
    fn walk(&mut self, ms: u64) -> [Vec<SensorSample>; 3] {
        let trace = &*TRACE;
        let end = trace.accelerometer.last().map_or(0, |s| s.timestamp_ns);
        if self.walked_ns >= end {
            self.walked_ns = 0; // round again
        }
        let (from, to) = (self.walked_ns, self.walked_ns + ms * 1_000_000);
        let shift = self.now.saturating_add(1).saturating_sub(from);
        let slice = |stream: &[SensorSample]| -> Vec<SensorSample> {
            stream
                .iter()
                .filter(|s| s.timestamp_ns >= from && s.timestamp_ns < to)
                .map(|s| SensorSample { timestamp_ns: s.timestamp_ns.saturating_add(shift), ..*s })
                .collect()
        };
        let out = [slice(&trace.accelerometer), slice(&trace.gyroscope), slice(&trace.magnetometer)];
        self.walked_ns = to;
        self.now = self.now.max(to.saturating_add(shift));
        out
    }
}

// --- Checks ---------------------------------------------------------------------------------

fn check_posterior(posterior: &[f64]) -> Result<(), TestCaseError> {
    prop_assert!(!posterior.is_empty());
    for (k, &p) in posterior.iter().enumerate() {
        prop_assert!(p.is_finite() && p >= 0.0, "posterior[{}] = {}", k, p);
    }
    let sum: f64 = posterior.iter().sum();
    prop_assert!((sum - 1.0).abs() <= 1e-9, "posterior sums to {}", sum);
    Ok(())
}

fn check_on_site(f: &Fixture, floor: usize, x: f64, y: f64, what: &str) -> Result<(), TestCaseError> {
    prop_assert!(floor < f.bounds.len(), "{}: floor {} of {}", what, floor, f.bounds.len());
    let b = f.bounds[floor];
    prop_assert!(x.is_finite() && y.is_finite(), "{}: ({}, {})", what, x, y);
    prop_assert!(
        x >= b[0] && x <= b[1] && y >= b[2] && y <= b[3],
        "{}: ({}, {}) on floor {} is off the site {:?}",
        what,
        x,
        y,
        floor,
        b
    );
    Ok(())
}

fn check_accuracy(accuracy_m: f64, accuracy_95_m: f64) -> Result<(), TestCaseError> {
    prop_assert!(accuracy_m.is_finite() && accuracy_m > 0.0, "accuracy_m = {}", accuracy_m);
    prop_assert!(
        accuracy_95_m.is_finite() && accuracy_95_m >= accuracy_m,
        "accuracy_95_m = {} (68%: {})",
        accuracy_95_m,
        accuracy_m
    );
    Ok(())
}

fn check_optional(value: Option<f64>, what: &str) -> Result<(), TestCaseError> {
    if let Some(v) = value {
        prop_assert!(v.is_finite(), "{} = {}", what, v);
    }
    Ok(())
}

fn check_position(f: &Fixture, p: &Position) -> Result<(), TestCaseError> {
    check_on_site(f, p.floor, p.x, p.y, "position")?;
    prop_assert!(p.zone.is_none_or(|z| z < f.site.zones().len()), "zone {:?}", p.zone);
    prop_assert!((0.0..=1.0 + 1e-9).contains(&p.zone_probability), "zone_probability {}", p.zone_probability);
    check_accuracy(p.accuracy_m, p.accuracy_95_m)?;
    prop_assert!(
        (0.0..=1.0 + 1e-9).contains(&p.floor_probability),
        "floor_probability {}",
        p.floor_probability
    );
    check_optional(p.heading_rad, "heading_rad")?;
    check_optional(p.heading_accuracy_rad, "heading_accuracy_rad")?;
    check_optional(p.radio_log_evidence, "radio_log_evidence")?;
    if let Some(s) = p.heading_accuracy_rad {
        prop_assert!(s >= 0.0, "heading_accuracy_rad {}", s);
    }
    Ok(())
}

fn check_estimate(f: &Fixture, p: &PositionEstimate) -> Result<(), TestCaseError> {
    check_on_site(f, p.floor as usize, p.x, p.y, "estimate")?;
    check_accuracy(p.accuracy_m, p.accuracy_95_m)?;
    prop_assert_eq!(&p.floor_name, &f.site.floors()[p.floor as usize].name);
    prop_assert!(
        (0.0..=1.0 + 1e-9).contains(&p.floor_probability),
        "floor_probability {}",
        p.floor_probability
    );
    check_optional(p.heading_deg, "heading_deg")?;
    check_optional(p.heading_accuracy_deg, "heading_accuracy_deg")?;
    prop_assert!(p.zone.as_ref().is_none_or(|name| f.site.zone_index(name).is_some()), "zone {:?}", p.zone);
    prop_assert!((0.0..=1.0 + 1e-9).contains(&p.zone_probability), "zone_probability {}", p.zone_probability);
    Ok(())
}

fn check_track(f: &Fixture, track: &[TrackPoint], last_epoch_ns: Option<u64>) -> Result<(), TestCaseError> {
    for p in track {
        check_on_site(f, p.floor, p.x, p.y, "track point")?;
        prop_assert!((p.state as usize) < f.site.states().len());
        prop_assert!(last_epoch_ns.is_some_and(|t| p.timestamp_ns <= t), "track point after the last epoch");
    }
    for w in track.windows(2) {
        prop_assert!(w[0].timestamp_ns < w[1].timestamp_ns, "track out of time order");
    }
    Ok(())
}

/// Everything a caller can read from a core engine is sound.
fn check_engine(f: &Fixture, engine: &Engine) -> Result<(), TestCaseError> {
    check_posterior(engine.posterior())?;
    let last = engine.snapshot().last_epoch_ns;
    let zones = engine.zone_posterior();
    prop_assert_eq!(zones.len(), f.site.zones().len());
    prop_assert!(zones.iter().all(|z| (0.0..=1.0 + 1e-9).contains(z)), "{:?}", zones);
    let outside = 1.0 - zones.iter().sum::<f64>();
    prop_assert!(outside >= -1e-9, "zones hold {} of the posterior", 1.0 - outside);
    if let Some(p) = engine.position() {
        check_position(f, p)?;
        prop_assert_eq!(Some(p.timestamp_ns), last);
        // The posterior has not changed since the epoch: its zone is the position's.
        let expected = p.zone.map_or(if zones.is_empty() { 1.0 } else { outside }, |z| zones[z]);
        prop_assert!(
            (p.zone_probability - expected).abs() <= 1e-9,
            "{} against {}",
            p.zone_probability,
            expected
        );
    }
    check_track(f, &engine.track(), last)?;
    if let Some(p) = engine.fixed_lag_position() {
        check_track(f, std::slice::from_ref(&p), last)?;
    }
    Ok(())
}

/// The state a rejected call must not change: the snapshot with the counters set aside.
fn without_stats(mut s: EngineSnapshot) -> EngineSnapshot {
    s.stats = InputStats::default();
    s
}

/// What an epoch call was.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Scan,
    Advance,
    Fix,
    Feedback,
}

/// Raises the one counter a rejected call raises.
fn count(stats: &mut InputStats, kind: Kind, e: &InputError) {
    if let InputError::TimeAhead { .. } = e {
        return stats.timestamps_ahead += 1;
    }
    match kind {
        Kind::Scan => {}
        Kind::Advance => return stats.advances_rejected += 1,
        Kind::Fix => return stats.fixes_rejected += 1,
        Kind::Feedback => return stats.feedback_rejected += 1,
    }
    *match e {
        InputError::OutOfOrder { .. } => &mut stats.scans_out_of_order,
        InputError::EmptyScan => &mut stats.scans_empty,
        InputError::NonFiniteRssi { .. } => &mut stats.scans_non_finite,
        InputError::RssiTooHigh { .. } => &mut stats.scans_rssi_too_high,
        InputError::NoKnownTransmitter { .. } => &mut stats.scans_no_known_transmitter,
        InputError::InvalidMotion { .. } => &mut stats.scans_invalid_motion,
        e => panic!("a scan cannot be rejected with {e}"),
    } += 1;
}

/// The rejection counters (of scans and of advances), summed, and the stats without them.
fn rejections(s: &InputStats) -> (u64, InputStats) {
    let sum = s.scans_out_of_order
        + s.scans_empty
        + s.scans_non_finite
        + s.scans_rssi_too_high
        + s.scans_no_known_transmitter
        + s.scans_invalid_motion
        + s.advances_rejected
        + s.fixes_rejected
        + s.feedback_rejected
        + s.timestamps_ahead;
    let rest = InputStats {
        scans_out_of_order: 0,
        scans_empty: 0,
        scans_non_finite: 0,
        scans_rssi_too_high: 0,
        scans_no_known_transmitter: 0,
        scans_invalid_motion: 0,
        advances_rejected: 0,
        fixes_rejected: 0,
        feedback_rejected: 0,
        timestamps_ahead: 0,
        ..s.clone()
    };
    (sum, rest)
}

/// An epoch call that panicked.
#[derive(Debug)]
struct Panicked;

/// Runs an epoch call, catching a panic (the injected one is expected; any other fails).
fn guarded(call: impl FnOnce() -> Result<Epoch, InputError>) -> Result<Result<Epoch, InputError>, Panicked> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(call)).map_err(|_| Panicked)
}

// --- The core engine ------------------------------------------------------------------------

fn core_reading(f: &Fixture, r: &ReadingSpec) -> Reading {
    let transmitter = match &r.who {
        Who::Known(k, _) => f.site.radio().transmitters()[k % f.bssids.len()].clone(),
        Who::Unknown(k) => TransmitterId::wifi(&format!("0a:00:00:00:00:{k:02x}")).unwrap(),
        Who::Garbage(_) | Who::Beacon { .. } => {
            TransmitterId::ble("fda50693-a4e2-4fb1-afcf-c6eb07647825", 7, 7).unwrap()
        }
    };
    Reading { transmitter, rssi_dbm: r.rssi_dbm, age_ns: r.age_ns }
}

fn realistic(f: &Fixture, index: usize) -> Vec<ReadingSpec> {
    f.scans[index % f.scans.len()]
        .iter()
        .map(|&(k, rssi_dbm)| ReadingSpec { who: Who::Known(k, 0), rssi_dbm, age_ns: 0 })
        .collect()
}

/// A place's coordinates on the fixture's site.
fn coordinates(f: &Fixture, at: Place) -> (f64, f64) {
    match at {
        Place::Near(k, dx, dy) => {
            let s = &f.site.states()[k % f.site.states().len()];
            (s.position.x + dx, s.position.y + dy)
        }
        Place::At(x, y) => (x, y),
    }
}

fn zone_name(f: &Fixture, zone: &ZoneRef) -> String {
    match zone {
        ZoneRef::Index(k) => f.site.zones().get(*k).map_or_else(|| format!("zone {k}"), |z| z.name.clone()),
        ZoneRef::Name(name) => name.clone(),
    }
}

fn run_core(
    fixture: usize,
    transition: TransitionModel,
    max_reading_age_ns: Option<u64>,
    calls: &[Call],
) -> Result<(), TestCaseError> {
    let f = &FIXTURES[fixture];
    let config = EngineConfig { transition, max_reading_age_ns, ..EngineConfig::default() };
    let mut engine = Engine::new(Arc::clone(&f.site), config).unwrap();
    let mut clock = Clock::default();
    check_engine(f, &engine)?;
    for (n, call) in calls.iter().enumerate() {
        let before = engine.snapshot();
        let outcome = match call {
            Call::Imu { stream, samples } => {
                let batch: Vec<SensorSample> = samples
                    .iter()
                    .map(|&(when, [x, y, z])| SensorSample { timestamp_ns: clock.at(when), x, y, z })
                    .collect();
                let report = match stream {
                    0 => engine.push_accelerometer(&batch),
                    1 => engine.push_gyroscope(&batch),
                    _ => engine.push_magnetometer(&batch),
                };
                prop_assert_eq!(
                    report.accepted + report.non_finite + report.out_of_order + report.ahead,
                    batch.len()
                );
                None
            }
            Call::Walk { ms } => {
                // Accepted unless an earlier batch went further ahead in time (`When::At`).
                let [a, g, m] = clock.walk(*ms);
                for (report, n) in [
                    (engine.push_accelerometer(&a), a.len()),
                    (engine.push_gyroscope(&g), g.len()),
                    (engine.push_magnetometer(&m), m.len()),
                ] {
                    prop_assert_eq!(report.non_finite, 0);
                    prop_assert_eq!(report.accepted + report.out_of_order + report.ahead, n);
                }
                None
            }
            Call::Scan { when, readings } => {
                let scan = Scan {
                    timestamp_ns: clock.at(*when),
                    readings: readings.iter().map(|r| core_reading(f, r)).collect(),
                };
                Some((scan.timestamp_ns, Kind::Scan, guarded(|| engine.push_scan(&scan))))
            }
            Call::RealisticScan { when, index, junk } => {
                let mut readings = realistic(f, *index);
                readings.extend(junk.iter().cloned());
                let scan = Scan {
                    timestamp_ns: clock.at(*when),
                    readings: readings.iter().map(|r| core_reading(f, r)).collect(),
                };
                Some((scan.timestamp_ns, Kind::Scan, guarded(|| engine.push_scan(&scan))))
            }
            Call::Advance { when } => {
                let t = clock.at(*when);
                Some((t, Kind::Advance, guarded(|| engine.advance(t))))
            }
            Call::WithMotion { when, scan: Some(index), motion } => {
                let t = clock.at(*when);
                let readings = realistic(f, *index).iter().map(|r| core_reading(f, r)).collect();
                let scan = Scan { timestamp_ns: t, readings };
                Some((t, Kind::Scan, guarded(|| engine.push_scan_with_motion(&scan, motion))))
            }
            Call::WithMotion { when, scan: None, motion } => {
                let t = clock.at(*when);
                Some((t, Kind::Advance, guarded(|| engine.advance_with_motion(t, motion))))
            }
            Call::Fix { when, at, floor, accuracy_m } => {
                let (x, y) = coordinates(f, *at);
                let fix = PositionFix {
                    timestamp_ns: clock.at(*when),
                    x,
                    y,
                    floor: *floor,
                    accuracy_m: *accuracy_m,
                };
                Some((fix.timestamp_ns, Kind::Fix, guarded(|| engine.push_fix(&fix))))
            }
            Call::ConfirmZone { when, zone } => {
                let t = clock.at(*when);
                let result = match zone {
                    ZoneRef::Index(k) => guarded(|| engine.confirm_zone(t, *k)),
                    ZoneRef::Name(name) => guarded(|| engine.confirm_zone_named(t, name)),
                };
                Some((t, Kind::Feedback, result))
            }
            Call::ConfirmPosition { when, at, floor, radius_m } => {
                let t = clock.at(*when);
                let (x, y) = coordinates(f, *at);
                Some((t, Kind::Feedback, guarded(|| engine.confirm_position(t, x, y, *floor, *radius_m))))
            }
            Call::Read => {
                let _ = (engine.position(), engine.track(), engine.fixed_lag_position());
                let _ =
                    (engine.stats(), engine.motion_stats(), engine.track_memory_bytes(), engine.posterior());
                let _ = (engine.zone_posterior(), engine.history());
                prop_assert_eq!(engine.snapshot(), before.clone(), "a read changed the engine");
                None
            }
        };
        let after = engine.snapshot();
        match outcome {
            Some((t, _, Err(Panicked))) => {
                // The injected panic half-way through an epoch: undone, counters included.
                prop_assert!(
                    cfg!(feature = "fault-injection") && t == INJECTED_MID_EPOCH_NS,
                    "call {} ({:?} at {}) panicked",
                    n,
                    call,
                    t
                );
                prop_assert_eq!(&after, &before, "call {} panicked half-way and changed the engine", n);
            }
            Some((t, _, Ok(Ok(epoch)))) => {
                let p = &epoch.position;
                prop_assert_eq!(p.timestamp_ns, t);
                prop_assert_eq!(after.last_epoch_ns, Some(t));
                prop_assert_eq!(engine.position(), Some(p));
                check_position(f, p)?;
                check_track(f, &epoch.revised_track, Some(u64::MAX))?;
            }
            Some((t, kind, Ok(Err(e)))) => {
                prop_assert_eq!(
                    without_stats(after.clone()),
                    without_stats(before.clone()),
                    "call {} ({:?} at {}) was rejected ({}) but changed the engine",
                    n,
                    call,
                    t,
                    e
                );
                // Bookkeeping: a rejected scan raises its own counter by one, a rejected
                // advance `advances_rejected`, a fix `fixes_rejected`, feedback
                // `feedback_rejected`.
                let mut expected = before.stats.clone();
                count(&mut expected, kind, &e);
                prop_assert_eq!(&after.stats, &expected);
            }
            None => {}
        }
        check_engine(f, &engine)
            .map_err(|e| TestCaseError::fail(format!("after call {n} ({call:?}): {e}")))?;
    }
    Ok(())
}

// --- The FFI engine -------------------------------------------------------------------------

/// An FFI listener that checks what it hears.
#[derive(Default)]
struct FfiRecorder {
    fixture: usize,
    heard: Mutex<(Vec<PositionEstimate>, usize, Vec<String>)>,
}

impl FfiListener for FfiRecorder {
    fn on_position(&self, position: PositionEstimate) {
        let mut heard = self.heard.lock().unwrap();
        if let Err(e) = check_estimate(&FIXTURES[self.fixture], &position) {
            heard.2.push(format!("listener: {e}"));
        }
        heard.0.push(position);
    }

    fn on_status(&self, status: StatusUpdate) {
        if let StatusUpdate::TrackRevised { points } = status {
            if let Err(e) = check_ffi_track(&FIXTURES[self.fixture], &points) {
                self.heard.lock().unwrap().2.push(format!("revision: {e}"));
            }
        }
    }

    fn on_error(&self, _error: waymark::ErrorReport) {
        self.heard.lock().unwrap().1 += 1;
    }
}

fn check_ffi_track(f: &Fixture, track: &[waymark::FfiTrackPoint]) -> Result<(), TestCaseError> {
    for p in track {
        check_on_site(f, p.floor as usize, p.x, p.y, "FFI track point")?;
    }
    Ok(())
}

fn bssid(f: &Fixture, k: usize, notation: u8) -> String {
    let b = &f.bssids[k % f.bssids.len()];
    match notation {
        0 => b.clone(),
        1 => b.to_uppercase(),
        _ => b.replace(':', "-"),
    }
}

fn ffi_scan(f: &Fixture, timestamp_ns: u64, readings: &[ReadingSpec]) -> RadioScan {
    let mut scan = RadioScan { timestamp_ns, wifi: Vec::new(), beacons: Vec::new() };
    for r in readings {
        let age_ms = r.age_ns / 1_000_000;
        let wifi = |bssid: String| WifiReading { bssid: bssid.into(), rssi_dbm: r.rssi_dbm, age_ms };
        match &r.who {
            Who::Known(k, notation) => scan.wifi.push(wifi(bssid(f, *k, *notation))),
            Who::Unknown(k) => scan.wifi.push(wifi(format!("0a:00:00:00:00:{k:02x}"))),
            Who::Garbage(text) => scan.wifi.push(wifi(text.clone())),
            Who::Beacon { uuid, major, minor, address } => scan.beacons.push(BeaconReading {
                uuid: uuid.as_str().into(),
                major: *major,
                minor: *minor,
                rssi_dbm: r.rssi_dbm,
                age_ms,
                address: address.as_deref().map(Into::into),
            }),
        }
    }
    scan
}

fn motion(batch: &[SensorSample]) -> Vec<MotionSample> {
    batch.iter().map(|s| MotionSample { timestamp_ns: s.timestamp_ns, x: s.x, y: s.y, z: s.z }).collect()
}

/// Everything an app can read from an FFI engine is sound.
fn check_ffi_engine(f: &Fixture, engine: &PositioningEngine) -> Result<(), TestCaseError> {
    let (state, latest) = engine.snapshot();
    check_posterior(&state.posterior)?;
    if let Some(p) = &latest {
        check_estimate(f, p)?;
    }
    prop_assert_eq!(engine.position().unwrap(), latest);
    check_ffi_track(f, &engine.track().unwrap())?;
    check_ffi_track(f, engine.fixed_lag_position().unwrap().as_slice())?;
    Ok(())
}

/// Options an app might pass, sane or not.
fn options() -> impl Strategy<Value = EngineOptions> {
    let transition = proptest::option::of(prop_oneof![
        Just(TransitionKind::Reach),
        Just(TransitionKind::Regions),
        Just(TransitionKind::MovementVector)
    ]);
    let length =
        proptest::option::of(prop_oneof![8 => 0.4..1.0f64, 1 => value(), 1 => Just(0.0), 1 => Just(-0.7)]);
    let lag = prop_oneof![8 => 0..10u32, 1 => any::<u32>()];
    let angle = proptest::option::of(prop_oneof![4 => -360.0..360.0f64, 1 => value()]);
    // A salt, long enough or not: the fixtures' ids are raw, so a valid one is ignored.
    let salt = proptest::option::of(proptest::collection::vec(any::<u8>(), 0..40));
    let options = (transition, length, lag, angle.clone(), angle, salt).prop_map(
        |(transition, step_length_m, fixed_lag_epochs, declination_deg, site_rotation_deg, site_salt)| {
            EngineOptions {
                transition,
                step_length_m,
                fixed_lag_epochs,
                declination_deg,
                site_rotation_deg,
                site_salt,
                track: true,
            }
        },
    );
    (options, any::<bool>()).prop_map(|(options, track)| EngineOptions { track, ..options })
}

fn run_ffi(fixture: usize, options: EngineOptions, calls: &[Call]) -> Result<(), TestCaseError> {
    let f = &FIXTURES[fixture];
    // Options out of range are an InvalidConfig error, never a panic nor an engine that
    // produces NaN; the calls then go to an engine with the default options.
    let engine = match PositioningEngine::new(f.json.clone(), options.clone()) {
        Ok(engine) => engine,
        Err(PositioningError::InvalidConfig { .. }) => {
            PositioningEngine::new(f.json.clone(), EngineOptions::default()).unwrap()
        }
        Err(e) => return Err(TestCaseError::fail(format!("{options:?}: {e}"))),
    };
    let recorder = Arc::new(FfiRecorder { fixture, ..FfiRecorder::default() });
    let _subscription = Arc::clone(&engine).subscribe(recorder.clone());
    let mut clock = Clock::default();
    let (mut epochs, mut errors) = (0, 0);
    for (n, call) in calls.iter().enumerate() {
        let before = engine.snapshot();
        let outcome = match call {
            Call::Imu { stream, samples } => {
                let batch: Vec<MotionSample> = samples
                    .iter()
                    .map(|&(when, [x, y, z])| MotionSample { timestamp_ns: clock.at(when), x, y, z })
                    .collect();
                let n = batch.len();
                let ahead = engine.input_stats().unwrap().timestamps_ahead;
                let accepted = match stream {
                    0 => engine.push_accelerometer(batch),
                    1 => engine.push_gyroscope(batch),
                    _ => engine.push_magnetometer(batch),
                };
                prop_assert!(matches!(accepted, Ok(a) if a as usize <= n), "{:?}", accepted);
                // Samples refused as too far ahead reach the listener as one error.
                errors += usize::from(engine.input_stats().unwrap().timestamps_ahead > ahead);
                None
            }
            Call::Walk { ms } => {
                let [a, g, m] = clock.walk(*ms);
                type Push<'a> = &'a dyn Fn() -> Result<u32, PositioningError>;
                let pushes: [(Push, usize); 3] = [
                    (&|| engine.push_accelerometer(motion(&a)), a.len()),
                    (&|| engine.push_gyroscope(motion(&g)), g.len()),
                    (&|| engine.push_magnetometer(motion(&m)), m.len()),
                ];
                for (push, n) in pushes {
                    let ahead = engine.input_stats().unwrap().timestamps_ahead;
                    let accepted = push();
                    prop_assert!(matches!(accepted, Ok(k) if k as usize <= n), "{:?}", accepted);
                    errors += usize::from(engine.input_stats().unwrap().timestamps_ahead > ahead);
                }
                None
            }
            Call::Scan { when, readings } => {
                let t = clock.at(*when);
                Some((t, Kind::Scan, engine.push_scan(ffi_scan(f, t, readings))))
            }
            Call::RealisticScan { when, index, junk } => {
                let t = clock.at(*when);
                let mut readings = realistic(f, *index);
                readings.extend(junk.iter().cloned());
                Some((t, Kind::Scan, engine.push_scan(ffi_scan(f, t, &readings))))
            }
            Call::Advance { when } | Call::WithMotion { when, scan: None, .. } => {
                let t = clock.at(*when);
                Some((t, Kind::Advance, engine.advance(t)))
            }
            Call::WithMotion { when, scan: Some(index), .. } => {
                let t = clock.at(*when);
                Some((t, Kind::Scan, engine.push_scan(ffi_scan(f, t, &realistic(f, *index)))))
            }
            Call::Fix { when, at, floor, accuracy_m } => {
                let (x, y) = coordinates(f, *at);
                let t = clock.at(*when);
                let floor = floor.map(|f| f as u32);
                Some((
                    t,
                    Kind::Fix,
                    engine.push_fix(FfiPositionFix {
                        timestamp_ns: t,
                        x: Some(x),
                        y: Some(y),
                        floor,
                        accuracy_m: *accuracy_m,
                        latitude_deg: None,
                        longitude_deg: None,
                    }),
                ))
            }
            Call::ConfirmZone { when, zone } => {
                let t = clock.at(*when);
                Some((t, Kind::Feedback, engine.confirm_zone(t, zone_name(f, zone))))
            }
            Call::ConfirmPosition { when, at, floor, radius_m } => {
                let t = clock.at(*when);
                let (x, y) = coordinates(f, *at);
                Some((t, Kind::Feedback, engine.confirm_position(t, x, y, *floor as u32, *radius_m)))
            }
            Call::Read => {
                let _ = (engine.position(), engine.track(), engine.fixed_lag_position());
                let zones = engine.zone_posterior().unwrap();
                prop_assert_eq!(zones.len(), f.site.zones().len());
                prop_assert_eq!(engine.snapshot(), before.clone(), "a read changed the engine");
                None
            }
        };
        let after = engine.snapshot();
        match outcome {
            Some((t, _, Ok(p))) => {
                epochs += 1;
                check_estimate(f, &p)?;
                prop_assert_eq!(p.timestamp_ns, t);
                prop_assert_eq!(after.1.as_ref(), Some(&p));
                let heard = recorder.heard.lock().unwrap();
                prop_assert_eq!(heard.0.len(), epochs, "one position per epoch to the listener");
                prop_assert_eq!(heard.0.last(), Some(&p));
            }
            Some((t, kind, Err(e))) => {
                errors += 1;
                // The injected panics: before a scan reaches the engine, or half-way through an
                // epoch (which the engine undoes).
                let injected = cfg!(feature = "fault-injection")
                    && ((kind == Kind::Scan && t == INJECTED_SCAN_NS) || t == INJECTED_MID_EPOCH_NS);
                match &e {
                    PositioningError::InputRejected { .. } => {}
                    PositioningError::Internal { .. } if injected => {}
                    other => prop_assert!(false, "call {} ({:?}): unexpected {:?}", n, call, other),
                }
                prop_assert_eq!(&after.1, &before.1);
                prop_assert_eq!(
                    without_stats(after.0.clone()),
                    without_stats(before.0.clone()),
                    "call {} ({:?} at {}) failed ({}) but changed the engine",
                    n,
                    call,
                    t,
                    e
                );
                // A rejected advance, fix or feedback raises its counter by one; a rejected scan
                // one scan counter, or none if the FFI could not even parse it (a malformed
                // id); a panic leaves everything as it was, counters included.
                let (raised_after, rest_after) = rejections(&after.0.stats);
                let (raised_before, rest_before) = rejections(&before.0.stats);
                let raised = raised_after - raised_before;
                match &e {
                    PositioningError::Internal { .. } => {
                        prop_assert_eq!(&after.0, &before.0, "a panic changed the engine");
                    }
                    _ if kind == Kind::Scan => prop_assert!(raised <= 1, "{} counters raised", raised),
                    _ => prop_assert_eq!(raised, 1, "a rejected {:?} is counted once", kind),
                }
                prop_assert_eq!(rest_after, rest_before);
                prop_assert_eq!(recorder.heard.lock().unwrap().1, errors, "listeners hear every error");
            }
            None => {}
        }
        check_ffi_engine(f, &engine)
            .map_err(|e| TestCaseError::fail(format!("after call {n} ({call:?}): {e}")))?;
        let heard = recorder.heard.lock().unwrap();
        prop_assert!(heard.2.is_empty(), "{:?}", heard.2);
    }
    Ok(())
}

// --- The properties -------------------------------------------------------------------------

fn config() -> ProptestConfig {
    ProptestConfig { cases: 256, max_shrink_iters: 2000, ..ProptestConfig::default() }
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn the_core_engine_keeps_its_promises(
        fixture in 0..2usize,
        transition in transition(),
        max_reading_age_ns in proptest::option::of(Just(2 * SECOND)),
        calls in proptest::collection::vec(call(), 1..60),
    ) {
        run_core(fixture, transition, max_reading_age_ns, &calls)?;
    }

    #[test]
    fn the_ffi_engine_keeps_its_promises(
        fixture in 0..2usize,
        options in options(),
        calls in proptest::collection::vec(call(), 1..60),
    ) {
        run_ffi(fixture, options, &calls)?;
    }
}

// --- Regressions found by the properties ------------------------------------------------------

/// An RSSI of 1.8e308 dBm is finite, but its squared deviation from every fingerprint
/// overflowed: no state could explain the scan, the filter restarted, and the position
/// carried `radio_log_evidence = -inf`. Such a value is a corrupt producer, as NaN is: the
/// scan is rejected whole and counted with the non-finite ones.
#[test]
fn an_impossible_rssi_is_rejected_like_nan() {
    let f = &FIXTURES[0];
    let mut engine = Engine::new(Arc::clone(&f.site), EngineConfig::default()).unwrap();
    let known = f.site.radio().transmitters()[0].clone();
    // Below -1000 dBm: as NaN. Above +100 dBm: too high for any receiver.
    for rssi_dbm in [f64::MAX, -f64::MAX, 1e200, -1001.0, 1001.0] {
        let scan = Scan {
            timestamp_ns: SECOND,
            readings: vec![Reading { transmitter: known.clone(), rssi_dbm, age_ns: 0 }],
        };
        let before = engine.snapshot();
        let result = engine.push_scan(&scan);
        if rssi_dbm > 0.0 {
            assert!(matches!(result, Err(InputError::RssiTooHigh { index: 0, .. })), "{rssi_dbm}");
        } else {
            assert!(matches!(result, Err(InputError::NonFiniteRssi { index: 0, .. })), "{rssi_dbm}");
        }
        assert_eq!(without_stats(engine.snapshot()), without_stats(before));
    }
    assert_eq!((engine.stats().scans_non_finite, engine.stats().scans_rssi_too_high), (2, 3));
}

/// Motion from outside Waymark went into the transitions unchecked: a negative heading spread
/// came out as a position's `heading_accuracy_rad`, and NaN would have reached the posterior.
/// Now such motion rejects the call, which changes nothing but its counter.
#[test]
fn invalid_motion_from_outside_is_rejected() {
    let f = &FIXTURES[0];
    let mut engine = Engine::new(Arc::clone(&f.site), EngineConfig::default()).unwrap();
    let good = MotionUpdate {
        start_ns: 0,
        end_ns: SECOND,
        steps: 2,
        distance_m: Some(1.4),
        distance_sigma_m: 0.2,
        heading_rad: Some(0.5),
        heading_sigma_rad: 0.1,
        displacement_m: Some([0.67, 1.23]),
        motion_state: MotionState::Walking,
        scenario: MotionScenario::DistanceHeading,
        compass_disturbed: false,
    };
    let scan =
        |t| Scan { timestamp_ns: t, readings: realistic(f, 0).iter().map(|r| core_reading(f, r)).collect() };
    let bad = [
        MotionUpdate { heading_sigma_rad: -13.1, ..good.clone() },
        MotionUpdate { heading_rad: Some(f64::NAN), ..good.clone() },
        MotionUpdate { distance_m: Some(-1.0), ..good.clone() },
        MotionUpdate { distance_sigma_m: f64::INFINITY, ..good.clone() },
        MotionUpdate { displacement_m: Some([0.0, f64::NAN]), ..good.clone() },
    ];
    for (k, motion) in bad.iter().enumerate() {
        let before = engine.snapshot();
        let result = engine.push_scan_with_motion(&scan(SECOND), motion);
        assert!(matches!(result, Err(InputError::InvalidMotion { .. })), "{motion:?}: {result:?}");
        assert!(matches!(engine.advance_with_motion(SECOND, motion), Err(InputError::InvalidMotion { .. })));
        assert_eq!(engine.stats().scans_invalid_motion, k as u64 + 1);
        assert_eq!(engine.stats().advances_rejected, k as u64 + 1);
        assert_eq!(without_stats(engine.snapshot()), without_stats(before));
    }
    let p = engine.push_scan_with_motion(&scan(SECOND), &good).unwrap().position;
    assert_eq!(p.heading_accuracy_rad, Some(0.1));
    engine.advance_with_motion(2 * SECOND, &good).unwrap();
}
