//! Issue 6's independent check: `waymark hmm decode` and `waymark hmm fit` against a small,
//! dense textbook implementation written here from Rabiner's tutorial and El Gemayel et al.
//! eqs. 7-13, sharing no code with `waymark_engine::hmm::learn`: log-space forward and backward
//! recursions with log-sum-exp over full N × N matrices (no scaling, no sparsity, no
//! thresholds), ξ and γ formed from them, and the M-step with the covariance taken in a second
//! pass around the new mean (the library accumulates around the old one in a single pass) and
//! 2 × 2 inverses and determinants written out (the library uses Cholesky factors).
//!
//! Random models (seeded): N up to 50 states, T up to 300 epochs, M_i up to 3 components, D =
//! 2, one to four sequences, random structural zeros (every row keeps at least one allowed
//! transition) and zeros in π; some decode cases have states that cannot emit (−∞, JSON null).
//! Issue 8's cases add log-emissions down to −1000 nats in groups of states closed by structural
//! zeros, and sequences of 1 000 to 2 000 epochs; there ln p(o) must also be at least the
//! Viterbi path's log-probability. Agreement is required to 1e-6 relative: probabilities
//! relative to the larger of the two values or a floor (1e-100 in decode, 1e-20 in fit: see
//! the constants), log-likelihoods relative to the larger magnitude or 1 nat, means and
//! covariances normwise per component.
//! Fit cases in which maximum likelihood collapses a component onto one observation have no
//! maximum to agree on and are redrawn ([`well_posed_case`]); the count is printed.
//!
//! `cargo test -p waymark-cli --test hmm_reference -- --nocapture` prints the largest
//! relative difference of each test.

// The reference is written with indices, as the equations are.
#![allow(clippy::needless_range_loop)]

use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use std::io::Write;
use std::process::{Command, Stdio};
use waymark_engine::hmm::learn::json::{
    decode_json, fit_json, DecodeInput, DecodeOutput, FitInput, FitOutput,
};
use waymark_engine::hmm::learn::LearnError;

const TOLERANCE: f64 = 1e-6;

// ---------------------------------------------------------------------------------------------
// The reference.

fn log_sum_exp(values: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = values.collect();
    let max = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if max == f64::NEG_INFINITY {
        return max;
    }
    max + v.iter().map(|x| (x - max).exp()).sum::<f64>().ln()
}

/// ln α_t(i) = ln p(o_1..t, s_t = i) and ln β_t(i) = ln p(o_t+1..T | s_t = i).
fn log_alpha_beta(pi: &[f64], a: &[Vec<f64>], e: &[Vec<f64>]) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let (n, t_len) = (pi.len(), e.len());
    let mut alpha = vec![vec![0.0; n]; t_len];
    let mut beta = vec![vec![0.0; n]; t_len];
    for i in 0..n {
        alpha[0][i] = pi[i].ln() + e[0][i];
    }
    for t in 1..t_len {
        for j in 0..n {
            alpha[t][j] = log_sum_exp((0..n).map(|i| alpha[t - 1][i] + a[i][j].ln())) + e[t][j];
        }
    }
    for t in (0..t_len - 1).rev() {
        for i in 0..n {
            beta[t][i] = log_sum_exp((0..n).map(|j| a[i][j].ln() + e[t + 1][j] + beta[t + 1][j]));
        }
    }
    (alpha, beta)
}

struct Reference {
    log_likelihood: f64,
    filtered: Vec<Vec<f64>>,
    smoothed: Vec<Vec<f64>>,
    viterbi: Vec<usize>,
    viterbi_log_prob: f64,
}

fn reference_decode(pi: &[f64], a: &[Vec<f64>], e: &[Vec<f64>]) -> Reference {
    let (n, t_len) = (pi.len(), e.len());
    let (alpha, beta) = log_alpha_beta(pi, a, e);
    let log_likelihood = log_sum_exp(alpha[t_len - 1].iter().copied());
    let filtered = alpha
        .iter()
        .map(|row| {
            let z = log_sum_exp(row.iter().copied());
            row.iter().map(|v| (v - z).exp()).collect()
        })
        .collect();
    let smoothed = (0..t_len)
        .map(|t| (0..n).map(|i| (alpha[t][i] + beta[t][i] - log_likelihood).exp()).collect())
        .collect();
    // Viterbi, ties to the lowest index.
    let mut delta: Vec<f64> = (0..n).map(|i| pi[i].ln() + e[0][i]).collect();
    let mut back = vec![vec![0usize; n]; t_len];
    for t in 1..t_len {
        let mut next = vec![f64::NEG_INFINITY; n];
        for j in 0..n {
            for i in 0..n {
                let v = delta[i] + a[i][j].ln();
                if v > next[j] {
                    next[j] = v;
                    back[t][j] = i;
                }
            }
            next[j] += e[t][j];
        }
        delta = next;
    }
    let mut last = 0;
    for i in 1..n {
        if delta[i] > delta[last] {
            last = i;
        }
    }
    let viterbi_log_prob = delta[last];
    let mut viterbi = vec![last; t_len];
    for t in (1..t_len).rev() {
        viterbi[t - 1] = back[t][viterbi[t]];
    }
    Reference { log_likelihood, filtered, smoothed, viterbi, viterbi_log_prob }
}

