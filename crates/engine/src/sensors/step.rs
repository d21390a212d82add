//! Steps from the accelerometer (Hoang §4, HIPE §3.1): the norm of the acceleration minus the
//! learned gravity (HIPE eq. 1), a moving average over a fixed duration, one of two detectors
//! (Hoang's threshold crossing with hysteresis, HIPE's peak + zero crossing), and a gait check
//! that counts steps only inside a run of regular steps at a walking cadence, so that handling
//! or shaking the phone in place is not counted.

use super::config::{MotionConfig, StepDetectorKind};
use super::filter::{ns_to_s, s_to_ns, WindowMean};

/// Gravity (ĝ of HIPE eq. 1) learned while the phone is still: the mean acceleration norm over
/// blocks of `gravity_window_s` whose standard deviation is below `still_std_mps2`, averaged
/// over the whole current still stretch. Starts from `initial_gravity_mps2`.
#[derive(Clone, Debug)]
pub struct GravityLearner {
    initial: f64,
    block_ns: u64,
    still_std: f64,
    max_gap_ns: u64,
    gravity: f64,
    learned: bool,
    still: bool,
    last_ns: Option<u64>,
    block_start_ns: Option<u64>,
    /// Sums of (norm − initial) and its square over the block (shifted for precision).
    block: (u32, f64, f64),
    /// Sum and count of (norm − initial) over the current still stretch.
    stretch: (u64, f64),
}

impl GravityLearner {
    /// A learner configured from `config`.
    pub fn new(config: &MotionConfig) -> Self {
        Self {
            initial: config.initial_gravity_mps2,
            block_ns: s_to_ns(config.gravity_window_s),
            still_std: config.still_std_mps2,
            max_gap_ns: s_to_ns(config.max_gap_s),
            gravity: config.initial_gravity_mps2,
            learned: false,
            still: false,
            last_ns: None,
            block_start_ns: None,
            block: (0, 0.0, 0.0),
            stretch: (0, 0.0),
        }
    }

    /// Current estimate of gravity, m/s².
    pub fn gravity(&self) -> f64 {
        self.gravity
    }

    /// Whether gravity has been learned at least once.
    #[cfg(test)]
    pub fn learned(&self) -> bool {
        self.learned
    }

    /// Whether the last complete block was still.
    pub fn still(&self) -> bool {
        self.still
    }

    /// Adds one acceleration norm.
    pub fn push(&mut self, t_ns: u64, norm: f64) {
        if let Some(last) = self.last_ns {
            if t_ns.saturating_sub(last) > self.max_gap_ns {
                // A gap: the block would average over time we did not see.
                self.block_start_ns = None;
                self.stretch = (0, 0.0);
                self.still = false;
            }
        }
        self.last_ns = Some(t_ns);
        let start = *self.block_start_ns.get_or_insert(t_ns);
        let d = norm - self.initial;
        self.block.0 += 1;
        self.block.1 += d;
        self.block.2 += d * d;
        if t_ns - start >= self.block_ns && self.block.0 >= 3 {
            let n = self.block.0 as f64;
            let mean = self.block.1 / n;
            let var = (self.block.2 / n - mean * mean).max(0.0);
            // A still block whose mean is more than 5 % off is not gravity (an accelerating
            // lift, a badly scaled sensor): it is not learned from.
            self.still = var.sqrt() < self.still_std;
            if self.still && mean.abs() < 0.05 * self.initial {
                self.stretch.0 += self.block.0 as u64;
                self.stretch.1 += self.block.1;
                self.gravity = self.initial + self.stretch.1 / self.stretch.0 as f64;
                self.learned = true;
            } else {
                self.stretch = (0, 0.0);
            }
            self.block_start_ns = None;
            self.block = (0, 0.0, 0.0);
        }
    }
}

/// A peak found by a detector, before the gait check.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawStep {
    /// When the step happened (delay of the moving average removed), ns.
    pub t_ns: u64,
    /// Largest gravity-free norm (unsmoothed) since the previous raw step, m/s².
    pub raw_max: f64,
    /// Smallest gravity-free norm (unsmoothed) since the previous raw step, m/s².
    pub raw_min: f64,
    /// Peak-to-peak of the smoothed signal over the same span, m/s².
    pub smooth_p2p: f64,
}

