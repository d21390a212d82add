//! The library's one panic boundary: every call into the engine (and into Waymark's own code on
//! an app's call) and every call out to app code (a listener, a log sink, a C callback) runs
//! inside [`guard`], so a panic never unwinds into Kotlin, Swift or C, where it would abort.
//!
//! What a caught panic becomes:
//!
//! - **On an app's call into Waymark**, the call's typed error: `PositioningError.Internal`,
//!   `RouteError.Internal`, `SurveyError.Internal`, `WAYMARK_RESULT_PANIC`. A call the engine
//!   undoes (an epoch, a read) leaves it as it was; any other engine call poisons the handle,
//!   so every later call on it fails with `Internal` too (`handle.rs`). What the call staged
//!   for the listeners is dropped.
//! - **On a call out to app code**, that one delivery is dropped: the app's listener, sink or
//!   callback misses the event (a listener's loss is logged at `WARN`), the others still hear
//!   it, and the Waymark call that delivered it is not affected.
//!
//! A panic on a thread inside a Waymark call reaches the log sink as an `ERROR` record, not
//! the app's stderr (`logging::install_panic_hook`).

use std::panic::{catch_unwind, AssertUnwindSafe};

/// A panic caught by [`guard`]; its message went to the log.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Panicked;

/// Runs `f`, catching a panic. Unwind safety is asserted: after a panic the callers either
/// drop what `f` touched, poison it (the engine handle), or only ever read it again through a
/// `Mutex` that recovers from poisoning (`delivery::lock`).
pub(crate) fn guard<T>(f: impl FnOnce() -> T) -> Result<T, Panicked> {
    catch_unwind(AssertUnwindSafe(f)).map_err(|_| Panicked)
}

/// Runs a call into Waymark that returns `Result<T, E>`; a panic becomes the error `internal`
/// makes (the call's typed `Internal`).
pub(crate) fn or_internal<T, E>(
    f: impl FnOnce() -> Result<T, E>,
    internal: impl FnOnce() -> E,
) -> Result<T, E> {
    guard(f).unwrap_or_else(|Panicked| Err(internal()))
}

/// Runs a call out to app code (`who` names it in the log): a panic, or a foreign exception
/// uniffi turned into one, drops this delivery and is logged at `WARN`.
pub(crate) fn deliver_to_app(who: &str, f: impl FnOnce()) {
    if guard(f).is_err() {
        log::warn!("{who} panicked or threw");
    }
}
