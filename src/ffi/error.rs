//! The one public error of both FFIs, and how the core's errors map to it. Kotlin and Swift
//! see [`PositioningError`] (thrown) and [`ErrorReport`] (given to listeners); C sees the
//! `waymark_result` code of each [`ErrorCode`].

/// Errors an app can act on.
#[derive(Clone, Debug, PartialEq, thiserror::Error, uniffi::Error)]
pub enum PositioningError {
    /// The site file could not be read or is malformed; `reason` says what and where.
    #[error("invalid site: {reason}")]
    InvalidSite {
        /// What is wrong and where.
        reason: String,
    },
    /// A configuration value is out of range.
    #[error("invalid configuration: {reason}")]
    InvalidConfig {
        /// Which field and why.
        reason: String,
    },
    /// An input was rejected; the engine is unchanged and goes on. A scan, an advance or a
    /// position fix whose time is not after the last epoch's, or feedback whose time is before
    /// it; a scan with no readings, with an RSSI that is NaN, infinite, below -1000 dBm or
    /// above +100 dBm, with no transmitter the site knows, or with a malformed transmitter id:
    /// a BSSID, UUID or address that does not parse (in Kotlin, one holding a lone UTF-16
    /// surrogate too), a beacon with neither a UUID nor an address; a position fix or a
    /// confirmed position with a NaN or infinite coordinate, an accuracy or radius not > 0, a
    /// floor the site does not have, or too far from the site; feedback naming a zone the
    /// site does not have.
    #[error("input rejected: {reason}")]
    InputRejected {
        /// Why.
        reason: String,
    },
    /// The site's transmitter ids are salted hashes and `EngineOptions.siteSalt` is missing or
    /// is not the salt they were hashed with: get the venue's salt for this site file.
    #[error("salt mismatch: {reason}")]
    SaltMismatch {
        /// Missing or wrong (the salt itself is never in the message).
        reason: String,
    },
    /// `importHabits` refused the model: the JSON does not parse, is not a Waymark habit
    /// model, is of a newer layout than this build reads, was learned on another site (or
    /// another build of the site file), or holds a value out of range. `reason` says which,
    /// with the field's path. The engine's habits are unchanged. A stored model refused for
    /// its site or its content will never be accepted by this engine: learn afresh.
    #[error("habit model rejected: {reason}")]
    HabitsRejected {
        /// Why.
        reason: String,
    },
    /// A bug in Waymark. An epoch (a scan, an advance, a fix, feedback) or a read that
    /// failed this way had no effect: the engine is as it was, no listener hears of it, and it
    /// stays usable. Any other call that failed this way may have left the engine half-changed:
    /// every later call on it throws `Internal` too (create a new engine). A getter throws it
    /// rather than answer with an empty or made-up value.
    #[error("internal error: {reason}")]
    Internal {
        /// What happened.
        reason: String,
    },
}

/// Which kind of error a [`PositioningError`] is, without its message: what a listener's
/// `onError` is told, and (as `waymark_result`) what a C call returns.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, uniffi::Enum)]
pub enum ErrorCode {
    /// `PositioningError.InvalidSite`.
    InvalidSite,
    /// `PositioningError.InvalidConfig`.
    InvalidConfig,
    /// `PositioningError.InputRejected`.
    InputRejected,
    /// `PositioningError.SaltMismatch`.
    SaltMismatch,
    /// `PositioningError.HabitsRejected`.
    HabitsRejected,
    /// `PositioningError.Internal`.
    Internal,
}

/// A failed call, as a listener's `onError` hears it: the kind of error and its message (the
/// same text the call threw).
#[derive(Clone, Debug, PartialEq, Eq, uniffi::Record)]
pub struct ErrorReport {
    /// Which kind of error.
    pub code: ErrorCode,
    /// What went wrong, for logs (not for users).
    pub message: String,
}

impl PositioningError {
    /// Its kind.
    pub fn code(&self) -> ErrorCode {
        match self {
            PositioningError::InvalidSite { .. } => ErrorCode::InvalidSite,
            PositioningError::InvalidConfig { .. } => ErrorCode::InvalidConfig,
            PositioningError::InputRejected { .. } => ErrorCode::InputRejected,
            PositioningError::SaltMismatch { .. } => ErrorCode::SaltMismatch,
            PositioningError::HabitsRejected { .. } => ErrorCode::HabitsRejected,
            PositioningError::Internal { .. } => ErrorCode::Internal,
        }
    }

    /// What a listener hears of it.
    pub fn report(&self) -> ErrorReport {
        ErrorReport { code: self.code(), message: self.to_string() }
    }

    pub(crate) fn input(e: impl std::fmt::Display) -> Self {
        PositioningError::InputRejected { reason: e.to_string() }
    }

    pub(crate) fn internal(reason: impl Into<String>) -> Self {
        PositioningError::Internal { reason: reason.into() }
    }
}

impl From<uniffi::UnexpectedUniFFICallbackError> for PositioningError {
    fn from(e: uniffi::UnexpectedUniFFICallbackError) -> Self {
        PositioningError::Internal { reason: format!("foreign callback failed: {}", e.reason) }
    }
}

impl From<waymark_engine::Error> for PositioningError {
    fn from(e: waymark_engine::Error) -> Self {
        match e {
            waymark_engine::Error::InvalidConfig(reason) => PositioningError::InvalidConfig { reason },
            waymark_engine::Error::Site(s) => s.into(),
            waymark_engine::Error::Input(i) => PositioningError::input(i),
        }
    }
}

impl From<waymark_engine::SiteError> for PositioningError {
    fn from(e: waymark_engine::SiteError) -> Self {
        match e {
            s @ (waymark_engine::SiteError::SaltRequired | waymark_engine::SiteError::WrongSalt) => {
                PositioningError::SaltMismatch { reason: s.to_string() }
            }
            s => PositioningError::InvalidSite { reason: s.to_string() },
        }
    }
}

impl From<waymark_engine::InputError> for PositioningError {
    fn from(e: waymark_engine::InputError) -> Self {
        PositioningError::input(e)
    }
}

impl From<waymark_engine::geofence::GeofenceError> for PositioningError {
    fn from(e: waymark_engine::geofence::GeofenceError) -> Self {
        PositioningError::InputRejected { reason: e.to_string() }
    }
}

impl From<waymark_engine::habits::HabitError> for PositioningError {
    fn from(e: waymark_engine::habits::HabitError) -> Self {
        match e {
            // Learning's input is the engine's own history and validated options: a bug.
            waymark_engine::habits::HabitError::Learn(e) => {
                PositioningError::internal(format!("habits: {e}"))
            }
            e => PositioningError::HabitsRejected { reason: e.to_string() },
        }
    }
}
