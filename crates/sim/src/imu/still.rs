//! A phone not carried anywhere: lying still on a table, or held in place and shaken.

use super::{attitude, sample_motion, Attitude, ImuConfig, ImuTrace, Motion, GRID_NS};
use nalgebra::{Point2, Vector3};
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use std::f64::consts::{PI, TAU};

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
