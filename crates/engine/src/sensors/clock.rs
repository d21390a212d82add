//! Input sanity for timestamps (docs/errors.md#timestamps-ahead-of-the-clock): one input with a
//! time far in the future must not become the clock every later input is "out of order" against.

/// The latest time any input may carry: `i64::MAX` ns (292 years of uptime). Phones keep time
/// as signed 64-bit ns (Android's `SensorEvent.timestamp` and `elapsedRealtimeNanos()` are
/// `long`s), so a larger time is a negative one passed as unsigned, e.g. a Kotlin `Long` as
/// `ULong`.
pub const MAX_TIMESTAMP_NS: u64 = i64::MAX as u64;

/// Whether a sample of a stream at `t_ns` is refused as too far ahead of the clock: after
/// [`MAX_TIMESTAMP_NS`]; or more than `bound_ns` after `clock_ns`, the latest time of the input
/// taken so far, unless it confirms a jump: it follows `jump_ns`, the time of the stream's
/// previous refused sample, by no more than `bound_ns`. Two samples in a row far ahead are the
/// clock having really moved on (the phone slept); one alone is a bad time.
pub(crate) fn refuse_ahead(t_ns: u64, clock_ns: Option<u64>, bound_ns: u64, jump_ns: Option<u64>) -> bool {
    if t_ns > MAX_TIMESTAMP_NS {
        return true;
    }
    let Some(clock_ns) = clock_ns else { return false };
    if t_ns <= clock_ns.saturating_add(bound_ns) {
        return false;
    }
    !jump_ns.is_some_and(|jump| t_ns > jump && t_ns - jump <= bound_ns)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_time_far_ahead_is_refused_unless_the_next_one_confirms_it() {
        let s = 1_000_000_000;
        assert!(!refuse_ahead(5 * s, None, 10 * s, None), "the first input sets the clock");
        assert!(refuse_ahead(u64::MAX - 8, None, 10 * s, None), "a negative time, as unsigned");
        assert!(refuse_ahead(MAX_TIMESTAMP_NS + 1, Some(MAX_TIMESTAMP_NS), 10 * s, None));
        assert!(!refuse_ahead(15 * s, Some(5 * s), 10 * s, None), "within the bound");
        assert!(refuse_ahead(16 * s, Some(5 * s), 10 * s, None), "beyond it");
        assert!(!refuse_ahead(16 * s + 1, Some(5 * s), 10 * s, Some(16 * s)), "a confirmed jump");
        assert!(refuse_ahead(16 * s, Some(5 * s), 10 * s, Some(16 * s)), "not after the refused time");
        assert!(refuse_ahead(27 * s, Some(5 * s), 10 * s, Some(16 * s)), "too far after it");
    }
}
