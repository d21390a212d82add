#![doc = include_str!("../README.md")]
#![deny(missing_docs)]
#![deny(rustdoc::broken_intra_doc_links)]

pub mod config;
pub mod engine;
pub mod error;
pub mod eval;
pub mod ffi;
pub mod fix;
pub mod habits;
pub mod history;
pub mod hmm;
pub mod io;
pub mod radio;
pub mod sensors;
pub mod sim;
pub mod site;
pub mod survey;

pub use config::EngineConfig;
pub use engine::{Engine, InputStats, Position, PositionListener, StatusEvent, SubscriptionId, TrackPoint};
pub use error::{Error, InputError};
pub use fix::PositionFix;
pub use radio::{Reading, Salt, Scan, TransmitterId};
pub use site::{Site, SiteError, Zone, ZoneKind};

uniffi::setup_scaffolding!();