impl RawStep {
    /// Raw peak-to-peak over smoothed peak-to-peak: about 1.3-2 for a walking rhythm, which
    /// the 0.25 s average passes, and large for shaking at 3 Hz and above, which it removes.
    pub fn roughness(&self) -> f64 {
        let raw = self.raw_max - self.raw_min;
        if self.smooth_p2p > 0.0 && raw.is_finite() {
            raw.max(0.0) / self.smooth_p2p
        } else {
            f64::INFINITY
        }
    }
}

/// Gravity removal, smoothing and one of the two detectors.
#[derive(Clone, Debug)]
pub struct StepDetector {
    kind: StepDetectorKind,
    gravity: GravityLearner,
    smooth: WindowMean,
    threshold: f64,
    rearm: f64,
    peak_threshold: f64,
    min_interval_ns: u64,
    reset_gap_ns: u64,
    /// Longest a step's bump may last: from the peak to the zero crossing, or from the
    /// threshold crossing to the re-arm (a quarter to half a period; the slow swells of the
    /// norm while shaking last longer).
    max_bump_ns: u64,
    /// Longest span the raw extremes cover without a step (the slowest step period).
    raw_span_ns: u64,
    last_ns: Option<u64>,
    last_step_ns: Option<u64>,
    /// Threshold detector: may count the next rise; the time of the rise being counted.
    armed: bool,
    crossing: Option<u64>,
    /// Peak detector: the smoothed signal is above zero; the largest value and its time,
    /// with the samples either side of it (for sub-sample timing).
    above: bool,
    peak: (f64, u64),
    peak_left: Option<(u64, f64)>,
    peak_right: Option<(u64, f64)>,
    /// The previous smoothed sample (centre time, value).
    previous: Option<(u64, f64)>,
    raw_max: f64,
    raw_min: f64,
    smooth_max: f64,
    smooth_min: f64,
    raw_start_ns: u64,
}

impl StepDetector {
    /// A detector configured from `config`.
    pub fn new(config: &MotionConfig) -> Self {
        Self {
            kind: config.step_detector,
            gravity: GravityLearner::new(config),
            smooth: WindowMean::new(s_to_ns(config.smoothing_window_s)),
            threshold: config.step_threshold_mps2,
            rearm: config.step_rearm_mps2,
            peak_threshold: config.peak_threshold_mps2,
            min_interval_ns: s_to_ns(config.min_step_interval_s),
            reset_gap_ns: s_to_ns(config.max_gap_s.min(config.smoothing_window_s)),
            raw_span_ns: s_to_ns(1.0 / config.min_cadence_hz),
            max_bump_ns: s_to_ns(0.6 / config.min_cadence_hz),
            last_ns: None,
            last_step_ns: None,
            armed: true,
            crossing: None,
            above: false,
            peak: (f64::NEG_INFINITY, 0),
            peak_left: None,
            peak_right: None,
            previous: None,
            raw_max: f64::NEG_INFINITY,
            raw_min: f64::INFINITY,
            smooth_max: f64::NEG_INFINITY,
            smooth_min: f64::INFINITY,
            raw_start_ns: 0,
        }
    }

    /// The gravity learner.
    pub fn gravity(&self) -> &GravityLearner {
        &self.gravity
    }

