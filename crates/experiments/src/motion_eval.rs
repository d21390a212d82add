//! Measured figures of the [`MotionTracker`] on simulated phones ([`waymark_sim::imu`]): step
//! detection at several sampling rates for both detectors, steps counted on a phone lying
//! still or shaken in place (which must be none), and heading error of the fused filter
//! against compass-only and gyro-only tracking on walks past steel. The tracker only ever sees
//! raw samples, pushed in batches ahead of each update as a phone would deliver them.

use nalgebra::{Point2, Vector2};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use serde::Serialize;
use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};
use waymark_engine::sensors::{wrap_angle, MotionConfig, MotionTracker, StepDetectorKind};
use waymark_sim::imu::{lying_still, shaken_in_place, synthesize, ImuConfig, ImuTrace, MagneticDisturbance};
use waymark_sim::Trajectory;

/// What to measure.
#[derive(Clone, Debug, PartialEq)]
pub struct EvalOptions {
    /// Seed of everything (walks, phones, noise).
    pub seed: u64,
    /// Walks per sampling rate (and lying-still and shaken traces per rate).
    pub runs: usize,
    /// Walks past steel for heading.
    pub heading_runs: usize,
    /// Length of each walk, m.
    pub walk_length_m: f64,
    /// Sampling rates for step detection, Hz.
    pub rates_hz: Vec<f64>,
    /// Length of each lying-still and shaken trace, s (one of each per run and rate).
    pub in_place_s: f64,
    /// Steel disturbances placed along each heading walk.
    pub disturbances_per_walk: usize,
    /// Stream gaps per minute in the step-detection traces (irregular delivery).
    pub gaps_per_minute: f64,
    /// The tracker configuration under test; the detector, declination and site rotation are
    /// set per case.
    pub config: MotionConfig,
}

impl EvalOptions {
    /// The defaults of [`evaluate`]: 150 m walks (Hoang §6.1 walks 200 m; shorter keeps the
    /// run count up) at 20, 50, 100 and 200 Hz, 60 s in place, 5 steel objects per walk, one
    /// stream gap a minute.
    pub fn new(seed: u64, runs: usize) -> Self {
        Self {
            seed,
            runs,
            heading_runs: runs,
            walk_length_m: 150.0,
            rates_hz: vec![20.0, 50.0, 100.0, 200.0],
            in_place_s: 60.0,
            disturbances_per_walk: 5,
            gaps_per_minute: 1.0,
            config: MotionConfig::default(),
        }
    }
}

/// Step detection at one rate with one detector, pooled over the walks.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StepDetectionRow {
    /// Sampling rate, Hz.
    pub rate_hz: f64,
    /// The detector.
    pub detector: StepDetectorKind,
    /// True steps.
    pub true_steps: usize,
    /// Steps counted.
    pub counted_steps: usize,
    /// Share of true steps matched by a counted step within ±0.25 s.
    pub detected_share: f64,
    /// Counted steps matching no true step, as a share of true steps.
    pub false_share: f64,
}

/// Steps counted on phones that did not walk, pooled over runs.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InPlaceRow {
    /// Sampling rate, Hz.
    pub rate_hz: f64,
    /// The detector.
    pub detector: StepDetectorKind,
    /// Seconds of each kind of trace.
    pub duration_s: f64,
    /// Steps counted while lying still.
    pub lying_still_steps: u64,
    /// Steps counted while shaken in place.
    pub shaken_steps: u64,
    /// Raw detections rejected by the gait check while shaken.
    pub shaken_rejected: u64,
}

