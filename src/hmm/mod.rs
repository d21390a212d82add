//! The hidden Markov model over the site's states: sparse transitions, the forward recursion
//! (Hoang eq. 3) and the position estimate (Hoang eq. 4).

mod estimate;
mod forward;
mod transition;

pub use estimate::{estimate, Estimate};
pub use forward::{FilterError, ForwardFilter};
pub use transition::{hipe_probabilities, predict, viterbi_step, Transition, UniformReach};
