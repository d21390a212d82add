//! The serde model of a site file, shared by both encodings: the JSON document, and the
//! binary file's header and fingerprint columns. It parses and checks the format version;
//! `file.rs` validates what it holds.

use super::error::{invalid, json_error};
use super::{Anchor, Calibration, North, SiteError, StateKind, ZoneKind};
use crate::radio::{RssiModel, TransmitterId, LEVEL_STEP_DB};
use serde::{Deserialize, Serialize};

/// The site-file format this build writes. It reads this and every version back to
/// [`OLDEST_FORMAT_VERSION`], and refuses a newer one ([`SiteError::NewerFormat`]). Version 2
/// holds the optional fields added within version 1, version 3 adds the optional geo anchor
/// and floor levels, version 4 the survey's reading-age limit, version 5 the calibrated M of
/// the estimate, version 6 the floor probability's calibration, version 7 the transmitters
/// that share a radio, version 8 the survey's floor-change rate
/// (docs/site-files.md#versioning): each version's files are files of the next.
pub const FORMAT_VERSION: u32 = 8;

/// The oldest site-file format this build reads.
pub const OLDEST_FORMAT_VERSION: u32 = 1;

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SiteFile {
    pub(super) format_version: u32,
    pub(super) name: String,
    #[serde(default)]
    pub(super) north: North,
    /// Since version 3.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) anchor: Option<Anchor>,
    pub(super) floors: Vec<FloorFile>,
    pub(super) radio: RadioFile,
    pub(super) states: Vec<StateFile>,
    #[serde(default)]
    pub(super) edges: Vec<EdgeFile>,
    #[serde(default, skip_serializing_if = "Calibration::is_empty")]
    pub(super) calibration: Calibration,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub(super) zones: Vec<ZoneFile>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ZoneFile {
    pub(super) name: String,
    #[serde(default)]
    pub(super) kind: ZoneKind,
    /// State ids.
    pub(super) states: Vec<u32>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct FloorFile {
    pub(super) name: String,
    #[serde(default)]
    pub(super) elevation_m: f64,
    /// Since version 3.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) level: Option<i32>,
    /// Since version 3.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) origin_m: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) rssi_weight: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) rssi_weight_without_movement: Option<f64>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RadioFile {
    #[serde(default)]
    pub(super) model: RssiModel,
    pub(super) clip_dbm: f64,
    pub(super) unheard: GaussianFile,
    /// Present when `transmitters` are salted hashes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) id_hash: Option<IdHashFile>,
    /// Since version 4: readings older than this before their scan were not heard when the
    /// fingerprints were fitted, ms.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) max_reading_age_ms: Option<u64>,
    /// Since version 7: groups of transmitter indices that one radio sends.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub(super) shared_radios: Vec<Vec<u32>>,
    pub(super) transmitters: Vec<TransmitterId>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct IdHashFile {
    /// `hmac-sha256-128`.
    pub(super) scheme: String,
    /// 1.
    pub(super) version: u32,
    /// HMAC-SHA256(salt, "waymark salt check"), 128 bits as hex.
    pub(super) salt_check: String,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct GaussianFile {
    pub(super) mean_dbm: f64,
    pub(super) std_db: f64,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct StateFile {
    pub(super) id: u32,
    pub(super) floor: usize,
    pub(super) x: f64,
    pub(super) y: f64,
    #[serde(default)]
    pub(super) kind: StateKind,
    #[serde(default)]
    pub(super) training_scans: u32,
    /// Empty in the header of a binary site file, whose fingerprints follow in columns.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub(super) fingerprint: Vec<FingerprintFile>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct FingerprintFile {
    /// Index into `radio.transmitters`.
    pub(super) tx: usize,
    pub(super) mean_dbm: f64,
    pub(super) std_db: f64,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct EdgeFile {
    /// State id.
    pub(super) from: u32,
    /// State id.
    pub(super) to: u32,
    /// Walking length; required between floors, else the straight-line distance.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) length_m: Option<f64>,
}

/// Why a file of `format_version` `found` cannot be read, if it cannot: a newer format than
/// this build knows, or a version before the first.
fn version_error(found: u64) -> Option<SiteError> {
    if found > u64::from(FORMAT_VERSION) {
        Some(SiteError::NewerFormat { found, supported: FORMAT_VERSION })
    } else if found < u64::from(OLDEST_FORMAT_VERSION) {
        Some(SiteError::UnsupportedVersion { found, supported: FORMAT_VERSION })
    } else {
        None
    }
}

/// Why a file that does not parse is not a site file of this version, if it is not: a
/// missing or other `format_version` says more than the first field that fails to parse.
fn check_version(bytes: &[u8]) -> Result<(), SiteError> {
    #[derive(Deserialize)]
    struct Version {
        format_version: Option<serde_json::Value>,
    }
    let version: Version = serde_json::from_slice(bytes).map_err(|e| json_error(&e))?;
    match version.format_version {
        None => Err(invalid("format_version", "missing: is this a Waymark site file?")),
        Some(v) => match v.as_u64() {
            Some(found) => version_error(found).map_or(Ok(()), Err),
            None => Err(invalid("format_version", format!("expected an integer, found {v}"))),
        },
    }
}

/// The UTF-8 byte order mark, which some editors (Windows Notepad) put before the text: a site
/// file may begin with it, and the reader skips it (RFC 8259 §8.1 lets a parser ignore it).
pub(super) const UTF8_BOM: &[u8] = b"\xEF\xBB\xBF";

/// Parses (but does not validate) a JSON site file of a format version this build reads. A
/// newer file is refused as such, not by the first field it has that this build does not know.
/// The file is one JSON document, after an optional [`UTF8_BOM`]: anything but white space
/// after it (a second document, a copy appended to the file) is refused, never ignored.
pub(super) fn parse_json(bytes: &[u8]) -> Result<SiteFile, SiteError> {
    let bytes = bytes.strip_prefix(UTF8_BOM).unwrap_or(bytes);
    if bytes.starts_with(b"\xFE\xFF") || bytes.starts_with(b"\xFF\xFE") {
        return Err(SiteError::Syntax {
            line: 1,
            column: 1,
            message: "the file begins with a UTF-16 byte order mark: a site file is UTF-8".into(),
        });
    }
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let parsed: Result<SiteFile, _> = serde_path_to_error::deserialize(&mut de);
    // The version is checked first only when the file does not parse as this version:
    // reading the document twice doubled the load time of a 10 000-state site.
    match parsed {
        Ok(file) => {
            if let Err(e) = de.end() {
                return Err(SiteError::Syntax {
                    line: e.line(),
                    column: e.column(),
                    message: "data after the end of the site's JSON document (a second document, \
                              or bytes appended to the file)"
                        .into(),
                });
            }
            version_error(u64::from(file.format_version)).map_or(Ok(file), Err)
        }
        Err(e) => {
            check_version(bytes)?;
            let inner = e.inner();
            Err(match inner.classify() {
                serde_json::error::Category::Data => invalid(e.path().to_string(), inner.to_string()),
                _ => json_error(inner),
            })
        }
    }
}

/// Where a site file keeps its fingerprints.
pub(super) enum Fingerprints<'a> {
    /// In each state's `fingerprint` array (JSON).
    Nested,
    /// In columns after the header, state by state (binary); every state's array is empty.
    Columns(&'a Columns<'a>),
}

/// The fingerprint columns of a binary site file, read in place.
pub(super) struct Columns<'a> {
    pub(super) counts: &'a [u8],
    pub(super) tx: &'a [u8],
    pub(super) mean: &'a [u8],
    pub(super) std: &'a [u8],
}

impl Columns<'_> {
    /// Entries of state `i`.
    #[inline]
    pub(super) fn count(&self, i: usize) -> usize {
        u32_at(self.counts, i) as usize
    }

    /// Entry `k` as (transmitter, mean dBm, σ dB).
    pub(super) fn entry(&self, k: usize) -> (usize, f64, f64) {
        let (tx, mean, std) = self.entry_steps(k);
        // Division, not multiplication by LEVEL_STEP_DB: the nearest double to the level, so
        // that it prints as written (-67.31, not -67.31000000000001).
        let step = 1.0 / LEVEL_STEP_DB;
        (tx, f64::from(mean) / step, f64::from(std) / step)
    }

    /// Entry `k` as (transmitter, mean and σ in [`LEVEL_STEP_DB`] steps), as stored.
    #[inline]
    pub(super) fn entry_steps(&self, k: usize) -> (usize, i16, u16) {
        let mean = i16::from_le_bytes([self.mean[2 * k], self.mean[2 * k + 1]]);
        let std = u16::from_le_bytes([self.std[2 * k], self.std[2 * k + 1]]);
        (u32_at(self.tx, k) as usize, mean, std)
    }
}

fn u32_at(bytes: &[u8], i: usize) -> u32 {
    u32::from_le_bytes([bytes[4 * i], bytes[4 * i + 1], bytes[4 * i + 2], bytes[4 * i + 3]])
}