/// Heading error on walks past steel, sampled every 0.5 s while walking.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct HeadingRow {
    /// Walks.
    pub walks: usize,
    /// Samples (per method).
    pub samples: usize,
    /// Gyroscope + compass Kalman filter, RMSE in degrees.
    pub fused_rmse_deg: f64,
    /// Compass only (no gyroscope), RMSE in degrees.
    pub compass_only_rmse_deg: f64,
    /// Gyroscope only, relative heading aligned on the standing start, RMSE in degrees.
    pub gyro_only_rmse_deg: f64,
    /// Share of samples within a steel object's radius.
    pub near_steel_share: f64,
    /// Share of samples the fused tracker flagged the compass as disturbed.
    pub flagged_share: f64,
    /// Share of samples with a trusted (σ ≤ 55°) fused heading.
    pub fused_trusted_share: f64,
    /// Share of samples with a trusted compass-only heading.
    pub compass_trusted_share: f64,
    /// Mean of the fused tracker's reported heading sigma, degrees (to compare with its
    /// RMSE: the sigma should be about as large).
    pub fused_mean_sigma_deg: f64,
    /// Fused RMSE over the samples near steel only, degrees.
    pub fused_near_steel_rmse_deg: f64,
    /// Compass-only RMSE over the samples near steel only, degrees.
    pub compass_near_steel_rmse_deg: f64,
}

/// Everything [`evaluate`] measured.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MotionReport {
    /// The seed.
    pub seed: u64,
    /// Walks per rate.
    pub runs: usize,
    /// Length of each walk, m.
    pub walk_length_m: f64,
    /// Step detection per rate and detector.
    pub step_detection: Vec<StepDetectionRow>,
    /// Steps while lying still and shaken, per rate and detector.
    pub in_place: Vec<InPlaceRow>,
    /// Heading errors.
    pub heading: HeadingRow,
}

/// Measures the tracker on `runs` simulated walks per rate (see [`EvalOptions::new`]).
pub fn evaluate(seed: u64, runs: usize) -> MotionReport {
    evaluate_with(&EvalOptions::new(seed, runs))
}

/// A random walk: straight legs of 4-15 m with turns of ±45°, ±90° or none, at a steady pace
/// of 0.8-1.4 m/s, with two 2-6 s pauses.
pub fn random_walk(rng: &mut ChaCha8Rng, length_m: f64) -> Trajectory {
    let mut heading = rng.random_range(-PI..PI);
    let mut at = Point2::new(0.0, 0.0);
    let mut points = vec![at];
    let mut walked = 0.0;
    while walked < length_m {
        let leg = rng.random_range(4.0..15.0);
        at += Vector2::new(heading.sin(), heading.cos()) * leg;
        points.push(at);
        walked += leg;
        let turns = [-FRAC_PI_2, FRAC_PI_2, -FRAC_PI_4, FRAC_PI_4, 0.0, -FRAC_PI_2, FRAC_PI_2];
        heading = wrap_angle(heading + turns[rng.random_range(0..turns.len())]);
    }
    let pauses = (0..2).map(|_| (rng.random_range(0.1..0.9) * walked, rng.random_range(2.0..6.0))).collect();
    Trajectory::new(10_000_000_000, rng.random_range(0.8..1.4), &points, pauses)
}

/// Steel objects near the walk: centres 0.5-2 m off points of the path, radius 2-4 m, an
/// extra field of 15-40 µT in a random, mostly horizontal direction.
fn steel_along(trajectory: &Trajectory, count: usize, rng: &mut ChaCha8Rng) -> Vec<MagneticDisturbance> {
    let span = (trajectory.end_ns() - trajectory.start_ns()) as f64;
    (0..count)
        .map(|_| {
            let t = trajectory.start_ns() + (rng.random_range(0.05..0.95) * span) as u64;
            let pose = trajectory.pose_at(t);
            let side = if rng.random_range(0.0..1.0) < 0.5 { -1.0 } else { 1.0 };
            let off = rng.random_range(0.5..2.0) * side;
            let normal = Vector2::new(pose.heading_rad.cos(), -pose.heading_rad.sin());
            let direction = Vector2::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0))
                .try_normalize(1e-6)
                .unwrap_or(Vector2::x());
            let strength = rng.random_range(15.0..40.0);
            MagneticDisturbance {
                centre: pose.position + normal * off,
                radius_m: rng.random_range(2.0..4.0),
                field_ut: [
                    strength * direction.x,
                    strength * direction.y,
                    strength * rng.random_range(-0.4..0.4),
                ],
            }
        })
        .collect()
}

