//! Evaluating Waymark on recorded walks: surveyed sites scored on held-out test walks against
//! the baselines ([`real`]), pedestrian dead reckoning on its own ([`pdr`]) and plots of
//! tracks and error curves ([`plot`]), where the recorded data is found ([`data`]), and the
//! accuracy benchmark over buildings every accuracy change is judged by ([`benchmark`]).
//!
//! A tool beside the SDK: it depends on `waymark`, `waymark-survey` and `waymark-sim`, never
//! the reverse.

#![deny(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod benchmark;
pub mod data;
pub mod drift;
pub mod pdr;
pub mod plot;
pub mod real;
