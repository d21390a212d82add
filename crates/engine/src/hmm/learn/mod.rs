//! Learning a hidden Markov model from observations: exact inference (log-space forward-backward,
//! smoothed posteriors, Viterbi) and Baum-Welch re-estimation of the initial distribution, a
//! sparse transition matrix and Gaussian-mixture emissions, after El Gemayel et al.,
//! "Improved Indoor Positioning Using the Baum-Welch Algorithm", who follow Rabiner's tutorial.
//!
//! - [`Chain`]: initial distribution π and a row-stochastic [`SparseTransition`] holding only the
//!   allowed transitions (the paper's §II-B: "some elements are known to be zero").
//! - [`EpochMatrix`]: a T × N table, for log-emissions ln p_i(o_t) and for posteriors.
//! - [`forward_backward`], [`viterbi`], [`decode`]: inference on a chain and log-emissions
//!   (eqs. 8-9 in logs, with Rabiner's per-epoch normalisation); [`Known`] pins epochs to a set of states (§IV-C).
//! - [`GaussianMixtures`]: eq. 7, M_i components per state with fixed weights 1/M_i.
//! - [`fit`]: Baum-Welch (eqs. 10-13) over several [`Sequence`]s, with [`FitOptions`] for plain
//!   maximum likelihood or the regularised fit a live engine needs.
//! - [`json`]: the JSON documents of a decode and a fit, for tools and tests.
//!
//! These recursions are exact: unlike [`predict`](super::predict) and
//! `viterbi_step`, which prune rows and paths for the live engine, they
//! keep every state's forward and backward variable as a logarithm and drop none (see
//! [`forward_backward`]).
//!
//! # Cost
//!
//! With N states, E allowed transitions, C = Σ M_i mixture components in D dimensions, and
//! sequences of T epochs (T_max the longest):
//!
//! - inference: time O(T · (E + N)); memory O(T · N) for the log forward variables (and
//!   the posteriors returned), O(N) for the backward pass; Viterbi O(T · (E + N)) time and
//!   O(T · N) back-pointers (4 bytes each).
//! - one Baum-Welch iteration: time O(T · (E + C · D²)) per sequence plus O(C · D³) for the
//!   Cholesky factors; memory O(E + C · D² + T_max · (N + C)): the transition counts, the
//!   components' sufficient statistics, and one sequence at a time's log-emissions, forward
//!   variables and component responsibilities (eq. 13's bracket, kept from the emission pass
//!   so that no Gaussian is evaluated twice).
//!
//! A 10 000-state site with ~100 neighbours per state (E = 10⁶), one component per state and
//! 500-epoch sequences needs 12 MB for the transitions and their counts and
//! 3 × 500 × 10 000 × 8 B = 120 MB for one sequence's tables; a dense N × N matrix would be
//! 800 MB per copy. (Only the time per epoch grows with E, not with N².)

mod baum_welch;
mod chain;
mod emission;
mod inference;
pub mod json;

pub use baum_welch::{fit, log_likelihood, FitOptions, FitReport, GaussianHmm, Sequence};
pub use chain::{Chain, SparseTransition};
pub use emission::{Gaussian, GaussianMixtures};
pub(crate) use inference::expected_counts;
pub use inference::{decode, forward_backward, viterbi, Decoded, EpochMatrix, Known, Posterior};

/// Why a model, an observation sequence or a fit was refused. Nothing is changed when one is
/// returned.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LearnError {
    /// Two things that must have the same size do not.
    #[error("{what} has {got} entries, expected {expected}")]
    Dimension {
        /// What has the wrong size, e.g. `transition[3]`.
        what: String,
        /// The size it must have.
        expected: usize,
        /// The size it has.
        got: usize,
    },
    /// Something that must not be empty is.
    #[error("{0} is empty")]
    Empty(String),
    /// A number is NaN or infinite (or, for a log-emission, NaN or +∞).
    #[error("{what} is not finite ({value})")]
    NonFinite {
        /// Where, e.g. `observations[0][12]`.
        what: String,
        /// The value.
        value: f64,
    },
    /// A probability is negative.
    #[error("{what} is a negative probability ({value})")]
    Negative {
        /// Where.
        what: String,
        /// The value.
        value: f64,
    },
    /// A distribution does not sum to 1 within 10⁻⁶.
    #[error("{what} sums to {sum}, not 1")]
    NotStochastic {
        /// The distribution, e.g. `initial` or `transition[4]`.
        what: String,
        /// Its sum.
        sum: f64,
    },
    /// A state index is not below the number of states.
    #[error("{what} names state {state}, but there are {states} states")]
    StateOutOfRange {
        /// Where.
        what: String,
        /// The index.
        state: usize,
        /// The number of states.
        states: usize,
    },
    /// A state appears twice where each may appear once.
    #[error("{what} names state {state} twice")]
    Duplicate {
        /// Where.
        what: String,
        /// The index.
        state: usize,
    },
    /// A covariance matrix is not symmetric or not positive definite.
    #[error("{what} is not a symmetric positive definite covariance")]
    NotPositiveDefinite {
        /// Which one, e.g. `covariances[2][0]`.
        what: String,
    },
    /// No state sequence allowed by the model (and by the known states) explains the
    /// observations up to this epoch: every path has probability zero.
    #[error("no path of the model explains sequence {sequence} at epoch {epoch}")]
    Impossible {
        /// The sequence.
        sequence: usize,
        /// The first epoch no path reaches.
        epoch: usize,
    },
    /// A feature the input asks for is not supported.
    #[error("{0}")]
    Unsupported(String),
}
