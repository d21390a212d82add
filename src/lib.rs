//! Waymark's SDK library, the one mobile apps link: the engine of the `waymark-engine` crate
//! behind uniffi for Kotlin and Swift (`libwaymark.so`, `.a`, namespace `waymark`) and behind
//! a C ABI (the header `bindings/c/waymark.h`). The README says how to embed it per platform.
//!
//! From Rust, this crate is the API Kotlin and Swift see: the [`PositioningEngine`] object
//! with its listeners, the shared site, the records, routes, the survey recorder, errors and
//! logging. Where the engine crate has a type of the same name, the Rust type here is prefixed
//! `Ffi` and Kotlin and Swift see the name without it ([`FfiSite`] is `Site`); the motion,
//! zone-kind and turn enums are the engine's own. A Rust app uses the engine directly: depend
//! on `waymark-engine`. The C functions are the library's exported symbols, not a Rust API.
#![deny(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

mod ffi;

pub use ffi::logging::{init_logging, LogLevel, LogSink, MAX_HELD_RECORDS};
pub use ffi::uniffi::*;

uniffi::setup_scaffolding!();
