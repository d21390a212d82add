//! Synthetic raw inertial sensors for a simulated walk: what a phone held flat in front of a
//! walker would report. The walker's body follows a [`Trajectory`](crate::Trajectory) and
//! turns at a limited rate; the phone's attitude (yaw offset from the walking direction, slow
//! tilt wobble, sway with the steps) gives gravity and the Earth's field in the phone's frame
//! and, by differentiating the attitude, the gyroscope. Steps add a vertical bounce, a forward
//! surge and a lateral sway at the cadence. Steel adds local fields. Sensors are sampled at
//! their own jittered instants with noise and bias. Also: a phone lying still, and a phone
//! shaken in place.
//!
//! Frames: the site frame has x and y in the floor plan and z up; the phone frame is Android's
//! (x right, y to the top edge, z out of the screen). An attitude maps phone to site vectors.

use nalgebra::{Point2, Vector3};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use std::f64::consts::PI;
use waymark_engine::sensors::SensorSample;

mod still;
mod walk;

pub use still::{lying_still, shaken_in_place};
pub use walk::synthesize;

/// Standard gravity, m/s² (the simulator's Earth).
const GRAVITY: f64 = 9.80665;
/// The kinematics are integrated on this grid, ns.
const GRID_NS: u64 = 1_000_000;
/// Attitude is differentiated over ±this, s, for the gyroscope.
const DIFF_S: f64 = 5e-5;

/// Extra magnetic field near steel (a pillar, a lift, a radiator).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MagneticDisturbance {
    /// Centre, site frame, m.
    pub centre: Point2<f64>,
    /// Beyond this distance there is no extra field, m.
    pub radius_m: f64,
    /// Extra field at the centre in the site frame (x, y, up), µT; it falls off smoothly as
    /// (1 − (d/r)²)² towards the radius.
    pub field_ut: [f64; 3],
}

/// How the synthetic phone senses.
#[derive(Clone, Debug, PartialEq)]
pub struct ImuConfig {
    /// Sampling rate of every sensor, Hz. Default 100 (Android's `SENSOR_DELAY_GAME` is 50,
    /// `FASTEST` 100-500).
    pub rate_hz: f64,
    /// Timestamp jitter as a fraction of the sampling period: each sample is taken at its
    /// nominal instant ± `jitter`/2 periods, uniformly. Default 0.2. At most 0.9.
    pub jitter: f64,
    /// Gaps (the OS not delivering) per minute of each stream. Default 0.
    pub gaps_per_minute: f64,
    /// Length of each gap, s. Default 0.3.
    pub gap_s: f64,
    /// Whether the phone has an accelerometer. Default true.
    pub accelerometer: bool,
    /// Whether the phone has a gyroscope. Default true.
    pub gyroscope: bool,
    /// Whether the phone has a magnetometer. Default true.
    pub magnetometer: bool,
    /// White noise of each accelerometer axis, m/s². Default 0.05 (phone IMUs: 0.01-0.05 at
    /// 100 Hz, more in a hand).
    pub accel_noise_mps2: f64,
    /// Standard deviation of each axis's constant bias, m/s² (drawn per trace). Default 0.05.
    pub accel_bias_mps2: f64,
    /// White noise of each gyroscope axis, rad/s. Default 0.004.
    pub gyro_noise_radps: f64,
    /// Standard deviation of each axis's constant bias, rad/s. Default 0.005 (0.3°/s, left
    /// after the platform's calibration).
    pub gyro_bias_radps: f64,
    /// White noise of each magnetometer axis, µT. Default 0.5.
    pub mag_noise_ut: f64,
    /// Total intensity of the Earth's field, µT. Default 52 (southern Finland, where HIPE was
    /// measured; World Magnetic Model, approximate).
    pub earth_field_ut: f64,
    /// Inclination of the Earth's field, rad, positive downwards. Default 75° (as above).
    pub dip_rad: f64,
    /// Declination, rad, positive east. Default 7°43′ (HIPE §5.1, Helsinki 2012).
    pub declination_rad: f64,
    /// True azimuth of the site's +y axis, rad. Default 0.
    pub site_rotation_rad: f64,
    /// Local fields near steel. Default none.
    pub disturbances: Vec<MagneticDisturbance>,
    /// Amplitude of the slow pitch and roll wobble of the hand-held phone, rad. Default 3°.
    pub tilt_wobble_rad: f64,
    /// Largest misalignment between where the phone points and where the walker goes, rad
    /// (constant per trace, plus a slow wobble of half of it). Default 4°.
    pub yaw_offset_rad: f64,
    /// Range of walking cadence, Hz (one per trace, ±2 % from step to step). Default 1.5-2.2
    /// (MacDougall & Moore 2005: 2 ± 0.13 Hz).
    pub cadence_hz: (f64, f64),
    /// Range of the vertical bounce amplitude at the phone, m/s² (one per trace, ±15 % per
    /// step). Default 1.5-3.5.
    pub bounce_mps2: (f64, f64),
    /// Fastest the walker turns, rad/s; a 90° turn takes about 0.8 s. Default 150°/s.
    pub max_turn_rate_radps: f64,
    /// Standing still before the walk starts and after it ends, s. Default 3.
    pub standing_s: f64,
}

