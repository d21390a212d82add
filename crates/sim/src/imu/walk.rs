//! A phone held flat in front of a walker: the body follows the trajectory, turning at a limited
//! rate, with a step bounce, surge and sway at the cadence, and the phone's yaw offset and tilt
//! wobbling slowly.

use super::{attitude, sample_motion, Attitude, ImuConfig, ImuTrace, Motion, GRID_NS};
use crate::Trajectory;
use nalgebra::{Point2, Vector3};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::Distribution;
use std::f64::consts::{PI, TAU};
use waymark_engine::sensors::wrap_angle;

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
