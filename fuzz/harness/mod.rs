//! The fuzz targets' logic, shared by `fuzz/fuzz_targets/*.rs` (cargo-fuzz, nightly) and the
//! main crate's `tests/fuzz_corpus.rs` (stable), which replays the committed corpus through it.
//! Each `run` panics when an invariant breaks; every other outcome is a pass.

pub mod checks;
pub mod cursor;
pub mod engine_calls;
pub mod ilc_trace;
pub mod site_cost;
pub mod site_file;
