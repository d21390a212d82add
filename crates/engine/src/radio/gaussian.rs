//! Gaussian RSSI models for one transmitter at one place: the censored-Gaussian EM of
//! Hoang et al. §3 (eqs. 5-8), the naive fit that ignores clipping, and the per-reading
//! likelihood of eq. 10, all in log space.

use serde::{Deserialize, Serialize};
use statrs::function::erf::erfc;

/// ln √(2π).
const LN_SQRT_2PI: f64 = 0.918_938_533_204_672_8;

/// Below this z the normal tail is evaluated by a continued fraction instead of `erfc`, whose
/// relative precision is gone long before it underflows (near z = -38).
const TAIL_Z: f64 = -5.0;

/// A normal distribution of RSSI in dBm.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Gaussian {
    /// Mean, dBm.
    pub mean_dbm: f64,
    /// Standard deviation, dB. Always finite and positive in a validated model.
    pub std_db: f64,
}

/// How RSSI readings at the receiver's clip level are interpreted.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RssiModel {
    /// Hoang eq. 10: a reading at or below the clip level `c` (or a transmitter not heard at
    /// all) means "somewhere below c", with probability I_0 = Φ((c - μ)/σ).
    #[default]
    CensoredGaussian,
    /// The comparison model that disregards censoring: a reading at `c` is an ordinary
    /// Gaussian observation of the value `c`.
    NaiveGaussian,
}

/// Options of the fitting procedures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitOptions {
    /// Receiver clip level c, dBm (Hoang §3: phones report -30 to -100 dBm).
    pub clip_dbm: f64,
    /// Smallest standard deviation a fit may return, dB. Phones report RSSI in whole dBm, so a
    /// spread below one reporting step is not resolvable; it also keeps eq. 10 finite when all
    /// training readings are equal.
    pub min_std_db: f64,
    /// Largest standard deviation a fit may return, dB. A transmitter heard once in a handful
    /// of scans has no finite censored ML fit (σ → ∞ explains one reading and many misses
    /// equally well), and real surveys are made of such columns. `INFINITY` (the default) is
    /// Hoang's unconstrained EM; a survey of real walks caps it
    /// (`docs/site-files.md#surveying`).
    pub max_std_db: f64,
    /// EM steps at most: 500. The EM converges linearly, slowest when most readings are
    /// clipped, and `fit_censored` accelerates it; the property test
    /// `em_recovers_clipped_gaussian` (up to 90% clipped) asserts convergence within this bound
    /// for every case it draws.
    pub max_iterations: usize,
    /// EM stops when μ and σ both move less than this: 1e-4 dB, a hundredth of the 0.01 dB
    /// step a site file stores μ and σ in (`LEVEL_STEP_DB`), and a ten-thousandth of the 1 dBm
    /// phones report RSSI in; what a tighter tolerance would change and cost is measured in
    /// docs/tuning.md#radio-map.
    pub tolerance_db: f64,
}

impl Default for FitOptions {
    fn default() -> Self {
        Self {
            clip_dbm: -100.0,
            min_std_db: 1.0,
            max_std_db: f64::INFINITY,
            max_iterations: 500,
            tolerance_db: 1e-4,
        }
    }
}

/// The outcome of a censored fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CensoredFit {
    /// The estimate, or `None` when every sample was clipped (nothing to fit: Hoang §3 then
    /// uses a mean far below c, the unheard model).
    pub gaussian: Option<Gaussian>,
    /// EM steps taken (the accelerated EM's extrapolated steps included).
    pub iterations: usize,
    /// Whether the tolerance was reached before `max_iterations`.
    pub converged: bool,
}

/// ln φ(z) of the standard normal.
pub fn ln_std_normal_pdf(z: f64) -> f64 {
    -0.5 * z * z - LN_SQRT_2PI
}

