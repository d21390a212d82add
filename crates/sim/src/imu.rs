//! Synthetic raw inertial sensors for a simulated walk: what a phone held flat in front of a
//! walker would report. The walker's body follows a [`Trajectory`] and turns at a limited rate;
//! the phone's attitude (yaw offset from the walking direction, slow tilt wobble, sway with the
//! steps) gives gravity and the Earth's field in the phone's frame and, by differentiating the
//! attitude, the gyroscope. Steps add a vertical bounce, a forward surge and a lateral sway at
//! the cadence. Steel adds local fields. Sensors are sampled at their own jittered instants
//! with noise and bias. Also: a phone lying still, and a phone shaken in place.
//!
//! Frames: the site frame has x and y in the floor plan and z up; the phone frame is Android's
//! (x right, y to the top edge, z out of the screen). An attitude maps phone to site vectors.

use super::Trajectory;
use nalgebra::{Point2, Vector3};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, Normal};
use std::f64::consts::{PI, TAU};
use waymark_engine::sensors::{wrap_angle, SensorSample};

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

/// A slow wobble: a sum of two sinusoids with random frequencies (0.05-0.3 Hz) and phases.
#[derive(Clone, Copy, Debug)]
struct Wobble([(f64, f64, f64); 2]);

impl Wobble {
    fn new(amplitude: f64, rng: &mut ChaCha8Rng) -> Self {
        let mut part = || (amplitude / 2.0, TAU * rng.random_range(0.05..0.3), rng.random_range(0.0..TAU));
        Wobble([part(), part()])
    }

    fn at(&self, t_s: f64) -> f64 {
        self.0.iter().map(|&(a, w, p)| a * (w * t_s + p).sin()).sum()
    }
}

/// The walker's state at a grid instant.
#[derive(Clone, Copy, Debug, Default)]
struct BodyState {
    t_s: f64,
    /// Body heading (direction of travel) and its rate.
    yaw: f64,
    yaw_rate: f64,
    /// Gait phase: steps at integers.
    phase: f64,
    cadence: f64,
    /// Amplitude of the step waveform (0 standing, 1 walking), low-passed.
    envelope: f64,
    /// Bounce of the current and next step, m/s².
    bounce: (f64, f64),
    speed: f64,
    /// While stopping: the gait phase at which the step under way is complete.
    stop_at: Option<f64>,
}

/// A walk along a trajectory.
struct Walk<'a> {
    trajectory: &'a Trajectory,
    t0_ns: u64,
    walk_start_s: f64,
    max_turn_rate: f64,
    cadence: f64,
    bounce: f64,
    yaw_offset: (f64, Wobble),
    pitch: Wobble,
    roll: Wobble,
    rng: ChaCha8Rng,
    now: BodyState,
    next: BodyState,
    started: bool,
    steps: Vec<u64>,
    heading: Vec<(u64, f64)>,
}

/// Gain of the body's heading follower, 1/s, and its largest angular acceleration, rad/s².
const TURN_GAIN: f64 = 6.0;
const TURN_ACCEL: f64 = 15.0;
/// Time constants of the step envelope when starting and (once the step under way is
/// complete) stopping, s.
const ENVELOPE_START_S: f64 = 0.1;
const ENVELOPE_STOP_S: f64 = 0.08;

