//! Simulated walks as recorded traces: a phone's IMU along a route, with the waypoints a
//! surveyor would have tapped, in the trace format `waymark_survey` reads.

use crate::imu::{synthesize, ImuConfig};
use crate::Trajectory;
use nalgebra::Point2;
use waymark_survey::io::ilc::{Trace, Waypoint};

/// Walking pace of the simulated walks, m/s.
pub const SPEED_MPS: f64 = 1.2;

/// A phone at 50 Hz held by a walker of fixed cadence 1.8 Hz (step 1.2 / 1.8 = 0.667 m),
/// pointing where the walker goes, the site's +y `site_rotation_rad` from true north,
/// declination `declination_rad`.
pub fn imu(site_rotation_rad: f64, declination_rad: f64) -> ImuConfig {
    ImuConfig {
        yaw_offset_rad: 0.0,
        rate_hz: 50.0,
        cadence_hz: (1.8, 1.8),
        site_rotation_rad,
        declination_rad,
        ..ImuConfig::default()
    }
}

/// The walk along `points` as a trace whose waypoints are the vertices `labelled` (their
/// coordinates times `scale`, at the times the walker passes them), and the true number of
/// steps between the first and last of them.
pub fn walk(
    points: &[(f64, f64)],
    labelled: &[usize],
    scale: f64,
    imu: &ImuConfig,
    seed: u64,
) -> (Trace, usize) {
    let route: Vec<Point2<f64>> = points.iter().map(|&(x, y)| Point2::new(x, y)).collect();
    let trajectory = Trajectory::new(5_000_000_000, SPEED_MPS, &route, Vec::new());
    let sim = synthesize(&trajectory, imu, seed);
    let mut walked = 0.0;
    let mut times = vec![trajectory.start_ns()];
    for w in route.windows(2) {
        walked += nalgebra::distance(&w[0], &w[1]);
        times.push(trajectory.start_ns() + (walked / SPEED_MPS * 1e9) as u64);
    }
    let waypoints: Vec<Waypoint> = labelled
        .iter()
        .map(|&k| Waypoint {
            timestamp_ns: times[k],
            x: scale * points[k].0,
            y: scale * points[k].1,
            floor: None,
        })
        .collect();
    let steps = match (waypoints.first(), waypoints.last()) {
        (Some(a), Some(b)) => {
            sim.true_step_times_ns.iter().filter(|&&t| t >= a.timestamp_ns && t <= b.timestamp_ns).count()
        }
        _ => 0,
    };
    let trace = Trace {
        name: format!("sim{seed}"),
        waypoints,
        accelerometer: sim.accelerometer,
        gyroscope: sim.gyroscope,
        magnetometer: sim.magnetometer,
        ..Trace::default()
    };
    (trace, steps)
}