/// ln Φ(z), accurate in the far lower tail (no underflow to -inf for any finite z).
pub fn ln_std_normal_cdf(z: f64) -> f64 {
    if z < TAIL_Z {
        // Φ(z) = φ(z) · R(-z), R the Mills ratio.
        ln_std_normal_pdf(z) + mills_ratio(-z).ln()
    } else {
        // Φ(z) = erfc(-z/√2)/2, precise for z ≥ -5; ln_1p keeps precision as Φ → 1.
        let upper = 0.5 * erfc(z / std::f64::consts::SQRT_2);
        if upper < 0.5 {
            (-upper).ln_1p()
        } else {
            (0.5 * erfc(-z / std::f64::consts::SQRT_2)).ln()
        }
    }
}

/// φ(z)/Φ(z), the inverse Mills ratio of the lower tail, stable for every finite z.
pub fn lower_tail_hazard(z: f64) -> f64 {
    if z < TAIL_Z {
        1.0 / mills_ratio(-z)
    } else {
        (ln_std_normal_pdf(z) - ln_std_normal_cdf(z)).exp()
    }
}

/// Mills ratio R(x) = (1 - Φ(x)) / φ(x) for x ≥ 5, by Laplace's continued fraction
/// R(x) = 1/(x + 1/(x + 2/(x + 3/(x + ...)))), evaluated bottom-up; 40 terms give full double
/// precision for x ≥ 5.
fn mills_ratio(x: f64) -> f64 {
    let mut tail = x;
    for k in (1..=40).rev() {
        tail = x + k as f64 / tail;
    }
    1.0 / tail
}

/// Where the table interpolates: z in [-40, 8). Censored-model scores take
/// z = (c - μ)/σ, which on real sites lies within about [-20, 2]; outside the table the exact
/// function is called.
const TABLE_Z: (f64, f64) = (-40.0, 8.0);

/// Table knots per unit of z: 256. Linear interpolation errs by at most h²/8 · max|f″| with
/// |f″| ≤ 1 for ln Φ, under a millionth of what one 1 dBm step of a reading changes; a cubic
/// table on fewer knots is more exact but slower (docs/tuning.md#radio-map).
const TABLE_KNOTS_PER_Z: f64 = 256.0;

/// ln Φ(z) by linear interpolation in a table: several times faster than
/// `ln_std_normal_cdf`, for scoring scans against compact radio maps that do not cache ln Φ
/// per entry. Built once per process ([`LnCdfTable::get`]).
pub struct LnCdfTable {
    /// (ln Φ at each knot, its rise to the next knot).
    knots: Vec<(f64, f64)>,
}

impl LnCdfTable {
    /// The table (built on first use, 192 KB).
    pub fn get() -> &'static LnCdfTable {
        static TABLE: std::sync::OnceLock<LnCdfTable> = std::sync::OnceLock::new();
        TABLE.get_or_init(|| {
            let count = ((TABLE_Z.1 - TABLE_Z.0) * TABLE_KNOTS_PER_Z) as usize;
            let at = |k: usize| ln_std_normal_cdf(TABLE_Z.0 + k as f64 / TABLE_KNOTS_PER_Z);
            let knots = (0..count).map(|k| (at(k), at(k + 1) - at(k))).collect();
            LnCdfTable { knots }
        })
    }

    /// ln Φ(z): interpolated within `TABLE_Z`, exact outside.
    #[inline]
    pub fn ln_cdf(&self, z: f64) -> f64 {
        /// 1.5 · 2^52: adding it rounds a float below 2^51 in magnitude to an integer, which
        /// the low bits of the sum then hold, without the range checks of an `as` conversion
        /// (this lookup is most of the time a scan takes, docs/tuning.md#engine-speed).
        const ROUND: f64 = 6_755_399_441_055_744.0;
        let u = (z - TABLE_Z.0) * TABLE_KNOTS_PER_Z;
        // Below 2^31 the rounded value's low 32 bits are it, in two's complement: below the
        // table they index past its end, and the lookup misses (so does NaN).
        if u.abs() < 2_147_483_648.0 {
            // The knot at or below u: u - 1/2 rounded to a whole number. For a whole u that
            // can be u - 1 (ties round to even); the interpolation then runs to u's own knot.
            let below = (u - 0.5) + ROUND;
            if let Some(&(y, rise)) = self.knots.get(below.to_bits() as u32 as usize) {
                return y + (u - (below - ROUND)) * rise;
            }
        }
        exact_ln_cdf(z)
    }
}

