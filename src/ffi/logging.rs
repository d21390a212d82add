//! Where the core's `log` records go. On Android, logcat through `android_logger`; elsewhere,
//! an app-provided [`LogSink`] (application-services' log forwarder), so Swift apps can route
//! them to `os_log` without Waymark depending on it.

use std::sync::{Arc, Mutex, OnceLock};

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
#[uniffi::export(with_foreign)]
pub trait LogSink: Send + Sync {
    /// One record: its level, the Rust module it came from, and the message.
    fn log(&self, level: LogLevel, target: String, message: String);
}

/// The sink records go to; replaced by each `init_logging`.
static SINK: Mutex<Option<Arc<dyn LogSink>>> = Mutex::new(None);
static INSTALLED: OnceLock<()> = OnceLock::new();

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
        let sink = SINK.lock().ok().and_then(|s| s.clone());
        if let Some(sink) = sink {
            // The lock is released before calling foreign code.
            sink.log(
                LogLevel::from_level(record.level()),
                record.target().to_owned(),
                record.args().to_string(),
            );
        }
    }

    fn flush(&self) {}
}

/// Sends Waymark's log records at `level` and above to `sink` (on Android, with no sink, to
/// logcat under the tag "waymark"). Safe to call again: the latest sink and level win.
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
