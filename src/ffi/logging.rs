//! Where the core's `log` records go. On Android, logcat through `android_logger`; elsewhere,
//! an app-provided [`LogSink`] (application-services' log forwarder), so Swift apps can route
//! them to `os_log` without Waymark depending on it.
//!
//! A record logged on a thread inside a Waymark call is held on that thread and handed to the
//! sink when the call's outermost FFI frame ends, after every lock of Waymark's is released
//! (`hold`; docs/errors.md#callbacks): a sink may call the engine, and a slow sink slows only
//! the thread it runs on. The same frame keeps panics it catches off the host's stderr
//! (`install_panic_hook`).

use std::cell::RefCell;
use std::collections::VecDeque;
use std::sync::{Arc, Mutex, Once, OnceLock};

/// Severity of a log record.
#[derive(Clone, Copy, Debug, PartialEq, Eq, uniffi::Enum)]
pub enum LogLevel {
    /// Something failed.
    Error,
    /// Something unexpected (a dropped input, a filter restart).
    Warn,
    /// Lifecycle.
    Info,
    /// Per-epoch detail.
    Debug,
    /// Everything.
    Trace,
}

impl LogLevel {
    fn filter(self) -> log::LevelFilter {
        match self {
            LogLevel::Error => log::LevelFilter::Error,
            LogLevel::Warn => log::LevelFilter::Warn,
            LogLevel::Info => log::LevelFilter::Info,
            LogLevel::Debug => log::LevelFilter::Debug,
            LogLevel::Trace => log::LevelFilter::Trace,
        }
    }

    fn from_level(level: log::Level) -> Self {
        match level {
            log::Level::Error => LogLevel::Error,
            log::Level::Warn => LogLevel::Warn,
            log::Level::Info => LogLevel::Info,
            log::Level::Debug => LogLevel::Debug,
            log::Level::Trace => LogLevel::Trace,
        }
    }
}

/// Receives Waymark's log records (implemented in Kotlin or Swift).
///
/// Called on the thread that logged, after the Waymark call it logged in has released its
/// locks and just before that call returns (a record logged outside any call: at once),
/// possibly on several threads at once. It may call the engine or close it; the records its
/// own calls make are delivered after it returns. See docs/errors.md#callbacks.
#[uniffi::export(with_foreign)]
pub trait LogSink: Send + Sync {
    /// One record: its level, the Rust module it came from, and the message.
    fn log(&self, level: LogLevel, target: String, message: String);
}

/// The sink records go to; replaced by each `init_logging`.
static SINK: Mutex<Option<Arc<dyn LogSink>>> = Mutex::new(None);
static INSTALLED: OnceLock<()> = OnceLock::new();

/// At most this many records are held during one Waymark call on one thread; later ones are
/// dropped and counted, and the count is delivered as one `Warn` record after the held ones.
pub const MAX_HELD_RECORDS: usize = 1000;

/// A record waiting for the sink.
struct Record {
    level: LogLevel,
    target: String,
    message: String,
}

/// The calling thread's held records.
#[derive(Default)]
struct Held {
    /// How many [`Hold`]s are alive on this thread: it is inside that many Waymark frames.
    depth: usize,
    /// The records are being handed to the sink (by [`flush`], further up this thread's stack).
    flushing: bool,
    records: VecDeque<Record>,
    /// Records dropped past [`MAX_HELD_RECORDS`], not yet reported.
    dropped: usize,
}

thread_local! {
    static HELD: RefCell<Held> = RefCell::new(Held::default());
}

/// While alive, the calling thread is inside a Waymark call: records it logs are held, and a
/// panic is reported as a log record instead of on stderr. Dropping the outermost one hands
/// the held records to the sink. Not `Send`: it belongs to the thread that made it.
pub(crate) struct Hold {
    _not_send: std::marker::PhantomData<*const ()>,
}

/// Marks the calling thread as inside a Waymark call until the returned guard drops. Take it
/// before any of Waymark's locks, so that it drops after they are released.
pub(crate) fn hold() -> Hold {
    install_panic_hook();
    // On a thread whose thread-locals are being destroyed nothing is held: records go to the
    // sink at once, as before there was a hold.
    let _ = HELD.try_with(|h| h.borrow_mut().depth += 1);
    Hold { _not_send: std::marker::PhantomData }
}

impl Hold {
    /// Whether dropping this guard will call the sink: it is the outermost and records wait.
    pub(crate) fn will_flush(&self) -> bool {
        HELD.try_with(|h| {
            let h = h.borrow();
            h.depth == 1 && !h.flushing && (!h.records.is_empty() || h.dropped > 0)
        })
        .unwrap_or(false)
    }
}

impl Drop for Hold {
    fn drop(&mut self) {
        let outermost = HELD
            .try_with(|h| {
                let mut h = h.borrow_mut();
                h.depth = h.depth.saturating_sub(1);
                h.depth == 0 && !h.flushing
            })
            .unwrap_or(false);
        if outermost {
            flush();
        }
    }
}

