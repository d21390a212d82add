//! Calibrating the motion tracker on survey walks: the walkers' step length model, fitted
//! against the waypoint path lengths, and the site's north, the offset between the tracker's
//! heading while walking straight and the bearings of the waypoint segments walked.
//!
//! Each survey walk is replayed through a [`MotionTracker`] as an app would feed it
//! ([`replay_steps`]); only the steps between the first and the last waypoint count, because
//! the path outside them is unknown. Every estimate is robust: walks too short to say anything
//! are skipped, outlying walks are dropped by their median absolute deviation before the
//! fit, and the heading offset is a circular median over walks.

use crate::io::ilc::Trace;
use serde::Serialize;
use waymark_engine::sensors::{
    wrap_angle, MotionConfig, MotionTracker, SensorSample, StepEvent, StepLengthModel,
};
use waymark_engine::site::North;

/// Samples are fed to the tracker in batches of this length, ns, each followed by an update:
/// Android delivers sensor batches every few hundred ms, and the engine updates every 1.5 s
/// (Hoang §6.1); the steps found do not depend on it.
const REPLAY_BATCH_NS: u64 = 500_000_000;
/// A walk is used for the step length only if its waypoint path is at least this long, m:
/// shorter, a step or two of error at either end is over 10 %.
const MIN_PATH_M: f64 = 10.0;
/// ... and it has at least this many steps between its first and last waypoint.
const MIN_STEPS: usize = 5;
/// A segment is used for the heading only if it is at least this long, m, and only its steps
/// more than `TURN_MARGIN_NS` from either waypoint: the surveyor turns at waypoints.
const MIN_SEGMENT_M: f64 = 5.0;
/// See `MIN_SEGMENT_M`: about two steps either side of a waypoint, ns.
const TURN_MARGIN_NS: u64 = 1_000_000_000;
/// A walk's mean heading offset is used only if it rests on at least this many steps.
const MIN_HEADING_STEPS: usize = 10;
/// Walks whose step-length ratio is more than this many scaled median absolute deviations
/// from the median are outliers (Hampel's rule; 1.4826 · MAD estimates σ for normal data).
const OUTLIER_MADS: f64 = 3.0;

/// Every step the tracker counts in `trace`, fed as an app would: the three streams in
/// batches of 500 ms, each batch followed by `update`. `None` when the walk has no
/// accelerometer or `config` is invalid.
pub fn replay_steps(trace: &Trace, config: &MotionConfig) -> Option<Vec<StepEvent>> {
    let first = trace.accelerometer.first()?.timestamp_ns;
    let last = trace.accelerometer.last()?.timestamp_ns;
    let mut tracker = MotionTracker::new(config.clone()).ok()?;
    let slice = |v: &[SensorSample], after: u64, until: u64| -> Vec<SensorSample> {
        let i = v.partition_point(|s| s.timestamp_ns <= after);
        let j = v.partition_point(|s| s.timestamp_ns <= until);
        v[i..j].to_vec()
    };
    let mut steps = Vec::new();
    // Start just before the first sample so that it is taken.
    let mut now = first.saturating_sub(1);
    tracker.update(now);
    while now < last.saturating_add(2 * REPLAY_BATCH_NS) {
        let next = now + REPLAY_BATCH_NS;
        tracker.push_accelerometer(&slice(&trace.accelerometer, now, next));
        tracker.push_gyroscope(&slice(&trace.gyroscope, now, next));
        tracker.push_magnetometer(&slice(&trace.magnetometer, now, next));
        tracker.update(next);
        steps.extend_from_slice(tracker.last_steps());
        now = next;
    }
    Some(steps)
}

/// The first and last waypoint times, when there are at least two waypoints.
pub fn waypoint_span(trace: &Trace) -> Option<(u64, u64)> {
    let (a, b) = (trace.waypoints.first()?, trace.waypoints.last()?);
    (b.timestamp_ns > a.timestamp_ns).then_some((a.timestamp_ns, b.timestamp_ns))
}

/// The steps between the first and last waypoint.
pub fn steps_within(steps: &[StepEvent], span: (u64, u64)) -> impl Iterator<Item = &StepEvent> {
    steps.iter().filter(move |s| s.timestamp_ns >= span.0 && s.timestamp_ns <= span.1)
}

/// Bearing (rad clockwise from the site's +y) and length of the waypoint segment being walked
/// at `t_ns`, and the times of its ends; `None` outside the waypoints.
pub fn segment_at(trace: &Trace, t_ns: u64) -> Option<(f64, f64, u64, u64)> {
    let w = &trace.waypoints;
    let k = w.partition_point(|p| p.timestamp_ns <= t_ns);
    let (a, b) = (w.get(k.checked_sub(1)?)?, w.get(k)?);
    let (dx, dy) = (b.x - a.x, b.y - a.y);
    Some((dx.atan2(dy), dx.hypot(dy), a.timestamp_ns, b.timestamp_ns))
}