impl Walk<'_> {
    fn pose(&self, t_s: f64) -> (f64, f64, Point2<f64>) {
        let t_ns = self.t0_ns.saturating_add((t_s.max(0.0) * 1e9) as u64);
        let pose = self.trajectory.pose_at(t_ns);
        let speed = if t_s >= self.walk_start_s { pose.speed_mps } else { 0.0 };
        (pose.heading_rad, speed, pose.position)
    }

    /// Integrates one grid step from `s`.
    fn step(&mut self, s: BodyState) -> BodyState {
        let dt = GRID_NS as f64 * 1e-9;
        let t = s.t_s + dt;
        let (target, speed, _) = self.pose(t);
        let wanted = (TURN_GAIN * wrap_angle(target - s.yaw)).clamp(-self.max_turn_rate, self.max_turn_rate);
        let yaw_rate = s.yaw_rate + (wanted - s.yaw_rate).clamp(-TURN_ACCEL * dt, TURN_ACCEL * dt);
        let yaw = wrap_angle(s.yaw + 0.5 * (s.yaw_rate + yaw_rate) * dt);
        let moving = speed > 0.0;
        // Stopping completes the step under way: up to the next trough of the bounce.
        let stop_at = if moving {
            None
        } else if s.speed > 0.0 {
            let f = s.phase - s.phase.floor();
            Some(s.phase.floor() + if f < 0.5 { 0.5 } else { 1.5 })
        } else {
            s.stop_at
        };
        let stepping = moving || stop_at.is_some_and(|p| s.phase < p);
        let tau = if stepping { ENVELOPE_START_S } else { ENVELOPE_STOP_S };
        let envelope = s.envelope + (f64::from(u8::from(stepping)) - s.envelope) * (1.0 - (-dt / tau).exp());
        let mut phase = s.phase;
        let mut cadence = s.cadence;
        let mut bounce = s.bounce;
        if moving && s.speed == 0.0 {
            // Starting: mid-step, so the first bounce peak comes half a step later.
            phase = phase.floor() + 0.5;
        }
        if stepping || envelope > 0.05 {
            let advanced = phase + cadence * dt;
            if advanced.floor() > phase.floor() {
                // A bounce peak: a step unless it is the fading end of a stop.
                let at = s.t_s + (advanced.floor() - phase) / cadence;
                if envelope >= 0.5 {
                    self.steps.push(self.t0_ns.saturating_add((at * 1e9).round() as u64));
                }
                let z: f64 = rand_distr::StandardNormal.sample(&mut self.rng);
                cadence = self.cadence * (1.0 + 0.02 * z);
                bounce = (bounce.1, self.bounce * self.rng.random_range(0.85..1.15));
            }
            phase = advanced;
        }
        BodyState { t_s: t, yaw, yaw_rate, phase, cadence, envelope, bounce, speed, stop_at }
    }

    /// State at `t_s` inside the current cell, by the cell's own expansion.
    fn at(&self, t_s: f64) -> BodyState {
        let (a, b) = (&self.now, &self.next);
        let dt = b.t_s - a.t_s;
        let tau = t_s - a.t_s;
        let yaw_accel = (b.yaw_rate - a.yaw_rate) / dt;
        let frac = tau / dt;
        BodyState {
            t_s,
            yaw: a.yaw + a.yaw_rate * tau + 0.5 * yaw_accel * tau * tau,
            yaw_rate: a.yaw_rate + yaw_accel * tau,
            phase: a.phase + (b.phase - a.phase) * frac,
            cadence: a.cadence,
            envelope: a.envelope + (b.envelope - a.envelope) * frac,
            bounce: a.bounce,
            speed: a.speed,
            stop_at: a.stop_at,
        }
    }
}

impl Motion for Walk<'_> {
    fn advance(&mut self, t_s: f64) {
        if !self.started {
            self.started = true;
            let (yaw, _, _) = self.pose(t_s);
            let b = self.bounce;
            self.now = BodyState {
                t_s,
                yaw,
                phase: 0.5,
                cadence: self.cadence,
                bounce: (b, b),
                ..BodyState::default()
            };
        } else {
            self.now = self.next;
        }
        self.next = self.step(self.now);
        let t_ns = self.t0_ns.saturating_add((t_s * 1e9).round() as u64);
        if self.heading.last().is_none_or(|h| t_ns >= h.0 + 10_000_000) {
            self.heading.push((t_ns, self.now.yaw));
        }
    }

    fn attitude(&self, t_s: f64) -> Attitude {
        let s = self.at(t_s);
        let sway = s.envelope * (PI * s.phase).sin();
        let nod = s.envelope * (TAU * s.phase).sin();
        let azimuth = s.yaw + self.yaw_offset.0 + self.yaw_offset.1.at(t_s);
        let pitch = self.pitch.at(t_s) + 0.5f64.to_radians() * nod;
        let roll = self.roll.at(t_s) + 1.5f64.to_radians() * sway;
        attitude(azimuth, pitch, roll)
    }

    fn acceleration(&self, t_s: f64) -> Vector3<f64> {
        let s = self.at(t_s);
        // The step's bounce amplitude moves from this step's to the next one's.
        let frac = s.phase - s.phase.floor();
        let amplitude = s.envelope * (s.bounce.0 + (s.bounce.1 - s.bounce.0) * frac);
        let p = TAU * s.phase;
        let vertical = amplitude * (p.cos() + 0.25 * (2.0 * p - 0.6).cos());
        let forward = 0.35 * amplitude * (p - 0.4).sin();
        let lateral = 0.25 * amplitude * (0.5 * p).sin();
        let (sin, cos) = s.yaw.sin_cos();
        let ahead = Vector3::new(sin, cos, 0.0);
        let right = Vector3::new(cos, -sin, 0.0);
        // Turning: centripetal acceleration towards the inside of the turn, at about half
        // pace (people slow down in sharp turns).
        let centripetal = 0.5 * s.speed * s.yaw_rate;
        ahead * forward + right * (lateral + centripetal) + Vector3::new(0.0, 0.0, vertical)
    }

    fn position(&self, t_s: f64) -> Point2<f64> {
        self.pose(t_s).2
    }
}