/// [`ln_std_normal_cdf`] out of line, for the table's rare misses.
#[cold]
#[inline(never)]
fn exact_ln_cdf(z: f64) -> f64 {
    ln_std_normal_cdf(z)
}

/// ln Φ(z) through [`LnCdfTable`], for the tests that bound its error.
#[cfg(test)]
fn ln_std_normal_cdf_tabled(z: f64) -> f64 {
    LnCdfTable::get().ln_cdf(z)
}

impl Gaussian {
    /// A model, if both parameters are finite and σ > 0.
    pub fn new(mean_dbm: f64, std_db: f64) -> Option<Self> {
        (mean_dbm.is_finite() && std_db.is_finite() && std_db > 0.0).then_some(Self { mean_dbm, std_db })
    }

    /// ln N(x; μ, σ²).
    pub fn ln_pdf(&self, x: f64) -> f64 {
        ln_std_normal_pdf((x - self.mean_dbm) / self.std_db) - self.std_db.ln()
    }

    /// ln I_0 = ln P(x ≤ c) = ln Φ((c - μ)/σ): the probability that the receiver clips.
    ///
    /// Hoang eq. 8 prints the integral over (-∞, ∞); the censored region, and what eq. 10 needs,
    /// is (-∞, c], so that is what is computed.
    pub fn ln_below(&self, clip_dbm: f64) -> f64 {
        ln_std_normal_cdf((clip_dbm - self.mean_dbm) / self.std_db)
    }
}

impl RssiModel {
    /// ln p(o | state) for one transmitter heard at `rssi_dbm` (Hoang eq. 10).
    pub fn ln_heard(self, model: &Gaussian, rssi_dbm: f64, clip_dbm: f64) -> f64 {
        if rssi_dbm > clip_dbm {
            model.ln_pdf(rssi_dbm)
        } else {
            self.ln_absent(model, clip_dbm)
        }
    }

    /// ln p(o | state) for a transmitter reported at the clip level or not reported at all.
    pub fn ln_absent(self, model: &Gaussian, clip_dbm: f64) -> f64 {
        match self {
            RssiModel::CensoredGaussian => model.ln_below(clip_dbm),
            RssiModel::NaiveGaussian => model.ln_pdf(clip_dbm),
        }
    }

    /// Fits one transmitter's training samples (not-heard samples given as the clip level).
    pub fn fit(self, samples: &[f64], options: &FitOptions) -> Option<Gaussian> {
        match self {
            RssiModel::CensoredGaussian => fit_censored(samples, options).gaussian,
            RssiModel::NaiveGaussian => fit_naive(samples, options),
        }
    }
}

/// Mean and variance of `values` (population variance, as the ML estimate).
fn mean_variance(values: impl Iterator<Item = f64> + Clone) -> (f64, f64, usize) {
    let (sum, n) = values.clone().fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n == 0 {
        return (f64::NAN, f64::NAN, 0);
    }
    let mean = sum / n as f64;
    let var = values.map(|v| (v - mean) * (v - mean)).sum::<f64>() / n as f64;
    (mean, var, n)
}

/// The fit that disregards censoring: sample mean and standard deviation of the readings with
/// clipped ones taken at face value (the "disreg. cens." comparison). `None` for no samples.
pub fn fit_naive(samples: &[f64], options: &FitOptions) -> Option<Gaussian> {
    let clip = options.clip_dbm;
    let (mean, var, n) = mean_variance(samples.iter().map(|&s| s.max(clip)));
    if n == 0 {
        return None;
    }
    Gaussian::new(mean, var.sqrt().clamp(options.min_std_db, options.max_std_db.max(options.min_std_db)))
}

