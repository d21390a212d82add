//! The Kotlin and Swift API, through uniffi proc-macros: the engine object, its listeners and
//! the shared site. The records it takes and returns are in `records`; the engine itself is
//! the `Handle` (`handle.rs`) the C API wraps too. A change in this module is a possible breaking change
//! for apps (CHANGELOG, "Breaking changes").

mod geo;
mod geofence;
mod recorder;
mod records;
mod route;

pub use super::error::{ErrorCode, ErrorReport, PositioningError};
#[cfg(feature = "fault-injection")]
pub use super::handle::{FAULT_INJECTION_HABITS_JSON, FAULT_INJECTION_TIMESTAMP_NS};
pub use geo::{FfiGeoError, FfiLatLon, GeoPoint, ZoneOutline};
pub use geofence::{FfiGeofence, FfiGeofenceShape, SitePoint};
pub use recorder::*;
pub use records::*;
pub use route::*;

use super::delivery::lock;
use super::handle::{Event, Handle, Listeners};
use super::panic::deliver_to_app;
use super::record::{AppFixBias, AppHabitReport};
use std::sync::{Arc, Mutex, Weak};
use waymark_engine as engine;
use waymark_engine::site::Site;

/// Waymark's version, as `"0.1.0"`: the version of the Rust library the app bundles.
#[uniffi::export]
pub fn version() -> String {
    env!("CARGO_PKG_VERSION").to_owned()
}

/// Receives positions and status after the engine's lock is released, in the order they
/// happened, on a thread that called the engine (usually the one that pushed the input; while
/// one thread is delivering, input pushed by others is delivered by it). Never called from two
/// threads at once. A listener may call the engine, subscribe and cancel from its methods.
/// Its methods return nothing: an exception thrown from one is caught and logged, and the
/// other listeners still hear the event.
#[uniffi::export(with_foreign)]
pub trait PositionListener: Send + Sync {
    /// A new position.
    fn on_position(&self, position: PositionEstimate);
    /// A status change.
    fn on_status(&self, status: StatusUpdate);
    /// A call failed (it also threw `error`): for apps that push from sensor callbacks and
    /// want failures in one place. Mostly `InputRejected`.
    fn on_error(&self, error: ErrorReport);
}

/// The subscribed listeners, in the order they subscribed.
struct Subscribers {
    list: Mutex<Vec<(u64, Arc<dyn PositionListener>)>>,
    next: Mutex<u64>,
}

impl Listeners for Subscribers {
    /// A listener subscribed during an event hears the events after it; one cancelled during
    /// an event hears nothing more.
    fn deliver(&self, event: &Event) {
        let listeners = lock(&self.list).clone();
        for (id, listener) in &listeners {
            // Cancelled by a callback earlier in this event.
            if !lock(&self.list).iter().any(|(l, _)| l == id) {
                continue;
            }
            deliver_to_app("a position listener", || match event {
                Event::Position(p, site) => listener.on_position(estimate(p, site)),
                Event::Status(s) => listener.on_status(s.into()),
                Event::Error(e) => listener.on_error(e.report()),
            });
        }
    }
}

/// A site file, loaded and checked once, that several engines can share
/// (`PositioningEngine.withSite`): one per user, or a new one per session, without reading the
/// file again or holding it twice in memory.
#[derive(uniffi::Object)]
#[uniffi(name = "Site")]
pub struct FfiSite {
    inner: Arc<Site>,
}

#[uniffi::export(name = "Site")]
impl FfiSite {
    /// A site file's contents: the binary encoding (what an app should ship, see
    /// docs/site-files.md#binary-encoding) or JSON. Throws `InvalidSite` for a file that is not
    /// a valid site.
    #[uniffi::constructor]
    pub fn from_bytes(site: Vec<u8>) -> Result<Arc<Self>, PositioningError> {
        Ok(Arc::new(Self { inner: Arc::new(Site::from_bytes(&site)?) }))
    }