impl Default for ImuConfig {
    fn default() -> Self {
        let deg = PI / 180.0;
        Self {
            rate_hz: 100.0,
            jitter: 0.2,
            gaps_per_minute: 0.0,
            gap_s: 0.3,
            accelerometer: true,
            gyroscope: true,
            magnetometer: true,
            accel_noise_mps2: 0.05,
            accel_bias_mps2: 0.05,
            gyro_noise_radps: 0.004,
            gyro_bias_radps: 0.005,
            mag_noise_ut: 0.5,
            earth_field_ut: 52.0,
            dip_rad: 75.0 * deg,
            declination_rad: DEFAULT_DECLINATION_RAD,
            site_rotation_rad: 0.0,
            disturbances: Vec::new(),
            tilt_wobble_rad: 3.0 * deg,
            yaw_offset_rad: 4.0 * deg,
            cadence_hz: (1.5, 2.2),
            bounce_mps2: (1.5, 3.5),
            max_turn_rate_radps: 150.0 * deg,
            standing_s: 3.0,
        }
    }
}

/// Magnetic declination of the simulated Earth field: 7°43′ east (HIPE §5.1, Helsinki 2012).
/// The simulated office's site file records the same, as a survey would.
pub const DEFAULT_DECLINATION_RAD: f64 = (7.0 + 43.0 / 60.0) * std::f64::consts::PI / 180.0;

/// Raw samples of a simulated phone and the truth behind them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImuTrace {
    /// Accelerometer samples, m/s², gravity included (empty if the phone has none).
    pub accelerometer: Vec<SensorSample>,
    /// Gyroscope samples, rad/s.
    pub gyroscope: Vec<SensorSample>,
    /// Magnetometer samples, µT.
    pub magnetometer: Vec<SensorSample>,
    /// When each step happened (the peak of its vertical bounce), ns.
    pub true_step_times_ns: Vec<u64>,
    /// The walker's direction of travel (the body, turning at a limited rate) in the site
    /// frame, rad clockwise from +y, every 10 ms.
    pub true_heading: Vec<(u64, f64)>,
}

impl ImuTrace {
    /// The walker's direction of travel at `t_ns` (nearest record), rad clockwise from the
    /// site's +y; `None` for an empty trace.
    pub fn true_heading_at(&self, t_ns: u64) -> Option<f64> {
        let k = self.true_heading.partition_point(|h| h.0 <= t_ns);
        let before = k.checked_sub(1).and_then(|k| self.true_heading.get(k));
        let after = self.true_heading.get(k);
        match (before, after) {
            (Some(a), Some(b)) => Some(if t_ns - a.0 <= b.0 - t_ns { a.1 } else { b.1 }),
            (Some(a), None) => Some(a.1),
            (None, Some(b)) => Some(b.1),
            (None, None) => None,
        }
    }
}

