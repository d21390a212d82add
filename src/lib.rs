//! Waymark: indoor positioning on the phone.
//!
//! Apps hand Waymark radio scans (WiFi access points, BLE beacons) with monotonic nanosecond
//! timestamps; Waymark runs a hidden Markov model over the states of a surveyed site and
//! returns position, floor and a calibrated 68% accuracy radius.
//!
//! The algorithms follow Hoang et al., "A hidden Markov model for indoor user tracking based on
//! WiFi fingerprinting and step detection" (censored-Gaussian fingerprints, forward recursion,
//! eq. 4 estimate) and Li et al., "HIPE" (transition probabilities with a floor).
//!
//! ```
//! use std::sync::Arc;
//! use waymark::{sim, Engine, EngineConfig};
//!
//! let building = sim::Office::generate(&sim::OfficeConfig::default());
//! let site = Arc::new(building.site.clone());
//! let mut engine = Engine::new(site, EngineConfig::default()).unwrap();
//! let walk = building.walk(7, 60.0);
//! for epoch in &walk.epochs {
//!     let position = engine.push_scan(&epoch.scan).unwrap();
//!     assert!(position.accuracy_m > 0.0);
//! }
//! ```
#![deny(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod config;
pub mod engine;
pub mod error;
pub mod eval;
pub mod hmm;
pub mod radio;
pub mod sim;
pub mod site;

pub use config::EngineConfig;
pub use engine::{Engine, InputStats, Position, PositionListener, SubscriptionId};
pub use error::{Error, InputError};
pub use radio::{Reading, Scan, TransmitterId};
pub use site::{Site, SiteError};

uniffi::setup_scaffolding!();