/// Pushes a trace's samples into a tracker batch by batch, streams in an arbitrary order.
struct Feeder<'a> {
    trace: &'a ImuTrace,
    cursor: [usize; 3],
    streams: [bool; 3],
}

impl<'a> Feeder<'a> {
    fn new(trace: &'a ImuTrace, streams: [bool; 3]) -> Self {
        Self { trace, cursor: [0; 3], streams }
    }

    /// Pushes every sample up to `until_ns` (magnetometer first, then accelerometer, then
    /// gyroscope).
    fn feed(&mut self, tracker: &mut MotionTracker, until_ns: u64) {
        for stream in [2, 0, 1] {
            let samples = match stream {
                0 => &self.trace.accelerometer,
                1 => &self.trace.gyroscope,
                _ => &self.trace.magnetometer,
            };
            let from = self.cursor[stream];
            let to = from + samples[from..].partition_point(|s| s.timestamp_ns <= until_ns);
            self.cursor[stream] = to;
            if !self.streams[stream] || to == from {
                continue;
            }
            let batch = &samples[from..to];
            match stream {
                0 => tracker.push_accelerometer(batch),
                1 => tracker.push_gyroscope(batch),
                _ => tracker.push_magnetometer(batch),
            };
        }
    }
}

/// Samples are pushed this far ahead of each update, as a phone batches them, ns.
const AHEAD_NS: u64 = 700_000_000;
/// Updates every 1.5 s (Hoang §6.1's epoch) for steps, every 0.5 s for heading.
const STEP_EPOCH_NS: u64 = 1_500_000_000;
const HEADING_EPOCH_NS: u64 = 500_000_000;

fn trace_span(trace: &ImuTrace) -> (u64, u64) {
    let all = [&trace.accelerometer, &trace.gyroscope, &trace.magnetometer];
    let start = all.iter().filter_map(|s| s.first().map(|x| x.timestamp_ns)).min().unwrap_or(0);
    let end = all.iter().filter_map(|s| s.last().map(|x| x.timestamp_ns)).max().unwrap_or(0);
    (start, end)
}

/// Runs a trace through a fresh tracker; returns the counted step times and the number of
/// raw detections the gait check rejected.
fn count_steps(trace: &ImuTrace, config: &MotionConfig) -> (Vec<u64>, u64) {
    let mut tracker = MotionTracker::new(config.clone()).expect("a valid configuration");
    let mut feeder = Feeder::new(trace, [true; 3]);
    let (start, end) = trace_span(trace);
    let mut steps = Vec::new();
    let mut t = start;
    while t < end + 2 * STEP_EPOCH_NS {
        t += STEP_EPOCH_NS;
        feeder.feed(&mut tracker, t + AHEAD_NS);
        let update = tracker.update(t);
        debug_assert_eq!(update.steps as usize, tracker.last_steps().len());
        steps.extend(tracker.last_steps().iter().map(|s| s.timestamp_ns));
    }
    (steps, tracker.stats().rejected_step_candidates)
}

/// Matches counted to true steps in time order, each at most once, within `tolerance_ns`.
fn matched_steps(truth: &[u64], counted: &[u64], tolerance_ns: u64) -> usize {
    let mut next = 0;
    let mut matched = 0;
    for &c in counted {
        while next < truth.len() && truth[next] + tolerance_ns < c {
            next += 1;
        }
        if next < truth.len() && truth[next] <= c + tolerance_ns {
            matched += 1;
            next += 1;
        }
    }
    matched
}

