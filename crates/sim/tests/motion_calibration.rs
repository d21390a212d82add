//! The survey's motion calibration on simulated phones: the fitted step length and north
//! recover the walker's.

use waymark_engine::sensors::{wrap_angle, MotionConfig, StepLengthModel};
use waymark_sim::recorded::{imu, walk};
use waymark_survey::calibrate_motion;
use waymark_survey::io::Trace;

const L_ROUTE: [(f64, f64); 3] = [(0.0, 0.0), (0.0, 40.0), (30.0, 40.0)];

/// Walks in a site rotated 0.5 rad from true north with a declination of 0.1 rad, read
/// from a tracker told a wrong declination: the fitted offset is the truth's
/// declination − rotation whatever the base says, and the step length is the walker's,
/// despite a walk with one waypoint, one without sensors and one whose waypoints claim
/// three times the distance.
#[test]
fn calibration_recovers_step_length_and_north() {
    let (rotation, declination) = (0.5, 0.1);
    let imu = imu(rotation, declination);
    let mut traces = Vec::new();
    let (mut path, mut true_steps) = (0.0, 0);
    for seed in 1..=3 {
        let (t, n) = walk(&L_ROUTE, &[0, 1, 2], 1.0, &imu, seed);
        path += t.path_length_m();
        true_steps += n;
        traces.push(t);
    }
    traces.push(walk(&L_ROUTE, &[1], 1.0, &imu, 4).0);
    traces.push(Trace { waypoints: traces[0].waypoints.clone(), ..Trace::default() });
    traces.push(walk(&L_ROUTE, &[0, 1, 2], 3.0, &imu, 5).0);
    let refs: Vec<&Trace> = traces.iter().collect();
    let base = MotionConfig { declination_rad: 0.3, ..MotionConfig::default() };
    let c = calibrate_motion(&refs, &base).unwrap();
    assert_eq!(c.walks, 6);
    assert_eq!(c.distance_walks, 3, "{c:?}");
    let truth = path / true_steps as f64;
    let StepLengthModel::Constant { length_m } = c.candidates[0].model else { panic!() };
    assert!((length_m / truth - 1.0).abs() < 0.03, "{length_m} vs {truth}");
    for r in &c.distance_residuals {
        assert!(r.abs() < 0.05, "{c:?}");
    }
    let expected = declination - rotation;
    assert!(wrap_angle(c.heading_offset_rad - expected).abs() < 3f64.to_radians(), "{c:?}");
    let north = c.north();
    assert_eq!(north.declination_rad, 0.0);
    assert!(wrap_angle(north.site_rotation_rad - (rotation - declination)).abs() < 3f64.to_radians());
    let mut config = base.clone();
    c.apply(&mut config);
    assert_eq!(config.step_length, c.step_length);
    assert_eq!((config.declination_rad, config.site_rotation_rad), (0.0, north.site_rotation_rad));
}