/// ln p(path, o).
fn path_log_prob(pi: &[f64], a: &[Vec<f64>], e: &[Vec<f64>], path: &[usize]) -> f64 {
    let mut lp = pi[path[0]].ln() + e[0][path[0]];
    for t in 1..path.len() {
        lp += a[path[t - 1]][path[t]].ln() + e[t][path[t]];
    }
    lp
}

type Mat2 = [[f64; 2]; 2];

fn ln_gauss(mean: &[f64; 2], cov: &Mat2, o: &[f64; 2]) -> f64 {
    let det = cov[0][0] * cov[1][1] - cov[0][1] * cov[1][0];
    let inv = [[cov[1][1] / det, -cov[0][1] / det], [-cov[1][0] / det, cov[0][0] / det]];
    let d = [o[0] - mean[0], o[1] - mean[1]];
    let quad = d[0] * (inv[0][0] * d[0] + inv[0][1] * d[1]) + d[1] * (inv[1][0] * d[0] + inv[1][1] * d[1]);
    -(2.0 * std::f64::consts::PI).ln() - 0.5 * det.ln() - 0.5 * quad
}

#[derive(Clone)]
struct Model {
    pi: Vec<f64>,
    a: Vec<Vec<f64>>,
    means: Vec<Vec<[f64; 2]>>,
    covs: Vec<Vec<Mat2>>,
}

/// Eq. 7: ln p_i(o) = ln Σ_m (1/M_i) N(o; μ_im, Σ_im).
fn emissions(model: &Model, obs: &[[f64; 2]]) -> Vec<Vec<f64>> {
    obs.iter()
        .map(|o| {
            (0..model.pi.len())
                .map(|i| {
                    let m = model.means[i].len() as f64;
                    log_sum_exp(
                        (0..model.means[i].len()).map(|k| ln_gauss(&model.means[i][k], &model.covs[i][k], o)),
                    ) - m.ln()
                })
                .collect()
        })
        .collect()
}

/// The smaller eigenvalue of a symmetric 2 × 2 matrix.
fn smallest_eigenvalue(c: &Mat2) -> f64 {
    let half_trace = 0.5 * (c[0][0] + c[1][1]);
    let det = c[0][0] * c[1][1] - c[0][1] * c[1][0];
    half_trace - (half_trace * half_trace - det).max(0.0).sqrt()
}

/// (γ_im(t), o_t) for every epoch of every sequence.
type Responsibilities = Vec<(f64, [f64; 2])>;

struct ReferenceFit {
    model: Model,
    /// ln p(o | θ) before each iteration and after the last.
    history: Vec<f64>,
    /// The smallest covariance eigenvalue of any component after any iteration.
    smallest_variance: f64,
}

