//! Why a site file could not be loaded.

use super::schema::OLDEST_FORMAT_VERSION;
use crate::radio::{ID_HASH_SCHEME, ID_HASH_VERSION};

/// Why a site file could not be loaded.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SiteError {
    /// The file could not be read.
    #[error("cannot read site file {path}: {message}")]
    Io {
        /// The path given.
        path: String,
        /// The operating system's reason.
        message: String,
    },
    /// The JSON ends early: a truncated download or copy.
    #[error("site file is truncated (JSON ends at line {line}, column {column})")]
    Truncated {
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
    },
    /// Not JSON at all at some point.
    #[error("site file is not valid JSON at line {line}, column {column}: {message}")]
    Syntax {
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// serde_json's description.
        message: String,
    },
    /// A `format_version` before the first (0): not a file any build of Waymark wrote.
    #[error(
        "site file has format_version {found}; this build of Waymark reads versions {} to {supported}",
        OLDEST_FORMAT_VERSION
    )]
    UnsupportedVersion {
        /// The version in the file.
        found: u64,
        /// The newest version this build reads.
        supported: u32,
    },
    /// Written in a newer format than this build reads: the app needs a newer Waymark, or a
    /// site file made for the version it has.
    #[error(
        "site file is in a newer format (format_version {found}) than this build of Waymark reads ({supported})"
    )]
    NewerFormat {
        /// The version in the file.
        found: u64,
        /// The newest version this build reads.
        supported: u32,
    },
    /// Valid JSON, but a field is missing, of the wrong type, or its value is impossible.
    #[error("site file: {path}: {message}")]
    Invalid {
        /// Where, as a JSON path (`states[12].fingerprint[3].std_db`).
        path: String,
        /// What is wrong.
        message: String,
    },
    /// Within the format, but over one of the limits on what a site may cost (its size, its
    /// states, the walking-distance tables an engine builds from it): a file crafted to
    /// exhaust memory or time, or far larger than any real site
    /// (`waymark_engine::site::budget`, docs/errors.md#site-limits).
    #[error(
        "site is over a limit: {what} (the most allowed is {limit}: {name}, docs/errors.md#site-limits)"
    )]
    OverLimit {
        /// The limit's name, a constant of `waymark_engine::site::budget` (`MAX_REACHABLE_STATES`).
        name: &'static str,
        /// Its value.
        limit: u64,
        /// What is over it, and where.
        what: String,
    },
    /// A binary site file that was cut short or changed after it was written (its checksum
    /// differs), or whose parts do not fit together.
    #[error("binary site file is damaged: {message}")]
    Damaged {
        /// What is wrong, and where.
        message: String,
    },
    /// A binary site file in a newer (or unknown) layout.
    #[error(
        "binary site file has layout version {found}; this build of Waymark reads layout version {supported}"
    )]
    UnsupportedLayout {
        /// The layout version in the file.
        found: u32,
        /// The layout version this build reads.
        supported: u32,
    },
    /// The transmitter ids are hashed with a scheme this build does not know (a newer one).
    #[error(
        "site file hashes its transmitter ids with {scheme} version {version}; this build knows {} version {}",
        ID_HASH_SCHEME,
        ID_HASH_VERSION
    )]
    UnsupportedIdHash {
        /// The scheme in the file.
        scheme: String,
        /// Its version.
        version: u32,
    },
    /// The site's transmitter ids are salted hashes and no salt was given, so no scan could
    /// match.
    #[error("the site's transmitter ids are hashed ({ID_HASH_SCHEME} version {ID_HASH_VERSION}): the engine needs the site's salt")]
    SaltRequired,
    /// The salt given is not the one the site's ids were hashed with (its salt check differs),
    /// so no scan could match.
    #[error(
        "the salt given is not the one this site's transmitter ids were hashed with (the salt check differs)"
    )]
    WrongSalt,
}

pub(super) fn invalid(path: impl Into<String>, message: impl Into<String>) -> SiteError {
    SiteError::Invalid { path: path.into(), message: message.into() }
}

pub(super) fn json_error(e: &serde_json::Error) -> SiteError {
    let (line, column) = (e.line(), e.column());
    match e.classify() {
        serde_json::error::Category::Eof => SiteError::Truncated { line, column },
        _ => SiteError::Syntax { line, column, message: e.to_string() },
    }
}
