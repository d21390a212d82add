//! Issue 7, long runs: a short stretch of the long-run experiment (25 simulated minutes at
//! 100 Hz through the FFI engine and the core engine in lockstep) keeps the engine's accounted
//! memory at its bound, every position finite, and the two engines in agreement. The full day
//! is `waymark simulate --experiment long-run` (README); this runs the same command.

use serde_json::Value;
use std::process::Command;

fn u(v: &Value) -> u64 {
    v.as_u64().unwrap_or_else(|| panic!("not a count: {v}"))
}

#[test]
fn a_short_long_run_keeps_memory_bounded_and_positions_finite() {
    // Seed 21 is used nowhere else; a report every 5 simulated minutes.
    let hours = (25.0f64 / 60.0).to_string();
    let run = Command::new(env!("CARGO_BIN_EXE_waymark"))
        .args(["simulate", "--experiment", "long-run", "--json", "--seed", "21", "--report-every-s", "300"])
        .args(["--hours", &hours])
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", String::from_utf8_lossy(&run.stderr));
    let report: Value = serde_json::from_slice(&run.stdout).expect("one JSON report");
    let intervals = report["intervals"].as_array().unwrap();
    assert_eq!(intervals.len(), 5);
    assert_eq!(u(&report["epochs"]), 750);
    assert_eq!(u(&report["non_finite_positions"]), 0);
    for i in intervals {
        assert_eq!(i["finite_positions"], i["epochs"], "{i}");
        assert_eq!(u(&i["ffi_core_mismatches"]), 0, "{i}");
        // The Viterbi window is full from the first report on and its memory within its bound.
        assert_eq!(i["track_window_epochs"], report["track_window_capacity"], "{i}");
        assert!(u(&i["track_memory_bytes"]) > 0, "{i}");
        assert!(u(&i["track_memory_bytes"]) <= u(&report["track_memory_bound_bytes"]), "{i}");
        // The fixed-lag smoother holds its steps, within its bound.
        assert!(u(&i["fixed_lag_memory_bytes"]) > 0, "{i}");
        assert!(u(&i["fixed_lag_memory_bytes"]) <= u(&report["fixed_lag_memory_bound_bytes"]), "{i}");
        let mean_error_m = i["mean_error_m"].as_f64().unwrap();
        assert!(mean_error_m.is_finite() && mean_error_m < 2.0, "{i}");
    }
    let input = &intervals.last().unwrap()["input"];
    assert_eq!(u(&input["scans_accepted"]), 750);
    assert_eq!(
        [&input["scans_rejected"], &input["samples_dropped"], &input["filter_restarts"]].map(u),
        [0, 0, 0]
    );
    // 25 minutes of three 100 Hz streams, give or take the seams between activities.
    assert!((u(&input["samples_accepted"]) as f64 - 450_000.0).abs() < 2_000.0, "{input}");
    assert!(u(&input["steps"]) > 100, "{input}");
    // A gross leak guard on the process itself: between the first and the last report the
    // resident set may move by what the allocator keeps of the generator's segment buffers,
    // not more. (The day-long figures are in the README.)
    let first = intervals[0]["rss_kb"].as_u64();
    if let (Some(first), Some(last)) = (first, report["rss_end_kb"].as_u64()) {
        let slack_kb = 2 * u(&report["generator_peak_bytes"]) / 1024 + 8 * 1024;
        assert!(last <= first + slack_kb, "RSS {first} kB -> {last} kB (slack {slack_kb} kB)");
    }
}