/// Phone-to-site attitude: azimuth (clockwise from +y) of the phone's y axis, then pitch about
/// its x axis, then roll about its y axis.
fn attitude(azimuth: f64, pitch: f64, roll: f64) -> Attitude {
    // Rz(−azimuth) · Rx(pitch) · Ry(roll), multiplied out (the simulator evaluates it three
    // times per gyroscope sample).
    let (sa, ca) = (-azimuth).sin_cos();
    let (sp, cp) = pitch.sin_cos();
    let (sr, cr) = roll.sin_cos();
    Attitude([
        [ca * cr - sa * sp * sr, -sa * cp, ca * sr + sa * sp * cr],
        [sa * cr + ca * sp * sr, ca * cp, sa * sr - ca * sp * cr],
        [-cp * sr, sp, cp * cr],
    ])
}

/// A rotation matrix, phone to site, row-major.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Attitude([[f64; 3]; 3]);

impl Attitude {
    /// A site-frame vector in the phone frame: Rᵀ v.
    fn in_phone(&self, v: Vector3<f64>) -> Vector3<f64> {
        let m = &self.0;
        Vector3::new(
            m[0][0] * v.x + m[1][0] * v.y + m[2][0] * v.z,
            m[0][1] * v.x + m[1][1] * v.y + m[2][1] * v.z,
            m[0][2] * v.x + m[1][2] * v.y + m[2][2] * v.z,
        )
    }

    /// Body angular rate taking `self` to `later` in `dt_s`: R₀ᵀR₁ ≈ I + [ω]× dt, read from
    /// its antisymmetric part (exact to second order in the small rotation).
    fn rate_to(&self, later: &Attitude, dt_s: f64) -> Vector3<f64> {
        let (a, b) = (&self.0, &later.0);
        // (R₀ᵀR₁)[i][j] = Σ_k a[k][i] b[k][j].
        let d = |i: usize, j: usize| (0..3).map(|k| a[k][i] * b[k][j]).sum::<f64>();
        Vector3::new(d(2, 1) - d(1, 2), d(0, 2) - d(2, 0), d(1, 0) - d(0, 1)) / (2.0 * dt_s)
    }
}

/// Something that moves the phone: advanced on a 1 ms grid, then asked about instants inside
/// the current grid cell (or just around it).
trait Motion {
    /// Moves to the grid cell starting at `t_s` (seconds since the trace start).
    fn advance(&mut self, t_s: f64);
    /// Phone-to-site attitude at `t_s`.
    fn attitude(&self, t_s: f64) -> Attitude;
    /// The phone's acceleration in the site frame, gravity excluded, m/s².
    fn acceleration(&self, t_s: f64) -> Vector3<f64>;
    /// Where the phone is, site frame.
    fn position(&self, t_s: f64) -> Point2<f64>;
}

/// The per-trace sensor errors.
struct Errors {
    accel_bias: Vector3<f64>,
    gyro_bias: Vector3<f64>,
    accel: Normal<f64>,
    gyro: Normal<f64>,
    mag: Normal<f64>,
}

fn normal(sigma: f64) -> Normal<f64> {
    Normal::new(0.0, if sigma.is_finite() { sigma.max(0.0) } else { 0.0 })
        .expect("a finite, non-negative sigma")
}

fn noise3(n: &Normal<f64>, rng: &mut ChaCha8Rng) -> Vector3<f64> {
    Vector3::new(n.sample(rng), n.sample(rng), n.sample(rng))
}

