//! Error metrics of a track against the truth: mean, median, 90th percentile, RMSE, maximum
//! (HIPE Table 5 reports RMSE, mean and maximum), CDF points (Hoang eq. 15), how often the
//! reported accuracy radius held the truth, and room-level accuracy (El Gemayel et al. §II-B:
//! the share of epochs whose most likely zone is the true one).

use crate::scoring::quantile;
use serde::Serialize;

/// One scored epoch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EpochError {
    /// Horizontal distance between estimate and truth, m.
    pub error_m: f64,
    /// The engine's `accuracy_m` for that epoch.
    pub accuracy_m: f64,
    /// Whether the floor was right.
    pub floor_correct: bool,
    /// Whether the most likely zone was the true zone (both "no zone" counts as right);
    /// `None` when the site has no zones.
    pub zone_correct: Option<bool>,
}

/// Summary over many epochs.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ErrorSummary {
    /// Epochs scored.
    pub epochs: usize,
    /// Mean error, m.
    pub mean_error_m: f64,
    /// Median error, m.
    pub median_error_m: f64,
    /// 90th percentile of the error, m.
    pub p90_error_m: f64,
    /// Root mean square error, m.
    pub rmse_m: f64,
    /// Largest error, m.
    pub max_error_m: f64,
    /// Share of epochs with error ≤ accuracy_m: 0.68 when the radius is calibrated.
    pub accuracy_68_hit: f64,
    /// Median reported accuracy radius, m.
    pub median_accuracy_m: f64,
    /// Share of epochs on the right floor.
    pub floor_hit: f64,
    /// Room-level accuracy: the share of epochs whose most likely zone was the true zone
    /// (El Gemayel et al. §II-B), over the epochs scored by zone; `None` when none was.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zone_hit: Option<f64>,
}

impl ErrorSummary {
    /// Summarises `epochs`; every figure is NaN when there are none.
    pub fn new(epochs: &[EpochError]) -> Self {
        let n = epochs.len();
        let mut errors: Vec<f64> = epochs.iter().map(|e| e.error_m).collect();
        errors.sort_by(f64::total_cmp);
        let mut accuracies: Vec<f64> = epochs.iter().map(|e| e.accuracy_m).collect();
        accuracies.sort_by(f64::total_cmp);
        let share = |count: usize| if n == 0 { f64::NAN } else { count as f64 / n as f64 };
        Self {
            epochs: n,
            mean_error_m: errors.iter().sum::<f64>() / n as f64,
            median_error_m: quantile(&errors, 0.5),
            p90_error_m: quantile(&errors, 0.9),
            rmse_m: (errors.iter().map(|e| e * e).sum::<f64>() / n as f64).sqrt(),
            max_error_m: errors.last().copied().unwrap_or(f64::NAN),
            accuracy_68_hit: share(epochs.iter().filter(|e| e.error_m <= e.accuracy_m).count()),
            median_accuracy_m: quantile(&accuracies, 0.5),
            floor_hit: share(epochs.iter().filter(|e| e.floor_correct).count()),
            zone_hit: zone_hit(epochs.iter().map(|e| e.zone_correct)),
        }
    }

    /// CDF of the error (Hoang eq. 15) at `distance_m`: the share of epochs with error ≤ d.
    pub fn cdf(epochs: &[EpochError], distance_m: f64) -> f64 {
        epochs.iter().filter(|e| e.error_m <= distance_m).count() as f64 / epochs.len() as f64
    }
}

/// The share of `true` among the `Some`s; `None` without any.
pub fn zone_hit(correct: impl Iterator<Item = Option<bool>>) -> Option<f64> {
    let (mut scored, mut hits) = (0usize, 0usize);
    for c in correct.flatten() {
        scored += 1;
        hits += usize::from(c);
    }
    (scored > 0).then(|| hits as f64 / scored as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figures_by_hand() {
        let e =
            |error_m, accuracy_m| EpochError { error_m, accuracy_m, floor_correct: true, zone_correct: None };
        let epochs: Vec<EpochError> = (1..=10).map(|k| e(k as f64, 5.0)).collect();
        let s = ErrorSummary::new(&epochs);
        assert_eq!(s.epochs, 10);
        assert_eq!(s.mean_error_m, 5.5);
        assert_eq!(s.median_error_m, 5.0);
        assert_eq!(s.p90_error_m, 9.0);
        assert_eq!(s.max_error_m, 10.0);
        assert_eq!(s.accuracy_68_hit, 0.5);
        assert!((s.rmse_m - (385.0f64 / 10.0).sqrt()).abs() < 1e-12);
        assert_eq!(ErrorSummary::cdf(&epochs, 3.0), 0.3);
        assert!(ErrorSummary::new(&[]).mean_error_m.is_nan());
        assert_eq!(s.zone_hit, None);
        let zoned: Vec<EpochError> = [Some(true), Some(false), None, Some(true), Some(true)]
            .into_iter()
            .map(|zone_correct| EpochError { zone_correct, ..e(1.0, 1.0) })
            .collect();
        assert_eq!(ErrorSummary::new(&zoned).zone_hit, Some(0.75));
    }
}