/// A phone lying still on a table, or held and shaken.
struct InPlace {
    azimuth: f64,
    shake: Option<Shake>,
}

/// Vigorous shaking: bursts of 2-6 s at a frequency wandering over 3-6 Hz with an amplitude
/// jumping over 4-25 m/s², along a drifting direction, with the hand rotating too; short
/// rests between bursts.
struct Shake {
    rng: ChaCha8Rng,
    /// Knots every ~0.2-0.6 s: (time, frequency, amplitude, direction).
    knots: Vec<(f64, f64, f64, Vector3<f64>)>,
    phase: f64,
    /// Start of the current grid cell, s, and the phase and its rate there.
    cell: (f64, f64, f64),
    cursor: usize,
}

impl Shake {
    fn new(duration_s: f64, mut rng: ChaCha8Rng) -> Self {
        let mut knots = Vec::new();
        let mut t = 0.0;
        let mut burst_end = rng.random_range(2.0..6.0);
        while t < duration_s + 1.0 {
            let resting = t > burst_end;
            if resting && t > burst_end + rng.random_range(0.5..2.0) {
                burst_end = t + rng.random_range(2.0..6.0);
            }
            let amplitude = if t > burst_end { 0.0 } else { rng.random_range(4.0..25.0) };
            let direction = Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
            .try_normalize(1e-6)
            .unwrap_or(Vector3::z());
            knots.push((t, rng.random_range(3.0..6.0), amplitude, direction));
            t += rng.random_range(0.2..0.6);
        }
        Self { rng, knots, phase: 0.0, cell: (0.0, 0.0, 0.0), cursor: 0 }
    }

    /// (frequency, amplitude, direction) at `t_s`, interpolated between knots.
    fn params(&self, t_s: f64) -> (f64, f64, Vector3<f64>) {
        let mut k = self.cursor;
        while k + 1 < self.knots.len() && self.knots[k + 1].0 <= t_s {
            k += 1;
        }
        let a = self.knots[k];
        let Some(b) = self.knots.get(k + 1) else { return (a.1, a.2, a.3) };
        let w = ((t_s - a.0) / (b.0 - a.0)).clamp(0.0, 1.0);
        let w = w * w * (3.0 - 2.0 * w);
        let direction = (a.3 * (1.0 - w) + b.3 * w).try_normalize(1e-6).unwrap_or(a.3);
        (a.1 + (b.1 - a.1) * w, a.2 + (b.2 - a.2) * w, direction)
    }

    fn advance(&mut self, t_s: f64) {
        while self.cursor + 1 < self.knots.len() && self.knots[self.cursor + 1].0 <= t_s {
            self.cursor += 1;
        }
        let (f, _, _) = self.params(t_s);
        // Phase at the cell start and its rate; a little irregularity in every cycle.
        let jitter = 1.0 + 0.1 * self.rng.random_range(-1.0..1.0);
        self.cell = (t_s, self.phase, TAU * f * jitter);
        self.phase += self.cell.2 * GRID_NS as f64 * 1e-9;
    }

    fn phase_at(&self, t_s: f64) -> f64 {
        self.cell.1 + self.cell.2 * (t_s - self.cell.0)
    }
}

impl Motion for InPlace {
    fn advance(&mut self, t_s: f64) {
        if let Some(shake) = &mut self.shake {
            shake.advance(t_s);
        }
    }

