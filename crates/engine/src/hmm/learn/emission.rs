//! Gaussian-mixture emissions, El Gemayel eq. 7: state i emits o from M_i Gaussians with fixed
//! equal weights 1/M_i (one per cell point of the state, §II-D), each with its own mean and
//! full covariance.

use super::inference::EpochMatrix;
use super::LearnError;
use nalgebra::{SMatrix, SVector};

/// ln 2π.
const LN_2PI: f64 = 1.837_877_066_409_345_5;

/// How far from symmetric a covariance given by a caller may be, relative to its largest entry,
/// before it is refused; accepted ones are symmetrised. Round-off in a covariance computed as
/// a sum of outer products is ~1e-16 relative; 1e-9 also passes matrices printed with 10
/// significant digits.
const SYMMETRY_TOLERANCE: f64 = 1e-9;

/// A D-dimensional Gaussian with its Cholesky factor cached.
#[derive(Clone, Debug, PartialEq)]
pub struct Gaussian<const D: usize> {
    mean: SVector<f64, D>,
    covariance: SMatrix<f64, D, D>,
    /// L⁻¹, where Σ = L Lᵀ.
    whiten: SMatrix<f64, D, D>,
    /// −½ (D ln 2π + ln |Σ|).
    ln_norm: f64,
}

impl<const D: usize> Gaussian<D> {
    /// Checks that the mean is finite and the covariance symmetric positive definite.
    pub fn new(mean: SVector<f64, D>, covariance: SMatrix<f64, D, D>) -> Result<Self, LearnError> {
        Self::checked(mean, covariance, &|| "gaussian".into())
    }

    pub(super) fn checked(
        mean: SVector<f64, D>,
        covariance: SMatrix<f64, D, D>,
        what: &dyn Fn() -> String,
    ) -> Result<Self, LearnError> {
        if let Some(v) = mean.iter().find(|v| !v.is_finite()) {
            return Err(LearnError::NonFinite { what: format!("{} mean", what()), value: *v });
        }
        if let Some(v) = covariance.iter().find(|v| !v.is_finite()) {
            return Err(LearnError::NonFinite { what: format!("{} covariance", what()), value: *v });
        }
        let scale = covariance.amax();
        if (covariance - covariance.transpose()).amax() > SYMMETRY_TOLERANCE * scale {
            return Err(LearnError::NotPositiveDefinite { what: what() });
        }
        let covariance = (covariance + covariance.transpose()) * 0.5;
        let Some(cholesky) = covariance.cholesky() else {
            return Err(LearnError::NotPositiveDefinite { what: what() });
        };
        let l = cholesky.l();
        let ln_det: f64 = 2.0 * l.diagonal().iter().map(|v| v.ln()).sum::<f64>();
        let whiten = l
            .solve_lower_triangular(&SMatrix::<f64, D, D>::identity())
            .ok_or_else(|| LearnError::NotPositiveDefinite { what: what() })?;
        let ln_norm = -0.5 * (D as f64 * LN_2PI + ln_det);
        if !ln_norm.is_finite() || whiten.iter().any(|v| !v.is_finite()) {
            return Err(LearnError::NotPositiveDefinite { what: what() });
        }
        Ok(Self { mean, covariance, whiten, ln_norm })
    }

    /// μ.
    pub fn mean(&self) -> &SVector<f64, D> {
        &self.mean
    }

    /// Σ.
    pub fn covariance(&self) -> &SMatrix<f64, D, D> {
        &self.covariance
    }

    /// ln N(o; μ, Σ).
    pub fn ln_pdf(&self, o: &SVector<f64, D>) -> f64 {
        let z = self.whiten * (o - self.mean);
        self.ln_norm - 0.5 * z.norm_squared()
    }
}

/// Eq. 7 for every state: ln p_i(o) = ln Σ_m (1/M_i) N(o; μ_im, Σ_im).
#[derive(Clone, Debug, PartialEq)]
pub struct GaussianMixtures<const D: usize> {
    /// State i's components are `start[i]..start[i + 1]`.
    start: Vec<usize>,
    components: Vec<Gaussian<D>>,
}

impl<const D: usize> GaussianMixtures<D> {
    /// One list of components per state, each with at least one.
    pub fn new(per_state: Vec<Vec<Gaussian<D>>>) -> Result<Self, LearnError> {
        if per_state.is_empty() {
            return Err(LearnError::Empty("means".into()));
        }
        let mut start = vec![0];
        let mut components = Vec::new();
        for (i, state) in per_state.into_iter().enumerate() {
            if state.is_empty() {
                return Err(LearnError::Empty(format!("means[{i}]")));
            }
            components.extend(state);
            start.push(components.len());
        }
        Ok(Self { start, components })
    }

    pub(super) fn from_parts(start: Vec<usize>, components: Vec<Gaussian<D>>) -> Self {
        Self { start, components }
    }

    /// N.
    pub fn states(&self) -> usize {
        self.start.len() - 1
    }

    /// State i's components.
    pub fn components(&self, i: usize) -> &[Gaussian<D>] {
        &self.components[self.start[i]..self.start[i + 1]]
    }

