//! The engine handle both FFIs wrap: Kotlin and Swift's `PositioningEngine`
//! ([`super::uniffi`]) and C's `waymark_engine` ([`super::c`]).
//!
//! It owns what the two used to write each on their own: the lock around the single-threaded
//! core [`Engine`], the panic boundary around every call into it, the queue of what the epochs
//! produced (delivered after the lock is released, in the order of the epochs, by one thread
//! at a time: [`Delivery`]), and the mapping of the core's errors to [`PositioningError`].
//! Each FFI only converts arguments and results and says how to call its app's listeners
//! ([`Listeners`]).

use super::delivery::{lock, Delivery};
use super::error::PositioningError;
use super::panic::{deliver_to_app, guard};
use super::record::AppStatus;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use waymark_engine::radio::Scan;
use waymark_engine::site::Site;
use waymark_engine::{Engine, EngineConfig, Epoch, Position, TransitionModel};

/// What an epoch produced, or a call's failure, waiting for delivery to the app.
#[derive(Clone, Debug)]
pub(crate) enum Event {
    /// A new position, of an engine on that site (a site replaced later does not change it).
    Position(Position, Arc<Site>),
    /// Something about the session changed.
    Status(AppStatus),
    /// A call failed (it also returned the error).
    Error(PositioningError),
}

/// How an FFI calls its app's listeners. Called with no lock of the handle held, never from
/// two threads at once; a panic inside is caught and logged.
pub(crate) trait Listeners: Send + Sync {
    /// Hands `event` to every listener.
    fn deliver(&self, event: &Event);
}

/// The engine options both FFIs offer, before they become an [`EngineConfig`].
#[derive(Clone, Default)]
pub(crate) struct Options {
    /// `None`: the default model.
    pub transition: Option<TransitionModel>,
    /// `None`: the default.
    pub fixed_lag_epochs: Option<usize>,
    /// Whether the engine keeps the Viterbi track ([`EngineConfig::track`]); `None`: the
    /// default (it does).
    pub track: Option<bool>,
    /// Degrees; `None`: the site file's.
    pub declination_deg: Option<f64>,
    /// Degrees; `None`: the site file's.
    pub site_rotation_deg: Option<f64>,
    /// The salt of a hashed site.
    pub site_salt: Option<Vec<u8>>,
    /// The user's own step length, m, in place of the site's surveyed one; `None`: the
    /// site's, or the engine's default on a site without one.
    pub step_length_m: Option<f64>,
}

impl Options {
    /// The configuration of an engine on `site` with these options.
    pub(crate) fn config(&self, site: &Site) -> Result<EngineConfig, PositioningError> {
        let defaults = EngineConfig::default();
        let mut config = EngineConfig {
            transition: self.transition.unwrap_or_default(),
            fixed_lag_epochs: self.fixed_lag_epochs.unwrap_or(defaults.fixed_lag_epochs),
            track: self.track.unwrap_or(defaults.track),
            ..defaults
        };
        if let Some(length_m) = self.step_length_m {
            config.step_length_override =
                Some(waymark_engine::sensors::StepLengthModel::Constant { length_m });
        }
        if self.declination_deg.is_some() || self.site_rotation_deg.is_some() {
            let from_site = site.north();
            config.north = Some(waymark_engine::site::North {
                declination_rad: self.declination_deg.map_or(from_site.declination_rad, f64::to_radians),
                site_rotation_rad: self
                    .site_rotation_deg
                    .map_or(from_site.site_rotation_rad, f64::to_radians),
            });
        }
        config.site_salt = match &self.site_salt {
            None => None,
            Some(bytes) => Some(
                waymark_engine::Salt::new(bytes.clone())
                    .map_err(|m| PositioningError::InvalidConfig { reason: format!("site_salt: {m}") })?,
            ),
        };
        Ok(config)
    }
}

/// A scan at this timestamp panics inside the engine call, to show that a panic comes out as
/// an error, not an abort. Only with the `fault-injection` feature (test builds).
#[cfg(feature = "fault-injection")]
pub const FAULT_INJECTION_TIMESTAMP_NS: u64 = u64::MAX - 7;

/// Importing this text as a habit model panics inside the engine call, half-way through a
/// change the engine cannot undo: the engine is left unusable, so every later call fails with
/// `Internal`. Only with the `fault-injection` feature (test builds).
#[cfg(feature = "fault-injection")]
pub const FAULT_INJECTION_HABITS_JSON: &str = "waymark fault injection";

