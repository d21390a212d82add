//! Baum-Welch (El Gemayel §III-A, after Rabiner): re-estimate π, the allowed transitions
//! (eq. 10) and the mixture components' means and covariances (eqs. 11-13) from the smoothed
//! posteriors of one or more sequences, until the likelihood stops improving.

use super::chain::Chain;
use super::emission::{Gaussian, GaussianMixtures};
use super::inference::{backward, forward_into, EpochMatrix, Known, Scratch};
use super::LearnError;
use nalgebra::{SMatrix, SVector};

/// An HMM with Gaussian-mixture emissions (eq. 7).
#[derive(Clone, Debug, PartialEq)]
pub struct GaussianHmm<const D: usize> {
    chain: Chain,
    emission: GaussianMixtures<D>,
}

impl<const D: usize> GaussianHmm<D> {
    /// Checks that the chain and the emissions have the same states.
    pub fn new(chain: Chain, emission: GaussianMixtures<D>) -> Result<Self, LearnError> {
        if emission.states() != chain.states() {
            return Err(LearnError::Dimension {
                what: "means".into(),
                expected: chain.states(),
                got: emission.states(),
            });
        }
        Ok(Self { chain, emission })
    }

    /// π and A.
    pub fn chain(&self) -> &Chain {
        &self.chain
    }

    /// The mixtures.
    pub fn emission(&self) -> &GaussianMixtures<D> {
        &self.emission
    }

    /// ln p_i(o_t) for a sequence, with its feedback applied.
    pub fn log_emissions(&self, sequence: &Sequence<D>) -> Result<EpochMatrix, LearnError> {
        let mut e = self.emission.log_emissions(&sequence.observations);
        e.pin(&sequence.known)?;
        Ok(e)
    }
}

/// One observation sequence, with the epochs at which the user said where they were.
#[derive(Clone, Debug, PartialEq)]
pub struct Sequence<const D: usize> {
    /// o_1..o_T.
    pub observations: Vec<SVector<f64, D>>,
    /// User feedback (§IV-C), in any order.
    pub known: Vec<Known>,
}

impl<const D: usize> Sequence<D> {
    /// A sequence without feedback.
    pub fn new(observations: Vec<SVector<f64, D>>) -> Self {
        Self { observations, known: Vec::new() }
    }
}

/// How [`fit`] runs.
#[derive(Clone, Debug, PartialEq)]
pub struct FitOptions {
    /// At most this many re-estimations.
    pub max_iterations: usize,
    /// Stop when an iteration improves ln p(o | θ) by less than this many nats per observation;
    /// `None` runs all `max_iterations`.
    pub tolerance: Option<f64>,
    /// Added to the expected number of sequences starting in each state where π_i > 0 (a
    /// Dirichlet prior); states with π_i = 0 stay at 0.
    pub initial_pseudocount: f64,
    /// Added to the expected count of every allowed transition (a Dirichlet prior on each row);
    /// structural zeros stay zero.
    pub transition_pseudocount: f64,
    /// Added to the diagonal of every re-estimated covariance (as scikit-learn's `reg_covar`),
    /// in the observations' units squared.
    pub covariance_floor: f64,
    /// Eigenvalues of a re-estimated covariance below this are raised to it, so that no
    /// component can collapse onto a few observations. 0 disables it.
    pub min_variance: f64,
    /// When the user names a state the model rules out (its predicted probability is zero,
    /// so the pinned forward variable of §IV-C would be 0 everywhere), restart the
    /// sequence there from the named states instead of failing: the transition into that
    /// epoch is not counted and the epochs before it end a segment.
    pub restart_on_contradicted_feedback: bool,
    /// Re-estimate the transitions; with `false` they stay as given (El Gemayel Fig. 4: the
    /// transition matrix known, the emissions learned).
    pub learn_transitions: bool,
    /// τ, the weight in observations of a Gaussian prior on each component's mean, centred on
    /// the mean the component had when [`fit`] was called: eq. 11 becomes the maximum a
    /// posteriori estimate μ̂ = (τ μ₀ + Σ_t γ_im(t) o_t) / (τ + Σ_t γ_im(t)) (Gauvain & Lee,
    /// "Maximum a posteriori estimation for multivariate Gaussian mixture observations of
    /// Markov chains", 1994; Reynolds, Quatieri & Dunn, "Speaker verification using adapted
    /// Gaussian mixture models", 2000, their relevance factor), and eq. 12 is taken around μ̂.
    /// A component that explains many observations moves to them; one that explains a few
    /// (a cell of a room the walks rarely enter) stays near where it started instead of
    /// jumping to the weighted mean of whatever its state's tiny posterior touches. 0 is
    /// eq. 11 itself.
    pub mean_prior_weight: f64,
}