    /// Every component, state after state.
    pub(super) fn all(&self) -> &[Gaussian<D>] {
        &self.components
    }

    pub(super) fn starts(&self) -> &[usize] {
        &self.start
    }

    /// ln p_i(o), eq. 7.
    pub fn ln_emission(&self, i: usize, o: &SVector<f64, D>) -> f64 {
        // One component per cell point (§II-C): a 4 m × 8 m room on a 1 m grid has 32.
        let mut buffer = [0.0; 32];
        let components = self.components(i);
        if components.len() <= buffer.len() {
            return log_mean_exp(components, o, &mut buffer[..components.len()]);
        }
        log_mean_exp(components, o, &mut vec![0.0; components.len()])
    }

    /// The T × N table ln p_i(o_t) of a sequence. Observations must be finite.
    pub fn log_emissions(&self, observations: &[SVector<f64, D>]) -> EpochMatrix {
        let mut responsibilities = Vec::new();
        self.log_emissions_and_responsibilities(observations, &mut responsibilities)
    }

    /// [`Self::log_emissions`], and in `responsibilities` (T × C, C the components) each
    /// component's share of its state's density, N_m(o_t) / Σ_l N_l(o_t): eq. 13's bracket,
    /// which the E-step would otherwise compute again.
    pub(super) fn log_emissions_and_responsibilities(
        &self,
        observations: &[SVector<f64, D>],
        responsibilities: &mut Vec<f64>,
    ) -> EpochMatrix {
        let (n, c) = (self.states(), self.components.len());
        let mut table = EpochMatrix::zeros(n, observations.len());
        responsibilities.clear();
        responsibilities.resize(c * observations.len(), 0.0);
        for ((t, o), shares) in observations.iter().enumerate().zip(responsibilities.chunks_mut(c.max(1))) {
            for (i, e) in table.row_mut(t).iter_mut().enumerate() {
                let range = self.start[i]..self.start[i + 1];
                let share = &mut shares[range.clone()];
                *e = log_mean_exp(&self.components[range], o, share);
                let total: f64 = share.iter().sum();
                share.iter_mut().for_each(|r| *r /= total);
            }
        }
        table
    }
}

/// ln (1/M Σ_m N_m(o)) of M components; leaves exp(ln N_m(o) − max_m ln N_m(o)) in `scratch`.
fn log_mean_exp<const D: usize>(components: &[Gaussian<D>], o: &SVector<f64, D>, scratch: &mut [f64]) -> f64 {
    let mut max = f64::NEG_INFINITY;
    for (b, g) in scratch.iter_mut().zip(components) {
        *b = g.ln_pdf(o);
        max = max.max(*b);
    }
    let mut sum = 0.0;
    for b in scratch.iter_mut() {
        *b = (*b - max).exp();
        sum += *b;
    }
    max + sum.ln() - (components.len() as f64).ln()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::{Matrix2, Vector2};

    #[test]
    fn density_and_mixture_match_the_closed_form() {
        let sigma = Matrix2::new(2.0, 0.6, 0.6, 1.0);
        let mu = Vector2::new(1.0, -2.0);
        let g = Gaussian::new(mu, sigma).unwrap();
        let o = Vector2::new(0.3, -1.1);
        let d = o - mu;
        let det: f64 = 2.0 - 0.36;
        let quad = d.dot(&(sigma.try_inverse().unwrap() * d));
        let expected = -(2.0 * std::f64::consts::PI).ln() - 0.5 * det.ln() - 0.5 * quad;
        assert_relative_eq!(g.ln_pdf(&o), expected, max_relative = 1e-14);
        let h = Gaussian::new(Vector2::new(4.0, 0.0), Matrix2::identity() * 3.0).unwrap();
        let mix = GaussianMixtures::new(vec![vec![g.clone(), h.clone()], vec![h.clone()]]).unwrap();
        let expected = (0.5 * g.ln_pdf(&o).exp() + 0.5 * h.ln_pdf(&o).exp()).ln();
        assert_relative_eq!(mix.ln_emission(0, &o), expected, max_relative = 1e-14);
        assert_relative_eq!(mix.ln_emission(1, &o), h.ln_pdf(&o), max_relative = 1e-14);
        // Far in the tail: no underflow to −∞.
        assert!(mix.ln_emission(0, &Vector2::new(1e6, 1e6)).is_finite());
    }

    #[test]
    fn bad_covariances_are_refused() {
        let mu = Vector2::zeros();
        for sigma in [
            Matrix2::new(1.0, 2.0, 2.0, 1.0),
            Matrix2::new(1.0, 0.5, 0.0, 1.0),
            Matrix2::zeros(),
            Matrix2::new(f64::NAN, 0.0, 0.0, 1.0),
        ] {
            assert!(Gaussian::new(mu, sigma).is_err(), "{sigma}");
        }
        assert!(matches!(GaussianMixtures::<2>::new(vec![vec![]]), Err(LearnError::Empty(_))));
    }
}
