//! The JSON documents of a decode and a fit, and the functions that compute them from the
//! documents, so that other implementations can be checked against this one.
//!
//! Decode reads `{"initial": [N], "transition": [[N × N]], "log_emission": [[T × N]]}` (a
//! `null` log-emission is −∞: the state cannot emit that observation) and writes
//! `{"log_likelihood", "filtered": [[T × N]], "smoothed": [[T × N]], "viterbi": [T],
//! "viterbi_log_prob"}`.
//!
//! Fit reads `{"initial", "transition", "means": [N][M_i][D], "covariances": [N][M_i][D][D],
//! "observations": [[[T × D]], ...], "iterations": K}` and writes the re-estimated `initial`,
//! `transition`, `means` and `covariances` with `"log_likelihood": [K + 1 values]`, by
//! [`FitOptions::maximum_likelihood`]. Zeros in `transition` are structural. D may be 1, 2 or 3.

use super::{
    decode, fit, Chain, EpochMatrix, FitOptions, Gaussian, GaussianHmm, GaussianMixtures, LearnError,
    Sequence, SparseTransition,
};
use nalgebra::{SMatrix, SVector};
use serde::{Deserialize, Serialize};

/// Input of a decode.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DecodeInput {
    /// π.
    pub initial: Vec<f64>,
    /// A, dense; zeros are structural.
    pub transition: Vec<Vec<f64>>,
    /// ln p_i(o_t), T rows of N; `null` is −∞.
    pub log_emission: Vec<Vec<Option<f64>>>,
}

/// Output of a decode.
#[derive(Clone, Debug, Deserialize, Serialize)]
pub struct DecodeOutput {
    /// ln p(o_1..T).
    pub log_likelihood: f64,
    /// P(s_t | o_1..t).
    pub filtered: Vec<Vec<f64>>,
    /// P(s_t | o_1..T).
    pub smoothed: Vec<Vec<f64>>,
    /// The most likely state sequence.
    pub viterbi: Vec<u32>,
    /// ln p(viterbi path, o_1..T).
    pub viterbi_log_prob: f64,
}

/// Input of a fit.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FitInput {
    /// π.
    pub initial: Vec<f64>,
    /// A, dense; zeros are structural.
    pub transition: Vec<Vec<f64>>,
    /// μ_im, per state a list of D-vectors.
    pub means: Vec<Vec<Vec<f64>>>,
    /// Σ_im, per state a list of D × D matrices (rows).
    pub covariances: Vec<Vec<Vec<Vec<f64>>>>,
    /// Sequences of D-vectors.
    pub observations: Vec<Vec<Vec<f64>>>,
    /// K, the number of re-estimations.
    pub iterations: usize,
}

/// Output of a fit.
#[derive(Clone, Debug, Deserialize, Serialize)]
pub struct FitOutput {
    /// π̂.
    pub initial: Vec<f64>,
    /// Â, dense.
    pub transition: Vec<Vec<f64>>,
    /// μ̂_im.
    pub means: Vec<Vec<Vec<f64>>>,
    /// Σ̂_im.
    pub covariances: Vec<Vec<Vec<Vec<f64>>>>,
    /// ln p(o | θ) before each re-estimation and after the last: K + 1 values.
    pub log_likelihood: Vec<f64>,
}

/// What a decode computes.
pub fn decode_json(input: &DecodeInput) -> Result<DecodeOutput, LearnError> {
    let transition = SparseTransition::from_dense(&input.transition)?;
    let chain = Chain::new(input.initial.clone(), transition)?;
    let n = chain.states();
    let rows: Vec<Vec<f64>> = input
        .log_emission
        .iter()
        .map(|r| r.iter().map(|v| v.unwrap_or(f64::NEG_INFINITY)).collect())
        .collect();
    let emissions = EpochMatrix::from_rows(n, &rows)?;
    let decoded = decode(&chain, &emissions)?;
    Ok(DecodeOutput {
        log_likelihood: decoded.posterior.log_likelihood,
        filtered: decoded.posterior.filtered.to_rows(),
        smoothed: decoded.posterior.smoothed.to_rows(),
        viterbi: decoded.viterbi,
        viterbi_log_prob: decoded.viterbi_log_prob,
    })
}