/// A thread-safe engine with its app's listeners `L`.
pub(crate) struct Handle<L> {
    engine: Mutex<Engine>,
    /// Set when a call that the engine cannot undo panicked: the engine may be half-changed,
    /// so every later call fails.
    broken: AtomicBool,
    /// The engine's site, for the calls that need it without the engine's lock; replaced
    /// under that lock with the engine's ([`Handle::replace_site`]).
    site: Mutex<Arc<Site>>,
    events: Arc<Delivery<Event>>,
    listeners: L,
}

impl<L: Listeners> Handle<L> {
    /// An engine on `site` with `options`.
    pub(crate) fn new(site: Arc<Site>, options: &Options, listeners: L) -> Result<Self, PositioningError> {
        let config = options.config(&site)?;
        let engine = Engine::new(Arc::clone(&site), config)?;
        let events = Arc::new(Delivery::new());
        let site = Mutex::new(site);
        Ok(Self { engine: Mutex::new(engine), broken: AtomicBool::new(false), site, events, listeners })
    }

    /// The engine's site.
    pub(crate) fn site(&self) -> Arc<Site> {
        Arc::clone(&lock(&self.site))
    }

    /// Loads `site` in place of the engine's ([`Engine::replace_site`]): the evidence gathered
    /// on the old site and not yet taken.
    pub(crate) fn replace_site(
        &self,
        site: Arc<Site>,
    ) -> Result<Option<waymark_engine::SessionEvidence>, PositioningError> {
        // Not undoable: a panic half-way through would leave a half-replaced session.
        self.call(|engine| {
            let taken = engine.replace_site(Arc::clone(&site))?;
            *lock(&self.site) = site;
            Ok(taken)
        })
    }

    /// The app's listeners.
    pub(crate) fn listeners(&self) -> &L {
        &self.listeners
    }

    /// Runs `f` on the engine under its lock, then delivers what it staged to the listeners
    /// with no lock held. A panic inside becomes `Internal`, and what the call staged is
    /// dropped; the engine is then unusable (it may be half-changed): every later
    /// call fails with `Internal` too. A failure is also reported to the listeners, after what
    /// the call published. The log records the call made reach the log sink last, when the
    /// outermost Waymark call on this thread ends ([`super::logging`]).
    pub(crate) fn call<T>(
        &self,
        f: impl FnOnce(&mut Engine) -> Result<T, PositioningError>,
    ) -> Result<T, PositioningError> {
        self.run(true, f)
    }

    /// As [`call`](Self::call), for `f` that leaves the engine as it was if it panics: a read,
    /// or an epoch (the engine undoes an epoch that panics). The engine stays usable.
    pub(crate) fn call_undoable<T>(
        &self,
        f: impl FnOnce(&mut Engine) -> Result<T, PositioningError>,
    ) -> Result<T, PositioningError> {
        self.run(false, f)
    }

    fn run<T>(
        &self,
        breaks: bool,
        f: impl FnOnce(&mut Engine) -> Result<T, PositioningError>,
    ) -> Result<T, PositioningError> {
        // Log records (and a caught panic's message) wait until the lock is released
        // (docs/errors.md#callbacks): a log sink may call the engine.
        let _hold = super::logging::hold();
        let result = {
            let mut engine = lock(&self.engine);
            let result = if self.broken.load(Ordering::SeqCst) {
                Err(PositioningError::internal(
                    "an earlier call panicked and left the engine unusable: create a new engine",
                ))
            } else {
                match guard(|| f(&mut engine)) {
                    Ok(result) => {
                        self.events.commit();
                        result
                    }
                    Err(_) => {
                        self.events.discard();
                        if breaks {
                            self.broken.store(true, Ordering::SeqCst);
                            Err(PositioningError::internal(
                                "Waymark panicked; the engine is unusable: create a new engine",
                            ))
                        } else {
                            Err(PositioningError::internal("Waymark panicked; the call had no effect"))
                        }
                    }
                }
            };
            // Queued under the engine's lock, so listeners hear it in the order of the calls.
            if let Err(e) = &result {
                self.events.push(Event::Error(e.clone()));
            }
            result
        };
        self.deliver();
        result
    }