    /// The site file (binary or JSON) at `path`.
    #[uniffi::constructor]
    pub fn from_path(path: String) -> Result<Arc<Self>, PositioningError> {
        Ok(Arc::new(Self { inner: Arc::new(Site::load(&path)?) }))
    }

    /// The names of the site's floors, by floor index.
    pub fn floor_names(&self) -> Vec<String> {
        self.inner.floors().iter().map(|f| f.name.clone()).collect()
    }

    /// The names of the site's zones (rooms, corridors), in the site file's order.
    pub fn zone_names(&self) -> Vec<String> {
        self.inner.zones().iter().map(|z| z.name.clone()).collect()
    }
}

/// The positioning engine. Thread-safe: sensor threads and the scan receiver may call it at
/// once. Create it from a site file; feed it sensor batches and scans with timestamps on one
/// monotonic clock; read positions by polling or by subscribing a listener.
///
/// Every method that fails throws `PositioningException` (Kotlin) or `PositioningError`
/// (Swift): a getter never hides a failure behind an empty or default value.
///
/// Kotlin: a `String` argument holding a lone UTF-16 surrogate (`"\uD800"`, not text) cannot
/// be encoded by uniffi's generated code. In a transmitter id it is replaced by `?` on the way
/// in, so the scan throws `PositioningException.InputRejected`; in a constructor's `siteJson`
/// or `path` it throws `java.nio.charset.CharacterCodingException` (a
/// `MalformedInputException`) before the call reaches Waymark: no engine is made.
#[derive(uniffi::Object)]
pub struct PositioningEngine {
    handle: Handle<Subscribers>,
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
            lock(&engine.handle.listeners().list).retain(|(id, _)| *id != self.id);
        }
    }
}

impl Drop for Subscription {
    fn drop(&mut self) {
        self.cancel();
    }
}

impl PositioningEngine {
    fn create(site: Arc<Site>, options: &EngineOptions) -> Result<Arc<Self>, PositioningError> {
        let subscribers = Subscribers { list: Mutex::new(Vec::new()), next: Mutex::new(0) };
        let handle = Handle::new(site, &options.to_options(), subscribers)?;
        Ok(Arc::new(Self { handle }))
    }

    /// Input rejected before it reached the engine (a malformed transmitter id): reported to
    /// the listeners' `on_error` as the engine's own rejections are.
    fn reject(&self, reason: String) -> PositioningError {
        self.handle.reject(PositioningError::InputRejected { reason })
    }

    fn epoch(
        &self,
        f: impl FnOnce(&mut engine::Engine) -> Result<engine::Epoch, waymark_engine::InputError>,
    ) -> Result<PositionEstimate, PositioningError> {
        let (position, site) = self.handle.epoch(f)?;
        Ok(estimate(&position, &site))
    }

    /// The core engine's state and the last position in FFI form, for tests that check a
    /// failed call changed nothing. Not part of the Kotlin / Swift API: only with the
    /// `fault-injection` feature, which test builds turn on.
    #[cfg(feature = "fault-injection")]
    pub fn snapshot(&self) -> (engine::EngineSnapshot, Option<PositionEstimate>) {
        let engine = self.handle.lock_engine();
        (engine.snapshot(), engine.position().map(|p| estimate(p, engine.site())))
    }
}

#[uniffi::export]
impl PositioningEngine {
    /// An engine on the site file given as JSON text.
    #[uniffi::constructor]
    pub fn new(site_json: String, options: EngineOptions) -> Result<Arc<Self>, PositioningError> {
        let site = Site::from_json(site_json.as_bytes())?;
        Self::create(Arc::new(site), &options)
    }

    /// An engine on a site file's contents: the binary encoding (what an app should ship: it
    /// loads faster and in less memory, docs/site-files.md#binary-encoding) or JSON.
    #[uniffi::constructor]
    pub fn from_site_bytes(site: Vec<u8>, options: EngineOptions) -> Result<Arc<Self>, PositioningError> {
        let site = Site::from_bytes(&site)?;
        Self::create(Arc::new(site), &options)
    }

