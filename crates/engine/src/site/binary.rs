//! The binary site encoding: what an app ships and loads. JSON stays the interchange form
//! (the survey writes it, people read and diff it; `docs/site-files.md`); packed, it becomes
//! this, which loads a large site in a fraction of the time and memory the JSON parser needs
//! (docs/tuning.md#engine-speed).
//!
//! Layout, all integers little-endian:
//!
//! | bytes | content |
//! |---|---|
//! | 8 | signature `\x89WMSITE\n` (not text, so never mistaken for JSON) |
//! | 4 | layout version, `u32` ([`LAYOUT_VERSION`]) |
//! | 8 | header length H, `u64` |
//! | H | the JSON site file (same `format_version`) with every state's `fingerprint` empty |
//! | 8 | fingerprint entries E, `u64` |
//! | 4 × states | entries per state, `u32`, in the header's state order |
//! | 4 × E | transmitter index, `u32` |
//! | 2 × E | mean, `i16`, in 0.01 dB ([`LEVEL_STEP_DB`]) |
//! | 2 × E | σ, `u16`, in 0.01 dB |
//! | 4 | CRC-32 (IEEE) of every byte before it |
//!
//! The header goes through the same validation as a JSON file, and so does every entry, with
//! the same error paths (`states[12].fingerprint[3]`). The levels are those the radio map
//! stores anyway, so JSON → binary → JSON is exact.

use super::schema::{parse_json, Columns, Fingerprints};
use super::{Site, SiteError};
use crate::radio::LEVEL_STEP_DB;

/// The first 8 bytes of a binary site file.
pub const SIGNATURE: &[u8; 8] = b"\x89WMSITE\n";

/// The layout this build reads and writes.
pub const LAYOUT_VERSION: u32 = 1;

/// Whether `bytes` start like a binary site file.
pub(super) fn is_binary(bytes: &[u8]) -> bool {
    bytes.starts_with(SIGNATURE)
}

fn damaged(message: impl Into<String>) -> SiteError {
    SiteError::Damaged { message: message.into() }
}

/// Reads a binary site file front to back, naming what is missing when it ends early.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: u64, what: &str) -> Result<&'a [u8], SiteError> {
        let left = (self.bytes.len() - self.at) as u64;
        if n > left {
            return Err(damaged(format!(
                "truncated: {what} needs {n} bytes at offset {}, the file has {left} left",
                self.at
            )));
        }
        let slice = &self.bytes[self.at..self.at + n as usize];
        self.at += n as usize;
        Ok(slice)
    }

    fn u32(&mut self, what: &str) -> Result<u32, SiteError> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn u64(&mut self, what: &str) -> Result<u64, SiteError> {
        let b = self.take(8, what)?;
        Ok(u64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]))
    }
}

/// Loads a binary site file.
pub(super) fn decode(bytes: &[u8]) -> Result<Site, SiteError> {
    let mut r = Reader { bytes, at: SIGNATURE.len() };
    let version = r.u32("the layout version")?;
    if version != LAYOUT_VERSION {
        return Err(SiteError::UnsupportedLayout { found: version, supported: LAYOUT_VERSION });
    }
    // The checksum first: a damaged file must not load as some other site.
    if bytes.len() < r.at + 4 {
        return Err(damaged("truncated: no room for the checksum"));
    }
    let (body, stored) = bytes.split_at(bytes.len() - 4);
    let stored = u32::from_le_bytes([stored[0], stored[1], stored[2], stored[3]]);
    let computed = crc32fast::hash(body);
    // Fuzzing builds (cargo-fuzz sets `--cfg fuzzing`) skip the check, or nearly every
    // mutation would stop here and the decoder behind it would go unexplored.
    if stored != computed && !cfg!(fuzzing) {
        return Err(damaged(format!(
            "checksum {stored:08x} does not match the contents ({computed:08x}): the file was changed or cut short"
        )));
    }
    let r = &mut Reader { bytes: body, at: r.at };
    let header_len = r.u64("the header length")?;
    let header = r.take(header_len, "the header")?;
    let entries = r.u64("the entry count")?;
    let file = parse_json(header)?;
    let states = file.states.len() as u64;
    let counts = r.take(states.saturating_mul(4), "the entries per state")?;
    let tx = r.take(entries.saturating_mul(4), "the transmitter column")?;
    let mean = r.take(entries.saturating_mul(2), "the mean column")?;
    let std = r.take(entries.saturating_mul(2), "the σ column")?;
    if r.at != body.len() {
        return Err(damaged(format!("{} bytes after the last column", body.len() - r.at)));
    }
    let columns = Columns { counts, tx, mean, std };
    let listed: u64 = (0..file.states.len()).map(|i| columns.count(i) as u64).sum();
    if listed != entries {
        return Err(damaged(format!("the states list {listed} entries, the columns hold {entries}")));
    }
    Site::from_file(file, Fingerprints::Columns(&columns))
}

/// Encodes a site (see the module documentation for the layout).
pub(super) fn encode(site: &Site) -> Vec<u8> {
    let header =
        serde_json::to_vec(&site.to_file(false)).expect("a site serialises: every float in it is finite");
    let n = site.states().len();
    // Entries state by state, so the loader's buckets by transmitter come out sorted.
    let mut by_state: Vec<(u32, u32, i16, u16)> = site
        .radio()
        .fingerprints()
        .map(|(s, t, g)| {
            let steps = |v: f64| (v / LEVEL_STEP_DB).round();
            (s, t, steps(g.mean_dbm) as i16, steps(g.std_db) as u16)
        })
        .collect();
    by_state.sort_unstable_by_key(|e| (e.0, e.1));
    let mut counts = vec![0u32; n];
    for e in &by_state {
        counts[e.0 as usize] += 1;
    }
    let e = by_state.len();
    let mut out = Vec::with_capacity(SIGNATURE.len() + 4 + 8 + header.len() + 8 + 4 * n + 8 * e + 4);
    out.extend_from_slice(SIGNATURE);
    out.extend_from_slice(&LAYOUT_VERSION.to_le_bytes());
    out.extend_from_slice(&(header.len() as u64).to_le_bytes());
    out.extend_from_slice(&header);
    out.extend_from_slice(&(e as u64).to_le_bytes());
    counts.iter().for_each(|c| out.extend_from_slice(&c.to_le_bytes()));
    by_state.iter().for_each(|x| out.extend_from_slice(&x.1.to_le_bytes()));
    by_state.iter().for_each(|x| out.extend_from_slice(&x.2.to_le_bytes()));
    by_state.iter().for_each(|x| out.extend_from_slice(&x.3.to_le_bytes()));
    let crc = crc32fast::hash(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

impl Site {
    /// The site in the binary encoding (see `site/binary.rs`): what an app should ship.
    /// [`Site::from_bytes`] and [`Site::load`] read it; JSON ([`Site::to_json`]) stays the
    /// interchange form. Exact: the levels are those the radio map stores.
    pub fn to_binary(&self) -> Vec<u8> {
        encode(self)
    }
}