/// Baum-Welch, `iterations` times.
fn reference_fit(start: &Model, sequences: &[Vec<[f64; 2]>], iterations: usize) -> ReferenceFit {
    let mut model = start.clone();
    let n = model.pi.len();
    let mut history = Vec::new();
    let mut smallest_variance = f64::INFINITY;
    for _ in 0..iterations {
        let mut pi_num = vec![0.0; n];
        let mut xi_sum = vec![vec![0.0; n]; n];
        let mut gamma_sum = vec![0.0; n]; // over t < T, eq. 10's denominator
                                          // γ_im(t) and o_t, kept for the two-pass covariance.
        let mut resp: Vec<Vec<Responsibilities>> =
            (0..n).map(|i| vec![Vec::new(); model.means[i].len()]).collect();
        let mut total_ll = 0.0;
        for obs in sequences {
            let e = emissions(&model, obs);
            let (alpha, beta) = log_alpha_beta(&model.pi, &model.a, &e);
            let t_len = obs.len();
            let ll = log_sum_exp(alpha[t_len - 1].iter().copied());
            total_ll += ll;
            for t in 0..t_len {
                for i in 0..n {
                    let gamma = (alpha[t][i] + beta[t][i] - ll).exp(); // eq. 8
                    if t == 0 {
                        pi_num[i] += gamma;
                    }
                    if t + 1 < t_len {
                        gamma_sum[i] += gamma;
                        for j in 0..n {
                            // Eq. 9.
                            xi_sum[i][j] +=
                                (alpha[t][i] + model.a[i][j].ln() + e[t + 1][j] + beta[t + 1][j] - ll).exp();
                        }
                    }
                    // Eq. 13.
                    let ln_n: Vec<f64> = (0..model.means[i].len())
                        .map(|k| ln_gauss(&model.means[i][k], &model.covs[i][k], &obs[t]))
                        .collect();
                    let z = log_sum_exp(ln_n.iter().copied());
                    for (k, l) in ln_n.iter().enumerate() {
                        resp[i][k].push((gamma * (l - z).exp(), obs[t]));
                    }
                }
            }
        }
        history.push(total_ll);
        let s = sequences.len() as f64;
        model.pi = pi_num.iter().map(|v| v / s).collect();
        for i in 0..n {
            if gamma_sum[i] > 0.0 {
                for j in 0..n {
                    model.a[i][j] = xi_sum[i][j] / gamma_sum[i]; // eq. 10
                }
            }
            for k in 0..model.means[i].len() {
                let w: f64 = resp[i][k].iter().map(|r| r.0).sum();
                if w <= 0.0 {
                    continue;
                }
                // Eq. 11.
                let mut mean = [0.0; 2];
                for (g, o) in &resp[i][k] {
                    mean[0] += g * o[0] / w;
                    mean[1] += g * o[1] / w;
                }
                // Eq. 12 around the new mean, plus the 1e-9 diagonal floor.
                let mut cov = [[0.0; 2]; 2];
                for (g, o) in &resp[i][k] {
                    let d = [o[0] - mean[0], o[1] - mean[1]];
                    for r in 0..2 {
                        for c in 0..2 {
                            cov[r][c] += g * d[r] * d[c] / w;
                        }
                    }
                }
                cov[0][0] += 1e-9;
                cov[1][1] += 1e-9;
                model.means[i][k] = mean;
                smallest_variance = smallest_variance.min(smallest_eigenvalue(&cov));
                model.covs[i][k] = cov;
            }
        }
    }
    let final_ll = sequences
        .iter()
        .map(|obs| {
            let e = emissions(&model, obs);
            let (alpha, _) = log_alpha_beta(&model.pi, &model.a, &e);
            log_sum_exp(alpha[obs.len() - 1].iter().copied())
        })
        .sum();
    history.push(final_ll);
    ReferenceFit { model, history, smallest_variance }
}

// ---------------------------------------------------------------------------------------------
// Random models.

fn random_distribution(rng: &mut ChaCha8Rng, n: usize, density: f64) -> Vec<f64> {
    let mut p: Vec<f64> = (0..n)
        .map(|_| if rng.random_range(0.0..1.0) < density { rng.random_range(0.05..1.0) } else { 0.0 })
        .collect();
    if p.iter().all(|&v| v == 0.0) {
        let k = rng.random_range(0..n);
        p[k] = 1.0;
    }
    let s: f64 = p.iter().sum();
    p.iter().map(|v| v / s).collect()
}

fn random_chain(rng: &mut ChaCha8Rng, n: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
    let density = rng.random_range(0.05..1.0);
    let pi_density = rng.random_range(0.3..1.0);
    let pi = random_distribution(rng, n, pi_density);
    let a = (0..n).map(|_| random_distribution(rng, n, density)).collect();
    (pi, a)
}

fn random_covariance(rng: &mut ChaCha8Rng) -> Mat2 {
    let (l1, l2) = (rng.random_range(0.3..3.0), rng.random_range(0.3..3.0));
    let th: f64 = rng.random_range(0.0..std::f64::consts::PI);
    let (c, s) = (th.cos(), th.sin());
    [[l1 * c * c + l2 * s * s, (l1 - l2) * c * s], [(l1 - l2) * c * s, l1 * s * s + l2 * c * c]]
}

fn draw(rng: &mut ChaCha8Rng, p: &[f64]) -> usize {
    let u: f64 = rng.random_range(0.0..1.0);
    let mut acc = 0.0;
    for (i, &q) in p.iter().enumerate() {
        acc += q;
        if u < acc && q > 0.0 {
            return i;
        }
    }
    p.iter().rposition(|&q| q > 0.0).unwrap()
}

