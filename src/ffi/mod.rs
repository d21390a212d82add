//! The only place that knows about uniffi and the C ABI: thin wrappers over the pure core.
//! Kotlin and Swift see [`uniffi`]'s types; C (and dart:ffi, React Native, Unity) sees [`c`]'s,
//! through the header `bindings/c/waymark.h`.

pub mod c;
pub mod logging;
pub mod uniffi;