    /// Adds one accelerometer sample's norm; returns a raw step when the detector fires.
    pub fn push(&mut self, t_ns: u64, norm: f64) -> Option<RawStep> {
        if let Some(last) = self.last_ns {
            // A gap longer than the window leaves the average with one sample: start afresh
            // (a step lost in the gap is restored by the gait check's missed-step rule).
            if t_ns.saturating_sub(last) > self.reset_gap_ns {
                self.smooth.clear();
                self.armed = true;
                self.crossing = None;
                self.above = false;
                self.previous = None;
                self.reset_extremes(t_ns);
            }
        }
        self.last_ns = Some(t_ns);
        self.gravity.push(t_ns, norm);
        // HIPE eq. 1: pedestrian acceleration = |a| − ĝ.
        let p = norm - self.gravity.gravity();
        if t_ns.saturating_sub(self.raw_start_ns) > self.raw_span_ns {
            self.reset_extremes(t_ns);
        }
        let s = self.smooth.push(t_ns, p);
        // The raw signal as delayed as the smoothed one, so both cover the same span.
        let raw = self.smooth.middle();
        self.raw_max = self.raw_max.max(raw);
        self.raw_min = self.raw_min.min(raw);
        self.smooth_max = self.smooth_max.max(s);
        self.smooth_min = self.smooth_min.min(s);
        let tc = self.smooth.center_ns();
        let min_interval_ns = self.min_interval_ns;
        let spaced =
            |at: u64, last: Option<u64>| last.is_none_or(|l| at.saturating_sub(l) >= min_interval_ns);
        let previous = self.previous.replace((tc, s));
        let fired = match self.kind {
            StepDetectorKind::Threshold => {
                if self.armed && s > self.threshold {
                    // The rise is consumed either way; it counts if far enough from the last.
                    // Dated where the line between the two samples crosses the threshold, and
                    // reported when the signal falls back (so the gait check sees the whole
                    // bump).
                    self.armed = false;
                    let at = previous.map_or(tc, |(t0, s0)| crossing_time(t0, s0, tc, s, self.threshold));
                    self.crossing = spaced(at, self.last_step_ns).then_some(at);
                    None
                } else if !self.armed && s < self.rearm {
                    self.armed = true;
                    self.crossing.take().filter(|&at| tc.saturating_sub(at) <= self.max_bump_ns)
                } else {
                    None
                }
            }
            StepDetectorKind::PeakZeroCrossing => {
                if s > 0.0 {
                    if !self.above || s > self.peak.0 {
                        self.peak = (s, tc);
                        self.peak_left = previous;
                        self.peak_right = None;
                    } else if self.peak_right.is_none() {
                        self.peak_right = Some((tc, s));
                    }
                    self.above = true;
                    None
                } else if self.above {
                    self.above = false;
                    let (peak, t1) = self.peak;
                    let at = match (self.peak_left, self.peak_right) {
                        (Some(left), Some(right)) => vertex_time(left, (t1, peak), right),
                        _ => t1,
                    };
                    let brief = tc.saturating_sub(t1) <= self.max_bump_ns;
                    (peak > self.peak_threshold && brief && spaced(at, self.last_step_ns)).then_some(at)
                } else {
                    None
                }
            }
        };
        fired.map(|at| {
            self.last_step_ns = Some(at);
            let step = RawStep {
                t_ns: at,
                raw_max: self.raw_max,
                raw_min: self.raw_min,
                smooth_p2p: self.smooth_max - self.smooth_min,
            };
            self.reset_extremes(t_ns);
            self.raw_max = raw;
            self.raw_min = raw;
            self.smooth_max = s;
            self.smooth_min = s;
            step
        })
    }

    /// Forgets the extremes (a new step, a gap, or too long without a step).
    fn reset_extremes(&mut self, t_ns: u64) {
        self.raw_max = f64::NEG_INFINITY;
        self.raw_min = f64::INFINITY;
        self.smooth_max = f64::NEG_INFINITY;
        self.smooth_min = f64::INFINITY;
        self.raw_start_ns = t_ns;
    }
}

/// When the line from (t0, s0) to (t1, s1) crosses `level` (t1 if it is flat).
fn crossing_time(t0: u64, s0: f64, t1: u64, s1: f64, level: f64) -> u64 {
    if s1 > s0 && t1 > t0 {
        let w = ((level - s0) / (s1 - s0)).clamp(0.0, 1.0);
        t0 + ((t1 - t0) as f64 * w).round() as u64
    } else {
        t1
    }
}

/// Time of the vertex of the parabola through three samples around a peak (irregular spacing
/// allowed), kept between the outer two: sub-sample timing, so that step periods measured at
/// 20 Hz are as regular as the gait.
fn vertex_time(left: (u64, f64), peak: (u64, f64), right: (u64, f64)) -> u64 {
    let (a, b) = (left.0 as f64 - peak.0 as f64, right.0 as f64 - peak.0 as f64);
    let (da, db) = (peak.1 - left.1, peak.1 - right.1);
    let denominator = a * db - b * da;
    if !(a < 0.0 && b > 0.0) || denominator.abs() < 1e-300 {
        return peak.0;
    }
    let offset = 0.5 * (a * a * db - b * b * da) / denominator;
    let offset = offset.clamp(a, b);
    (peak.0 as f64 + offset).round().max(0.0) as u64
}

/// An average cannot swing more than what it averages: a roughness well below 1 means the
/// span was not one oscillation (a plateau, a gap), so not a step.
const MIN_ROUGHNESS: f64 = 0.8;

/// A step accepted by the gait check.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GaitStep<H> {
    /// When it happened, ns.
    pub t_ns: u64,
    /// Its period (time since the previous step, or the bout's first interval), s.
    pub period_s: f64,
    /// Peak-to-peak gravity-free acceleration over the step, m/s² (Weinberg's a_max − a_min).
    pub peak_to_peak: f64,
    /// What the caller attached to the raw step (its heading).
    pub tag: H,
}