/// The censored-Gaussian EM of Hoang eqs. 6-7 over `samples`, where every sample at or below
/// `options.clip_dbm` counts as clipped (z_i = 1).
///
/// The truncated moments of eq. 8 are taken in closed form: with α = (c - μ)/σ and
/// λ = φ(α)/Φ(α), I_1/I_0 = μ - σλ and I_2/I_0 - 2μ I_1/I_0 + μ² = σ²(1 - αλ).
#[allow(non_snake_case)]
pub fn fit_censored(samples: &[f64], options: &FitOptions) -> CensoredFit {
    let clip = options.clip_dbm;
    let observed = samples.iter().copied().filter(|&s| s > clip);
    let (obs_mean, obs_var, n_obs) = mean_variance(observed.clone());
    let N = samples.len();
    // Start from the fit that puts clipped samples at c: biased, but close, and always finite.
    let (start_mean, start_var, _) = mean_variance(samples.iter().map(|&s| s.max(clip)));
    fit_censored_moments(
        &CensoredMoments {
            samples: N as f64,
            heard: n_obs as f64,
            heard_mean: obs_mean,
            heard_var: obs_var,
            start_mean,
            start_var,
        },
        options,
    )
}

/// What the censored EM needs of a transmitter's samples, possibly weighted (a weight is a
/// share of a sample: unlabelled evidence weighs each scan by where the phone probably was).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CensoredMoments {
    /// The samples' total weight N, clipped ones included.
    pub samples: f64,
    /// The weight of the samples heard above the clip level.
    pub heard: f64,
    /// Their weighted mean, dBm.
    pub heard_mean: f64,
    /// Their weighted population variance, dB².
    pub heard_var: f64,
    /// The weighted mean of all samples with the clipped ones at the clip level, dBm: where the
    /// EM starts.
    pub start_mean: f64,
    /// Their weighted population variance, dB².
    pub start_var: f64,
}

impl CensoredMoments {
    /// The moments of weighted samples given by their sums above the clip level: total weight
    /// `samples`, and of the heard ones their weight, Σ w·(r - c) and Σ w·(r - c)² (a clipped
    /// sample, taken at c, adds nothing to either sum).
    pub fn from_sums_above_clip(samples: f64, heard: f64, sum: f64, sum_squares: f64, clip_dbm: f64) -> Self {
        let (heard_above, start_above) = (sum / heard, sum / samples);
        CensoredMoments {
            samples,
            heard,
            heard_mean: clip_dbm + heard_above,
            heard_var: (sum_squares / heard - heard_above * heard_above).max(0.0),
            start_mean: clip_dbm + start_above,
            start_var: (sum_squares / samples - start_above * start_above).max(0.0),
        }
    }
}

