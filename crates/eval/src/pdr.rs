//! Pedestrian dead reckoning against recorded walks: how far the tracker says each walk went
//! between its first and last waypoint against the waypoint path length, and its heading
//! while walking against the bearing of the waypoint segment being walked.

use serde::Serialize;
use waymark_engine::sensors::{wrap_angle, MotionConfig};
use waymark_survey::io::ilc::Trace;
use waymark_survey::motion::{replay_steps, segment_at, steps_within, waypoint_span};

/// A segment shorter than this has no meaningful bearing (waypoint labelling error is about
/// a metre), m.
const MIN_SEGMENT_M: f64 = 2.0;

/// How the motion tracker did on test walks.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PdrReport {
    /// Walks scored (at least two waypoints, a non-zero path, an accelerometer).
    pub walks: usize,
    /// Walks not scored.
    pub skipped_walks: usize,
    /// Mean over walks of |steps · length − waypoint path length| / path length, counting
    /// only steps between the first and the last waypoint.
    pub distance_error: f64,
    /// Median over walks of the same.
    pub median_distance_error: f64,
    /// |Σ estimated − Σ true| / Σ true over all walks.
    pub pooled_distance_error: f64,
    /// Σ waypoint path lengths, m.
    pub true_distance_m: f64,
    /// Σ estimated distances, m.
    pub estimated_distance_m: f64,
    /// Walks with no step counted between their first and last waypoint.
    pub zero_step_walks: usize,
    /// RMSE of the heading at each step against the bearing of the waypoint segment (at
    /// least 2 m long) being walked, degrees.
    pub heading_rmse_deg: f64,
    /// Median absolute error of the same, degrees (turns at waypoints weigh less).
    pub heading_median_abs_deg: f64,
    /// Steps with a trusted heading on such a segment.
    pub heading_samples: usize,
    /// Steps counted between the first and last waypoints.
    pub steps: u64,
}

/// Replays every `test` walk through a tracker configured by `config` (calibrated on other,
/// survey walks) and scores it; every figure is NaN when no walk can be scored.
pub fn evaluate_pdr(test: &[&Trace], config: &MotionConfig) -> PdrReport {
    let mut report = PdrReport::default();
    let mut errors = Vec::new();
    let mut heading_errors = Vec::new();
    for trace in test {
        let path = trace.path_length_m();
        let (Some(span), Some(steps)) = (waypoint_span(trace), replay_steps(trace, config)) else {
            report.skipped_walks += 1;
            continue;
        };
        if path <= 0.0 {
            report.skipped_walks += 1;
            continue;
        }
        let (mut n, mut estimated) = (0u64, 0.0);
        for step in steps_within(&steps, span) {
            n += 1;
            estimated += step.length_m;
        }
        report.walks += 1;
        report.steps += n;
        report.zero_step_walks += usize::from(n == 0);
        report.true_distance_m += path;
        report.estimated_distance_m += estimated;
        errors.push((estimated - path).abs() / path);
        for step in &steps {
            let (Some(h), Some((bearing, length, _, _))) =
                (step.heading_rad, segment_at(trace, step.timestamp_ns))
            else {
                continue;
            };
            if length >= MIN_SEGMENT_M {
                heading_errors.push(wrap_angle(h - bearing).to_degrees());
            }
        }
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        match v.len() {
            0 => f64::NAN,
            n if n % 2 == 1 => v[n / 2],
            n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
        }
    };
    report.distance_error = mean(&errors);
    report.median_distance_error = median(&mut errors);
    report.pooled_distance_error = if report.walks > 0 {
        (report.estimated_distance_m - report.true_distance_m).abs() / report.true_distance_m
    } else {
        f64::NAN
    };
    report.heading_samples = heading_errors.len();
    report.heading_rmse_deg = mean(&heading_errors.iter().map(|e| e * e).collect::<Vec<_>>()).sqrt();
    report.heading_median_abs_deg = median(&mut heading_errors.iter().map(|e| e.abs()).collect());
    report
}