fn rms_deg(errors: &[f64]) -> f64 {
    if errors.is_empty() {
        return f64::NAN;
    }
    (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt().to_degrees()
}

/// Measures the tracker as described by `options`.
pub fn evaluate_with(options: &EvalOptions) -> MotionReport {
    let detectors = [StepDetectorKind::Threshold, StepDetectorKind::PeakZeroCrossing];
    let mut step_detection = Vec::new();
    let mut in_place = Vec::new();
    for (r, &rate_hz) in options.rates_hz.iter().enumerate() {
        let imu = ImuConfig { rate_hz, gaps_per_minute: options.gaps_per_minute, ..ImuConfig::default() };
        let mut rows: Vec<(usize, usize, usize)> = vec![(0, 0, 0); detectors.len()];
        let mut still: Vec<(u64, u64, u64)> = vec![(0, 0, 0); detectors.len()];
        for run in 0..options.runs {
            // The same walks at every rate.
            let mut rng = ChaCha8Rng::seed_from_u64(options.seed.wrapping_mul(1000).wrapping_add(run as u64));
            let trajectory = random_walk(&mut rng, options.walk_length_m);
            let trace = synthesize(&trajectory, &imu, rng.random());
            let phone_seed = rng.random::<u64>() ^ r as u64;
            let lying = lying_still(options.in_place_s, &imu, phone_seed);
            let shaken = shaken_in_place(options.in_place_s, &imu, phone_seed.wrapping_add(1));
            for (d, &detector) in detectors.iter().enumerate() {
                let config = MotionConfig { step_detector: detector, ..options.config.clone() };
                let (counted, _) = count_steps(&trace, &config);
                let matched = matched_steps(&trace.true_step_times_ns, &counted, 250_000_000);
                rows[d].0 += trace.true_step_times_ns.len();
                rows[d].1 += counted.len();
                rows[d].2 += matched;
                still[d].0 += count_steps(&lying, &config).0.len() as u64;
                let (shaken_steps, rejected) = count_steps(&shaken, &config);
                still[d].1 += shaken_steps.len() as u64;
                still[d].2 += rejected;
            }
        }
        for (d, &detector) in detectors.iter().enumerate() {
            let (true_steps, counted_steps, matched) = rows[d];
            let share = |n: usize| if true_steps > 0 { n as f64 / true_steps as f64 } else { f64::NAN };
            step_detection.push(StepDetectionRow {
                rate_hz,
                detector,
                true_steps,
                counted_steps,
                detected_share: share(matched),
                false_share: share(counted_steps - matched),
            });
            in_place.push(InPlaceRow {
                rate_hz,
                detector,
                duration_s: options.in_place_s,
                lying_still_steps: still[d].0,
                shaken_steps: still[d].1,
                shaken_rejected: still[d].2,
            });
        }
    }
    MotionReport {
        seed: options.seed,
        runs: options.runs,
        walk_length_m: options.walk_length_m,
        step_detection,
        in_place,
        heading: heading_errors(options),
    }
}

/// Heading RMSE of fused, compass-only and gyro-only trackers on walks past steel.
fn heading_errors(options: &EvalOptions) -> HeadingRow {
    let mut fused = Vec::new();
    let mut compass = Vec::new();
    let mut gyro = Vec::new();
    let mut fused_near = Vec::new();
    let mut compass_near = Vec::new();
    let (mut near, mut flagged, mut fused_trusted, mut compass_trusted) = (0, 0, 0, 0);
    let mut sigma_sum = 0.0;
    for run in 0..options.heading_runs {
        let mut rng =
            ChaCha8Rng::seed_from_u64(options.seed.wrapping_mul(1000).wrapping_add(500 + run as u64));
        let trajectory = random_walk(&mut rng, options.walk_length_m);
        let site_rotation_rad = rng.random_range(-PI..PI);
        let imu = ImuConfig {
            site_rotation_rad,
            disturbances: steel_along(&trajectory, options.disturbances_per_walk, &mut rng),
            ..ImuConfig::default()
        };
        let trace = synthesize(&trajectory, &imu, rng.random());
        let config = MotionConfig {
            declination_rad: imu.declination_rad,
            site_rotation_rad,
            ..options.config.clone()
        };
        let streams = [[true, true, true], [true, false, true], [true, true, false]];
        let mut trackers: Vec<MotionTracker> = streams
            .iter()
            .map(|_| MotionTracker::new(config.clone()).expect("a valid configuration"))
            .collect();
        let mut feeders: Vec<Feeder> = streams.iter().map(|&s| Feeder::new(&trace, s)).collect();
        let (start, end) = trace_span(&trace);
        // Gyro-only: the offset between the relative heading and the truth, averaged (as a
        // unit vector) while standing before the walk.
        let mut offset = (0.0, 0.0);
        let mut t = start;
        while t < end {
            t += HEADING_EPOCH_NS;
            for (tracker, feeder) in trackers.iter_mut().zip(&mut feeders) {
                feeder.feed(tracker, t + AHEAD_NS);
                tracker.update(t);
            }
            let Some(truth) = trace.true_heading_at(t) else { continue };
            let estimates: Vec<_> = trackers.iter().map(|m| m.heading_estimate()).collect();
            let pose = trajectory.pose_at(t);
            if t < trajectory.start_ns() {
                if let Some(rel) = estimates[2].relative_rad {
                    let d = wrap_angle(truth - rel);
                    offset.0 += d.cos();
                    offset.1 += d.sin();
                }
                continue;
            }
            if pose.speed_mps <= 0.0 {
                continue;
            }
            let (Some(f), Some(c), Some(g)) =
                (estimates[0].heading_rad, estimates[1].heading_rad, estimates[2].relative_rad)
            else {
                continue;
            };
            let is_near =
                imu.disturbances.iter().any(|d| nalgebra::distance(&pose.position, &d.centre) < d.radius_m);
            let (ef, ec) = (wrap_angle(f - truth), wrap_angle(c - truth));
            fused.push(ef);
            compass.push(ec);
            gyro.push(wrap_angle(g + offset.1.atan2(offset.0) - truth));
            if is_near {
                near += 1;
                fused_near.push(ef);
                compass_near.push(ec);
            }
            sigma_sum += estimates[0].sigma_rad.to_degrees();
            flagged += usize::from(estimates[0].compass_disturbed);
            fused_trusted += usize::from(estimates[0].trusted);
            compass_trusted += usize::from(estimates[1].trusted);
        }
    }
    let n = fused.len();
    let share = |k: usize| if n > 0 { k as f64 / n as f64 } else { f64::NAN };
    HeadingRow {
        walks: options.heading_runs,
        samples: n,
        fused_rmse_deg: rms_deg(&fused),
        compass_only_rmse_deg: rms_deg(&compass),
        gyro_only_rmse_deg: rms_deg(&gyro),
        near_steel_share: share(near),
        flagged_share: share(flagged),
        fused_trusted_share: share(fused_trusted),
        compass_trusted_share: share(compass_trusted),
        fused_mean_sigma_deg: if n > 0 { sigma_sum / n as f64 } else { f64::NAN },
        fused_near_steel_rmse_deg: rms_deg(&fused_near),
        compass_near_steel_rmse_deg: rms_deg(&compass_near),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matching_is_one_to_one_within_tolerance() {
        let truth = [1000, 2000, 3000, 4000];
        assert_eq!(matched_steps(&truth, &[1100, 1150, 2900, 5000], 200), 2);
        assert_eq!(matched_steps(&truth, &[], 200), 0);
        assert_eq!(matched_steps(&[], &[1], 200), 0);
    }

    #[test]
    fn random_walks_are_long_enough_and_deterministic() {
        let a = random_walk(&mut ChaCha8Rng::seed_from_u64(3), 50.0);
        let b = random_walk(&mut ChaCha8Rng::seed_from_u64(3), 50.0);
        assert_eq!(a, b);
        assert!(a.length_m() >= 50.0);
    }
}
