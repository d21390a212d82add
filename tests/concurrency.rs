//! One FFI engine hammered from eight threads (issue 7): sensor batches, scans and `advance`
//! with clashing timestamps, reads, and listeners subscribed and cancelled all the while.
//! Checked: no deadlock (a watchdog fails the test instead of hanging), no panic, no lost or
//! reordered listener call, and listeners that fail, panic or call back into the engine break
//! nothing.

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Barrier, LazyLock, Mutex, Weak};
use std::time::{Duration, Instant};
use waymark::{
    EngineOptions, ErrorReport, FfiTrackPoint, MotionSample, PositionEstimate, PositionListener,
    PositioningEngine, PositioningError, RadioScan, StatusUpdate, Subscription, WifiReading,
};
use waymark_engine::sensors::SensorSample;
use waymark_engine::TransmitterId;
use waymark_sim::{imu, Office, OfficeConfig, EPOCH_NS};

/// How long the hammer runs.
const HAMMER: Duration = Duration::from_secs(3);
/// The watchdog: a run that takes longer than this is a deadlock.
const WATCHDOG: Duration = Duration::from_secs(60);
/// Simulated time runs this much faster than the wall clock.
const SPEED: u64 = 10;

struct Fixture {
    json: String,
    /// The walk's scans, as an app would pass them.
    scans: Vec<Vec<WifiReading>>,
    /// Its raw IMU, timestamps from 0, and the trace's length in ns.
    imu: [Vec<SensorSample>; 3],
    imu_ns: u64,
}

static FIXTURE: LazyLock<Fixture> = LazyLock::new(|| {
    let office = Office::generate(&OfficeConfig { training_scans: 20, ..OfficeConfig::default() });
    let walk = office.walk(9, 60.0);
    let trace = imu::synthesize(&walk.trajectory, &imu::ImuConfig::default(), 9);
    let t0 = trace.accelerometer[0].timestamp_ns;
    let shift = |v: &[SensorSample]| -> Vec<SensorSample> {
        v.iter()
            .filter(|s| s.timestamp_ns >= t0)
            .map(|s| SensorSample { timestamp_ns: s.timestamp_ns - t0, ..*s })
            .collect()
    };
    let imu = [shift(&trace.accelerometer), shift(&trace.gyroscope), shift(&trace.magnetometer)];
    let imu_ns = imu[0].last().unwrap().timestamp_ns + 10_000_000;
    let scans = walk
        .epochs
        .iter()
        .map(|e| {
            e.scan
                .readings
                .iter()
                .map(|r| match &r.transmitter {
                    TransmitterId::Wifi { bssid } => {
                        WifiReading { bssid: bssid.clone().into(), rssi_dbm: r.rssi_dbm, age_ms: 0 }
                    }
                    other => unreachable!("the simulator makes WiFi only: {other:?}"),
                })
                .collect()
        })
        .collect();
    Fixture { json: office.site.to_json(), scans, imu, imu_ns }
});

fn engine() -> Arc<PositioningEngine> {
    PositioningEngine::new(FIXTURE.json.clone(), EngineOptions::default()).unwrap()
}

/// Runs `work` on its own thread and fails (instead of hanging) if it does not finish within
/// the watchdog's time: a deadlock.
fn with_watchdog<T: Send + 'static>(what: &str, work: impl FnOnce() -> T + Send + 'static) -> T {
    let (done, finished) = mpsc::channel();
    let worker = std::thread::spawn(move || {
        let result = work();
        let _ = done.send(());
        result
    });
    match finished.recv_timeout(WATCHDOG) {
        Ok(()) => worker.join().unwrap_or_else(|e| std::panic::resume_unwind(e)),
        // The worker panicked (the channel closed without a message): report its panic.
        Err(mpsc::RecvTimeoutError::Disconnected) => {
            std::panic::resume_unwind(worker.join().err().unwrap_or_else(|| Box::new("no panic")))
        }
        Err(mpsc::RecvTimeoutError::Timeout) => panic!("{what}: not finished after {WATCHDOG:?}: deadlock"),
    }
}

