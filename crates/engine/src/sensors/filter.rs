//! Small signal-processing pieces shared by the step and heading filters: angle wrapping, a
//! moving average whose window is a duration (so any sampling rate, and irregular sampling,
//! give the same filter), and the smoothing factor of a first-order low-pass filter.

use std::collections::VecDeque;
use std::f64::consts::{PI, TAU};

/// `angle` wrapped into (-π, π]. NaN stays NaN.
pub fn wrap_angle(angle: f64) -> f64 {
    if (-PI..=PI).contains(&angle) && angle != -PI {
        return angle;
    }
    let wrapped = (angle + PI).rem_euclid(TAU) - PI;
    if wrapped <= -PI {
        wrapped + TAU
    } else {
        wrapped
    }
}

/// Smoothing factor of a first-order low-pass filter with time constant `tau_s` over a step
/// of `dt_s`: y += α (x − y), α = 1 − exp(−dt/τ), exact for any step length.
pub fn lowpass_alpha(dt_s: f64, tau_s: f64) -> f64 {
    if dt_s <= 0.0 {
        0.0
    } else {
        1.0 - (-dt_s / tau_s).exp()
    }
}

/// Nanoseconds to seconds, for differences of timestamps.
pub fn ns_to_s(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

/// Seconds to nanoseconds, saturating (the configuration is validated as finite and > 0).
pub fn s_to_ns(s: f64) -> u64 {
    if s.is_nan() || s <= 0.0 {
        0
    } else if s >= u64::MAX as f64 * 1e-9 {
        u64::MAX
    } else {
        (s * 1e9).round() as u64
    }
}

/// Mean of the samples of the last `window` (those with timestamp > newest − window). The
/// window is a duration, so 0.25 s is 9 samples at 35 Hz (HIPE §3.1), 5 at 20 Hz and 50 at
/// 200 Hz, and a jittered or gappy stream is averaged over the same span of time.
#[derive(Clone, Debug)]
pub struct WindowMean {
    window_ns: u64,
    samples: VecDeque<(u64, f64)>,
    sum: f64,
    /// Removals since the sum was last recomputed from scratch (bounds rounding drift).
    removals: u32,
}

impl WindowMean {
    /// An empty average over `window_ns`.
    pub fn new(window_ns: u64) -> Self {
        Self { window_ns, samples: VecDeque::with_capacity(64), sum: 0.0, removals: 0 }
    }

    /// Forgets every sample.
    pub fn clear(&mut self) {
        self.samples.clear();
        self.sum = 0.0;
        self.removals = 0;
    }

    /// Adds a sample (timestamps must increase) and returns the mean over the window.
    pub fn push(&mut self, t_ns: u64, value: f64) -> f64 {
        self.samples.push_back((t_ns, value));
        self.sum += value;
        while let Some(&(t0, v0)) = self.samples.front() {
            if t_ns - t0 >= self.window_ns && self.samples.len() > 1 {
                self.samples.pop_front();
                self.sum -= v0;
                self.removals += 1;
            } else {
                break;
            }
        }
        if self.removals >= 1024 {
            self.sum = self.samples.iter().map(|s| s.1).sum();
            self.removals = 0;
        }
        self.sum / self.samples.len() as f64
    }

    /// The middle of the span the current mean covers: the time the mean best describes
    /// (a moving average delays the signal by half its window).
    pub fn center_ns(&self) -> u64 {
        match (self.samples.front(), self.samples.back()) {
            (Some(a), Some(b)) => a.0 + (b.0 - a.0) / 2,
            _ => 0,
        }
    }

    /// The sample in the middle of the window: the raw signal delayed as much as the mean.
    pub fn middle(&self) -> f64 {
        self.samples.get(self.samples.len() / 2).map_or(0.0, |s| s.1)
    }

    /// Number of samples in the window.
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.samples.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn wrapping_crosses_plus_minus_pi() {
        assert_relative_eq!(wrap_angle(PI + 0.1), -PI + 0.1, epsilon = 1e-12);
        assert_relative_eq!(wrap_angle(-PI - 0.1), PI - 0.1, epsilon = 1e-12);
        assert_eq!(wrap_angle(PI), PI);
        assert_relative_eq!(wrap_angle(-PI), PI, epsilon = 1e-12);
        assert_relative_eq!(wrap_angle(7.0 * TAU + 0.3), 0.3, epsilon = 1e-9);
        assert_relative_eq!(wrap_angle(-3.0 * TAU - 0.3), -0.3, epsilon = 1e-9);
        // The short way round: 179° to -179° is +2°.
        let d = wrap_angle((-179f64).to_radians() - 179f64.to_radians());
        assert_relative_eq!(d, 2f64.to_radians(), epsilon = 1e-12);
        assert!(wrap_angle(f64::NAN).is_nan());
        assert!(wrap_angle(f64::INFINITY).is_nan());
    }

    #[test]
    fn lowpass_alpha_is_exact_for_any_step() {
        // Two half steps equal one whole step.
        let (a_half, a_whole) = (lowpass_alpha(0.05, 0.5), lowpass_alpha(0.1, 0.5));
        assert_relative_eq!(1.0 - (1.0 - a_half) * (1.0 - a_half), a_whole, epsilon = 1e-12);
        assert_eq!(lowpass_alpha(0.0, 1.0), 0.0);
    }

    /// The 0.25 s window holds 9 samples at 35 Hz (HIPE), 5 at 20 Hz, 50 at 200 Hz, and
    /// averages a sinusoid equally at every rate.
    #[test]
    fn smoothing_window_is_a_duration() {
        for (rate, expected) in [(20.0, 5), (35.0, 9), (100.0, 25), (200.0, 50)] {
            let mut m = WindowMean::new(250_000_000);
            let period = (1e9 / rate) as u64;
            let mut peak: f64 = 0.0;
            for k in 0..(rate as u64 * 3) {
                let t = k * period;
                let x = (2.0 * PI * 2.0 * t as f64 * 1e-9).sin();
                let out = m.push(t, x);
                if t > 1_000_000_000 {
                    peak = peak.max(out.abs());
                }
            }
            assert_eq!(m.len(), expected, "rate {rate}");
            // A 2 Hz sine through a 0.25 s moving average keeps sinc(0.5) = 2/π of its
            // amplitude, whatever the rate (a window counted in samples would not).
            assert!((peak - 2.0 / PI).abs() < 0.04, "rate {rate}: {peak}");
        }
        // The same span of time with jittered timestamps.
        let mut m = WindowMean::new(250_000_000);
        let ts = [0u64, 9_000_000, 21_000_000, 30_000_000, 240_000_000, 260_000_000, 500_000_000];
        for &t in &ts {
            m.push(t, 1.0);
        }
        assert_eq!(m.len(), 2); // 260 and 500 ms: 240 ms is ≥ 250 ms before 500.
        assert_eq!(m.center_ns(), 380_000_000);
    }
}
