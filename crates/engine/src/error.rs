//! The crate's error types.

use crate::radio::ScanError;
use crate::sensors::MotionConfigError;
use crate::site::SiteError;

/// Everything that can go wrong in Waymark.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Error {
    /// A configuration field is out of range.
    #[error("invalid configuration: {0}")]
    InvalidConfig(String),
    /// The site file could not be loaded.
    #[error(transparent)]
    Site(#[from] SiteError),
    /// An input was rejected; the engine is unchanged.
    #[error(transparent)]
    Input(#[from] InputError),
}

impl From<MotionConfigError> for Error {
    /// A motion configuration field out of range is the engine's configuration out of range.
    fn from(e: MotionConfigError) -> Self {
        Error::InvalidConfig(e.0)
    }
}

/// Why an input was rejected. A rejected input leaves the engine exactly as it was, and is
/// counted in [`InputStats`](crate::engine::InputStats).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum InputError {
    /// The timestamp is not after the last accepted one (a duplicate or a step back in time).
    #[error("timestamp {timestamp_ns} ns is not after the last accepted scan at {last_ns} ns")]
    OutOfOrder {
        /// The rejected timestamp.
        timestamp_ns: u64,
        /// The last accepted timestamp.
        last_ns: u64,
    },
    /// A time after [`MAX_TIMESTAMP_NS`](crate::sensors::MAX_TIMESTAMP_NS): a negative
    /// signed time passed as unsigned. Taken, it would put every later input out of order
    /// (docs/errors.md#timestamps-ahead-of-the-clock).
    #[error("timestamp {timestamp_ns} ns is past any phone's clock (a negative time passed as unsigned?)")]
    TimeAhead {
        /// The refused timestamp.
        timestamp_ns: u64,
    },
    /// A scan with no readings.
    #[error("the scan has no readings")]
    EmptyScan,
    /// A reading's RSSI is NaN, infinite or below -1000 dBm: the scan is corrupt and is
    /// rejected whole.
    #[error("reading {index} ({transmitter}) has a non-finite or impossible RSSI")]
    NonFiniteRssi {
        /// Position of the reading in the scan.
        index: usize,
        /// Its transmitter.
        transmitter: String,
    },
    /// A reading's RSSI is above [`MAX_RSSI_DBM`](crate::radio::MAX_RSSI_DBM) (+100 dBm), which
    /// no receiver reports: the scan is corrupt and is rejected whole.
    #[error("reading {index} ({transmitter}) has an RSSI of {rssi_dbm} dBm, above any receiver's")]
    RssiTooHigh {
        /// Position of the reading in the scan.
        index: usize,
        /// Its transmitter.
        transmitter: String,
        /// The RSSI, dBm.
        rssi_dbm: f64,
    },
    /// Motion given with an epoch (`push_scan_with_motion`, `advance_with_motion`) has a
    /// non-finite value, or a negative distance or spread.
    #[error("invalid motion: {field} is {value}")]
    InvalidMotion {
        /// The field of the `MotionUpdate`.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// None of the scan's readings is of a transmitter in the site's radio map (after dropping
    /// duplicates and stale readings): it says nothing about where the phone is.
    #[error("no reading is of a transmitter this site knows ({unknown} unknown, {stale} stale)")]
    NoKnownTransmitter {
        /// Readings of unknown transmitters.
        unknown: usize,
        /// Readings older than the age limit.
        stale: usize,
    },
    /// User feedback named a zone the site does not have.
    #[error("the site has no zone {zone:?}")]
    UnknownZone {
        /// The zone as given: its name, or `#index`.
        zone: String,
    },
    /// A floor index the site does not have (a position fix's or a confirmed position's).
    #[error("floor {floor} does not exist (the site has {floors} floors)")]
    UnknownFloor {
        /// The floor given.
        floor: usize,
        /// How many floors the site has.
        floors: usize,
    },
    /// A position fix or a confirmed position with a NaN or infinite coordinate, or an
    /// accuracy or radius that is not finite and > 0.
    #[error("invalid {field}: {value}")]
    InvalidValue {
        /// Which argument.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// A position fix too far from every state for the phone to be on the site (beyond the
    /// fix's own error bound), or a confirmed position with no state within its radius.
    #[error("the position is {distance_m:.1} m from the site's nearest state (at most {limit_m:.1} m)")]
    OutsideSite {
        /// Distance from the position to the nearest state (on the floor given, if any), m.
        distance_m: f64,
        /// The most it may be, m.
        limit_m: f64,
    },
}

impl From<ScanError> for InputError {
    /// A scan whose readings fail [`check_readings`](crate::radio::check_readings) is rejected
    /// as the input error of the same name.
    fn from(e: ScanError) -> Self {
        match e {
            ScanError::EmptyScan => InputError::EmptyScan,
            ScanError::NonFiniteRssi { index, transmitter } => {
                InputError::NonFiniteRssi { index, transmitter }
            }
            ScanError::RssiTooHigh { index, transmitter, rssi_dbm } => {
                InputError::RssiTooHigh { index, transmitter, rssi_dbm }
            }
        }
    }
}