/// What a fit computes.
pub fn fit_json(input: &FitInput) -> Result<FitOutput, LearnError> {
    let d = input
        .means
        .first()
        .and_then(|m| m.first())
        .map(Vec::len)
        .ok_or_else(|| LearnError::Empty("means[0]".into()))?;
    match d {
        1 => fit_d::<1>(input),
        2 => fit_d::<2>(input),
        3 => fit_d::<3>(input),
        _ => Err(LearnError::Unsupported(format!("means[0][0] has {d} coordinates: D must be 1, 2 or 3"))),
    }
}

fn vector<const D: usize>(what: &dyn Fn() -> String, v: &[f64]) -> Result<SVector<f64, D>, LearnError> {
    if v.len() != D {
        return Err(LearnError::Dimension { what: what(), expected: D, got: v.len() });
    }
    Ok(SVector::from_column_slice(v))
}

fn fit_d<const D: usize>(input: &FitInput) -> Result<FitOutput, LearnError> {
    let transition = SparseTransition::from_dense(&input.transition)?;
    let chain = Chain::new(input.initial.clone(), transition)?;
    let n = chain.states();
    if input.means.len() != n {
        return Err(LearnError::Dimension { what: "means".into(), expected: n, got: input.means.len() });
    }
    if input.covariances.len() != n {
        return Err(LearnError::Dimension {
            what: "covariances".into(),
            expected: n,
            got: input.covariances.len(),
        });
    }
    let mut per_state = Vec::with_capacity(n);
    for (i, (means, covariances)) in input.means.iter().zip(&input.covariances).enumerate() {
        if covariances.len() != means.len() {
            return Err(LearnError::Dimension {
                what: format!("covariances[{i}]"),
                expected: means.len(),
                got: covariances.len(),
            });
        }
        let mut state = Vec::with_capacity(means.len());
        for (m, (mean, covariance)) in means.iter().zip(covariances).enumerate() {
            let mean = vector::<D>(&|| format!("means[{i}][{m}]"), mean)?;
            if covariance.len() != D {
                return Err(LearnError::Dimension {
                    what: format!("covariances[{i}][{m}]"),
                    expected: D,
                    got: covariance.len(),
                });
            }
            let mut sigma = SMatrix::<f64, D, D>::zeros();
            for (r, row) in covariance.iter().enumerate() {
                sigma.set_row(r, &vector::<D>(&|| format!("covariances[{i}][{m}][{r}]"), row)?.transpose());
            }
            state.push(Gaussian::checked(mean, sigma, &|| format!("covariances[{i}][{m}]"))?);
        }
        per_state.push(state);
    }
    let model = GaussianHmm::new(chain, GaussianMixtures::new(per_state)?)?;
    let mut sequences = Vec::with_capacity(input.observations.len());
    for (s, sequence) in input.observations.iter().enumerate() {
        let observations = sequence
            .iter()
            .enumerate()
            .map(|(t, o)| vector::<D>(&|| format!("observations[{s}][{t}]"), o))
            .collect::<Result<Vec<_>, _>>()?;
        sequences.push(Sequence::new(observations));
    }
    let (learned, report) = fit(&model, &sequences, &FitOptions::maximum_likelihood(input.iterations))?;
    let emission = learned.emission();
    Ok(FitOutput {
        initial: learned.chain().initial().to_vec(),
        transition: learned.chain().transition().to_dense(),
        means: (0..n)
            .map(|i| emission.components(i).iter().map(|g| g.mean().iter().copied().collect()).collect())
            .collect(),
        covariances: (0..n)
            .map(|i| {
                emission
                    .components(i)
                    .iter()
                    .map(|g| (0..D).map(|r| g.covariance().row(r).iter().copied().collect()).collect())
                    .collect()
            })
            .collect(),
        log_likelihood: report.log_likelihood,
    })
}
