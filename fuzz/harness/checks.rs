//! What must hold of everything that leaves the engine, whatever went in. A broken invariant
//! panics, which the fuzzer reports as a crash and the corpus-replay test as a failure.

use waymark as ffi;
use waymark_engine::{Position, TrackPoint};

/// The posterior is a probability distribution: finite, non-negative, summing to 1.
pub fn posterior(p: &[f64], states: usize) {
    assert_eq!(p.len(), states, "posterior length");
    assert!(p.iter().all(|v| v.is_finite() && *v >= 0.0), "posterior has a negative or non-finite value");
    let total: f64 = p.iter().sum();
    assert!((total - 1.0).abs() <= 1e-6, "posterior sums to {total}");
}

/// A core position: finite fields, a known floor, radii > 0 and in order.
pub fn position(p: &Position, floors: usize) {
    assert!(p.floor < floors, "floor {} of {floors}", p.floor);
    assert!(p.x.is_finite() && p.y.is_finite(), "position ({}, {})", p.x, p.y);
    assert!(
        p.floor_probability.is_finite() && (0.0..=1.0 + 1e-9).contains(&p.floor_probability),
        "floor probability {}",
        p.floor_probability
    );
    assert!(p.accuracy_m.is_finite() && p.accuracy_m > 0.0, "accuracy_m {}", p.accuracy_m);
    assert!(
        p.accuracy_95_m.is_finite() && p.accuracy_95_m >= p.accuracy_m,
        "accuracy_95_m {} (68%: {})",
        p.accuracy_95_m,
        p.accuracy_m
    );
    if let Some(h) = p.heading_rad {
        assert!(h.is_finite(), "heading {h}");
        let sigma = p.heading_accuracy_rad.expect("a heading has an accuracy");
        assert!(sigma.is_finite() && sigma >= 0.0, "heading accuracy {sigma}");
    }
    if let Some(e) = p.radio_log_evidence {
        assert!(e.is_finite(), "radio log evidence {e}");
    }
}

/// A smoothed track: existing states, finite coordinates, strictly increasing times.
pub fn track(points: &[TrackPoint], states: usize, floors: usize) {
    for p in points {
        assert!((p.state as usize) < states && p.floor < floors, "track point {p:?}");
        assert!(p.x.is_finite() && p.y.is_finite(), "track point {p:?}");
    }
    assert!(points.windows(2).all(|w| w[0].timestamp_ns < w[1].timestamp_ns), "track times not increasing");
}

/// A position as Kotlin and Swift see it.
pub fn estimate(p: &ffi::PositionEstimate, floor_names: &[String]) {
    let name = floor_names.get(p.floor as usize).unwrap_or_else(|| panic!("floor {}", p.floor));
    assert_eq!(&p.floor_name, name);
    assert!(p.x.is_finite() && p.y.is_finite(), "estimate ({}, {})", p.x, p.y);
    assert!(p.floor_probability.is_finite() && (0.0..=1.0 + 1e-9).contains(&p.floor_probability));
    assert!(p.accuracy_m.is_finite() && p.accuracy_m > 0.0, "accuracy_m {}", p.accuracy_m);
    assert!(p.accuracy_95_m.is_finite() && p.accuracy_95_m >= p.accuracy_m, "accuracy_95_m");
    if let Some(h) = p.heading_deg {
        assert!(h.is_finite(), "heading {h}");
        assert!(p.heading_accuracy_deg.is_some_and(|s| s.is_finite() && s >= 0.0), "heading accuracy");
    }
}

/// FFI track points.
pub fn ffi_track(points: &[ffi::FfiTrackPoint], floors: usize) {
    for p in points {
        assert!((p.floor as usize) < floors && p.x.is_finite() && p.y.is_finite(), "track point {p:?}");
    }
    assert!(points.windows(2).all(|w| w[0].timestamp_ns < w[1].timestamp_ns), "track times not increasing");
}

/// An FFI error that is not a caught panic.
pub fn not_internal(e: &ffi::PositioningError) {
    assert!(!matches!(e, ffi::PositioningError::Internal { .. }), "internal error (a caught panic): {e}");
}