impl FitOptions {
    /// Plain maximum likelihood, as the JSON `fit` runs it ([`super::json`]): exactly `iterations`
    /// re-estimations, no priors, and only 1e-9 added to the covariances' diagonals (so a
    /// component fitted to one point stays invertible).
    pub fn maximum_likelihood(iterations: usize) -> Self {
        Self {
            max_iterations: iterations,
            tolerance: None,
            initial_pseudocount: 0.0,
            transition_pseudocount: 0.0,
            covariance_floor: 1e-9,
            min_variance: 0.0,
            restart_on_contradicted_feedback: false,
            learn_transitions: true,
            mean_prior_weight: 0.0,
        }
    }
}

impl Default for FitOptions {
    /// The regularised fit for the live engine, positions in metres. Each value is chosen on
    /// the simulated Baum-Welch experiment (El Gemayel §IV); the sweep and its figures are in
    /// `docs/tuning.md#baum-welch-options`.
    fn default() -> Self {
        Self {
            // The paper stops when "the improvement of the likelihood is negligible" (§III-A.3).
            tolerance: Some(1e-3),
            // A bound only, above what any run needs.
            max_iterations: 50,
            // A tenth of an observed move on every allowed transition, so that none vanishes
            // and feedback is rarely ruled out.
            transition_pseudocount: 0.1,
            // π is the row out of "before the first epoch": the same prior as a transition row.
            initial_pseudocount: 0.1,
            covariance_floor: 1e-9,
            // The spread of a position uniform over a 1 m × 1 m cell (El Gemayel §IV's cell
            // size), 1/12 m² per axis: a component stands for one cell, and its observations
            // vary at least as much as the true positions inside it.
            min_variance: 1.0 / 12.0,
            restart_on_contradicted_feedback: true,
            learn_transitions: true,
            // Reynolds et al.'s relevance factor, 16 (their adaptation of a Gaussian mixture to a
            // speaker's little data). Without a prior, eq. 15's wide Σ lets eq. 11 move every
            // component to the walks' mean and the states lose their place on the floor.
            mean_prior_weight: 16.0,
        }
    }
}

/// What [`fit`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct FitReport {
    /// ln p(o | θ) summed over the sequences, before each re-estimation and for the returned
    /// model (last entry): `iterations + 1` values.
    pub log_likelihood: Vec<f64>,
    /// Re-estimations made.
    pub iterations: usize,
    /// Whether it stopped on the tolerance.
    pub converged: bool,
    /// Transition rows left as they were, summed over the iterations: the state had no
    /// expected visit (and no pseudo-count).
    pub unvisited_rows: usize,
    /// Components left as they were, summed over the iterations: no responsibility at all, or
    /// a re-estimated covariance that was not positive definite.
    pub kept_components: usize,
    /// Feedback epochs at which a sequence was restarted, summed over the E-steps (see
    /// [`FitOptions::restart_on_contradicted_feedback`]).
    pub restarts: usize,
}

/// The expected counts of an E-step, from which the M-step re-estimates (eqs. 10-12).
struct SufficientStatistics<const D: usize> {
    /// Expected sequence starts per state.
    initial: Vec<f64>,
    /// Σ_t ξ_t(i, j) per allowed transition.
    transition: Vec<f64>,
    /// Σ_t γ_im(t) per component (eq. 13).
    weight: Vec<f64>,
    /// Σ_t γ_im(t) o_t / Σ_t γ_im(t).
    mean: Vec<SVector<f64, D>>,
    /// Σ_t γ_im(t) (o_t − mean)(o_t − mean)ᵀ.
    scatter: Vec<SMatrix<f64, D, D>>,
}

/// One E-step's result.
struct Expectation<const D: usize> {
    log_likelihood: f64,
    /// Feedback epochs at which a sequence restarted.
    restarts: usize,
    statistics: SufficientStatistics<D>,
}

