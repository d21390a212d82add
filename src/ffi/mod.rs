//! The only place that knows about uniffi and the C ABI: thin wrappers over the pure core.
//! Apps see [`uniffi`]'s types from Kotlin and Swift.

pub mod uniffi;
