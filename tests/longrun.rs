//! Issue 7, long runs: a short stretch of the long-run experiment (25 simulated minutes at
//! 100 Hz through the FFI engine and the core engine in lockstep) keeps the engine's accounted
//! memory at its bound, every position finite, and the two engines in agreement. The full day
//! is `waymark simulate --experiment long-run` (README).

use waymark_sim::longrun::{self, LongRunConfig};

#[test]
fn a_short_long_run_keeps_memory_bounded_and_positions_finite() {
    // Seed 21 is used nowhere else; a report every 5 simulated minutes.
    let config =
        LongRunConfig { hours: 25.0 / 60.0, seed: 21, report_every_s: 300.0, ..LongRunConfig::default() };
    let report = longrun::run(&config, |_| {}).unwrap();
    assert_eq!(report.intervals.len(), 5);
    assert_eq!(report.epochs, 750);
    assert_eq!(report.non_finite_positions, 0);
    for i in &report.intervals {
        assert_eq!(i.finite_positions, i.epochs, "{i:?}");
        assert_eq!(i.ffi_core_mismatches, 0, "{i:?}");
        // The Viterbi window is full from the first report on and its memory within its bound.
        assert_eq!(i.track_window_epochs, report.track_window_capacity, "{i:?}");
        assert!(i.track_memory_bytes > 0, "{i:?}");
        assert!(i.track_memory_bytes <= report.track_memory_bound_bytes, "{i:?}");
        // The fixed-lag smoother holds its steps, within its bound.
        assert!(i.fixed_lag_memory_bytes > 0, "{i:?}");
        assert!(i.fixed_lag_memory_bytes <= report.fixed_lag_memory_bound_bytes, "{i:?}");
        assert!(i.mean_error_m.is_finite() && i.mean_error_m < 2.0, "{i:?}");
    }
    let input = &report.intervals.last().unwrap().input;
    assert_eq!(input.scans_accepted, 750);
    assert_eq!((input.scans_rejected, input.samples_dropped, input.filter_restarts), (0, 0, 0));
    // 25 minutes of three 100 Hz streams, give or take the seams between activities.
    assert!((input.samples_accepted as f64 - 450_000.0).abs() < 2_000.0, "{input:?}");
    assert!(input.steps > 100, "{input:?}");
    // A gross leak guard on the process itself: between the first and the last report the
    // resident set may move by what the allocator keeps of the generator's segment buffers,
    // not more. (The day-long figures are in the README.)
    let first = report.intervals.first().and_then(|i| i.rss_kb);
    if let (Some(first), Some(last)) = (first, report.rss_end_kb) {
        let slack_kb = (2 * report.generator_peak_bytes / 1024) as u64 + 8 * 1024;
        assert!(last <= first + slack_kb, "RSS {first} kB -> {last} kB (slack {slack_kb} kB)");
    }
}