/// Records every call it gets, in order.
#[derive(Default)]
struct Recorder {
    positions: Mutex<Vec<PositionEstimate>>,
    statuses: AtomicUsize,
    errors: AtomicUsize,
    /// A call made while another was running on this listener.
    overlapped: AtomicBool,
    busy: AtomicBool,
}

impl Recorder {
    fn enter(&self) -> impl Drop + '_ {
        if self.busy.swap(true, Ordering::SeqCst) {
            self.overlapped.store(true, Ordering::SeqCst);
        }
        struct Leave<'a>(&'a AtomicBool);
        impl Drop for Leave<'_> {
            fn drop(&mut self) {
                self.0.store(false, Ordering::SeqCst);
            }
        }
        Leave(&self.busy)
    }

    fn timestamps(&self) -> Vec<u64> {
        self.positions.lock().unwrap().iter().map(|p| p.timestamp_ns).collect()
    }
}

impl PositionListener for Recorder {
    fn on_position(&self, position: PositionEstimate) {
        let _busy = self.enter();
        self.positions.lock().unwrap().push(position);
    }
    fn on_status(&self, _: StatusUpdate) {
        let _busy = self.enter();
        self.statuses.fetch_add(1, Ordering::SeqCst);
    }
    fn on_error(&self, _: ErrorReport) {
        let _busy = self.enter();
        self.errors.fetch_add(1, Ordering::SeqCst);
    }
}

/// Fails every call, as a Kotlin or Swift listener that throws does.
#[derive(Default)]
struct Failing {
    calls: AtomicUsize,
    positions: AtomicUsize,
}

/// The failing listeners' panics are expected: keep them out of the test output, and print
/// every other panic as usual.
fn quiet_listener_panics() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let default = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if info.payload().downcast_ref::<&str>() != Some(&"a listener bug") {
                default(info);
            }
        }));
    });
}

impl Failing {
    /// What a listener that throws in Kotlin or Swift is on the Rust side: uniffi turns the
    /// exception of a method that returns nothing into a panic.
    fn fail(&self) {
        self.calls.fetch_add(1, Ordering::SeqCst);
        panic!("a listener bug");
    }
}

impl PositionListener for Failing {
    fn on_position(&self, _: PositionEstimate) {
        self.positions.fetch_add(1, Ordering::SeqCst);
        self.fail()
    }
    fn on_status(&self, _: StatusUpdate) {
        self.fail()
    }
    fn on_error(&self, _: ErrorReport) {
        self.fail()
    }
}

/// From inside its callback: subscribes a listener and cancels it again, reads the engine,
/// and from its `cancel_after`-th position on cancels its own subscription (as soon as it has
/// it: the subscribing thread stores it after `subscribe` returns, and a call may come first).
/// Holds the engine weakly (a strong reference would be a cycle: engine -> listener -> engine).
struct Reentrant {
    engine: Weak<PositioningEngine>,
    own: Mutex<Option<Arc<Subscription>>>,
    cancel_after: usize,
    positions: AtomicUsize,
    cancelled: AtomicBool,
    after_cancel: AtomicUsize,
}

impl PositionListener for Reentrant {
    fn on_position(&self, _: PositionEstimate) {
        if self.cancelled.load(Ordering::SeqCst) {
            self.after_cancel.fetch_add(1, Ordering::SeqCst);
        }
        let n = self.positions.fetch_add(1, Ordering::SeqCst) + 1;
        let Some(engine) = self.engine.upgrade() else { return };
        let other = Arc::clone(&engine).subscribe(Arc::new(Recorder::default()));
        let _ = (engine.position().unwrap(), engine.track().unwrap());
        other.cancel();
        if n >= self.cancel_after {
            if let Some(own) = self.own.lock().unwrap().take() {
                own.cancel();
                self.cancelled.store(true, Ordering::SeqCst);
            }
        }
    }
    fn on_status(&self, _: StatusUpdate) {}
    fn on_error(&self, _: ErrorReport) {}
}