/// Circular mean of angles, rad; `None` for none or when they cancel out.
pub(crate) fn circular_mean(angles: impl IntoIterator<Item = f64>) -> Option<f64> {
    let (mut s, mut c, mut n) = (0.0, 0.0, 0usize);
    for a in angles {
        s += a.sin();
        c += a.cos();
        n += 1;
    }
    (n > 0 && s.hypot(c) > 1e-9 * n as f64).then(|| s.atan2(c))
}

/// Circular median (Fisher, "Statistical analysis of circular data", 1993, §2.3.2): the
/// sample angle minimising the sum of absolute angular deviations.
pub(crate) fn circular_median(angles: &[f64]) -> Option<f64> {
    angles.iter().copied().min_by(|&a, &b| {
        let cost = |m: f64| angles.iter().map(|&x| wrap_angle(x - m).abs()).sum::<f64>();
        cost(a).total_cmp(&cost(b))
    })
}

fn median(values: &[f64]) -> Option<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) })
}

/// One survey walk's contribution to the step-length fit.
#[derive(Clone, Copy, Debug, PartialEq)]
struct WalkSums {
    /// Waypoint path length, m.
    path_m: f64,
    /// Steps between the first and last waypoint.
    steps: f64,
    /// Σ step frequency (1/period, clamped to the cadence range), Hz.
    frequency: f64,
    /// Σ (peak-to-peak)^(1/4), Weinberg's term.
    weinberg: f64,
}

/// How well one step length model fitted, by leave-one-walk-out cross-validation.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ModelFit {
    /// The model fitted on all used walks.
    pub model: StepLengthModel,
    /// Median over walks of |predicted − waypoint path| / path, each walk predicted by the
    /// model fitted without it.
    pub median_error: f64,
    /// Mean of the same.
    pub mean_error: f64,
}

/// What [`calibrate_motion`] found on the survey walks.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MotionCalibration {
    /// The step length model chosen: the candidate with the lowest cross-validated mean
    /// relative distance error.
    pub step_length: StepLengthModel,
    /// Every candidate, with its cross-validated error: constant length (HIPE §3.1),
    /// Weinberg (AN-602), linear in frequency (Shin et al. 2007).
    pub candidates: Vec<ModelFit>,
    /// Site heading = magnetic azimuth + this, rad: declination and the site's rotation from
    /// north folded together (they cannot be told apart from walks).
    pub heading_offset_rad: f64,
    /// Survey walks read.
    pub walks: usize,
    /// Walks used for the step length (long enough, with steps, not outliers).
    pub distance_walks: usize,
    /// Walks used for the heading offset.
    pub heading_walks: usize,
    /// Steps between the first and last waypoint of the distance walks.
    pub steps: u64,
    /// Waypoint path length of the distance walks, m.
    pub distance_m: f64,
    /// Per distance walk, (fitted distance − path) / path with the chosen model (in-sample).
    pub distance_residuals: Vec<f64>,
    /// Per heading walk, its mean heading offset minus the fitted one, rad.
    pub heading_residuals_rad: Vec<f64>,
}

impl MotionCalibration {
    /// Puts the fitted step length and north into `config`.
    pub fn apply(&self, config: &mut MotionConfig) {
        config.step_length = self.step_length;
        let north = self.north();
        config.declination_rad = north.declination_rad;
        config.site_rotation_rad = north.site_rotation_rad;
    }

    /// The site's north: declination folded into the rotation (declination 0), so that the
    /// tracker's site heading, magnetic + declination − rotation, is magnetic + offset.
    pub fn north(&self) -> North {
        North { site_rotation_rad: wrap_angle(-self.heading_offset_rad), declination_rad: 0.0 }
    }
}