/// Counts steps only within a bout of regular steps at a walking cadence: `confirm_steps`
/// consecutive raw steps with periods in [1/max_cadence, 1/min_cadence], each within
/// `max_interval_change` of the previous, and no acceleration above
/// `max_step_acceleration_mps2`; those are then all counted, and later steps as long as they
/// keep the cadence. Shaking (too fast, irregular, too strong) never completes a bout.
#[derive(Clone, Debug)]
pub struct GaitValidator<H> {
    min_period_ns: u64,
    max_period_ns: u64,
    latency_ns: u64,
    confirm: usize,
    max_change: f64,
    max_accel: f64,
    max_roughness: f64,
    pending: Vec<(RawStep, H)>,
    walking: bool,
    last_accepted_ns: Option<u64>,
    /// Recent accepted periods, s (the bout's pace).
    periods: [f64; 4],
    period_count: usize,
    fast_strikes: u32,
    rejected: u64,
}

impl<H: Copy> GaitValidator<H> {
    /// A validator configured from `config`.
    pub fn new(config: &MotionConfig) -> Self {
        Self {
            min_period_ns: s_to_ns(1.0 / config.max_cadence_hz),
            max_period_ns: s_to_ns(1.0 / config.min_cadence_hz),
            latency_ns: s_to_ns(config.smoothing_window_s),
            confirm: config.confirm_steps,
            max_change: config.max_interval_change,
            max_accel: config.max_step_acceleration_mps2,
            max_roughness: config.max_step_roughness,
            pending: Vec::with_capacity(config.confirm_steps + 1),
            walking: false,
            last_accepted_ns: None,
            periods: [0.0; 4],
            period_count: 0,
            fast_strikes: 0,
            rejected: 0,
        }
    }

    /// Whether a bout of walking is going on.
    pub fn walking(&self) -> bool {
        self.walking
    }

    /// Raw steps rejected so far.
    pub fn rejected(&self) -> u64 {
        self.rejected
    }

    fn mean_period(&self) -> Option<f64> {
        let n = self.period_count.min(self.periods.len());
        (n > 0).then(|| self.periods[..n].iter().sum::<f64>() / n as f64)
    }

    fn remember_period(&mut self, period_s: f64) {
        self.periods[self.period_count % self.periods.len()] = period_s;
        self.period_count += 1;
    }

    /// Whether the pending steps' periods are all within `max_change` of their mean (one
    /// step dated early makes one period short and the next long, so the mean is the
    /// reference, not the previous period).
    fn regular(&self) -> bool {
        let n = self.pending.len();
        if n < 3 {
            return true;
        }
        let span = (self.pending[n - 1].0.t_ns - self.pending[0].0.t_ns) as f64;
        let mean = span / (n - 1) as f64;
        self.pending
            .windows(2)
            .all(|w| ((w[1].0.t_ns - w[0].0.t_ns) as f64 - mean).abs() <= self.max_change * mean)
    }

    fn end_bout(&mut self) {
        self.walking = false;
        self.rejected += self.pending.len() as u64;
        self.pending.clear();
        self.period_count = 0;
        self.fast_strikes = 0;
    }

    /// Ends the bout when no step has come for longer than the slowest step period plus the
    /// detectors' latency (a step is dated at its peak but found up to half a period and the
    /// smoothing delay later).
    pub fn tick(&mut self, t_ns: u64) {
        let timeout = self.max_period_ns + self.max_period_ns / 2 + self.latency_ns;
        if let Some(last) = self.last_accepted_ns {
            if self.walking && t_ns.saturating_sub(last) > timeout {
                self.end_bout();
            }
        }
        if let Some(&(last, _)) = self.pending.last() {
            if t_ns.saturating_sub(last.t_ns) > timeout {
                self.end_bout();
            }
        }
    }