/// Sampling instants of one stream over [t0, t1]: nominal rate, jitter, gaps.
fn schedule(config: &ImuConfig, t0_ns: u64, t1_ns: u64, rng: &mut ChaCha8Rng) -> Vec<u64> {
    let period = 1e9 / config.rate_hz.max(1e-3);
    let jitter = if config.jitter.is_finite() { config.jitter.clamp(0.0, 0.9) } else { 0.0 };
    let gap_chance = config.gaps_per_minute.max(0.0) / 60.0 * period * 1e-9;
    let offset = rng.random_range(0.0..period);
    let mut times = Vec::with_capacity(((t1_ns - t0_ns) as f64 / period) as usize + 1);
    let mut gap_until = 0.0;
    for n in 0.. {
        let nominal = offset + n as f64 * period;
        if nominal > (t1_ns - t0_ns) as f64 {
            break;
        }
        let t = nominal + jitter * period * rng.random_range(-0.5..0.5);
        if t < gap_until || t < 0.0 {
            continue;
        }
        if gap_chance > 0.0 && rng.random_range(0.0..1.0) < gap_chance {
            gap_until = t + config.gap_s.max(0.0) * 1e9;
        }
        times.push(t0_ns + t.round() as u64);
    }
    times
}

/// Runs `motion` from `t0_ns` to `t1_ns` and samples the enabled sensors.
fn sample_motion(motion: &mut dyn Motion, config: &ImuConfig, t0_ns: u64, t1_ns: u64, seed: u64) -> ImuTrace {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_0f5e_4504);
    let errors = Errors {
        accel_bias: noise3(&normal(config.accel_bias_mps2), &mut rng),
        gyro_bias: noise3(&normal(config.gyro_bias_radps), &mut rng),
        accel: normal(config.accel_noise_mps2),
        gyro: normal(config.gyro_noise_radps),
        mag: normal(config.mag_noise_ut),
    };
    let enabled = [config.accelerometer, config.gyroscope, config.magnetometer];
    let schedules: Vec<Vec<u64>> = enabled
        .iter()
        .map(|&on| if on { schedule(config, t0_ns, t1_ns, &mut rng) } else { Vec::new() })
        .collect();
    // The Earth's field in the site frame: magnetic north lies at site azimuth
    // declination − site rotation.
    let north = config.declination_rad - config.site_rotation_rad;
    let horizontal = config.earth_field_ut * config.dip_rad.cos();
    let earth = Vector3::new(
        horizontal * north.sin(),
        horizontal * north.cos(),
        -config.earth_field_ut * config.dip_rad.sin(),
    );
    let mut out: [Vec<SensorSample>; 3] = Default::default();
    for (k, s) in schedules.iter().enumerate() {
        out[k].reserve(s.len());
    }
    let mut cursor = [0usize; 3];
    let mut cell = t0_ns;
    while cell <= t1_ns {
        let cell_s = (cell - t0_ns) as f64 * 1e-9;
        motion.advance(cell_s);
        let cell_end = cell + GRID_NS;
        for stream in 0..3 {
            while let Some(&t_ns) = schedules[stream].get(cursor[stream]) {
                if t_ns >= cell_end {
                    break;
                }
                cursor[stream] += 1;
                let t = (t_ns - t0_ns) as f64 * 1e-9;
                let r = motion.attitude(t);
                let v = match stream {
                    0 => {
                        let specific = motion.acceleration(t) + Vector3::new(0.0, 0.0, GRAVITY);
                        r.in_phone(specific) + errors.accel_bias + noise3(&errors.accel, &mut rng)
                    }
                    1 => {
                        let (r0, r1) = (motion.attitude(t - DIFF_S), motion.attitude(t + DIFF_S));
                        let w = r0.rate_to(&r1, 2.0 * DIFF_S);
                        w + errors.gyro_bias + noise3(&errors.gyro, &mut rng)
                    }
                    _ => {
                        let p = motion.position(t);
                        let mut field = earth;
                        for d in &config.disturbances {
                            let x = nalgebra::distance(&p, &d.centre) / d.radius_m.max(1e-9);
                            if x < 1.0 {
                                let w = (1.0 - x * x).powi(2);
                                field += Vector3::from(d.field_ut) * w;
                            }
                        }
                        r.in_phone(field) + noise3(&errors.mag, &mut rng)
                    }
                };
                out[stream].push(SensorSample { timestamp_ns: t_ns, x: v.x, y: v.y, z: v.z });
            }
        }
        cell = cell_end;
    }
    let [accelerometer, gyroscope, magnetometer] = out;
    ImuTrace { accelerometer, gyroscope, magnetometer, ..ImuTrace::default() }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Trajectory;
    use approx::assert_relative_eq;
    use waymark_engine::sensors::{compass_azimuth, gyro_yaw_rate, wrap_angle};

    fn quiet() -> ImuConfig {
        ImuConfig {
            accel_noise_mps2: 0.0,
            accel_bias_mps2: 0.0,
            gyro_noise_radps: 0.0,
            gyro_bias_radps: 0.0,
            mag_noise_ut: 0.0,
            ..ImuConfig::default()
        }
    }

    fn square() -> Trajectory {
        let points =
            [Point2::new(0.0, 0.0), Point2::new(0.0, 20.0), Point2::new(20.0, 20.0), Point2::new(20.0, 0.0)];
        Trajectory::new(5_000_000_000, 1.2, &points, vec![(30.0, 4.0)])
    }

    /// The multiplied-out attitude is nalgebra's product, and the rate is its derivative.
    #[test]
    fn attitude_matches_nalgebra() {
        use nalgebra::Rotation3;
        let (a, p, r) = (0.7, -0.3, 0.2);
        let reference = Rotation3::from_axis_angle(&Vector3::z_axis(), -a)
            * Rotation3::from_axis_angle(&Vector3::x_axis(), p)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), r);
        let v = Vector3::new(0.3, -1.2, 9.0);
        assert_relative_eq!(attitude(a, p, r).in_phone(v), reference.inverse() * v, epsilon = 1e-12);
        // Turning about the phone's own z axis at 0.5 rad/s.
        let w = Vector3::new(0.0, 0.0, 0.5);
        let later = reference * Rotation3::from_scaled_axis(w * 1e-4);
        let later = Attitude(std::array::from_fn(|i| std::array::from_fn(|j| later[(i, j)])));
        assert_relative_eq!(attitude(a, p, r).rate_to(&later, 1e-4), w, epsilon = 1e-6);
    }

    #[test]
    fn lying_still_reads_gravity_and_the_earth_field() {
        let c = quiet();
        let trace = lying_still(5.0, &c, 3);
        assert_eq!(trace.accelerometer.len(), trace.gyroscope.len());
        assert!((trace.accelerometer.len() as i64 - 500).abs() <= 1);
        let a = trace.accelerometer[10];
        assert_relative_eq!(a.z, GRAVITY, epsilon = 1e-9);
        let m = trace.magnetometer[10];
        let field = Vector3::new(m.x, m.y, m.z);
        assert_relative_eq!(field.norm(), 52.0, epsilon = 1e-9);
        // The compass reads the phone's azimuth minus the declination (site = true north).
        let g = Vector3::new(a.x, a.y, a.z);
        let z = compass_azimuth(&g, &field).unwrap();
        let truth = trace.true_heading_at(2_000_000_000).unwrap();
        assert_relative_eq!(wrap_angle(z + c.declination_rad - truth), 0.0, epsilon = 1e-9);
        assert!(trace.true_step_times_ns.is_empty());
    }

    /// The synthetic sensors agree with each other: the gyroscope integrates to the change of
    /// the compass heading, and the steps come at the cadence.
    #[test]
    fn walk_is_self_consistent() {
        let c = quiet();
        let t = square();
        let trace = synthesize(&t, &c, 11);
        assert_eq!(trace.accelerometer.len(), trace.magnetometer.len());
        let duration_s = (t.end_ns() - t.start_ns()) as f64 * 1e-9 - 4.0;
        let steps = trace.true_step_times_ns.len() as f64;
        assert!(
            steps > 1.5 * duration_s * 0.95 && steps < 2.2 * duration_s * 1.05,
            "{steps} in {duration_s} s"
        );
        // Integrate the gyroscope's yaw rate and compare with the compass. Gravity's direction
        // is turned by the gyroscope and slowly pulled to the accelerometer, so the hand's sway
        // with the steps is followed: the sensors must agree on the attitude.
        let mut yaw = None;
        let mut previous: Option<(u64, f64)> = None;
        let mut g = Vector3::new(0.0, 0.0, GRAVITY);
        let mut worst: f64 = 0.0;
        for ((a, w), m) in trace.accelerometer.iter().zip(&trace.gyroscope).zip(&trace.magnetometer) {
            let omega = Vector3::new(w.x, w.y, w.z);
            if let Some((t0, _)) = previous {
                g += g.cross(&omega) * ((w.timestamp_ns - t0) as f64 * 1e-9);
            }
            g += (Vector3::new(a.x, a.y, a.z) - g) * 0.002;
            let rate = gyro_yaw_rate(&g, &omega);
            let compass = compass_azimuth(&g, &Vector3::new(m.x, m.y, m.z)).unwrap();
            let y = yaw.get_or_insert(compass);
            if let Some((t0, r0)) = previous {
                *y = wrap_angle(*y + 0.5 * (r0 + rate) * (w.timestamp_ns - t0) as f64 * 1e-9);
            }
            previous = Some((w.timestamp_ns, rate));
            worst = worst.max(wrap_angle(*y - compass).abs());
        }
        // Three 90° turns and 60 m of walking: the integrated gyro stays within a few degrees
        // of the compass (what is left is the forward and sideways acceleration of the steps
        // and turns tilting the estimated gravity, magnified by tan(dip) = 3.7).
        assert!(worst < 4f64.to_radians(), "{}", worst.to_degrees());
        // True heading ends pointing along -y (south in the site), i.e. ±π.
        let end = trace.true_heading_at(t.end_ns()).unwrap();
        assert_relative_eq!(end.abs(), PI, epsilon = 0.01);
    }

    #[test]
    fn shaking_is_strong_and_fast() {
        let trace = shaken_in_place(10.0, &quiet(), 5);
        let peak = trace
            .accelerometer
            .iter()
            .map(|a| (Vector3::new(a.x, a.y, a.z).norm() - GRAVITY).abs())
            .fold(0.0, f64::max);
        assert!(peak > 10.0, "{peak}");
        let spin = trace.gyroscope.iter().map(|w| Vector3::new(w.x, w.y, w.z).norm()).fold(0.0, f64::max);
        assert!(spin > 2.0, "{spin}");
    }

    #[test]
    fn jitter_and_gaps_keep_timestamps_increasing() {
        let c = ImuConfig { jitter: 0.9, gaps_per_minute: 30.0, rate_hz: 20.0, ..ImuConfig::default() };
        let trace = lying_still(30.0, &c, 1);
        for s in [&trace.accelerometer, &trace.gyroscope, &trace.magnetometer] {
            assert!(s.windows(2).all(|w| w[1].timestamp_ns > w[0].timestamp_ns));
            let gaps = s.windows(2).filter(|w| w[1].timestamp_ns - w[0].timestamp_ns > 200_000_000).count();
            assert!(gaps >= 3, "{gaps}");
        }
        let missing = ImuConfig { gyroscope: false, ..ImuConfig::default() };
        assert!(lying_still(1.0, &missing, 1).gyroscope.is_empty());
    }
}