    /// An epoch made by `f`: its position and the site it is on, or the input error mapped to
    /// `InputRejected`. What the epoch produced is staged for the listeners in the order it
    /// happened: status changes, track revisions, then the position.
    pub(crate) fn epoch(
        &self,
        f: impl FnOnce(&mut Engine) -> Result<Epoch, waymark_engine::InputError>,
    ) -> Result<(Position, Arc<Site>), PositioningError> {
        let events = Arc::clone(&self.events);
        self.call_undoable(|engine| {
            let Epoch { position, status, revised_track } = f(engine)?;
            let site = engine.site();
            for change in status {
                events.stage(Event::Status(AppStatus::new(change, site)));
            }
            if !revised_track.is_empty() {
                events.stage(Event::Status(AppStatus::track_revised(&revised_track, site)));
            }
            let site = Arc::clone(engine.site());
            events.stage(Event::Position(position.clone(), Arc::clone(&site)));
            Ok((position, site))
        })
    }

    /// A read of the engine's state.
    pub(crate) fn read<T>(&self, f: impl FnOnce(&Engine) -> T) -> Result<T, PositioningError> {
        self.call_undoable(|engine| Ok(f(engine)))
    }

    /// Replaces the engine's habits by the model `json`.
    pub(crate) fn import_habits(&self, json: &str) -> Result<(), PositioningError> {
        self.call(|engine| {
            #[cfg(feature = "fault-injection")]
            if json == FAULT_INJECTION_HABITS_JSON {
                engine.clear_habits();
                panic!("fault injected half-way through importing habits");
            }
            Ok(engine.import_habits(json)?)
        })
    }

    /// A scan: one epoch. A scan that hears no transmitter of the site is rejected, and the
    /// listeners also hear `NoSiteCoverage`.
    pub(crate) fn push_scan(&self, scan: &Scan) -> Result<(Position, Arc<Site>), PositioningError> {
        let events = Arc::clone(&self.events);
        self.epoch(|engine| {
            #[cfg(feature = "fault-injection")]
            if scan.timestamp_ns == FAULT_INJECTION_TIMESTAMP_NS {
                panic!("fault injected at timestamp {}", scan.timestamp_ns);
            }
            let result = engine.push_scan(scan);
            if let Err(waymark_engine::InputError::NoKnownTransmitter { .. }) = result {
                events.stage(Event::Status(AppStatus::NoSiteCoverage { timestamp_ns: scan.timestamp_ns }));
            }
            result
        })
    }

    /// A sensor batch given to `push`: how many samples it took. The call succeeds even when
    /// samples were refused for a time too far ahead of the engine's clock, so the listeners
    /// hear of those as an `InputRejected` error (docs/errors.md#timestamps-ahead-of-the-clock).
    pub(crate) fn push_samples(
        &self,
        push: impl FnOnce(&mut Engine) -> waymark_engine::sensors::BatchReport,
    ) -> Result<usize, PositioningError> {
        let events = Arc::clone(&self.events);
        self.call(|engine| {
            let report = push(engine);
            if report.ahead > 0 {
                let reason = format!(
                    "{} sensor samples refused: their time is too far ahead of the engine's clock",
                    report.ahead
                );
                events.stage(Event::Error(PositioningError::InputRejected { reason }));
            }
            Ok(report.accepted)
        })
    }

    /// Input rejected before it reached the engine (a malformed transmitter id): reported to
    /// the listeners as the engine's own rejections are, and returned.
    pub(crate) fn reject(&self, error: PositioningError) -> PositioningError {
        let _hold = super::logging::hold();
        self.events.push(Event::Error(error.clone()));
        self.deliver();
        error
    }

    /// Whether the calling thread is inside a listener call.
    pub(crate) fn on_delivering_thread(&self) -> bool {
        self.events.on_delivering_thread()
    }