/// Hands the held records to the sink, oldest first, with no borrow of them kept while the
/// sink runs: records the sink causes (it called the engine) join the queue and are handed
/// over by this same loop, after the sink returns, instead of recursing into it.
fn flush() {
    let _ = HELD.try_with(|h| h.borrow_mut().flushing = true);
    loop {
        let next = HELD.try_with(|h| {
            let mut h = h.borrow_mut();
            h.records.pop_front().or_else(|| {
                let dropped = std::mem::take(&mut h.dropped);
                (dropped > 0).then(|| Record {
                    level: LogLevel::Warn,
                    target: module_path!().to_owned(),
                    message: format!(
                        "{dropped} log records dropped: more than {MAX_HELD_RECORDS} in one Waymark call"
                    ),
                })
            })
        });
        match next {
            Ok(Some(record)) => send(record),
            _ => break,
        }
    }
    let _ = HELD.try_with(|h| h.borrow_mut().flushing = false);
}

/// Calls the sink, if there is one, with no lock held. A sink that panics (or whose foreign
/// code throws) loses that record; the call that logged it is not affected.
fn send(record: Record) {
    let sink = SINK.lock().ok().and_then(|s| s.clone());
    if let Some(sink) = sink {
        // Not `deliver_to_app`: a sink that fails cannot be told so through itself.
        let _ = super::panic::guard(|| sink.log(record.level, record.target, record.message));
    }
}

/// Holds `record` if the calling thread is inside a Waymark call (or handing records over);
/// gives it back otherwise.
fn held(record: Record) -> Option<Record> {
    let mut record = Some(record);
    let _ = HELD.try_with(|h| {
        let Ok(mut h) = h.try_borrow_mut() else { return };
        if h.depth > 0 || h.flushing {
            if h.records.len() < MAX_HELD_RECORDS {
                h.records.extend(record.take());
            } else {
                record = None;
                h.dropped += 1;
            }
        }
    });
    record
}

/// Whether the calling thread is inside a Waymark call, so that a panic on it will be caught.
fn inside_call() -> bool {
    HELD.try_with(|h| h.try_borrow().is_ok_and(|h| h.depth > 0)).unwrap_or(false)
}

/// Installs, once per process, a panic hook that reports a panic on a thread inside a Waymark
/// call (which the call catches and returns as an error) as an `Error` log record, instead of
/// printing it and a backtrace on the host app's stderr. Any other panic goes to the hook that
/// was installed before, unchanged. An app that installs its own hook later replaces this one.
pub(crate) fn install_panic_hook() {
    static INSTALL: Once = Once::new();
    if std::thread::panicking() {
        return; // `set_hook` may not be called while panicking.
    }
    INSTALL.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !inside_call() {
                return previous(info);
            }
            let payload = info.payload();
            let message = payload
                .downcast_ref::<&str>()
                .copied()
                .or_else(|| payload.downcast_ref::<String>().map(String::as_str))
                .unwrap_or("(no message)");
            match info.location() {
                Some(at) => log::error!("Waymark panicked at {at}: {message}"),
                None => log::error!("Waymark panicked: {message}"),
            }
        }));
    });
}

struct Forwarder;

static FORWARDER: Forwarder = Forwarder;

impl log::Log for Forwarder {
    fn enabled(&self, metadata: &log::Metadata<'_>) -> bool {
        metadata.level() <= log::max_level()
    }

    fn log(&self, record: &log::Record<'_>) {
        if !self.enabled(record.metadata()) {
            return;
        }
        let record = Record {
            level: LogLevel::from_level(record.level()),
            target: record.target().to_owned(),
            message: record.args().to_string(),
        };
        if let Some(record) = held(record) {
            send(record);
        }
    }

    fn flush(&self) {}
}

/// Sends Waymark's log records at `level` and above to `sink` (on Android, with no sink, to
/// logcat under the tag "waymark"). Safe to call again, from a sink too: the latest sink and
/// level win. A record logged inside a Waymark call reaches the sink when that call has
/// released its locks (docs/errors.md#callbacks).
#[uniffi::export]
pub fn init_logging(sink: Option<Arc<dyn LogSink>>, level: LogLevel) {
    log::set_max_level(level.filter());
    #[cfg(target_os = "android")]
    if sink.is_none() {
        android_logger::init_once(
            android_logger::Config::default().with_max_level(level.filter()).with_tag("waymark"),
        );
        return;
    }
    if let Ok(mut current) = SINK.lock() {
        *current = sink;
    }
    INSTALLED.get_or_init(|| {
        // Fails only if the app installed another `log` logger first; then that one gets the
        // records, which is what the app wanted.
        let _ = log::set_logger(&FORWARDER);
    });
    log::set_max_level(level.filter());
}
