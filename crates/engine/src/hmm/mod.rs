//! The hidden Markov model over the site's states: sparse transitions, the forward recursion
//! (Hoang eq. 3) and the position estimate (Hoang eq. 4); and, in [`learn`], exact inference and
//! Baum-Welch learning (El Gemayel et al.).

mod estimate;
mod forward;
pub mod learn;
mod motion;
mod smoother;
mod transition;
mod viterbi;

pub use estimate::{estimate, positions_by_states, Estimate};
pub use forward::{FilterError, ForwardFilter};
pub use motion::{
    angle_between, azimuth, HipeRegion, MovementVectorTransition, PreparedHoang, RegionsTransition,
};
pub use smoother::{FixedLagSmoother, STEP_BYTES_PER_STATE};
pub use transition::{
    hipe_probabilities, predict, predict_and_viterbi_step, viterbi_step, BackPointer, RowBounds, Transition,
    UniformReach,
};
pub use viterbi::{BackPointers, ViterbiWindow};