/// Fits the step length model and the heading offset on `survey` walks, replaying each
/// through a tracker configured by `base` (its step length model and north are only the
/// starting point: both are re-estimated). `None` when no walk has enough waypoints and steps
/// for a step length; the heading offset falls back to `base`'s when no walk has enough
/// straight walking with a compass.
pub fn calibrate_motion(survey: &[&Trace], base: &MotionConfig) -> Option<MotionCalibration> {
    // Replay with a unit constant step so the tracker's clamps stay out of the way; the
    // models' terms come from each step's period and peak-to-peak.
    let replay_config =
        MotionConfig { step_length: StepLengthModel::Constant { length_m: 1.0 }, ..base.clone() };
    let base_offset = base.declination_rad - base.site_rotation_rad;
    let mut sums = Vec::new();
    let mut walk_offsets = Vec::new();
    for trace in survey {
        let Some(steps) = replay_steps(trace, &replay_config) else { continue };
        if let Some(span) = waypoint_span(trace) {
            let mut s = WalkSums { path_m: trace.path_length_m(), steps: 0.0, frequency: 0.0, weinberg: 0.0 };
            for step in steps_within(&steps, span) {
                s.steps += 1.0;
                s.frequency += frequency(step, base);
                s.weinberg += step.peak_to_peak_mps2.max(0.0).powf(0.25);
            }
            if s.path_m >= MIN_PATH_M && s.steps >= MIN_STEPS as f64 {
                sums.push(s);
            }
        }
        let offsets: Vec<f64> = steps
            .iter()
            .filter_map(|step| {
                let h = step.heading_rad?;
                let (bearing, length, t0, t1) = segment_at(trace, step.timestamp_ns)?;
                let inside = step.timestamp_ns >= t0.saturating_add(TURN_MARGIN_NS)
                    && step.timestamp_ns.saturating_add(TURN_MARGIN_NS) <= t1;
                (length >= MIN_SEGMENT_M && inside).then(|| wrap_angle(h - bearing))
            })
            .collect();
        if offsets.len() >= MIN_HEADING_STEPS {
            if let Some(m) = circular_mean(offsets.iter().copied()) {
                walk_offsets.push(m);
            }
        }
    }
    // Outlying walks (a step detector failure, a surveyor who stopped to chat) by their
    // step-length ratio.
    let ratios: Vec<f64> = sums.iter().map(|s| s.path_m / s.steps).collect();
    let centre = median(&ratios)?;
    let deviations: Vec<f64> = ratios.iter().map(|r| (r - centre).abs()).collect();
    // Floored at 1 % of the median: when most walks agree exactly the MAD is 0 and would
    // reject every walk that differs at all.
    let mad = (1.4826 * median(&deviations)?).max(0.01 * centre);
    let used: Vec<WalkSums> = sums
        .iter()
        .zip(&ratios)
        .filter(|(_, r)| (*r - centre).abs() <= OUTLIER_MADS * mad)
        .map(|(s, _)| *s)
        .collect();
    if used.is_empty() {
        return None;
    }
    let candidates: Vec<ModelFit> = [fit_constant, fit_weinberg, fit_linear]
        .iter()
        .filter_map(|fit| {
            let model = fit(&used)?;
            let errors: Vec<f64> = (0..used.len())
                .filter_map(|k| {
                    let rest: Vec<WalkSums> =
                        used.iter().enumerate().filter(|&(j, _)| j != k).map(|(_, s)| *s).collect();
                    let m = if rest.is_empty() { model } else { fit(&rest)? };
                    Some((predict(&m, &used[k]) - used[k].path_m).abs() / used[k].path_m)
                })
                .collect();
            let mean_error = errors.iter().sum::<f64>() / errors.len().max(1) as f64;
            Some(ModelFit { model, median_error: median(&errors)?, mean_error })
        })
        .collect();
    let best = candidates.iter().min_by(|a, b| a.mean_error.total_cmp(&b.mean_error))?;
    let step_length = best.model;
    let combined = circular_median(&walk_offsets);
    // The tracker reported magnetic + base_offset; subtracting the median offset leaves
    // magnetic + heading_offset matching the bearings.
    let heading_offset_rad = wrap_angle(base_offset - combined.unwrap_or(0.0));
    Some(MotionCalibration {
        step_length,
        heading_offset_rad,
        walks: survey.len(),
        distance_walks: used.len(),
        heading_walks: walk_offsets.len(),
        steps: used.iter().map(|s| s.steps as u64).sum(),
        distance_m: used.iter().map(|s| s.path_m).sum(),
        distance_residuals: used.iter().map(|s| (predict(&step_length, s) - s.path_m) / s.path_m).collect(),
        heading_residuals_rad: walk_offsets
            .iter()
            .map(|&o| wrap_angle(o - combined.unwrap_or(0.0)))
            .collect(),
        candidates,
    })
}

/// The step frequency the tracker's linear model uses: 1 / period, clamped to the cadence
/// range.
fn frequency(step: &StepEvent, config: &MotionConfig) -> f64 {
    if step.period_s > 0.0 {
        (1.0 / step.period_s).clamp(config.min_cadence_hz, config.max_cadence_hz)
    } else {
        config.min_cadence_hz
    }
}

fn predict(model: &StepLengthModel, s: &WalkSums) -> f64 {
    match *model {
        StepLengthModel::Constant { length_m } => length_m * s.steps,
        StepLengthModel::Weinberg { k } => k * s.weinberg,
        StepLengthModel::LinearFrequency { intercept_m, slope_m_per_hz } => {
            intercept_m * s.steps + slope_m_per_hz * s.frequency
        }
    }
}