#[cfg(test)]
mod tests {
    use super::*;
    use waymark_engine::sensors::StepLengthModel;
    use waymark_sim::recorded::{imu, walk};

    const L_ROUTE: [(f64, f64); 3] = [(0.0, 0.0), (0.0, 40.0), (30.0, 40.0)];
    const LONG_ROUTE: [(f64, f64); 4] = [(0.0, 0.0), (0.0, 40.0), (30.0, 40.0), (30.0, 100.0)];

    /// The tracker told the simulated site's north and the walker's true step length.
    fn config(length_m: f64, north_error_rad: f64) -> MotionConfig {
        let imu = imu(0.5, 0.1);
        MotionConfig {
            step_length: StepLengthModel::Constant { length_m },
            declination_rad: imu.declination_rad,
            site_rotation_rad: imu.site_rotation_rad + north_error_rad,
            ..MotionConfig::default()
        }
    }

    /// Walk A is labelled only on its last leg (30 m of its 70) and claims twice the
    /// distance there (60 m); walk B is 130 m, labelled right. Counting only the steps
    /// between the waypoints, A's error is 1/2 and B's 0: mean 1/4, pooled
    /// |30 + 130 − 190| / 190 = 3/19 (counting all of A's steps would give other figures).
    /// With 10 % longer steps B's error is 10 %.
    #[test]
    fn distance_errors_by_hand() {
        let sim = imu(0.5, 0.1);
        let (a, a_steps) = walk(&L_ROUTE, &[1, 2], 2.0, &sim, 7);
        let (b, b_steps) = walk(&LONG_ROUTE, &[0, 1, 2, 3], 1.0, &sim, 8);
        assert_eq!((a.path_length_m(), b.path_length_m()), (60.0, 130.0));
        // The walker's true step length, so that steps × length is the walked distance.
        let length = (30.0 + 130.0) / (a_steps + b_steps) as f64;
        let r = evaluate_pdr(&[&a, &b], &config(length, 0.0));
        assert_eq!((r.walks, r.skipped_walks, r.zero_step_walks), (2, 0, 0));
        assert!((r.distance_error - 0.25).abs() < 0.03, "{r:?}");
        let pooled = (30.0 + 130.0 - 190.0f64).abs() / 190.0;
        assert!((r.pooled_distance_error - pooled).abs() < 0.03, "{r:?}");
        assert!((r.true_distance_m - 190.0).abs() < 1e-9);
        assert!(r.steps.abs_diff((a_steps + b_steps) as u64) <= 4, "{r:?} {a_steps} {b_steps}");
        let b_only = evaluate_pdr(&[&b], &config(1.1 * length, 0.0));
        assert!((b_only.distance_error - 0.1).abs() < 0.03, "{b_only:?}");
    }

    /// North and east segments: with the site's north right the heading error is a few
    /// degrees; told a north 30° off, it is about 30°.
    #[test]
    fn heading_error_against_segment_bearings() {
        let (trace, _) = walk(&L_ROUTE, &[0, 1, 2], 1.0, &imu(0.5, 0.1), 9);
        let right = evaluate_pdr(&[&trace], &config(0.67, 0.0));
        assert!(right.heading_samples > 60, "{right:?}");
        assert!(right.heading_median_abs_deg < 6.0, "{right:?}");
        assert!(right.heading_rmse_deg < 15.0, "{right:?}");
        let off = evaluate_pdr(&[&trace], &config(0.67, 30f64.to_radians()));
        assert!((off.heading_median_abs_deg - 30.0).abs() < 6.0, "{off:?}");
    }

    #[test]
    fn unscorable_walks_are_skipped() {
        let (one, _) = walk(&L_ROUTE, &[1], 1.0, &imu(0.0, 0.0), 3);
        let bare = Trace { waypoints: one.waypoints.clone(), ..Trace::default() };
        let r = evaluate_pdr(&[&one, &bare], &MotionConfig::default());
        assert_eq!((r.walks, r.skipped_walks), (0, 2));
        assert!(r.distance_error.is_nan() && r.pooled_distance_error.is_nan());
    }
}