fn check_sequences<const D: usize>(states: usize, sequences: &[Sequence<D>]) -> Result<(), LearnError> {
    if sequences.is_empty() {
        return Err(LearnError::Empty("observations".into()));
    }
    for (s, sequence) in sequences.iter().enumerate() {
        if sequence.observations.is_empty() {
            return Err(LearnError::Empty(format!("observations[{s}]")));
        }
        for (t, o) in sequence.observations.iter().enumerate() {
            if let Some(v) = o.iter().find(|v| !v.is_finite()) {
                return Err(LearnError::NonFinite { what: format!("observations[{s}][{t}]"), value: *v });
            }
        }
        for (k, fact) in sequence.known.iter().enumerate() {
            if fact.epoch >= sequence.observations.len() {
                return Err(LearnError::Dimension {
                    what: format!("known[{s}][{k}].epoch"),
                    expected: sequence.observations.len(),
                    got: fact.epoch + 1,
                });
            }
            if let Some(&state) = fact.states.iter().find(|&&i| i as usize >= states) {
                return Err(LearnError::StateOutOfRange {
                    what: format!("known[{s}][{k}]"),
                    state: state as usize,
                    states,
                });
            }
        }
    }
    Ok(())
}

/// ln p(o | θ) summed over the sequences (forward pass only), the feedback applied; a
/// sequence whose feedback the model rules out is an error.
pub fn log_likelihood<const D: usize>(
    model: &GaussianHmm<D>,
    sequences: &[Sequence<D>],
) -> Result<f64, LearnError> {
    check_sequences(model.chain.states(), sequences)?;
    let mut scratch = Scratch::default();
    let mut total = 0.0;
    let mut alpha = None;
    for (s, sequence) in sequences.iter().enumerate() {
        let e = model.log_emissions(sequence)?;
        let forward = forward_into(&model.chain, &e, s, &mut scratch, alpha.take(), &[])?;
        total += forward.log_likelihood;
        alpha = Some(forward.log_alpha);
    }
    Ok(total)
}

/// The epochs with feedback, ascending.
fn feedback_epochs<const D: usize>(sequence: &Sequence<D>) -> Vec<usize> {
    let mut epochs: Vec<usize> = sequence.known.iter().map(|k| k.epoch).collect();
    epochs.sort_unstable();
    epochs
}

/// The E-step: smoothed posteriors of every sequence, summed into expected counts.
fn expect<const D: usize>(
    model: &GaussianHmm<D>,
    sequences: &[Sequence<D>],
    scratch: &mut Scratch,
    restart: bool,
) -> Result<Expectation<D>, LearnError> {
    let components = model.emission.all();
    let starts = model.emission.starts();
    let (mut log_likelihood, mut restarts) = (0.0, 0);
    let mut initial = vec![0.0; model.chain.states()];
    let mut transition = vec![0.0; model.chain.transition().allowed()];
    let mut weight = vec![0.0; components.len()];
    // Σ γ (o − μ) and Σ γ (o − μ)(o − μ)ᵀ around each component's current mean μ, which the
    // new mean is near: no cancellation of large raw moments.
    let mut first = vec![SVector::<f64, D>::zeros(); components.len()];
    let mut second = vec![SMatrix::<f64, D, D>::zeros(); components.len()];
    let mut shares = Vec::new();
    let mut alpha = None;
    for (s, sequence) in sequences.iter().enumerate() {
        let mut e = model.emission.log_emissions_and_responsibilities(&sequence.observations, &mut shares);
        e.pin(&sequence.known)?;
        let restartable = if restart { feedback_epochs(sequence) } else { Vec::new() };
        let forward = forward_into(&model.chain, &e, s, scratch, alpha.take(), &restartable)?;
        log_likelihood += forward.log_likelihood;
        restarts += forward.restarts.len();
        let (initial, transition, weight, first, second) =
            (&mut initial, &mut transition, &mut weight, &mut first, &mut second);
        backward(&model.chain, &e, &forward, scratch, Some(transition), |t, gamma| {
            if t == 0 {
                for (p, &g) in initial.iter_mut().zip(gamma) {
                    *p += g;
                }
            }
            let o = &sequence.observations[t];
            let shares = &shares[t * components.len()..(t + 1) * components.len()];
            for (i, &g) in gamma.iter().enumerate() {
                if g == 0.0 {
                    continue;
                }
                // Eq. 13: γ_im(t) = γ_i(t) · N_m(o_t) / Σ_l N_l(o_t) (the weights 1/M_i cancel).
                for c in starts[i]..starts[i + 1] {
                    let r = g * shares[c];
                    if r == 0.0 {
                        continue;
                    }
                    let d = o - components[c].mean();
                    weight[c] += r;
                    first[c] += d * r;
                    second[c] += d * d.transpose() * r;
                }
            }
        });
        alpha = Some(forward.log_alpha);
    }
    // Mean = μ + d̄ and scatter = Σ γ (o − μ)(o − μ)ᵀ − w d̄ d̄ᵀ, d̄ = Σ γ (o − μ) / w.
    let mut mean = Vec::with_capacity(components.len());
    let mut scatter = Vec::with_capacity(components.len());
    for (c, component) in components.iter().enumerate() {
        let w = weight[c];
        if w > 0.0 {
            let d = first[c] / w;
            mean.push(component.mean() + d);
            scatter.push(second[c] - d * d.transpose() * w);
        } else {
            mean.push(*component.mean());
            scatter.push(SMatrix::zeros());
        }
    }
    let statistics = SufficientStatistics { initial, transition, weight, mean, scatter };
    Ok(Expectation { log_likelihood, restarts, statistics })
}