fn sample(rng: &mut ChaCha8Rng, model: &Model, t_len: usize) -> Vec<[f64; 2]> {
    let mut s = draw(rng, &model.pi);
    let mut obs = Vec::with_capacity(t_len);
    for _ in 0..t_len {
        let k = rng.random_range(0..model.means[s].len());
        let (m, c) = (model.means[s][k], model.covs[s][k]);
        let l00 = c[0][0].sqrt();
        let l10 = c[1][0] / l00;
        let l11 = (c[1][1] - l10 * l10).sqrt();
        let (z0, z1): (f64, f64) = (StandardNormal.sample(rng), StandardNormal.sample(rng));
        obs.push([m[0] + l00 * z0, m[1] + l10 * z0 + l11 * z1]);
        s = draw(rng, &model.a[s]);
    }
    obs
}

/// A random model whose components sit on a grid 6 units apart, and a start for Baum-Welch: the
/// same sparsity, fresh random probabilities, means moved by up to 1.5 units, covariances
/// doubled.
fn random_fit_case(rng: &mut ChaCha8Rng, n: usize, max_m: usize) -> (Model, Model) {
    let (pi, a) = random_chain(rng, n);
    let mut means = Vec::new();
    let mut covs = Vec::new();
    let mut cell = 0;
    for _ in 0..n {
        let m = rng.random_range(1..=max_m);
        means.push(
            (0..m)
                .map(|_| {
                    cell += 1;
                    [
                        6.0 * (cell % 12) as f64 + rng.random_range(-1.0..1.0),
                        6.0 * (cell / 12) as f64 + rng.random_range(-1.0..1.0),
                    ]
                })
                .collect::<Vec<_>>(),
        );
        covs.push((0..m).map(|_| random_covariance(rng)).collect::<Vec<_>>());
    }
    let truth = Model { pi, a, means, covs };
    let mut start = truth.clone();
    for row in start.a.iter_mut() {
        let fresh: Vec<f64> =
            row.iter().map(|&v| if v > 0.0 { rng.random_range(0.1..1.0) } else { 0.0 }).collect();
        let s: f64 = fresh.iter().sum();
        *row = fresh.iter().map(|v| v / s).collect();
    }
    for (means, covs) in start.means.iter_mut().zip(start.covs.iter_mut()) {
        for m in means.iter_mut() {
            m[0] += rng.random_range(-1.5..1.5);
            m[1] += rng.random_range(-1.5..1.5);
        }
        for c in covs.iter_mut() {
            *c = [[2.0 * c[0][0], 2.0 * c[0][1]], [2.0 * c[1][0], 2.0 * c[1][1]]];
        }
    }
    (truth, start)
}

// ---------------------------------------------------------------------------------------------
// Comparison.

/// |a − b| relative to the larger magnitude, or to `floor` if both are smaller.
fn relative(a: f64, b: f64, floor: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(floor)
}

/// Floor for decode's probabilities: the smallest ones, e^(differences of log-probabilities
/// hundreds of nats apart), differ in their last bits between two implementations; below
/// 1e-100, 1e-6 of the floor is 1e-106 absolute.
const DECODE_FLOOR: f64 = 1e-100;

/// Floor for the fitted probabilities. Maximum likelihood drives some allowed transitions
/// towards zero (1e-90 after five iterations in a case of the fit test); such a value is
/// e^(a difference of log-densities hundreds of nats apart), whose last digits no two
/// implementations share (the first run of this test: 8e-7 relative at 1.26e-90). A
/// transition below 1e-20 changes a log-likelihood over 1 200 epochs by under 1e-17, so 1e-6
/// of it is 1e-26 absolute.
const FIT_FLOOR: f64 = 1e-20;

/// Floor for log-likelihoods and path scores, in nats: one within a nat of zero is compared to
/// 1e-6 nats absolute.
const LOG_FLOOR: f64 = 1.0;

#[derive(Default)]
struct Worst {
    value: f64,
    at: String,
}

impl Worst {
    fn check(&mut self, what: impl Fn() -> String, got: f64, expected: f64, floor: f64) {
        let r = relative(got, expected, floor);
        assert!(r <= TOLERANCE, "{}: {got} vs reference {expected} (relative {r:e})", what());
        if r > self.value {
            *self = Worst { value: r, at: what() };
        }
    }
}