    fn attitude(&self, t_s: f64) -> Attitude {
        match &self.shake {
            None => attitude(self.azimuth, 0.0, 0.0),
            Some(shake) => {
                let (_, amplitude, _) = shake.params(t_s);
                let phase = shake.phase_at(t_s);
                // The wrist turns with the shake: up to ±20° at 25 m/s².
                let swing = (amplitude / 25.0) * 20f64.to_radians();
                attitude(
                    self.azimuth + 0.5 * swing * phase.cos(),
                    swing * phase.sin(),
                    0.7 * swing * (phase + 1.0).sin(),
                )
            }
        }
    }

    fn acceleration(&self, t_s: f64) -> Vector3<f64> {
        match &self.shake {
            None => Vector3::zeros(),
            Some(shake) => {
                let (_, amplitude, direction) = shake.params(t_s);
                let phase = shake.phase_at(t_s);
                direction * (amplitude * phase.sin())
            }
        }
    }

    fn position(&self, _t_s: f64) -> Point2<f64> {
        Point2::origin()
    }
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

/// The raw samples a phone held flat in front of the walker of `trajectory` would report,
/// from `standing_s` before the walk starts to `standing_s` after it ends.
pub fn synthesize(trajectory: &Trajectory, config: &ImuConfig, seed: u64) -> ImuTrace {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let standing_ns = (config.standing_s.max(0.0) * 1e9) as u64;
    let t0_ns = trajectory.start_ns().saturating_sub(standing_ns);
    let t1_ns = trajectory.end_ns().saturating_add(standing_ns);
    let (c0, c1) = config.cadence_hz;
    let (b0, b1) = config.bounce_mps2;
    let yaw_offset = config.yaw_offset_rad.abs();
    let mut walk = Walk {
        trajectory,
        t0_ns,
        walk_start_s: (trajectory.start_ns() - t0_ns) as f64 * 1e-9,
        max_turn_rate: config.max_turn_rate_radps.abs().max(1e-3),
        cadence: if c1 > c0 { rng.random_range(c0..c1) } else { c0 },
        bounce: if b1 > b0 { rng.random_range(b0..b1) } else { b0 },
        yaw_offset: (
            if yaw_offset > 0.0 { rng.random_range(-yaw_offset..yaw_offset) } else { 0.0 },
            Wobble::new(yaw_offset / 2.0, &mut rng),
        ),
        pitch: Wobble::new(config.tilt_wobble_rad, &mut rng),
        roll: Wobble::new(config.tilt_wobble_rad, &mut rng),
        rng: ChaCha8Rng::seed_from_u64(rng.random()),
        now: BodyState::default(),
        next: BodyState::default(),
        started: false,
        steps: Vec::new(),
        heading: Vec::new(),
    };
    let mut trace = sample_motion(&mut walk, config, t0_ns, t1_ns, rng.random());
    trace.true_step_times_ns = walk.steps;
    trace.true_heading = walk.heading;
    trace
}

fn in_place(duration_s: f64, config: &ImuConfig, seed: u64, shaken: bool) -> ImuTrace {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let azimuth = rng.random_range(-PI..PI);
    let shake = shaken.then(|| Shake::new(duration_s, ChaCha8Rng::seed_from_u64(rng.random())));
    let mut motion = InPlace { azimuth, shake };
    let t0_ns = 1_000_000_000;
    let t1_ns = t0_ns + (duration_s.max(0.0) * 1e9) as u64;
    let mut trace = sample_motion(&mut motion, config, t0_ns, t1_ns, rng.random());
    trace.true_heading = vec![(t0_ns, azimuth), (t1_ns, azimuth)];
    trace
}

/// A phone lying flat and still on a table for `duration_s`: gravity, the Earth's field,
/// noise and bias only. No steps.
pub fn lying_still(duration_s: f64, config: &ImuConfig, seed: u64) -> ImuTrace {
    in_place(duration_s, config, seed, false)
}

/// A person standing still and shaking the phone vigorously for `duration_s`: bursts of
/// 3-6 Hz shaking with an irregular 4-25 m/s² amplitude along a drifting direction, the wrist
/// turning with it, short rests between bursts. No steps.
pub fn shaken_in_place(duration_s: f64, config: &ImuConfig, seed: u64) -> ImuTrace {
    in_place(duration_s, config, seed, true)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use waymark_engine::sensors::{compass_azimuth, gyro_yaw_rate};

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