    /// An engine on the site file (binary or JSON) at `path`.
    #[uniffi::constructor]
    pub fn from_path(path: String, options: EngineOptions) -> Result<Arc<Self>, PositioningError> {
        let site = Site::load(&path)?;
        Self::create(Arc::new(site), &options)
    }

    /// An engine on a site already loaded (`Site.fromBytes`, `Site.fromPath`): several engines
    /// (one per user, or a new one per session) share one site in memory, and none of them
    /// reads or checks the file again.
    #[uniffi::constructor]
    pub fn with_site(site: Arc<FfiSite>, options: EngineOptions) -> Result<Arc<Self>, PositioningError> {
        Self::create(Arc::clone(&site.inner), &options)
    }

    /// Accelerometer samples, oldest first. Bad samples are dropped and counted; returns how
    /// many were taken. Samples whose time is too far ahead of the engine's clock (more than
    /// 10 s after the latest input, unless the stream's next sample confirms the jump, or a
    /// negative `Long` passed as unsigned) are refused, counted in
    /// `InputStats.timestampsAhead` and reported to the listener as an `InputRejected` error.
    pub fn push_accelerometer(&self, batch: Vec<MotionSample>) -> Result<u32, PositioningError> {
        let batch = samples(&batch);
        Ok(self.handle.push_samples(|e| e.push_accelerometer(&batch))? as u32)
    }

    /// Gyroscope samples, oldest first; as `push_accelerometer`.
    pub fn push_gyroscope(&self, batch: Vec<MotionSample>) -> Result<u32, PositioningError> {
        let batch = samples(&batch);
        Ok(self.handle.push_samples(|e| e.push_gyroscope(&batch))? as u32)
    }

    /// Magnetometer samples, oldest first; as `push_accelerometer`.
    pub fn push_magnetometer(&self, batch: Vec<MotionSample>) -> Result<u32, PositioningError> {
        let batch = samples(&batch);
        Ok(self.handle.push_samples(|e| e.push_magnetometer(&batch))? as u32)
    }

    /// Barometer readings, oldest first: floor changes from the height climbed
    /// (docs/accuracy.md#barometer). Readings that are not a pressure (NaN, outside 300-1100
    /// hPa) or not after the previous are dropped and counted in `InputStats.pressureDropped`;
    /// times too far ahead as for `push_accelerometer`. Returns how many were taken.
    pub fn push_pressure(&self, batch: Vec<PressureReading>) -> Result<u32, PositioningError> {
        let batch = pressure_samples(&batch);
        Ok(self.handle.push_samples(|e| e.push_pressure(&batch))? as u32)
    }

    /// A WiFi / BLE scan: one positioning epoch. Push the sensor batches up to the scan's time
    /// first. Returns the new position; a rejected scan throws `InputRejected` and changes
    /// nothing.
    pub fn push_scan(&self, scan: RadioScan) -> Result<PositionEstimate, PositioningError> {
        let core = scan.to_core().map_err(|reason| self.reject(reason))?;
        let (position, site) = self.handle.push_scan(&core)?;
        Ok(estimate(&position, &site))
    }

    /// An epoch without radio, from the motion since the last one: call it on a timer when
    /// scans are rare. Sooner than 2 s after the filter's last step it is held: the position
    /// is the prediction by the motion since, and the next epoch steps over it.
    pub fn advance(&self, timestamp_ns: u64) -> Result<PositionEstimate, PositioningError> {
        self.epoch(|engine| engine.advance(timestamp_ns))
    }

