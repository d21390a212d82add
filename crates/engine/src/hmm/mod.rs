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
pub use motion::azimuth;
pub(crate) use motion::HipeRegion;
pub(crate) use motion::MovementVectorTransition;
pub(crate) use motion::RegionsTransition;
pub(crate) use smoother::kept;
pub(crate) use smoother::FixedLagSmoother;
pub use smoother::STEP_BYTES_PER_STATE;
pub use transition::{predict, RowBounds, Transition, UniformReach};
pub use viterbi::ViterbiWindow;