/// The M-step (eqs. 10-12), with the options' priors and floors.
fn maximise<const D: usize>(
    model: &GaussianHmm<D>,
    prior: &GaussianMixtures<D>,
    stats: &SufficientStatistics<D>,
    options: &FitOptions,
    report: &mut FitReport,
) -> Result<GaussianHmm<D>, LearnError> {
    // π: expected starts.
    let old = model.chain.initial();
    let pseudo = |i: usize| if old[i] > 0.0 { options.initial_pseudocount } else { 0.0 };
    let counts: Vec<f64> = (0..old.len()).map(|i| stats.initial[i] + pseudo(i)).collect();
    let total: f64 = counts.iter().sum();
    let initial = if total > 0.0 && total.is_finite() {
        counts.iter().map(|c| c / total).collect()
    } else {
        old.to_vec()
    };

    // Eq. 10, row by row over the allowed transitions.
    let transition = model.chain.transition();
    let mut probability = transition.probabilities().to_vec();
    for i in (0..transition.states()).filter(|_| options.learn_transitions) {
        let range = transition.row_range(i);
        let kappa = options.transition_pseudocount;
        let total: f64 = stats.transition[range.clone()].iter().map(|c| c + kappa).sum();
        if total > 0.0 && total.is_finite() {
            for k in range {
                probability[k] = (stats.transition[k] + kappa) / total;
            }
        } else {
            report.unvisited_rows += 1;
        }
    }
    let chain = Chain::new(initial, transition.with_probabilities(probability))?;

    // Eqs. 11-12: μ̂ = Σγo / Σγ, Σ̂ = Σγ(o − μ̂)(o − μ̂)ᵀ / Σγ; with a prior of weight τ on the
    // mean μ̂ = (τ μ₀ + Σγo) / (τ + Σγ), and Σγ(o − μ̂)(o − μ̂)ᵀ = S + Σγ (ō − μ̂)(ō − μ̂)ᵀ, S
    // the scatter around the weighted mean ō.
    let tau = options.mean_prior_weight;
    let mut components = Vec::with_capacity(model.emission.all().len());
    for (c, old) in model.emission.all().iter().enumerate() {
        let w = stats.weight[c];
        let new = (w > 0.0).then(|| {
            let (mut mean, mut sigma) = (stats.mean[c], stats.scatter[c] / w);
            if tau > 0.0 {
                let shift = (stats.mean[c] - prior.all()[c].mean()) * (tau / (tau + w));
                mean -= shift;
                sigma += shift * shift.transpose();
            }
            sigma = (sigma + sigma.transpose()) * 0.5;
            if options.min_variance > 0.0 {
                sigma = raise_eigenvalues(sigma, options.min_variance);
            }
            for k in 0..D {
                sigma[(k, k)] += options.covariance_floor;
            }
            Gaussian::checked(mean, sigma, &String::new).ok()
        });
        match new.flatten() {
            Some(g) => components.push(g),
            None => {
                report.kept_components += 1;
                components.push(old.clone());
            }
        }
    }
    let emission = GaussianMixtures::from_parts(model.emission.starts().to_vec(), components);
    GaussianHmm::new(chain, emission)
}