fn subscribe_reentrant(engine: &Arc<PositioningEngine>, cancel_after: usize) -> Arc<Reentrant> {
    let listener = Arc::new(Reentrant {
        engine: Arc::downgrade(engine),
        own: Mutex::new(None),
        cancel_after,
        positions: AtomicUsize::new(0),
        cancelled: AtomicBool::new(false),
        after_cancel: AtomicUsize::new(0),
    });
    let subscription = Arc::clone(engine).subscribe(listener.clone());
    *listener.own.lock().unwrap() = Some(subscription);
    listener
}

fn finite(p: &PositionEstimate) -> bool {
    [p.x, p.y, p.floor_probability, p.accuracy_m, p.accuracy_95_m].iter().all(|v| v.is_finite())
        && p.heading_deg.is_none_or(f64::is_finite)
        && p.accuracy_m > 0.0
}

fn finite_point(p: &FfiTrackPoint) -> bool {
    p.x.is_finite() && p.y.is_finite()
}

/// What the epoch threads did.
#[derive(Default)]
struct Tally {
    ok: AtomicUsize,
    rejected: AtomicUsize,
}

impl Tally {
    fn count(&self, result: Result<PositionEstimate, PositioningError>) {
        match result {
            Ok(p) => {
                assert!(finite(&p), "{p:?}");
                self.ok.fetch_add(1, Ordering::SeqCst);
            }
            Err(PositioningError::InputRejected { .. }) => {
                self.rejected.fetch_add(1, Ordering::SeqCst);
            }
            Err(e) => panic!("an epoch failed with {e:?}"),
        }
    }
}