fn compare_decode(
    worst: &mut Worst,
    case: &str,
    out: &DecodeOutput,
    pi: &[f64],
    a: &[Vec<f64>],
    e: &[Vec<f64>],
) {
    let r = reference_decode(pi, a, e);
    worst.check(|| format!("{case} log_likelihood"), out.log_likelihood, r.log_likelihood, LOG_FLOOR);
    for t in 0..e.len() {
        for i in 0..pi.len() {
            worst.check(
                || format!("{case} filtered[{t}][{i}]"),
                out.filtered[t][i],
                r.filtered[t][i],
                DECODE_FLOOR,
            );
            worst.check(
                || format!("{case} smoothed[{t}][{i}]"),
                out.smoothed[t][i],
                r.smoothed[t][i],
                DECODE_FLOOR,
            );
        }
    }
    worst.check(|| format!("{case} viterbi_log_prob"), out.viterbi_log_prob, r.viterbi_log_prob, LOG_FLOOR);
    let path: Vec<usize> = out.viterbi.iter().map(|&s| s as usize).collect();
    if path != r.viterbi {
        // A near-tie may break either way: then both paths must score the same.
        let (ours, theirs) = (path_log_prob(pi, a, e, &path), path_log_prob(pi, a, e, &r.viterbi));
        worst.check(|| format!("{case} viterbi path score"), ours, theirs, LOG_FLOOR);
    }
}

fn compare_fit(worst: &mut Worst, case: &str, out: &FitOutput, reference: &ReferenceFit) {
    let (r, history) = (&reference.model, &reference.history);
    assert_eq!(out.log_likelihood.len(), history.len(), "{case}");
    for (k, (&got, &expected)) in out.log_likelihood.iter().zip(history).enumerate() {
        worst.check(|| format!("{case} log_likelihood[{k}]"), got, expected, LOG_FLOOR);
    }
    let n = r.pi.len();
    for i in 0..n {
        worst.check(|| format!("{case} initial[{i}]"), out.initial[i], r.pi[i], FIT_FLOOR);
        for j in 0..n {
            if r.a[i][j] == 0.0 {
                assert_eq!(out.transition[i][j], 0.0, "{case} transition[{i}][{j}] is a structural zero");
            }
            worst.check(
                || format!("{case} transition[{i}][{j}]"),
                out.transition[i][j],
                r.a[i][j],
                FIT_FLOOR,
            );
        }
        // Means and covariances normwise, relative to the component's largest entry: an
        // off-diagonal covariance near zero is round-off in both implementations.
        for k in 0..r.means[i].len() {
            let scale = r.means[i][k].iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let diff = (0..2).fold(0.0f64, |m, d| m.max((out.means[i][k][d] - r.means[i][k][d]).abs()));
            worst.check(
                || format!("{case} means[{i}][{k}] (normwise)"),
                scale + diff,
                scale,
                f64::MIN_POSITIVE,
            );
            let scale = r.covs[i][k].iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
            let diff = (0..4).fold(0.0f64, |m, e| {
                m.max((out.covariances[i][k][e / 2][e % 2] - r.covs[i][k][e / 2][e % 2]).abs())
            });
            worst.check(
                || format!("{case} covariances[{i}][{k}] (normwise)"),
                scale + diff,
                scale,
                f64::MIN_POSITIVE,
            );
        }
    }
}

/// −∞ is written as null.
fn decode_input(pi: &[f64], a: &[Vec<f64>], e: &[Vec<f64>]) -> DecodeInput {
    DecodeInput {
        initial: pi.to_vec(),
        transition: a.to_vec(),
        log_emission: e
            .iter()
            .map(|r| r.iter().map(|&v| (v > f64::NEG_INFINITY).then_some(v)).collect())
            .collect(),
    }
}

/// Below this smallest eigenvalue a component has collapsed onto a single observation (the
/// generated covariances' eigenvalues are at least 0.3, and a component's sample covariance
/// with two distinct points already has one eigenvalue of their spread).
const COLLAPSED: f64 = 1e-6;

/// A fit case whose reference run never collapses a component, with the number of draws it
/// took. When maximum likelihood gives a component a single observation, its covariance is
/// the 1e-9 floor plus round-off (the sample covariance of one point is 0), the two
/// implementations' round-off differs by 1e-5 of it, and every density through that component
/// inherits the difference multiplied by its Mahalanobis distance (seed 14 of this test: 1e-5
/// on a 3e-15 probability). The likelihood has no maximum there, so nothing is to be compared.
fn well_posed_case(
    rng: &mut ChaCha8Rng,
    n: usize,
    max_m: usize,
    count: usize,
    t_len: usize,
    iterations: usize,
) -> (Model, Vec<Vec<[f64; 2]>>, ReferenceFit, usize) {
    for tries in 1.. {
        let (truth, start) = random_fit_case(rng, n, max_m);
        let sequences: Vec<_> = (0..count).map(|_| sample(rng, &truth, t_len)).collect();
        let reference = reference_fit(&start, &sequences, iterations);
        if reference.smallest_variance >= COLLAPSED {
            return (start, sequences, reference, tries);
        }
    }
    unreachable!()
}