    /// Offers a raw step; counted steps are appended to `out` (possibly several at once, when a
    /// bout is confirmed).
    pub fn offer(&mut self, step: RawStep, tag: H, out: &mut Vec<GaitStep<H>>) {
        let too_strong = step.raw_max > self.max_accel || -step.raw_min > self.max_accel;
        let peak_to_peak = (step.raw_max - step.raw_min).max(0.0);
        if self.walking {
            let last = self.last_accepted_ns.unwrap_or(step.t_ns);
            let dt = step.t_ns.saturating_sub(last);
            if too_strong {
                self.rejected += 1;
                self.end_bout();
                return;
            }
            if dt < self.min_period_ns {
                // A second bump within one step (or the start of shaking): ignored; twice in a
                // row ends the bout.
                self.rejected += 1;
                self.fast_strikes += 1;
                if self.fast_strikes >= 2 {
                    self.end_bout();
                }
                return;
            }
            self.fast_strikes = 0;
            let period = ns_to_s(dt);
            if let Some(mean) = self.mean_period() {
                // Steps missed by the detector (a weak bump, a sensor gap): the interval is two
                // or three periods of the bout's pace; the missing steps are put in between.
                let n = (period / mean).round();
                if (2.0..=3.0).contains(&n) && (period - n * mean).abs() <= 0.2 * mean {
                    let k = n as u64;
                    for j in 1..=k {
                        let at = if j == k { step.t_ns } else { last + dt * j / k };
                        out.push(GaitStep { t_ns: at, period_s: period / n, peak_to_peak, tag });
                    }
                    self.remember_period(period / n);
                    self.last_accepted_ns = Some(step.t_ns);
                    return;
                }
            }
            if dt > self.max_period_ns {
                // A pause: this step may start a new bout.
                self.end_bout();
                self.pending.push((step, tag));
                return;
            }
            out.push(GaitStep { t_ns: step.t_ns, period_s: period, peak_to_peak, tag });
            self.remember_period(period);
            self.last_accepted_ns = Some(step.t_ns);
            return;
        }
        let roughness = step.roughness();
        if too_strong || !(MIN_ROUGHNESS..=self.max_roughness).contains(&roughness) {
            self.rejected += 1;
            self.end_bout();
            return;
        }
        if let Some(&(last, _)) = self.pending.last() {
            let dt = step.t_ns.saturating_sub(last.t_ns);
            if dt < self.min_period_ns || dt > self.max_period_ns {
                self.end_bout();
            }
        }
        self.pending.push((step, tag));
        if self.pending.len() > self.confirm {
            self.pending.remove(0);
            self.rejected += 1;
        }
        if self.pending.len() >= self.confirm && !self.regular() {
            // Not (yet) a regular run: the oldest step may be the odd one out; wait for more.
            return;
        }
        if self.pending.len() >= self.confirm {
            // A bout: count every pending step.
            self.walking = true;
            self.period_count = 0;
            let n = self.pending.len();
            for k in 0..n {
                let (raw, tag) = self.pending[k];
                let period_ns = if k > 0 {
                    raw.t_ns - self.pending[k - 1].0.t_ns
                } else if n > 1 {
                    self.pending[1].0.t_ns - raw.t_ns
                } else {
                    self.max_period_ns
                };
                let period = ns_to_s(period_ns);
                if k > 0 {
                    self.remember_period(period);
                }
                out.push(GaitStep {
                    t_ns: raw.t_ns,
                    period_s: period,
                    peak_to_peak: (raw.raw_max - raw.raw_min).max(0.0),
                    tag,
                });
            }
            self.last_accepted_ns = Some(self.pending[n - 1].0.t_ns);
            self.pending.clear();
            self.fast_strikes = 0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn config() -> MotionConfig {
        MotionConfig::default()
    }

    /// Gravity starts at 9.81, is learned as the mean norm of a still block, and is not
    /// learned from a moving one.
    #[test]
    fn gravity_is_learned_while_still() {
        let c = config();
        let mut g = GravityLearner::new(&c);
        assert_eq!(g.gravity(), 9.81);
        // Walking: a 2 Hz bounce of 2 m/s² around 9.9.
        for k in 0..300u64 {
            let t = k * 10_000_000;
            g.push(t, 9.9 + 2.0 * (2.0 * PI * 2.0 * t as f64 * 1e-9).sin());
        }
        assert!(!g.learned());
        assert!(!g.still());
        // Still at 9.75 with ±0.02 of noise.
        for k in 300..520u64 {
            let noise = if k % 2 == 0 { 0.02 } else { -0.02 };
            g.push(k * 10_000_000, 9.75 + noise);
        }
        assert!(g.learned());
        assert!(g.still());
        assert!((g.gravity() - 9.75).abs() < 1e-3, "{}", g.gravity());
        // A still block 10 % off (an accelerating lift) is not gravity.
        let mut h = GravityLearner::new(&c);
        for k in 0..300u64 {
            h.push(k * 10_000_000, 10.8);
        }
        assert!(!h.learned());
    }

    #[test]
    fn sub_sample_timing() {
        // y = 1 − (t − 130)², sampled at 100, 150 and 200: vertex at 130.
        let y = |t: f64| 1.0 - ((t - 130.0) / 100.0).powi(2);
        assert_eq!(vertex_time((100, y(100.0)), (150, y(150.0)), (200, y(200.0))), 130);
        // Irregular spacing.
        assert_eq!(vertex_time((90, y(90.0)), (140, y(140.0)), (210, y(210.0))), 130);
        assert_eq!(crossing_time(100, 0.0, 200, 1.0, 0.25), 125);
        assert_eq!(crossing_time(100, 1.0, 200, 1.0, 0.25), 200);
    }

    fn raw(t_ms: u64) -> RawStep {
        RawStep { t_ns: t_ms * 1_000_000, raw_max: 2.0, raw_min: -2.0, smooth_p2p: 2.5 }
    }

    #[test]
    fn steps_are_counted_after_a_regular_run_and_all_of_them() {
        let mut v = GaitValidator::<()>::new(&config());
        let mut out = Vec::new();
        for k in 0..3 {
            v.offer(raw(1000 + 500 * k), (), &mut out);
        }
        assert!(out.is_empty() && !v.walking());
        v.offer(raw(2500), (), &mut out);
        assert_eq!(out.len(), 4);
        assert!(v.walking());
        v.offer(raw(3000), (), &mut out);
        assert_eq!(out.len(), 5);
        // A missed step: 1 s at a 0.5 s pace counts two.
        v.offer(raw(4000), (), &mut out);
        assert_eq!(out.len(), 7);
        assert_eq!(out[5].t_ns, 3_500_000_000);
        // A pause ends the bout (after the slowest period plus the detection latency).
        v.tick(4_900_000_000);
        assert!(v.walking());
        v.tick(5_800_000_000);
        assert!(!v.walking());
    }

    #[test]
    fn fast_irregular_or_strong_runs_are_not_counted() {
        let c = config();
        let mut out = Vec::new();
        // 4 Hz: too fast.
        let mut v = GaitValidator::<()>::new(&c);
        for k in 0..20 {
            v.offer(raw(1000 + 250 * k), (), &mut out);
        }
        // Irregular: 0.45, 0.8, 0.45, 0.8 s...
        for k in 0..20u64 {
            v.offer(raw(10_000 + 1250 * (k / 2) + if k % 2 == 1 { 450 } else { 0 }), (), &mut out);
        }
        // Regular but strong: above `max_step_acceleration_mps2` (25).
        for k in 0..20u64 {
            let s = RawStep {
                t_ns: (40_000 + 500 * k) * 1_000_000,
                raw_max: 30.0,
                raw_min: -5.0,
                smooth_p2p: 17.5,
            };
            v.offer(s, (), &mut out);
        }
        assert!(out.is_empty(), "{out:?}");
        assert!(v.rejected() >= 50);
    }

    /// The detector sees the same steps at 20 and 200 Hz (the window is a duration).
    #[test]
    fn detectors_find_a_clean_bounce_at_any_rate() {
        for kind in [StepDetectorKind::Threshold, StepDetectorKind::PeakZeroCrossing] {
            for rate in [20.0, 50.0, 200.0] {
                let c = MotionConfig { step_detector: kind, ..config() };
                let mut d = StepDetector::new(&c);
                let period = (1e9 / rate) as u64;
                let mut steps = Vec::new();
                for k in 0..(rate as u64 * 10) {
                    let t = k * period;
                    // 1.8 Hz, 2 m/s² bounce starting at 1 s.
                    let ts = t as f64 * 1e-9;
                    let bounce = if ts > 1.0 { 2.0 * (2.0 * PI * 1.8 * (ts - 1.0)).sin() } else { 0.0 };
                    steps.extend(d.push(t, 9.81 + bounce));
                }
                // 9 s at 1.8 Hz: 16.2 peaks.
                assert!((15..=17).contains(&steps.len()), "{kind:?} at {rate} Hz: {}", steps.len());
                if kind == StepDetectorKind::PeakZeroCrossing {
                    // Dated at the peak: (k + 0.25) / 1.8 s after the start.
                    let first = steps[0].t_ns as f64 * 1e-9 - 1.0;
                    assert!((first - 0.25 / 1.8).abs() < 0.6 / rate + 0.01, "{first}");
                }
            }
        }
    }
}