fn hammer() {
    quiet_listener_panics();
    let engine = engine();
    // Subscribed before the start and never cancelled: they must hear everything. The failing
    // ones go first, so the recorder's calls come after theirs.
    let failing = Arc::new(Failing::default());
    let panicking = Arc::new(Failing::default());
    let _s0 = Arc::clone(&engine).subscribe(failing.clone());
    let _s1 = Arc::clone(&engine).subscribe(panicking.clone());
    let steady = Arc::new(Recorder::default());
    let _s2 = Arc::clone(&engine).subscribe(steady.clone());

    let tally = Tally::default();
    let reentrant = Mutex::new(Vec::new());
    let start = Barrier::new(8);
    let t0 = Instant::now();
    // Simulated time: the wall clock since the start, sped up.
    let now = || t0.elapsed().as_nanos() as u64 * SPEED;
    let running = || t0.elapsed() < HAMMER;
    std::thread::scope(|scope| {
        // 0-2: one thread per inertial stream, pushing the walk's samples up to "now" in
        // batches, each stream in time order.
        for stream in 0..3 {
            let (engine, start) = (&engine, &start);
            scope.spawn(move || {
                start.wait();
                let samples = &FIXTURE.imu[stream];
                let (mut k, mut round) = (0, 0);
                while running() {
                    let until = now();
                    let mut batch = Vec::new();
                    loop {
                        let s = samples[k];
                        let t = s.timestamp_ns + round * FIXTURE.imu_ns;
                        if t > until {
                            break;
                        }
                        batch.push(MotionSample { timestamp_ns: t, x: s.x, y: s.y, z: s.z });
                        k += 1;
                        if k == samples.len() {
                            (k, round) = (0, round + 1);
                        }
                    }
                    let result = match stream {
                        0 => engine.push_accelerometer(batch),
                        1 => engine.push_gyroscope(batch),
                        _ => engine.push_magnetometer(batch),
                    };
                    result.expect("a sensor batch is never an error");
                    std::thread::sleep(Duration::from_millis(5));
                }
            });
        }
        // 3-4: scans at "now", racing each other (and 5) for the engine: the loser of a race
        // is rejected as out of order.
        for thread in 0..2 {
            let (engine, start, tally) = (&engine, &start, &tally);
            scope.spawn(move || {
                start.wait();
                let mut n = thread;
                while running() {
                    let t = now();
                    let wifi = FIXTURE.scans[(t / EPOCH_NS) as usize % FIXTURE.scans.len()].clone();
                    tally.count(engine.push_scan(RadioScan { timestamp_ns: t, wifi, beacons: vec![] }));
                    n += 1;
                    std::thread::sleep(Duration::from_millis(2 + n as u64 % 5));
                }
            });
        }
        // 5: advance, sometimes to a time already passed.
        {
            let (engine, start, tally) = (&engine, &start, &tally);
            scope.spawn(move || {
                start.wait();
                let mut n = 0u64;
                while running() {
                    let t = if n % 4 == 3 { now().saturating_sub(EPOCH_NS) } else { now() };
                    tally.count(engine.advance(t));
                    n += 1;
                    std::thread::sleep(Duration::from_millis(3));
                }
            });
        }
        // 6: reads.
        {
            let (engine, start) = (&engine, &start);
            scope.spawn(move || {
                start.wait();
                while running() {
                    if let Some(p) = engine.position().unwrap() {
                        assert!(finite(&p), "{p:?}");
                    }
                    assert!(engine.track().unwrap().iter().all(finite_point));
                    assert!(engine.fixed_lag_position().unwrap().iter().all(finite_point));
                    std::thread::yield_now();
                }
            });
        }
        // 7: listeners coming and going: cancelled, dropped, or cancelling themselves from
        // inside their own callback.
        {
            let (engine, start, reentrant) = (&engine, &start, &reentrant);
            scope.spawn(move || {
                start.wait();
                let mut n = 0usize;
                while running() {
                    let counter = Arc::new(Recorder::default());
                    let subscription = Arc::clone(engine).subscribe(counter);
                    std::thread::sleep(Duration::from_millis(1));
                    if n.is_multiple_of(2) {
                        subscription.cancel();
                    }
                    drop(subscription);
                    if n.is_multiple_of(10) {
                        reentrant.lock().unwrap().push(subscribe_reentrant(engine, 1 + n % 3));
                    }
                    n += 1;
                }
            });
        }
    });

    let ok = tally.ok.load(Ordering::SeqCst);
    let rejected = tally.rejected.load(Ordering::SeqCst);
    println!("{ok} epochs, {rejected} rejected in {:?}", t0.elapsed());
    assert!(ok > 50, "{ok} epochs: the hammer did little");
    // No lost, doubled or reordered call: one position per accepted epoch, in time order, and
    // one error per rejected one; the failing listeners were called as often.
    let heard = steady.timestamps();
    assert_eq!(heard.len(), ok, "positions heard / epochs accepted");
    assert!(heard.windows(2).all(|w| w[0] < w[1]), "positions out of order");
    assert_eq!(steady.errors.load(Ordering::SeqCst), rejected);
    assert!(!steady.overlapped.load(Ordering::SeqCst), "a listener was called from two threads at once");
    assert_eq!(failing.positions.load(Ordering::SeqCst), ok);
    assert_eq!(panicking.positions.load(Ordering::SeqCst), ok);
    assert_eq!(failing.calls.load(Ordering::SeqCst), panicking.calls.load(Ordering::SeqCst));
    // A listener that cancelled itself from its callback heard nothing after.
    let reentrant = reentrant.into_inner().unwrap();
    assert!(!reentrant.is_empty());
    for r in &reentrant {
        assert_eq!(r.after_cancel.load(Ordering::SeqCst), 0, "heard after cancelling itself");
    }
    assert!(reentrant.iter().any(|r| r.cancelled.load(Ordering::SeqCst)), "none cancelled itself");
    // The engine still works, and every listener still hears.
    let last = engine.position().unwrap().expect("a position").timestamp_ns;
    let p = engine.advance(last + EPOCH_NS).expect("usable after the hammer");
    assert!(finite(&p));
    assert_eq!(steady.timestamps().len(), ok + 1);
    assert_eq!(failing.positions.load(Ordering::SeqCst), ok + 1);
}

#[test]
fn eight_threads_hammer_one_engine() {
    with_watchdog("the hammer", hammer);
}