    /// A position from another positioning system (GNSS near an entrance, WiFi RTT, UWB): one
    /// positioning epoch, with the motion since the last one, whose observation is the fix. A
    /// precise fix pulls the estimate to it; a vague one barely moves it. Throws
    /// `InputRejected`, changing nothing, for a time not after the last epoch, a NaN or
    /// infinite coordinate, an accuracy not > 0, an unknown floor, or a fix too far from the
    /// site for its accuracy; and for a latitude/longitude on a site that is not
    /// geo-referenced, or without its floor on a site whose floors have different frames.
    pub fn push_fix(&self, fix: FfiPositionFix) -> Result<PositionEstimate, PositioningError> {
        let core = fix.to_core(&self.handle.site()).map_err(|reason| self.reject(reason))?;
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

    /// Adds a geofence: from the next position on, entering and leaving it reach the
    /// listeners as `StatusUpdate.GeofenceEntered` / `GeofenceExited`, with the hysteresis of
    /// the site's zones; a person already inside is reported as entering. Throws
    /// `InputRejected`, changing nothing, for an empty or taken id, an unknown floor, a shape
    /// that is not finite or has no area, or one that holds no place of the site.
    pub fn add_geofence(&self, geofence: FfiGeofence) -> Result<(), PositioningError> {
        self.handle.call_undoable(|engine| Ok(engine.add_geofence(geofence.into())?))
    }

    /// Removes the geofence `id` (no exit event); `false` if there was none.
    pub fn remove_geofence(&self, id: String) -> Result<bool, PositioningError> {
        self.handle.call_undoable(|engine| Ok(engine.remove_geofence(&id)))
    }

    /// The engine's geofences, in the order they were added.
    pub fn geofences(&self) -> Result<Vec<FfiGeofence>, PositioningError> {
        self.handle.read(|engine| engine.geofences().map(FfiGeofence::from).collect())
    }

    /// The probability of being inside geofence `id` now; `null` / `nil` for no such geofence.
    pub fn geofence_probability(&self, id: String) -> Result<Option<f64>, PositioningError> {
        self.handle.read(|engine| engine.geofence_probability(&id))
    }

    /// Every zone of the site, in the site file's order, with the probability of being in it
    /// now (before the first epoch, its share of the site's states: the prior is uniform).
    /// Empty for a site without zones.
    pub fn zone_posterior(&self) -> Result<Vec<ZoneProbability>, PositioningError> {
        // Both under one lock: a site replaced in between would name other zones.
        let (site, posterior) = self.handle.read(|e| (Arc::clone(e.site()), e.zone_posterior()))?;
        Ok(site
            .zones()
            .iter()
            .zip(posterior)
            .map(|(z, probability)| ZoneProbability { name: z.name.clone(), kind: z.kind, probability })
            .collect())
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
    pub fn learn_habits(&self) -> Result<FfiHabitReport, PositioningError> {
        self.handle.call(|e| match e.learn_habits() {
            Ok(report) => Ok(AppHabitReport::new(&report, e.habits()).into()),
            // Its input is the engine's own history and validated options: a bug.
            Err(err) => Err(PositioningError::internal(format!("learning habits: {err}"))),
        })
    }

    /// The learned habits as versioned JSON (a few kB to a few hundred kB), to store per user
    /// and site and give back to `importHabits` in a later session. An engine that learned
    /// nothing exports an empty model. Throws `Internal` (never an empty string) if the
    /// export failed.
    pub fn export_habits(&self) -> Result<String, PositioningError> {
        self.handle.read(|e| e.export_habits())
    }

    /// Replaces the engine's habits by a model from `exportHabits` on the same site, learning
    /// on from where it left off. Throws `HabitsRejected`, changing nothing, when the JSON
    /// does not parse, is not a habit model, is of a newer layout than this build reads, was
    /// learned on another site or another build of the site file, or holds a value out of
    /// range.
    pub fn import_habits(&self, json: HabitsJson) -> Result<(), PositioningError> {
        self.handle.import_habits(&json.0)
    }

    /// Starts gathering map evidence from this session's scans, for the app to upload to
    /// whoever refits the venue's site (docs/evidence.md#from-a-session): state indices and
    /// hashed transmitter ids, no time and no track (docs/privacy.md#evidence). Discards
    /// what was being gathered.
    pub fn start_evidence(&self) -> Result<(), PositioningError> {
        self.handle.call_undoable(|e| {
            e.start_evidence();
            Ok(())
        })
    }

    /// Stops gathering map evidence and discards what was gathered and not taken.
    pub fn stop_evidence(&self) -> Result<(), PositioningError> {
        self.handle.call_undoable(|e| {
            e.stop_evidence();
            Ok(())
        })
    }

    /// The map evidence gathered since `startEvidence` or the last take, as one walk, its
    /// bytes ready to upload (`waymark evidence merge` reads them); gathering goes on from
    /// nothing. `null` / `nil` when the engine is not gathering.
    pub fn take_evidence(&self) -> Result<Option<FfiSessionEvidence>, PositioningError> {
        let taken = self.handle.call(|e| Ok(e.take_evidence()))?;
        Ok(taken.map(FfiSessionEvidence::from))
    }

    /// Loads `site` (a site refitted from evidence, say) in place of the engine's own without
    /// ending the session (docs/evidence.md#loading-a-refitted-site): with the same states
    /// and zones the position, track and history carry on; otherwise the estimate starts
    /// afresh, keeping the motion, the phone's RSSI offset, the barometer and the geofences.
    /// Returns the evidence gathered on the old site and not taken yet. Throws as
    /// `withSite` does for a site the options do not fit, changing nothing.
    pub fn replace_site(&self, site: Arc<FfiSite>) -> Result<Option<FfiSessionEvidence>, PositioningError> {
        let taken = self.handle.replace_site(Arc::clone(&site.inner))?;
        Ok(taken.map(FfiSessionEvidence::from))
    }

    /// Forgets every learned habit and the fix error (when the user asks, or signs out).
    pub fn clear_habits(&self) -> Result<(), PositioningError> {
        self.handle.call(|e| {
            e.clear_habits();
            Ok(())
        })
    }

    /// The fix error learned so far: zero bias and spread 1 before any fix was learned from.
    /// Throws `Internal` (never a made-up value) if it could not be read.
    pub fn fix_bias(&self) -> Result<FfiFixBias, PositioningError> {
        self.handle.read(|e| AppFixBias::from(e.fix_bias()).into())
    }

    /// What the engine took and refused since it was created, and why.
    pub fn input_stats(&self) -> Result<FfiInputStats, PositioningError> {
        self.handle.read(|e| e.stats().into())
    }

    /// The latest position, if any.
    pub fn position(&self) -> Result<Option<PositionEstimate>, PositioningError> {
        self.handle.read(|e| e.position().map(|p| estimate(p, e.site())))
    }

    /// The most likely recent track, oldest first.
    pub fn track(&self) -> Result<Vec<FfiTrackPoint>, PositioningError> {
        self.handle.read(|e| e.track().iter().map(|p| track_point(p, e.site())).collect())
    }

    /// The fixed-lag position: a few epochs old, but revised by what came after.
    pub fn fixed_lag_position(&self) -> Result<Option<FfiTrackPoint>, PositioningError> {
        self.handle.read(|e| e.fixed_lag_position().as_ref().map(|p| track_point(p, e.site())))
    }

    /// Calls `listener` with every position and status change until the returned subscription
    /// is cancelled or dropped. Listeners run with no lock held, never two calls at once.
    pub fn subscribe(self: Arc<Self>, listener: Arc<dyn PositionListener>) -> Arc<Subscription> {
        let id = {
            let mut next = lock(&self.handle.listeners().next);
            *next += 1;
            *next
        };
        lock(&self.handle.listeners().list).push((id, listener));
        Arc::new(Subscription { engine: Arc::downgrade(&self), id })
    }
}