fn fit_input(start: &Model, sequences: &[Vec<[f64; 2]>], iterations: usize) -> FitInput {
    FitInput {
        initial: start.pi.clone(),
        transition: start.a.clone(),
        means: start.means.iter().map(|m| m.iter().map(|v| v.to_vec()).collect()).collect(),
        covariances: start
            .covs
            .iter()
            .map(|c| c.iter().map(|m| m.iter().map(|r| r.to_vec()).collect()).collect())
            .collect(),
        observations: sequences.iter().map(|s| s.iter().map(|o| o.to_vec()).collect()).collect(),
        iterations,
    }
}

/// Runs the CLI binary on a JSON document; returns its exit status, stdout and stderr.
fn cli(verb: &str, input: &str) -> (i32, String, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_waymark"))
        .args(["hmm", verb, "-"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the waymark binary runs");
    child.stdin.take().unwrap().write_all(input.as_bytes()).unwrap();
    let out = child.wait_with_output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8(out.stdout).unwrap(),
        String::from_utf8(out.stderr).unwrap(),
    )
}

// ---------------------------------------------------------------------------------------------
// The checks.

/// Sizes of the decode cases: the extremes first, then random ones.
/// Sizes of the decode cases (N, T, spread of the log-emissions in nats, share of −∞
/// entries): the extremes first, then random ones.
fn decode_sizes(rng: &mut ChaCha8Rng) -> Vec<(usize, usize, f64, f64)> {
    let mut sizes = vec![
        (50, 300, 3.0, 0.0),
        (1, 1, 1.0, 0.0),
        (1, 300, 3.0, 0.0),
        (50, 1, 3.0, 0.0),
        (30, 200, 300.0, 0.0),
    ];
    for k in 0..25 {
        // Spreads of 1 to 300 nats: the last leave probabilities far below 1e-100. One case in
        // five has states that cannot emit an observation (JSON null); some of those have no
        // path at all.
        let spread = [1.0, 3.0, 10.0, 30.0, 300.0][rng.random_range(0..5)];
        let impossible = if k % 5 == 0 { 0.2 } else { 0.0 };
        sizes.push((rng.random_range(1..=50), rng.random_range(1..=300), spread, impossible));
    }
    sizes
}

fn random_decode(
    rng: &mut ChaCha8Rng,
    n: usize,
    t_len: usize,
    spread: f64,
    impossible: f64,
) -> (Vec<f64>, Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let (pi, a) = random_chain(rng, n);
    let mut entry = || {
        if rng.random_range(0.0..1.0) < impossible {
            f64::NEG_INFINITY
        } else {
            -spread * rng.random_range(0.0..1.0f64)
        }
    };
    let e = (0..t_len).map(|_| (0..n).map(|_| entry()).collect()).collect();
    (pi, a, e)
}

#[test]
fn decode_matches_the_dense_reference() {
    let started = std::time::Instant::now();
    let mut rng = ChaCha8Rng::seed_from_u64(6);
    let mut worst = Worst::default();
    let mut without_path = 0;
    for (case, (n, t_len, spread, impossible)) in decode_sizes(&mut rng).into_iter().enumerate() {
        let (pi, a, e) = random_decode(&mut rng, n, t_len, spread, impossible);
        let result = decode_json(&decode_input(&pi, &a, &e));
        if reference_decode(&pi, &a, &e).log_likelihood == f64::NEG_INFINITY {
            assert!(matches!(result, Err(LearnError::Impossible { .. })), "case {case}");
            without_path += 1;
            continue;
        }
        compare_decode(
            &mut worst,
            &format!("decode case {case} (N {n}, T {t_len})"),
            &result.unwrap(),
            &pi,
            &a,
            &e,
        );
    }
    println!(
        "decode: 30 cases ({without_path} without a path, refused), largest relative difference {:.2e} ({}), {:.1} s",
        worst.value,
        worst.at,
        started.elapsed().as_secs_f64()
    );
}

/// Issue 8's shape: N states in `clusters` groups, transitions only within a group (every
/// other entry a structural zero) but for `leak` of each row's mass spread over a few states of
/// other groups, and log-emissions down to −1000 nats: each epoch gives each group an offset
/// in [−995, 0] and each state a further [−5, 0]. The group that explains the sequence best may
/// explain an epoch a thousand nats worse than another group does; its states' filtered
/// probabilities there are far below 1e-300 and must not be dropped. A share `impossible` of
/// the log-emissions are −∞.
fn peaked_decode(
    rng: &mut ChaCha8Rng,
    n: usize,
    t_len: usize,
    clusters: usize,
    leak: f64,
    impossible: f64,
) -> (Vec<f64>, Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let size = n.div_ceil(clusters);
    let pi = random_distribution(rng, n, 0.5);
    let a = (0..n)
        .map(|i| {
            let group = (i / size) * size..((i / size + 1) * size).min(n);
            let inside = random_distribution(rng, group.len(), 0.3);
            let mut row = vec![0.0; n];
            for (j, p) in group.clone().zip(inside) {
                row[j] = p * (1.0 - leak);
            }
            if leak > 0.0 && group.len() < n {
                let outside: Vec<usize> = (0..n).filter(|j| !group.contains(j)).collect();
                for _ in 0..3 {
                    row[outside[rng.random_range(0..outside.len())]] += leak / 3.0;
                }
            }
            row
        })
        .collect();
    let e = (0..t_len)
        .map(|_| {
            let offset: Vec<f64> = (0..clusters).map(|_| -995.0 * rng.random_range(0.0..1.0f64)).collect();
            (0..n)
                .map(|i| {
                    if rng.random_range(0.0..1.0) < impossible {
                        f64::NEG_INFINITY
                    } else {
                        offset[i / size] - 5.0 * rng.random_range(0.0..1.0f64)
                    }
                })
                .collect()
        })
        .collect();
    (pi, a, e)
}

/// ln p(o) ≥ ln p(Viterbi path, o): the total is a sum over paths that includes this one.
fn assert_likelihood_covers_the_path(case: &str, out: &DecodeOutput) {
    let slack = 1e-12 * out.viterbi_log_prob.abs().max(LOG_FLOOR);
    assert!(
        out.log_likelihood >= out.viterbi_log_prob - slack,
        "{case}: log-likelihood {} below the Viterbi path's log-probability {}",
        out.log_likelihood,
        out.viterbi_log_prob
    );
}

#[test]
fn peaked_emissions_and_structural_zeros_match_the_dense_reference() {
    let started = std::time::Instant::now();
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let mut worst = Worst::default();
    // (N, T, groups, leak, share of −∞): issue 8's 50 states and 10 epochs, then long sequences.
    let mut sizes: Vec<(usize, usize, usize, f64, f64)> =
        (0..30).map(|k| (50, 10, [2, 5, 10][k % 3], if k % 2 == 0 { 0.0 } else { 1e-3 }, 0.0)).collect();
    sizes.extend([
        (20, 1000, 4, 0.0, 0.0),
        (50, 1000, 5, 1e-3, 0.0),
        (10, 2000, 2, 1e-2, 0.0),
        (30, 1200, 3, 1e-3, 0.05),
    ]);
    let mut without_path = 0;
    for (case, &(n, t_len, clusters, leak, impossible)) in sizes.iter().enumerate() {
        let (pi, a, e) = peaked_decode(&mut rng, n, t_len, clusters, leak, impossible);
        let name = format!("peaked case {case} (N {n}, T {t_len}, {clusters} groups, leak {leak})");
        let result = decode_json(&decode_input(&pi, &a, &e));
        if reference_decode(&pi, &a, &e).log_likelihood == f64::NEG_INFINITY {
            assert!(matches!(result, Err(LearnError::Impossible { .. })), "{name}");
            without_path += 1;
            continue;
        }
        let out = result.unwrap();
        assert_likelihood_covers_the_path(&name, &out);
        compare_decode(&mut worst, &name, &out, &pi, &a, &e);
    }
    // The binary on one of issue 8's shape.
    let (pi, a, e) = peaked_decode(&mut rng, 50, 10, 5, 0.0, 0.0);
    let (status, stdout, stderr) = cli("decode", &serde_json::to_string(&decode_input(&pi, &a, &e)).unwrap());
    assert_eq!(status, 0, "{stderr}");
    let out: DecodeOutput = serde_json::from_str(&stdout).unwrap();
    assert_likelihood_covers_the_path("CLI peaked case", &out);
    compare_decode(&mut worst, "CLI peaked case", &out, &pi, &a, &e);
    println!(
        "peaked: {} cases ({without_path} without a path, refused), largest relative difference {:.2e} ({}), {:.1} s",
        sizes.len() + 1,
        worst.value,
        worst.at,
        started.elapsed().as_secs_f64()
    );
}

#[test]
fn fit_matches_the_dense_reference() {
    let started = std::time::Instant::now();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut worst = Worst::default();
    // (N, T, sequences, max M): the largest first.
    // Maximum likelihood is well posed only with several observations per component: with
    // fewer, components collapse onto single points (covariance → the 1e-9 floor) and
    // probabilities become differences of numbers ~1e10 nats, equal in no two implementations.
    // So each case has at least 8 observations per component on average.
    let mut sizes = vec![(50, 300, 4, 3), (1, 50, 1, 3), (5, 40, 4, 2)];
    while sizes.len() < 15 {
        let (count, max_m): (usize, usize) = (rng.random_range(1..=4), rng.random_range(1..=3));
        let n: usize = rng.random_range(1..=50);
        let shortest = (8 * n * max_m).div_ceil(count).max(20);
        if shortest <= 300 {
            sizes.push((n, rng.random_range(shortest..=300), count, max_m));
        }
    }
    let mut redrawn = 0;
    for (case, &(n, t_len, count, max_m)) in sizes.iter().enumerate() {
        let (start, sequences, reference, tries) = well_posed_case(&mut rng, n, max_m, count, t_len, 5);
        redrawn += tries - 1;
        let out = fit_json(&fit_input(&start, &sequences, 5)).unwrap();
        compare_fit(
            &mut worst,
            &format!("fit case {case} (N {n}, T {t_len}, {count} sequences)"),
            &out,
            &reference,
        );
    }
    println!(
        "fit: {} cases ({redrawn} redrawn after a collapse), largest relative difference {:.2e} ({}), {:.1} s",
        sizes.len(),
        worst.value,
        worst.at,
        started.elapsed().as_secs_f64()
    );
}

#[test]
fn the_cli_binary_matches_the_reference() {
    let mut rng = ChaCha8Rng::seed_from_u64(8);
    let mut worst = Worst::default();
    let (pi, a, e) = random_decode(&mut rng, 20, 100, 10.0, 0.0);
    let (status, stdout, stderr) = cli("decode", &serde_json::to_string(&decode_input(&pi, &a, &e)).unwrap());
    assert_eq!(status, 0, "{stderr}");
    let out: DecodeOutput = serde_json::from_str(&stdout).unwrap();
    compare_decode(&mut worst, "CLI decode", &out, &pi, &a, &e);

    let (start, sequences, reference, _) = well_posed_case(&mut rng, 15, 3, 3, 150, 4);
    let (status, stdout, stderr) =
        cli("fit", &serde_json::to_string(&fit_input(&start, &sequences, 4)).unwrap());
    assert_eq!(status, 0, "{stderr}");
    let out: FitOutput = serde_json::from_str(&stdout).unwrap();
    compare_fit(&mut worst, "CLI fit", &out, &reference);
    println!("CLI: largest relative difference {:.2e} ({})", worst.value, worst.at);
}

#[test]
fn the_cli_refuses_bad_input_with_status_2() {
    for (verb, input, expected) in [
        ("decode", "{\"initial\": [1.0],", "EOF"),
        ("decode", "{\"initial\": [0.5, 0.5], \"transition\": [[1.0, 0.0]], \"log_emission\": [[0.0, 0.0]]}", "transition"),
        ("decode", "{\"initial\": [1.0], \"transition\": [[1.0]], \"log_emission\": [[0.0, 1.0]]}", "log_emission[0]"),
        ("decode", "{\"initial\": [1.0], \"transition\": [[0.5]], \"log_emission\": [[0.0]]}", "sums to 0.5"),
        ("decode", "{\"initial\": [1.0], \"transition\": [[1.0]], \"log_emission\": [[0.0]], \"x\": 1}", "unknown field"),
        ("fit", "{\"initial\": [1.0], \"transition\": [[1.0]], \"means\": [[[0.0, 0.0]]], \"covariances\": [[[[1.0, 0.0], [0.0, -1.0]]]], \"observations\": [[[0.0, 0.0]]], \"iterations\": 1}", "covariances[0][0]"),
        ("fit", "{\"initial\": [1.0], \"transition\": [[1.0]], \"means\": [[[0.0, 0.0]]], \"covariances\": [[[[1.0, 0.0], [0.0, 1.0]]]], \"observations\": [[[0.0]]], \"iterations\": 1}", "observations[0][0]"),
        ("fit", "{\"initial\": [1.0], \"transition\": [[1.0]], \"means\": [[[0.0, 0.0]]], \"covariances\": [[[[1.0, 0.0], [0.0, 1.0]]]], \"observations\": [[[0.0, 0.0]]], \"iterations\": -1}", "iterations"),
    ] {
        let (status, stdout, stderr) = cli(verb, input);
        assert_eq!(status, 2, "{verb} {input}: {stderr}");
        assert!(stdout.is_empty());
        assert!(stderr.starts_with(&format!("waymark hmm {verb}: ")) && stderr.contains(expected), "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
}