/// A slow listener holds up delivery on one thread while another thread's epoch completes:
/// the listeners after it must still hear the two positions in time order.
#[test]
fn a_slow_listener_does_not_reorder_positions() {
    with_watchdog("a slow listener", || {
        let engine = engine();
        let (entered, in_slow) = mpsc::channel();
        struct Slow(Mutex<Option<mpsc::Sender<()>>>);
        impl PositionListener for Slow {
            fn on_position(&self, _: PositionEstimate) {
                if let Some(entered) = self.0.lock().unwrap().take() {
                    let _ = entered.send(());
                    std::thread::sleep(Duration::from_millis(300));
                }
            }
            fn on_status(&self, _: StatusUpdate) {}
            fn on_error(&self, _: ErrorReport) {}
        }
        let _slow = Arc::clone(&engine).subscribe(Arc::new(Slow(Mutex::new(Some(entered)))));
        let recorder = Arc::new(Recorder::default());
        let _recorder = Arc::clone(&engine).subscribe(recorder.clone());
        let first = {
            let engine = Arc::clone(&engine);
            std::thread::spawn(move || engine.advance(EPOCH_NS).unwrap())
        };
        in_slow.recv().unwrap();
        // The first epoch is being delivered (to the slow listener); the engine is free.
        engine.advance(2 * EPOCH_NS).unwrap();
        first.join().unwrap();
        assert_eq!(recorder.timestamps(), vec![EPOCH_NS, 2 * EPOCH_NS]);
    });
}

/// Inside a callback a listener may call the engine, subscribe, and cancel: a listener
/// subscribed there hears the epochs after the one being delivered; one cancelled there hears
/// nothing more; an epoch pushed from there is delivered after the current one.
#[test]
fn listeners_may_call_the_engine_from_their_callback() {
    with_watchdog("a re-entrant listener", || {
        let engine = engine();
        struct Nested {
            engine: Weak<PositioningEngine>,
            own: Mutex<Option<Arc<Subscription>>>,
            late: Arc<Recorder>,
            late_subscription: Mutex<Option<Arc<Subscription>>>,
            calls: AtomicUsize,
        }
        impl PositionListener for Nested {
            fn on_position(&self, p: PositionEstimate) {
                self.calls.fetch_add(1, Ordering::SeqCst);
                let engine = self.engine.upgrade().expect("the engine");
                let late = Arc::clone(&engine).subscribe(self.late.clone());
                *self.late_subscription.lock().unwrap() = Some(late);
                if let Some(own) = self.own.lock().unwrap().take() {
                    own.cancel();
                }
                // An epoch from inside the callback, while this one is still being delivered.
                let nested = engine.advance(p.timestamp_ns + EPOCH_NS).expect("a nested epoch");
                assert_eq!(nested.timestamp_ns, p.timestamp_ns + EPOCH_NS);
                assert_eq!(engine.position().unwrap().map(|p| p.timestamp_ns), Some(nested.timestamp_ns));
            }
            fn on_status(&self, _: StatusUpdate) {}
            fn on_error(&self, _: ErrorReport) {}
        }
        let before = Arc::new(Recorder::default());
        let _before = Arc::clone(&engine).subscribe(before.clone());
        let nested = Arc::new(Nested {
            engine: Arc::downgrade(&engine),
            own: Mutex::new(None),
            late: Arc::new(Recorder::default()),
            late_subscription: Mutex::new(None),
            calls: AtomicUsize::new(0),
        });
        let subscription = Arc::clone(&engine).subscribe(nested.clone());
        *nested.own.lock().unwrap() = Some(subscription);
        let after = Arc::new(Recorder::default());
        let _after = Arc::clone(&engine).subscribe(after.clone());

        engine.advance(EPOCH_NS).unwrap();
        assert_eq!(nested.calls.load(Ordering::SeqCst), 1, "cancelled inside its first call");
        let both = vec![EPOCH_NS, 2 * EPOCH_NS];
        assert_eq!(before.timestamps(), both);
        assert_eq!(after.timestamps(), both, "the nested epoch comes after the current one");
        assert_eq!(nested.late.timestamps(), vec![2 * EPOCH_NS], "subscribed during the first epoch");
        engine.advance(3 * EPOCH_NS).unwrap();
        assert_eq!(nested.calls.load(Ordering::SeqCst), 1);
        assert_eq!(after.timestamps().len(), 3);
    });
}