/// The censored EM of [`RssiModel::fit`] (Hoang eqs. 6-7) from the samples' moments: the same
/// steps, for weighted samples too.
#[allow(non_snake_case)]
pub fn fit_censored_moments(moments: &CensoredMoments, options: &FitOptions) -> CensoredFit {
    let clip = options.clip_dbm;
    let CensoredMoments {
        samples: Nf,
        heard: n_obs_f,
        heard_mean: obs_mean,
        heard_var: obs_var,
        start_mean,
        start_var,
    } = *moments;
    let n_clipped_f = Nf - n_obs_f;
    let usable = n_obs_f > 0.0 && Nf.is_finite() && obs_mean.is_finite() && obs_var.is_finite();
    if !usable {
        return CensoredFit { gaussian: None, iterations: 0, converged: true };
    }
    let min_var = options.min_std_db * options.min_std_db;
    // The M-step's variance projected onto [min, max]: for fixed μ the likelihood is unimodal
    // in σ², so the projection is the constrained maximum and the EM stays monotone.
    let max_var = (options.max_std_db * options.max_std_db).max(min_var);
    // Nothing clipped (N is finite and at least the heard weight here).
    if n_clipped_f <= 0.0 {
        return CensoredFit {
            gaussian: Gaussian::new(obs_mean, obs_var.clamp(min_var, max_var).sqrt()),
            iterations: 0,
            converged: true,
        };
    }
    let sum_obs = obs_mean * n_obs_f;
    // One EM step, (μ, σ²) → (μ, σ²).
    let em = |mu: f64, var: f64| -> (f64, f64) {
        let sigma = var.sqrt();
        let alpha = (clip - mu) / sigma;
        let lambda = lower_tail_hazard(alpha);
        let I1_over_I0 = mu - sigma * lambda;
        let centred_second = var * (1.0 - alpha * lambda);
        // Eq. 6.
        let next_mu = (sum_obs + I1_over_I0 * n_clipped_f) / Nf;
        // Eq. 7 (centred on μ^(κ), as printed; the fixed point is the ML estimate either way).
        let observed_ss = obs_var * n_obs_f + n_obs_f * (obs_mean - mu) * (obs_mean - mu);
        let next_var = ((observed_ss + centred_second.max(0.0) * n_clipped_f) / Nf).clamp(min_var, max_var);
        (next_mu, next_var)
    };
    // The censored log-likelihood (up to a constant), which the EM never lowers.
    let ln_likelihood = |mu: f64, var: f64| -> f64 {
        let observed_ss = obs_var * n_obs_f + n_obs_f * (obs_mean - mu) * (obs_mean - mu);
        -0.5 * observed_ss / var - 0.5 * n_obs_f * var.ln()
            + n_clipped_f * ln_std_normal_cdf((clip - mu) / var.sqrt())
    };
    // How far one EM step moved, dB: μ and σ.
    let moved = |a: (f64, f64), b: (f64, f64)| (b.0 - a.0).abs().max((b.1.sqrt() - a.1.sqrt()).abs());
    let mut theta = (start_mean, start_var.clamp(min_var, max_var));
    let mut steps = 0;
    let done = |theta: (f64, f64), steps: usize, converged: bool| CensoredFit {
        gaussian: Gaussian::new(theta.0, theta.1.sqrt()),
        iterations: steps,
        converged,
    };
    // The EM converges linearly, slowly when most readings are clipped: SQUAREM (Varadhan &
    // Roland 2008, scheme S3) extrapolates along two EM steps, steps once more from there, and
    // keeps that point only if the likelihood is no lower than after the two plain steps. The
    // stopping rule is the plain EM's: one step moves μ and σ less than the tolerance.
    loop {
        let mut plain = [theta; 3];
        for k in 1..3 {
            let next = em(plain[k - 1].0, plain[k - 1].1);
            steps += 1;
            if !(next.0.is_finite() && next.1.is_finite()) {
                return done(plain[k - 1], steps, false);
            }
            if moved(plain[k - 1], next) < options.tolerance_db {
                return done(next, steps, true);
            }
            if steps >= options.max_iterations {
                return done(next, steps, false);
            }
            plain[k] = next;
        }
        let r = (plain[1].0 - plain[0].0, plain[1].1 - plain[0].1);
        let v = (plain[2].0 - 2.0 * plain[1].0 + plain[0].0, plain[2].1 - 2.0 * plain[1].1 + plain[0].1);
        let (r_norm, v_norm) = (r.0.hypot(r.1), v.0.hypot(v.1));
        theta = plain[2];
        if v_norm > 0.0 && r_norm.is_finite() && v_norm.is_finite() {
            let a = (-r_norm / v_norm).min(-1.0);
            let jumped = (
                plain[0].0 - 2.0 * a * r.0 + a * a * v.0,
                (plain[0].1 - 2.0 * a * r.1 + a * a * v.1).clamp(min_var, max_var),
            );
            let stabilised = em(jumped.0, jumped.1);
            steps += 1;
            if stabilised.0.is_finite()
                && stabilised.1.is_finite()
                && ln_likelihood(stabilised.0, stabilised.1) >= ln_likelihood(plain[2].0, plain[2].1)
            {
                theta = stabilised;
            }
            if steps >= options.max_iterations {
                return done(theta, steps, false);
            }
        }
    }
}

