//! γ, the weight of the radio in Hoang's likelihood (eq. 3), chosen on held-out survey walks.

use super::held_out::HeldOut;
use super::report::GammaPoint;
use crate::scoring::Scored;

/// γ values the survey's leave-one-walk-out tries: log-spaced from eq. 3's 1 down to 0.003,
/// the value Hoang §6.2 found by jackknife on field data.
pub const GAMMA_GRID: [f64; 6] = [0.003, 0.01, 0.03, 0.1, 0.3, 1.0];

/// M of Hoang eq. 4 (the paper gives no value) the leave-one-walk-out tries at the chosen γ:
/// log-spaced like [`GAMMA_GRID`], from the most likely state alone to 100 states; the whole
/// posterior's mean averages across its modes (docs/tuning.md#mixture-components-m).
pub const ESTIMATE_STATES_GRID: [usize; 5] = [1, 3, 10, 30, 100];

/// The mean error at each γ of [`GAMMA_GRID`] that `walks` have epochs at (run `mask` of each
/// walk's held-out epochs), with the jackknife, and the position in that curve of its least.
pub(super) fn gamma_curve(walks: &[&HeldOut], mask: usize) -> (Vec<GammaPoint>, Option<usize>) {
    let sums: Vec<Vec<(f64, usize)>> = walks
        .iter()
        .map(|w| {
            w.iter().map(|m| (m[mask].iter().map(Scored::penalised_m).sum::<f64>(), m[mask].len())).collect()
        })
        .collect();
    let mut points = Vec::new();
    for (g, &gamma) in GAMMA_GRID.iter().enumerate() {
        let (total, n) = sums.iter().fold((0.0, 0usize), |acc, w| (acc.0 + w[g].0, acc.1 + w[g].1));
        if n == 0 {
            continue;
        }
        let leave_out: Vec<f64> = sums
            .iter()
            .filter(|w| w[g].1 > 0 && w[g].1 < n)
            .map(|w| (total - w[g].0) / (n - w[g].1) as f64)
            .collect();
        let k = leave_out.len() as f64;
        let mean = leave_out.iter().sum::<f64>() / k.max(1.0);
        let se = if k > 1.0 {
            ((k - 1.0) / k * leave_out.iter().map(|t| (t - mean).powi(2)).sum::<f64>()).sqrt()
        } else {
            f64::NAN
        };
        points.push((
            g,
            GammaPoint { gamma, mean_error_m: total / n as f64, jackknife_se_m: se, walks_preferring: 0 },
        ));
    }
    for w in &sums {
        let best = points
            .iter()
            .enumerate()
            .filter(|(_, (g, _))| w[*g].1 > 0)
            .min_by(|a, b| (w[a.1 .0].0 / w[a.1 .0].1 as f64).total_cmp(&(w[b.1 .0].0 / w[b.1 .0].1 as f64)))
            .map(|(k, _)| k);
        if let Some(k) = best {
            points[k].1.walks_preferring += 1;
        }
    }
    let best = (points.iter().enumerate())
        .min_by(|a, b| a.1 .1.mean_error_m.total_cmp(&b.1 .1.mean_error_m))
        .map(|(k, _)| k);
    (points.into_iter().map(|p| p.1).collect(), best)
}

/// A floor's own γ, only when on that floor's held-out walks it beats the site-wide γ by more
/// than its jackknife standard error: the one-standard-error rule of cross-validation
/// (Breiman et al. 1984, §3.4.3; Hastie, Tibshirani & Friedman, *Elements of Statistical
/// Learning* §7.10) preferring the simpler model, one γ for the whole site: each floor's argmin
/// taken outright did worse (`docs/tuning.md#gamma`). `None`: the floor uses the site-wide γ.
pub(super) fn own_gamma(curve: &[GammaPoint], best: Option<usize>, site_wide: Option<f64>) -> Option<f64> {
    let own = curve.get(best?)?;
    let Some(shared) = site_wide.and_then(|g| curve.iter().find(|p| p.gamma == g)) else {
        return Some(own.gamma);
    };
    // A NaN standard error (one walk) never counts as beating it.
    (shared.mean_error_m - own.mean_error_m > own.jackknife_se_m).then_some(own.gamma)
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    #[test]
    fn a_floor_keeps_its_own_gamma_only_beyond_one_standard_error() {
        let point = |gamma, mean_error_m, jackknife_se_m| GammaPoint {
            gamma,
            mean_error_m,
            jackknife_se_m,
            walks_preferring: 0,
        };
        let curve = [point(0.01, 5.0, 0.3), point(0.03, 5.2, 0.3), point(0.1, 6.0, 0.3)];
        // Best 0.01 beats the site-wide 0.03 by 0.2 m, inside its 0.3 m error: site-wide.
        assert_eq!(own_gamma(&curve, Some(0), Some(0.03)), None);
        // By 1.0 m against 0.1: its own.
        assert_eq!(own_gamma(&curve, Some(0), Some(0.1)), Some(0.01));
        // No site-wide γ on the curve: its own; no best: none; one walk (NaN error): site-wide.
        assert_eq!(own_gamma(&curve, Some(0), None), Some(0.01));
        assert_eq!(own_gamma(&curve, None, Some(0.1)), None);
        let lone = [point(0.01, 5.0, f64::NAN), point(0.1, 9.0, f64::NAN)];
        assert_eq!(own_gamma(&lone, Some(0), Some(0.1)), None);
    }

    /// A scored epoch on the right floor with this error.
    pub(in crate::calibrate) fn scored(error_m: f64) -> Scored {
        Scored {
            error_m,
            accuracy_m: 1.0,
            accuracy_95_m: 2.0,
            floor_correct: true,
            zone_correct: None,
            in_zone: None,
            floor_probability: None,
        }
    }

    fn points(errors: &[f64]) -> Vec<Scored> {
        errors.iter().map(|&e| scored(e)).collect()
    }

    /// Three walks scored at the first two γ of the grid (with the motion; nothing without).
    fn walk(first: &[f64], second: &[f64]) -> HeldOut {
        let mut h: HeldOut = vec![Default::default(); GAMMA_GRID.len()];
        h[0][0] = points(first);
        h[1][0] = points(second);
        h
    }

    #[test]
    fn the_gamma_curve_pools_epochs_and_the_jackknife_leaves_out_whole_walks() {
        let walks = [walk(&[1.0, 1.0], &[2.0, 2.0]), walk(&[3.0], &[1.0]), walk(&[2.0; 3], &[3.0; 3])];
        let refs: Vec<&HeldOut> = walks.iter().collect();
        let (curve, best) = gamma_curve(&refs, 0);
        assert_eq!(curve.len(), 2, "γ without epochs are left out");
        assert_eq!(best, Some(0));
        assert_eq!(curve[0].gamma, GAMMA_GRID[0]);
        assert!((curve[0].mean_error_m - 11.0 / 6.0).abs() < 1e-12);
        assert!((curve[1].mean_error_m - 14.0 / 6.0).abs() < 1e-12);
        // Leave-one-walk-out means 9/4, 8/5, 5/3: SE = √(2/3 Σ (θ₋w − θ̄)²).
        assert!((curve[0].jackknife_se_m - 0.412_909_6).abs() < 1e-6, "{curve:?}");
        assert_eq!(curve.iter().map(|p| p.walks_preferring).collect::<Vec<_>>(), [2, 1]);
        // Nothing without the motion.
        assert_eq!(gamma_curve(&refs, 1), (Vec::new(), None));
    }
}