/// Σ with its eigenvalues raised to at least `floor`.
fn raise_eigenvalues<const D: usize>(sigma: SMatrix<f64, D, D>, floor: f64) -> SMatrix<f64, D, D> {
    // nalgebra's symmetric eigensolver needs a type-level dimension; a D × D copy is cheap.
    let eigen = nalgebra::DMatrix::from_column_slice(D, D, sigma.as_slice()).symmetric_eigen();
    if eigen.eigenvalues.iter().all(|&l| l >= floor) {
        return sigma;
    }
    let raised = eigen.eigenvalues.map(|l| l.max(floor));
    let v = eigen.eigenvectors;
    let raised = &v * nalgebra::DMatrix::from_diagonal(&raised) * v.transpose();
    SMatrix::from_column_slice(raised.as_slice())
}

/// Baum-Welch from `model` on `sequences`: E-step (forward-backward per sequence, expected
/// counts summed over sequences as in Rabiner §V-B) and M-step, repeated until an iteration
/// improves the log-likelihood by less than the tolerance or `max_iterations` is reached.
///
/// Returns the re-estimated model; `model` is not changed, and on an error nothing is returned.
/// A state with no expected visit keeps its transition row, and a component with no
/// responsibility keeps its mean and covariance (the maximum-likelihood estimate is undefined
/// there).
pub fn fit<const D: usize>(
    model: &GaussianHmm<D>,
    sequences: &[Sequence<D>],
    options: &FitOptions,
) -> Result<(GaussianHmm<D>, FitReport), LearnError> {
    check_sequences(model.chain.states(), sequences)?;
    for (name, value) in [
        ("initial_pseudocount", options.initial_pseudocount),
        ("transition_pseudocount", options.transition_pseudocount),
        ("covariance_floor", options.covariance_floor),
        ("min_variance", options.min_variance),
        ("mean_prior_weight", options.mean_prior_weight),
        ("tolerance", options.tolerance.unwrap_or(0.0)),
    ] {
        if !(value.is_finite() && value >= 0.0) {
            return Err(LearnError::NonFinite { what: format!("options.{name}"), value });
        }
    }
    let observations: usize = sequences.iter().map(|s| s.observations.len()).sum();
    let mut report = FitReport {
        log_likelihood: Vec::new(),
        iterations: 0,
        converged: false,
        unvisited_rows: 0,
        kept_components: 0,
        restarts: 0,
    };
    let mut scratch = Scratch::default();
    let mut current = model.clone();
    loop {
        let e = expect(&current, sequences, &mut scratch, options.restart_on_contradicted_feedback)?;
        report.restarts += e.restarts;
        let improved = match (options.tolerance, report.log_likelihood.last()) {
            (Some(tolerance), Some(&previous)) => {
                e.log_likelihood - previous >= tolerance * observations as f64
            }
            _ => true,
        };
        report.log_likelihood.push(e.log_likelihood);
        if !improved {
            report.converged = true;
        }
        if !improved || report.iterations == options.max_iterations {
            return Ok((current, report));
        }
        current = maximise(&current, model.emission(), &e.statistics, options, &mut report)?;
        report.iterations += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::super::chain::SparseTransition;
    use super::*;
    use approx::assert_relative_eq;
    use nalgebra::{Matrix2, Vector2};
    use rand::rngs::ChaCha8Rng;
    use rand::{RngExt, SeedableRng};
    use rand_distr::{Distribution, StandardNormal};

    fn gaussian(x: f64, y: f64, s: f64) -> Gaussian<2> {
        Gaussian::new(Vector2::new(x, y), Matrix2::identity() * s).unwrap()
    }

    /// Two rooms 10 m apart, one component each, sticky transitions.
    fn truth() -> GaussianHmm<2> {
        let a = SparseTransition::from_dense(&[vec![0.9, 0.1], vec![0.2, 0.8]]).unwrap();
        let chain = Chain::new(vec![0.5, 0.5], a).unwrap();
        GaussianHmm::new(
            chain,
            GaussianMixtures::new(vec![vec![gaussian(0.0, 0.0, 1.0)], vec![gaussian(10.0, 0.0, 4.0)]])
                .unwrap(),
        )
        .unwrap()
    }

    fn sample(model: &GaussianHmm<2>, len: usize, seed: u64) -> (Vec<u32>, Sequence<2>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut draw = |p: &[f64]| {
            let u: f64 = rng.random_range(0.0..1.0);
            let mut acc = 0.0;
            for (i, &q) in p.iter().enumerate() {
                acc += q;
                if u < acc {
                    return i;
                }
            }
            p.len() - 1
        };
        let dense = model.chain().transition().to_dense();
        let mut s = draw(model.chain().initial());
        let mut states = Vec::new();
        let mut observations = Vec::new();
        let mut normal_rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed);
        for _ in 0..len {
            states.push(s as u32);
            let g = &model.emission().components(s)[0];
            let z =
                Vector2::new(StandardNormal.sample(&mut normal_rng), StandardNormal.sample(&mut normal_rng));
            let l = g.covariance().cholesky().unwrap().l();
            observations.push(g.mean() + l * z);
            s = draw(&dense[s]);
        }
        (states, Sequence::new(observations))
    }

    #[test]
    fn likelihood_never_decreases_and_recovers_the_truth() {
        let truth = truth();
        let sequences: Vec<_> = (0..4).map(|k| sample(&truth, 400, k).1).collect();
        let a = SparseTransition::from_dense(&[vec![0.5, 0.5], vec![0.5, 0.5]]).unwrap();
        let start = GaussianHmm::new(
            Chain::new(vec![0.5, 0.5], a).unwrap(),
            GaussianMixtures::new(vec![vec![gaussian(2.0, 1.0, 25.0)], vec![gaussian(7.0, -1.0, 25.0)]])
                .unwrap(),
        )
        .unwrap();
        let (learned, report) = fit(&start, &sequences, &FitOptions::maximum_likelihood(60)).unwrap();
        assert_eq!(report.log_likelihood.len(), 61);
        for w in report.log_likelihood.windows(2) {
            assert!(w[1] >= w[0] - 1e-9 * w[0].abs(), "{:?}", report.log_likelihood);
        }
        let a = learned.chain().transition();
        assert!((a.get(0, 0) - 0.9).abs() < 0.03 && (a.get(1, 1) - 0.8).abs() < 0.04, "{:?}", a.to_dense());
        let m = learned.emission().components(1)[0].mean();
        assert!((m - Vector2::new(10.0, 0.0)).norm() < 0.2, "{m}");
        let s = learned.emission().components(1)[0].covariance();
        assert!((s[(0, 0)] - 4.0).abs() < 0.4, "{s}");
        // The input model is untouched.
        assert_eq!(start.chain().transition().get(0, 0), 0.5);
    }

    #[test]
    fn structural_zeros_stay_zero_and_pseudocounts_keep_rows_alive() {
        let truth = truth();
        let sequences = vec![sample(&truth, 300, 9).1];
        // State 2 can never be reached: no expected visit, no data for its component.
        let a =
            SparseTransition::from_dense(&[vec![0.5, 0.5, 0.0], vec![0.5, 0.5, 0.0], vec![0.3, 0.3, 0.4]])
                .unwrap();
        let emission = GaussianMixtures::new(vec![
            vec![gaussian(1.0, 0.0, 9.0), gaussian(-1.0, 0.0, 9.0)],
            vec![gaussian(9.0, 0.0, 9.0)],
            vec![gaussian(50.0, 50.0, 1.0)],
        ])
        .unwrap();
        let start = GaussianHmm::new(Chain::new(vec![0.5, 0.5, 0.0], a).unwrap(), emission).unwrap();
        let (ml, report) = fit(&start, &sequences, &FitOptions::maximum_likelihood(5)).unwrap();
        let dense = ml.chain().transition().to_dense();
        assert_eq!(dense[0][2], 0.0);
        assert_eq!(dense[1][2], 0.0);
        assert_eq!(dense[2], vec![0.3, 0.3, 0.4]);
        assert_eq!(ml.chain().initial()[2], 0.0);
        assert_eq!(ml.emission().components(2)[0], start.emission().components(2)[0]);
        assert_eq!(report.unvisited_rows, 5);
        assert_eq!(report.kept_components, 5);
        let (map, _) = fit(&start, &sequences, &FitOptions::default()).unwrap();
        let row = map.chain().transition().row(2).1.to_vec();
        assert_relative_eq!(row.iter().sum::<f64>(), 1.0, epsilon = 1e-12);
        assert_eq!(map.chain().transition().get(0, 2), 0.0);
    }

    #[test]
    fn covariances_never_collapse_with_the_default_options() {
        // One observation per component: maximum likelihood collapses it onto the point.
        let a = SparseTransition::from_dense(&[vec![1.0]]).unwrap();
        let emission =
            GaussianMixtures::new(vec![vec![gaussian(0.0, 0.0, 1.0), gaussian(5.0, 0.0, 1.0)]]).unwrap();
        let start = GaussianHmm::new(Chain::new(vec![1.0], a).unwrap(), emission).unwrap();
        let seq = vec![Sequence::new(vec![Vector2::new(0.1, 0.2), Vector2::new(5.0, 0.3)])];
        let (ml, _) = fit(&start, &seq, &FitOptions::maximum_likelihood(20)).unwrap();
        let collapsed = ml.emission().components(0)[0].covariance().symmetric_eigenvalues().min();
        // (Matrix2 has a type-level dimension, so its eigenvalues are available directly.)
        assert!(collapsed < 1e-6, "{collapsed}");
        let (map, report) = fit(&start, &seq, &FitOptions::default()).unwrap();
        for g in map.emission().components(0) {
            assert!(g.covariance().symmetric_eigenvalues().min() >= 1.0 / 12.0 - 1e-12);
        }
        assert!(report.log_likelihood.iter().all(|l| l.is_finite()));
    }

    #[test]
    fn the_mean_prior_keeps_rarely_used_components_where_they_started() {
        // Two components far apart; every observation is near the first one.
        let a = SparseTransition::from_dense(&[vec![1.0]]).unwrap();
        let emission =
            GaussianMixtures::new(vec![vec![gaussian(0.0, 0.0, 4.0), gaussian(20.0, 0.0, 4.0)]]).unwrap();
        let start = GaussianHmm::new(Chain::new(vec![1.0], a).unwrap(), emission).unwrap();
        let observations: Vec<_> = (0..40).map(|k| Vector2::new(0.1 * (k % 5) as f64, 0.0)).collect();
        let seq = vec![Sequence::new(observations)];
        let one = |tau: f64| {
            let options = FitOptions { mean_prior_weight: tau, ..FitOptions::maximum_likelihood(1) };
            fit(&start, &seq, &options).unwrap().0
        };
        // Eq. 11: the far component's tiny responsibility puts it on the data's weighted mean.
        let ml = one(0.0);
        assert!(ml.emission().components(0)[1].mean().x < 1.0, "{}", ml.emission().components(0)[1].mean());
        // With the prior it barely moves, and eq. 12 is taken around its new mean.
        let map = one(16.0);
        let far = &map.emission().components(0)[1];
        assert!((far.mean() - Vector2::new(20.0, 0.0)).norm() < 1e-3, "{}", far.mean());
        assert!(far.covariance()[(0, 0)] > 300.0, "{}", far.covariance());
        // The near component, with ~40 observations, moves most of the way: μ̂ = (τ μ₀ + w ō) / (τ + w).
        let near = map.emission().components(0)[0].mean().x;
        let (w, o) = (40.0, 0.2);
        assert!((near - w * o / (16.0 + w)).abs() < 0.01, "{near}");
        assert!(fit(&start, &seq, &FitOptions { mean_prior_weight: -1.0, ..FitOptions::default() }).is_err());
    }

    #[test]
    fn feedback_pins_states_in_the_fit() {
        let truth = truth();
        let (states, mut sequence) = sample(&truth, 300, 3);
        // Feedback at every epoch: the fit is the supervised estimate.
        sequence.known =
            states.iter().enumerate().map(|(t, &s)| Known { epoch: t, states: vec![s] }).collect();
        let a = SparseTransition::from_dense(&[vec![0.5, 0.5], vec![0.5, 0.5]]).unwrap();
        let start = GaussianHmm::new(
            Chain::new(vec![0.5, 0.5], a).unwrap(),
            GaussianMixtures::new(vec![vec![gaussian(5.0, 0.0, 100.0)], vec![gaussian(5.0, 0.0, 100.0)]])
                .unwrap(),
        )
        .unwrap();
        let (learned, _) =
            fit(&start, std::slice::from_ref(&sequence), &FitOptions::maximum_likelihood(1)).unwrap();
        let stays = states.windows(2).filter(|w| w[0] == 0 && w[1] == 0).count() as f64;
        let leaves0 = states[..states.len() - 1].iter().filter(|&&s| s == 0).count() as f64;
        assert_relative_eq!(learned.chain().transition().get(0, 0), stays / leaves0, max_relative = 1e-12);
        let in0: Vec<_> =
            states.iter().zip(&sequence.observations).filter(|(&s, _)| s == 0).map(|(_, o)| o).collect();
        let mean = in0.iter().fold(Vector2::zeros(), |a, o| a + *o) / in0.len() as f64;
        assert_relative_eq!(*learned.emission().components(0)[0].mean(), mean, max_relative = 1e-12);
        let bad = Sequence { known: vec![Known { epoch: 300, states: vec![0] }], ..sequence };
        assert!(matches!(fit(&start, &[bad], &FitOptions::default()), Err(LearnError::Dimension { .. })));
    }

    #[test]
    fn feedback_the_model_rules_out_restarts_the_sequence() {
        // The chain can never leave state 0, but the user says they are in state 1 at epoch 2.
        let a = SparseTransition::from_rows(vec![vec![(0, 1.0), (1, 0.0)], vec![(1, 1.0)]]).unwrap();
        let start = GaussianHmm::new(
            Chain::new(vec![1.0, 0.0], a).unwrap(),
            GaussianMixtures::new(vec![vec![gaussian(0.0, 0.0, 1.0)], vec![gaussian(5.0, 0.0, 1.0)]])
                .unwrap(),
        )
        .unwrap();
        let observations = vec![
            Vector2::new(0.1, 0.0),
            Vector2::new(0.3, 0.0),
            Vector2::new(4.0, 0.0),
            Vector2::new(5.0, 0.0),
        ];
        let sequence = Sequence { observations, known: vec![Known { epoch: 2, states: vec![1] }] };
        let seqs = std::slice::from_ref(&sequence);
        assert_eq!(
            fit(&start, seqs, &FitOptions::maximum_likelihood(1)).unwrap_err(),
            LearnError::Impossible { sequence: 0, epoch: 2 }
        );
        assert!(log_likelihood(&start, seqs).is_err());
        let (learned, report) =
            fit(&start, seqs, &FitOptions { max_iterations: 1, ..FitOptions::default() }).unwrap();
        assert_eq!(report.restarts, 1);
        assert!(report.log_likelihood.iter().all(|l| l.is_finite()));
        // Epochs 0-1 in state 0, 2-3 in state 1, and no transition 0 → 1 counted: a_01 is its
        // pseudo-count κ, over 1 + 2κ.
        let row = learned.chain().transition().row(0).1;
        let kappa = FitOptions::default().transition_pseudocount;
        assert_relative_eq!(row[1], kappa / (1.0 + 2.0 * kappa), max_relative = 1e-9);
        // From then on the pseudo-count lets the model reach state 1: no more restarts.
        let (_, report) =
            fit(&learned, seqs, &FitOptions { max_iterations: 3, ..FitOptions::default() }).unwrap();
        assert_eq!(report.restarts, 0);
        // State 1's component saw epochs 2-3 (mean 4.5); the prior of weight τ holds it toward
        // where it started, 5.
        let tau = FitOptions::default().mean_prior_weight;
        let expected = (tau * 5.0 + 2.0 * 4.5) / (tau + 2.0);
        assert!((learned.emission().components(1)[0].mean().x - expected).abs() < 1e-6);
    }

    #[test]
    fn bad_input_is_an_error() {
        let start = truth();
        let nan = vec![Sequence::new(vec![Vector2::new(f64::NAN, 0.0)])];
        assert!(matches!(fit(&start, &nan, &FitOptions::default()), Err(LearnError::NonFinite { .. })));
        assert!(matches!(fit(&start, &[], &FitOptions::default()), Err(LearnError::Empty(_))));
        let empty = vec![Sequence::new(vec![])];
        assert!(matches!(fit(&start, &empty, &FitOptions::default()), Err(LearnError::Empty(_))));
        let options = FitOptions { transition_pseudocount: -1.0, ..FitOptions::default() };
        let ok = vec![Sequence::new(vec![Vector2::zeros()])];
        assert!(fit(&start, &ok, &options).is_err());
    }
}