/// Σ path / Σ steps: the least-squares fit of path = L · steps weighted by 1 / steps (the
/// ratio estimator), which weights walks by their length.
fn fit_constant(walks: &[WalkSums]) -> Option<StepLengthModel> {
    let steps: f64 = walks.iter().map(|s| s.steps).sum();
    (steps > 0.0)
        .then(|| StepLengthModel::Constant { length_m: walks.iter().map(|s| s.path_m).sum::<f64>() / steps })
}

/// k = Σ path / Σ (a_max − a_min)^(1/4), as `fit_constant`.
fn fit_weinberg(walks: &[WalkSums]) -> Option<StepLengthModel> {
    let w: f64 = walks.iter().map(|s| s.weinberg).sum();
    (w > 0.0).then(|| StepLengthModel::Weinberg { k: walks.iter().map(|s| s.path_m).sum::<f64>() / w })
}

/// path = a · steps + b · Σ f by least squares, weighted by 1 / steps (each walk's error
/// variance grows with its number of steps). `None` when the frequencies do not vary.
fn fit_linear(walks: &[WalkSums]) -> Option<StepLengthModel> {
    // Normal equations of Σ w (path − a N − b F)² with w = 1 / N.
    let (mut snn, mut snf, mut sff, mut snp, mut sfp) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for s in walks {
        let w = 1.0 / s.steps;
        snn += w * s.steps * s.steps;
        snf += w * s.steps * s.frequency;
        sff += w * s.frequency * s.frequency;
        snp += w * s.steps * s.path_m;
        sfp += w * s.frequency * s.path_m;
    }
    let det = snn * sff - snf * snf;
    // Also catches NaN.
    if det.is_nan() || det.abs() <= 1e-9 * snn * sff {
        return None;
    }
    let a = (sff * snp - snf * sfp) / det;
    let b = (snn * sfp - snf * snp) / det;
    (a.is_finite() && b.is_finite())
        .then_some(StepLengthModel::LinearFrequency { intercept_m: a, slope_m_per_hz: b })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fits(walks: &[WalkSums]) -> (StepLengthModel, StepLengthModel, StepLengthModel) {
        (fit_constant(walks).unwrap(), fit_weinberg(walks).unwrap(), fit_linear(walks).unwrap())
    }

    #[test]
    fn model_fits_by_hand() {
        // path = 0.3 N + 0.2 F exactly, for walks of various frequencies.
        let walks: Vec<WalkSums> = [(10.0, 18.0), (40.0, 80.0), (25.0, 40.0), (60.0, 100.0)]
            .iter()
            .map(|&(n, f)| WalkSums { path_m: 0.3 * n + 0.2 * f, steps: n, frequency: f, weinberg: 2.0 * n })
            .collect();
        let (constant, weinberg, linear) = fits(&walks);
        let path: f64 = walks.iter().map(|w| w.path_m).sum();
        let n: f64 = walks.iter().map(|w| w.steps).sum();
        assert_eq!(constant, StepLengthModel::Constant { length_m: path / n });
        assert_eq!(weinberg, StepLengthModel::Weinberg { k: path / (2.0 * n) });
        let StepLengthModel::LinearFrequency { intercept_m, slope_m_per_hz } = linear else { panic!() };
        assert!((intercept_m - 0.3).abs() < 1e-9 && (slope_m_per_hz - 0.2).abs() < 1e-9, "{linear:?}");
        for w in &walks {
            assert!((predict(&linear, w) - w.path_m).abs() < 1e-9);
        }
        // All at one frequency: the linear model is not identifiable.
        let flat: Vec<WalkSums> = walks.iter().map(|w| WalkSums { frequency: 2.0 * w.steps, ..*w }).collect();
        assert_eq!(fit_linear(&flat), None);
    }

    #[test]
    fn circular_statistics_wrap() {
        let deg = std::f64::consts::PI / 180.0;
        let m = circular_mean([179.0 * deg, -179.0 * deg]).unwrap();
        assert!(wrap_angle(m - std::f64::consts::PI).abs() < 1e-9, "{m}");
        // The median ignores the outlier; the mean would not.
        let angles = [178.0 * deg, -178.0 * deg, 179.0 * deg, 90.0 * deg, 177.0 * deg];
        assert_eq!(circular_median(&angles), Some(178.0 * deg));
        assert_eq!(circular_median(&[]), None);
    }

    #[test]
    fn nothing_to_calibrate_on() {
        assert!(calibrate_motion(&[], &MotionConfig::default()).is_none());
        let empty = Trace::default();
        assert!(calibrate_motion(&[&empty], &MotionConfig::default()).is_none());
        assert!(replay_steps(&empty, &MotionConfig::default()).is_none());
    }
}