/// The model of a transmitter never heard above the clip level in `training_scans` scans at a
/// place: Hoang §3 sets "μ ≪ c and σ² an average value" without numbers. Waymark takes the
/// σ given (the map's average) and the μ at which `training_scans` clipped readings in a row
/// are exactly as likely as not: Φ((c - μ)/σ)^n = 1/2, the median-unbiased choice, which moves
/// further below c the more scans found nothing.
pub fn unheard_model(clip_dbm: f64, average_std_db: f64, training_scans: u32) -> Option<Gaussian> {
    let n = f64::from(training_scans.max(1));
    let p_clip_once = 0.5f64.powf(1.0 / n);
    let z = statrs::function::erf::erfc_inv(2.0 * (1.0 - p_clip_once)) * std::f64::consts::SQRT_2;
    Gaussian::new(clip_dbm - z * average_std_db, average_std_db)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use proptest::prelude::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    #[test]
    fn tabled_ln_cdf_matches_exact() {
        let mut worst: f64 = 0.0;
        let mut z = -45.0;
        while z < 12.0 {
            worst = worst.max((ln_std_normal_cdf_tabled(z) - ln_std_normal_cdf(z)).abs());
            z += 0.001_37;
        }
        assert!(worst < 2e-6, "largest error {worst:e}");
        assert_eq!(ln_std_normal_cdf_tabled(-60.0), ln_std_normal_cdf(-60.0));
        assert!(ln_std_normal_cdf_tabled(f64::NAN).is_nan());
    }

    #[test]
    fn ln_cdf_matches_erfc_and_tail() {
        // Reference values of Φ from mpmath at 30 digits. statrs' erfc is good to about 1e-10
        // relative (0.5·erfc(1/√2) = 0.158655253945 against 0.158655253931), far below what
        // matters for a likelihood, so that is the tolerance.
        assert_relative_eq!(ln_std_normal_cdf(0.0), 0.5f64.ln(), epsilon = 1e-15);
        assert_relative_eq!(ln_std_normal_cdf(-1.0), 0.158_655_253_931_457_05f64.ln(), epsilon = 1e-9);
        assert_relative_eq!(ln_std_normal_cdf(-6.0), 9.865_876_450_376_98e-10f64.ln(), epsilon = 1e-10);
        assert_relative_eq!(ln_std_normal_cdf(-40.0), -804.608_442_013_754, epsilon = 1e-9);
        assert!(ln_std_normal_cdf(8.0) < 0.0 && ln_std_normal_cdf(8.0) > -1e-14);
        // The two branches meet continuously at the switch point.
        assert_relative_eq!(ln_std_normal_cdf(-5.0 - 1e-12), ln_std_normal_cdf(-5.0 + 1e-12), epsilon = 1e-9);
    }

    #[test]
    fn hazard_is_continuous_and_asymptotic() {
        assert_relative_eq!(lower_tail_hazard(-5.0 - 1e-12), lower_tail_hazard(-5.0 + 1e-12), epsilon = 1e-9);
        // λ(z) → -z for z → -∞.
        assert_relative_eq!(lower_tail_hazard(-1000.0), 1000.0, max_relative = 1e-5);
        assert_relative_eq!(lower_tail_hazard(0.0), 2.0 * (-LN_SQRT_2PI).exp(), epsilon = 1e-14);
    }

    #[test]
    fn likelihood_matches_hand_computation() {
        let g = Gaussian::new(-80.0, 4.0).unwrap();
        // N(-78; -80, 16) = exp(-0.125)/(4√(2π)).
        let expected = (-0.125f64).exp() / (4.0 * (2.0 * std::f64::consts::PI).sqrt());
        let censored = RssiModel::CensoredGaussian;
        assert_relative_eq!(censored.ln_heard(&g, -78.0, -100.0), expected.ln(), epsilon = 1e-12);
        // At the clip level: Φ((-100 + 80)/4) = Φ(-5) = 2.866515718791939e-7.
        assert_relative_eq!(
            censored.ln_heard(&g, -100.0, -100.0),
            2.866_515_718_791_939e-7f64.ln(),
            epsilon = 1e-9
        );
        assert_relative_eq!(censored.ln_absent(&g, -100.0), 2.866_515_718_791_939e-7f64.ln(), epsilon = 1e-9);
        // The naive model treats -100 as a value: N(-100; -80, 16) = exp(-12.5)/(4√(2π)).
        let naive_at_clip = (-12.5f64).exp() / (4.0 * (2.0 * std::f64::consts::PI).sqrt());
        assert_relative_eq!(
            RssiModel::NaiveGaussian.ln_absent(&g, -100.0),
            naive_at_clip.ln(),
            epsilon = 1e-12
        );
    }

    #[test]
    fn uncensored_fit_is_sample_moments() {
        let samples = [-70.0, -72.0, -74.0, -76.0];
        let fit = fit_censored(&samples, &FitOptions::default());
        let g = fit.gaussian.unwrap();
        assert_relative_eq!(g.mean_dbm, -73.0);
        assert_relative_eq!(g.std_db, 5.0f64.sqrt());
        assert_eq!(fit_naive(&samples, &FitOptions::default()), Some(g));
    }

    #[test]
    fn all_clipped_has_no_fit_and_constant_samples_hit_the_floor() {
        let opts = FitOptions::default();
        assert_eq!(fit_censored(&[-100.0; 10], &opts).gaussian, None);
        assert_eq!(fit_censored(&[], &opts).gaussian, None);
        let g = fit_censored(&[-60.0; 10], &opts).gaussian.unwrap();
        assert_eq!(g, Gaussian::new(-60.0, 1.0).unwrap());
        // One reading heard, nine clipped: finite, below the heard value, σ at least the floor.
        let mut one = vec![-100.0; 9];
        one.push(-97.0);
        let g = fit_censored(&one, &opts).gaussian.unwrap();
        assert!(g.mean_dbm < -97.0 && g.std_db >= 1.0 && g.mean_dbm.is_finite());
    }

    #[test]
    fn unheard_model_is_median_unbiased() {
        let g = unheard_model(-100.0, 5.0, 300).unwrap();
        let p_all_clipped = (300.0 * g.ln_below(-100.0)).exp();
        assert_relative_eq!(p_all_clipped, 0.5, epsilon = 1e-9);
        assert!(g.mean_dbm < -110.0);
        assert!(unheard_model(-100.0, 5.0, 10).unwrap().mean_dbm > g.mean_dbm);
    }

    /// The accelerated EM ends at the likelihood's maximum (no nearby (μ, σ) does better), in
    /// under a hundred steps where most readings are clipped, and at the σ cap when the data ask
    /// for more.
    #[test]
    fn accelerated_em_reaches_the_maximum_quickly() {
        let clip = -94.0;
        let ln_likelihood = |samples: &[f64], mu: f64, sigma: f64| -> f64 {
            samples
                .iter()
                .map(|&s| {
                    let g = Gaussian { mean_dbm: mu, std_db: sigma };
                    RssiModel::CensoredGaussian.ln_heard(&g, s, clip)
                })
                .sum()
        };
        // A transmitter heard in 3 scans of 20 (85% clipped), and in 9 of 12.
        let sparse: Vec<f64> =
            [-88.0, -91.0, -86.0].into_iter().chain(std::iter::repeat_n(clip, 17)).collect();
        let dense: Vec<f64> = [-70.0, -74.0, -69.0, -80.0, -72.0, -77.0, -71.0, -75.0, -73.0]
            .into_iter()
            .chain(std::iter::repeat_n(clip, 3))
            .collect();
        for samples in [&sparse, &dense] {
            let options = FitOptions { clip_dbm: clip, ..FitOptions::default() };
            let fit = fit_censored(samples, &options);
            assert!(fit.converged && fit.iterations <= 100, "{fit:?}");
            let g = fit.gaussian.unwrap();
            let best = ln_likelihood(samples, g.mean_dbm, g.std_db);
            for (dm, ds) in [(0.01, 0.0), (-0.01, 0.0), (0.0, 0.01), (0.0, -0.01)] {
                assert!(ln_likelihood(samples, g.mean_dbm + dm, g.std_db + ds) <= best + 1e-9);
            }
        }
        // Capped: the constrained maximum has σ at the cap.
        let capped = FitOptions { clip_dbm: clip, max_std_db: 2.0, ..FitOptions::default() };
        let fit = fit_censored(&sparse, &capped);
        assert!(fit.converged);
        assert!((fit.gaussian.unwrap().std_db - 2.0).abs() < 1e-9);
    }

    /// Standard errors of a censored Gaussian fit (μ, σ): the square roots of the diagonal of
    /// the inverse observed information, the log-likelihood's Hessian by central differences.
    fn censored_standard_errors(samples: &[f64], clip: f64, mu: f64, sigma: f64) -> (f64, f64) {
        let ln_l = |mu: f64, sigma: f64| -> f64 {
            let g = Gaussian { mean_dbm: mu, std_db: sigma };
            samples.iter().map(|&s| RssiModel::CensoredGaussian.ln_heard(&g, s, clip)).sum()
        };
        let h = 1e-3;
        let centre = ln_l(mu, sigma);
        let d_mm = (ln_l(mu + h, sigma) - 2.0 * centre + ln_l(mu - h, sigma)) / (h * h);
        let d_ss = (ln_l(mu, sigma + h) - 2.0 * centre + ln_l(mu, sigma - h)) / (h * h);
        let d_ms = (ln_l(mu + h, sigma + h) - ln_l(mu + h, sigma - h) - ln_l(mu - h, sigma + h)
            + ln_l(mu - h, sigma - h))
            / (4.0 * h * h);
        // Information I = -Hessian; Var = I⁻¹ for the 2 × 2 case.
        let (i_mm, i_ss, i_ms) = (-d_mm, -d_ss, -d_ms);
        let det = i_mm * i_ss - i_ms * i_ms;
        ((i_ss / det).sqrt(), (i_mm / det).sqrt())
    }

    /// The standard errors match the closed form where nothing is clipped: σ/√n and σ/√(2n).
    #[test]
    fn standard_errors_of_an_unclipped_fit_are_the_textbook_ones() {
        let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(7);
        let normal = Normal::new(-60.0, 4.0).unwrap();
        let samples: Vec<f64> = (0..2000).map(|_| normal.sample(&mut rng)).collect();
        let clip = -120.0;
        let fit = fit_censored(&samples, &FitOptions { clip_dbm: clip, ..FitOptions::default() });
        let g = fit.gaussian.unwrap();
        let (se_mean, se_std) = censored_standard_errors(&samples, clip, g.mean_dbm, g.std_db);
        assert_relative_eq!(se_mean, g.std_db / 2000f64.sqrt(), max_relative = 0.01);
        assert_relative_eq!(se_std, g.std_db / 4000f64.sqrt(), max_relative = 0.01);
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]
        /// The EM recovers μ and σ of clipped draws where the naive fit is biased, for means
        /// near the clip level (Hoang §3: "unbiased and efficient").
        #[test]
        fn em_recovers_clipped_gaussian(mean in -104.0f64..-86.0, std in 3.0f64..8.0, seed in 0u64..1000) {
            let clip = -100.0;
            let mut rng = rand::rngs::ChaCha8Rng::seed_from_u64(seed);
            let normal = Normal::new(mean, std).unwrap();
            let samples: Vec<f64> = (0..4000).map(|_| normal.sample(&mut rng).max(clip)).collect();
            let clipped = samples.iter().filter(|&&s| s <= clip).count() as f64 / samples.len() as f64;
            prop_assume!(clipped < 0.9);
            let opts = FitOptions { clip_dbm: clip, ..FitOptions::default() };
            let fit = fit_censored(&samples, &opts);
            prop_assert!(fit.converged);
            let em = fit.gaussian.unwrap();
            let naive = fit_naive(&samples, &opts).unwrap();
            // The censored MLE's standard errors grow with the clipped share (to ~0.4 dB at
            // 70% of 4000 draws), so the bound is five standard errors from the observed
            // information: a false failure is ~1e-6 per assertion.
            let (se_mean, se_std) = censored_standard_errors(&samples, clip, em.mean_dbm, em.std_db);
            prop_assert!((em.mean_dbm - mean).abs() < 5.0 * se_mean,
                "em mean {} vs {} (SE {se_mean})", em.mean_dbm, mean);
            prop_assert!((em.std_db - std).abs() < 5.0 * se_std,
                "em std {} vs {} (SE {se_std})", em.std_db, std);
            // The naive fit pulls the mean up and shrinks σ. With α = (c - μ)/σ its mean bias is
            // σ(φ(α) + αΦ(α)): 0.19σ ≥ 0.57 dB once 30% is clipped.
            if clipped > 0.3 {
                prop_assert!(naive.mean_dbm - mean > 0.4, "naive mean {} vs {}", naive.mean_dbm, mean);
                prop_assert!(std - naive.std_db > 0.4, "naive std {} vs {}", naive.std_db, std);
                prop_assert!((em.mean_dbm - mean).abs() < (naive.mean_dbm - mean).abs());
            }
        }
    }
}