    /// The engine, locked, for tests that look at its state. Not for the FFI calls: they go
    /// through [`call`](Self::call).
    #[cfg(feature = "fault-injection")]
    pub(crate) fn lock_engine(&self) -> std::sync::MutexGuard<'_, Engine> {
        lock(&self.engine)
    }

    /// Delivers what was published, oldest first, one thread at a time and with no lock held
    /// ([`Delivery`]). A listener that panics (or whose foreign code throws) is logged and
    /// skipped; the others still hear the event.
    fn deliver(&self) {
        self.events.deliver(|event| {
            deliver_to_app("a listener", || self.listeners.deliver(&event));
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use waymark_engine::sensors::StepLengthModel;
    use waymark_engine::site::{BuildOptions, Calibration, SiteBuilder};

    /// `stepLengthM` / `step_length_m` is honoured on a surveyed site: it replaces the site's
    /// step length model and keeps the rest of its calibration.
    #[test]
    fn a_given_step_length_overrides_the_surveyed_one() {
        let mut b = SiteBuilder::new("one");
        let f = b.floor("G", 0.0);
        b.state(f, nalgebra::Point2::new(0.0, 0.0), vec![]);
        let surveyed_model = StepLengthModel::Weinberg { k: 0.48 };
        let site = b
            .build(BuildOptions::default())
            .unwrap()
            .with_calibration(Calibration { step_length: Some(surveyed_model), ..Calibration::default() })
            .unwrap();
        let config = Options::default().config(&site).unwrap();
        assert_eq!(config.motion_for(&site).step_length, surveyed_model);
        let given = Options { step_length_m: Some(0.82), ..Options::default() }.config(&site).unwrap();
        assert_eq!(given.motion_for(&site).step_length, StepLengthModel::Constant { length_m: 0.82 });
        assert!(given.site_calibration);
        let negative = Options { step_length_m: Some(-0.7), ..Options::default() }.config(&site).unwrap();
        assert!(negative.validate().is_err(), "the engine refuses it as an invalid config");
    }

    /// Listeners that hear nothing.
    struct Deaf;

    impl Listeners for Deaf {
        fn deliver(&self, _: &Event) {}
    }

    /// What a log sink saw: each record the test's thread logged, and whether the engine's
    /// lock was free when the record arrived.
    struct Sink {
        handle: Arc<Handle<Deaf>>,
        thread: std::thread::ThreadId,
        seen: Mutex<Vec<(String, bool)>>,
    }

    impl crate::ffi::logging::LogSink for Sink {
        fn log(&self, _level: crate::ffi::logging::LogLevel, target: String, message: String) {
            let _ = target;
            if std::thread::current().id() == self.thread {
                let unlocked =
                    !matches!(self.handle.engine.try_lock(), Err(std::sync::TryLockError::WouldBlock));
                lock(&self.seen).push((message, unlocked));
            }
        }
    }

    /// Log records made under the engine's lock reach the sink after it is released, so a sink
    /// may call the engine (docs/errors.md#callbacks); a caught panic becomes an `Error` record;
    /// past `MAX_HELD_RECORDS` in one call, records are dropped and counted. One test: the
    /// sink is global.
    #[test]
    fn log_records_reach_the_sink_after_the_lock_is_released() {
        use crate::ffi::logging::{hold, init_logging, LogLevel, MAX_HELD_RECORDS};
        let mut b = SiteBuilder::new("one");
        let f = b.floor("G", 0.0);
        b.state(f, nalgebra::Point2::new(0.0, 0.0), vec![]);
        let site = Arc::new(b.build(BuildOptions::default()).unwrap());
        let handle = Arc::new(Handle::new(site, &Options::default(), Deaf).unwrap());
        let sink = Arc::new(Sink {
            handle: Arc::clone(&handle),
            thread: std::thread::current().id(),
            seen: Mutex::new(Vec::new()),
        });
        init_logging(Some(sink.clone()), LogLevel::Debug);

        assert!(handle.push_scan(&Scan { timestamp_ns: 5, readings: vec![] }).is_err());
        assert!(handle.call(|_| -> Result<(), _> { panic!("panic inside the lock") }).is_err());
        assert_eq!(lock(&sink.seen).len(), 2);
        let call = hold();
        for k in 0..MAX_HELD_RECORDS + 3 {
            log::debug!(target: "waymark::held_cap", "record {k}");
        }
        let held = lock(&sink.seen).len();
        drop(call);
        assert_eq!(held, 2, "held until the call ends");
        init_logging(None, LogLevel::Error);

        let seen = std::mem::take(&mut *lock(&sink.seen));
        assert!(seen.iter().all(|(_, unlocked)| *unlocked), "a record arrived under the lock: {seen:?}");
        assert!(seen[0].0.starts_with("scan rejected"), "{:?}", seen[0]);
        assert!(seen[1].0.starts_with("Waymark panicked at src/ffi/handle.rs"), "{:?}", seen[1]);
        assert_eq!(seen.len(), 2 + MAX_HELD_RECORDS + 1);
        assert_eq!(seen[2 + MAX_HELD_RECORDS - 1].0, format!("record {}", MAX_HELD_RECORDS - 1));
        assert!(seen.last().unwrap().0.starts_with("3 log records dropped"), "{:?}", seen.last());
    }
}
