//! The compact binary form of [`Evidence`] (docs/evidence.md#file-format): LEB128 varints,
//! states and entries in order with their indices as deltas, the transmitters' keys once in
//! a table, and a CRC-32 at the end. Equal evidence encodes to equal bytes.

use super::{Evidence, EvidenceError, HeardSums, TransmitterKey};
use std::collections::BTreeMap;

/// What an evidence file starts with.
const MAGIC: &[u8; 4] = b"WMEV";

/// The format version this build writes and the newest it reads.
pub const EVIDENCE_FORMAT_VERSION: u16 = 1;

/// The largest evidence read, bytes (1 GiB): a venue's merged evidence is bounded by its
/// states times the transmitters heard at each (a 22 543-state site hearing 200 at each is
/// about 90 MB); past this, bytes are refused before anything is allocated for them.
pub const MAX_EVIDENCE_BYTES: usize = 1 << 30;

impl Evidence {
    /// The evidence as bytes (the module's format).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(64 + 8 * self.scanned.len() + 12 * self.heard.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&EVIDENCE_FORMAT_VERSION.to_le_bytes());
        out.extend_from_slice(&self.site_key.to_le_bytes());
        put(&mut out, u128::from(self.states));
        put(&mut out, zigzag(i128::from(self.clip)));
        put(&mut out, u128::from(self.walks));
        put(&mut out, self.scanned.len() as u128);
        let mut previous = None;
        for (&state, weights) in &self.scanned {
            put(&mut out, u128::from(previous.map_or(state, |p: u32| state - p)));
            put(&mut out, u128::from(weights[0]));
            put(&mut out, u128::from(weights[1]));
            previous = Some(state);
        }
        let keys: BTreeMap<TransmitterKey, usize> = {
            let mut keys: Vec<TransmitterKey> = self.heard.keys().map(|&(_, k)| k).collect();
            keys.sort_unstable();
            keys.dedup();
            keys.into_iter().enumerate().map(|(i, k)| (k, i)).collect()
        };
        put(&mut out, keys.len() as u128);
        for key in keys.keys() {
            out.push(u8::from(key.ble));
            out.extend_from_slice(&key.hash);
        }
        put(&mut out, self.heard.len() as u128);
        let mut previous = 0;
        for (&(state, key), sums) in &self.heard {
            put(&mut out, u128::from(state - previous));
            put(&mut out, keys[&key] as u128);
            put(&mut out, u128::from(sums.weight));
            put(&mut out, sums.sum);
            put(&mut out, sums.sum_squares);
            previous = state;
        }
        let crc = crc32fast::hash(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        out
    }

    /// Evidence from [`to_bytes`](Self::to_bytes)'s bytes. Refused with a typed error, never a
    /// panic: other bytes, a newer format, a truncated or corrupt file, one over
    /// [`MAX_EVIDENCE_BYTES`].
    pub fn from_bytes(bytes: &[u8]) -> Result<Evidence, EvidenceError> {
        if bytes.len() > MAX_EVIDENCE_BYTES {
            return Err(EvidenceError::TooLarge(bytes.len()));
        }
        if bytes.len() < MAGIC.len() + 2 || &bytes[..MAGIC.len()] != MAGIC {
            return Err(EvidenceError::NotEvidence("it does not start with `WMEV`".into()));
        }
        let version = u16::from_le_bytes([bytes[4], bytes[5]]);
        if version > EVIDENCE_FORMAT_VERSION {
            return Err(EvidenceError::NewerFormat { found: version, supported: EVIDENCE_FORMAT_VERSION });
        }
        if version == 0 {
            return Err(EvidenceError::Corrupt("format version 0".into()));
        }
        let Some(body_len) = bytes.len().checked_sub(4).filter(|&n| n >= 6 + 8) else {
            return Err(EvidenceError::Truncated("shorter than its header and checksum".into()));
        };
        let (body, crc) = bytes.split_at(body_len);
        let mut reader = Reader { bytes: body, at: 6 };
        let site_key = u64::from_le_bytes(reader.take(8)?.try_into().unwrap_or_default());
        // The checksum after the header, so that a file cut short reads as truncated where
        // its structure says so, and a changed byte as corrupt.
        let states = reader.u32("the state count")?;
        let clip = i64::try_from(unzigzag(reader.varint("the clip level")?))
            .map_err(|_| EvidenceError::Corrupt("the clip level is out of range".into()))?;
        let walks = reader.u64("the walk count")?;
        let mut evidence =
            Evidence { site_key, states, clip, scanned: BTreeMap::new(), heard: BTreeMap::new(), walks };
        // Each state takes at least 3 bytes, each key 17, each entry 5: counts past what the
        // bytes left could hold are refused before anything is allocated.
        let count = reader.count("states", 3)?;
        let mut previous: Option<u32> = None;
        for _ in 0..count {
            let delta = reader.u32("a state")?;
            let state = match previous {
                None => delta,
                Some(p) if delta > 0 => {
                    p.checked_add(delta).ok_or_else(|| corrupt("a state index overflows"))?
                }
                Some(_) => return Err(corrupt("the states are not in increasing order")),
            };
            if state >= states {
                return Err(corrupt("a state is beyond the site"));
            }
            let weights = [reader.u64("a WiFi weight")?, reader.u64("a BLE weight")?];
            evidence.scanned.insert(state, weights);
            previous = Some(state);
        }
        let count = reader.count("transmitters", 17)?;
        let mut keys: Vec<TransmitterKey> = Vec::with_capacity(count);
        for _ in 0..count {
            let radio = reader.take(1)?[0];
            if radio > 1 {
                return Err(corrupt("a transmitter's radio is neither WiFi nor BLE"));
            }
            let key =
                TransmitterKey { ble: radio == 1, hash: reader.take(16)?.try_into().unwrap_or_default() };
            if keys.last().is_some_and(|&last| last >= key) {
                return Err(corrupt("the transmitters are not in increasing order"));
            }
            keys.push(key);
        }
        let count = reader.count("entries", 5)?;
        let mut previous: Option<(u32, usize)> = None;
        for _ in 0..count {
            let delta = reader.u32("an entry's state")?;
            let state = previous.map_or(Some(delta), |(p, _)| p.checked_add(delta));
            let state = state.ok_or_else(|| corrupt("an entry's state overflows"))?;
            let index = reader.u64("an entry's transmitter")?;
            let index = usize::try_from(index).ok().filter(|&i| i < keys.len());
            let index = index.ok_or_else(|| corrupt("an entry names no transmitter of the table"))?;
            if previous.is_some_and(|p| p >= (state, index)) {
                return Err(corrupt("the entries are not in increasing order"));
            }
            let sums = HeardSums {
                weight: reader.u64("an entry's weight")?,
                sum: reader.varint("an entry's sum")?,
                sum_squares: reader.varint("an entry's sum of squares")?,
            };
            let key = keys[index];
            let scanned = evidence.scanned.get(&state).map_or(0, |w| w[key.radio()]);
            if sums.weight == 0 || sums.weight > scanned {
                return Err(corrupt("an entry weighs more than the scans at its state, or nothing"));
            }
            evidence.heard.insert((state, key), sums);
            previous = Some((state, index));
        }
        if reader.at != body.len() {
            return Err(corrupt("bytes follow the entries"));
        }
        if crc32fast::hash(body).to_le_bytes() != crc {
            return Err(corrupt("the checksum does not match"));
        }
        Ok(evidence)
    }
}

fn corrupt(what: &str) -> EvidenceError {
    EvidenceError::Corrupt(what.into())
}

/// Appends `value` as an LEB128 varint.
fn put(out: &mut Vec<u8>, mut value: u128) {
    loop {
        let byte = (value & 0x7f) as u8;
        value >>= 7;
        if value == 0 {
            out.push(byte);
            return;
        }
        out.push(byte | 0x80);
    }
}

/// A signed value as an unsigned one, small magnitudes small.
fn zigzag(value: i128) -> u128 {
    ((value << 1) ^ (value >> 127)) as u128
}

fn unzigzag(value: u128) -> i128 {
    ((value >> 1) as i128) ^ -((value & 1) as i128)
}

/// Reads the body of an evidence file.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8], EvidenceError> {
        let end = self.at.checked_add(n).filter(|&end| end <= self.bytes.len());
        let end =
            end.ok_or_else(|| EvidenceError::Truncated(format!("{n} bytes expected at byte {}", self.at)))?;
        let taken = &self.bytes[self.at..end];
        self.at = end;
        Ok(taken)
    }

    /// An LEB128 varint of at most 128 bits.
    fn varint(&mut self, what: &str) -> Result<u128, EvidenceError> {
        let mut value = 0u128;
        for shift in (0..).step_by(7).take(19) {
            let Some(&byte) = self.bytes.get(self.at) else {
                return Err(EvidenceError::Truncated(format!("the file ends in {what}")));
            };
            self.at += 1;
            let bits = u128::from(byte & 0x7f);
            if shift == 126 && bits > 0b11 {
                return Err(corrupt("a varint is over 128 bits"));
            }
            value |= bits << shift;
            if byte & 0x80 == 0 {
                return Ok(value);
            }
        }
        Err(corrupt("a varint is over 128 bits"))
    }

    fn u64(&mut self, what: &str) -> Result<u64, EvidenceError> {
        u64::try_from(self.varint(what)?).map_err(|_| corrupt(&format!("{what} is over 64 bits")))
    }

    fn u32(&mut self, what: &str) -> Result<u32, EvidenceError> {
        u32::try_from(self.varint(what)?).map_err(|_| corrupt(&format!("{what} is over 32 bits")))
    }

    /// A count of items of at least `each` bytes, no more than the bytes left can hold.
    fn count(&mut self, what: &str, each: usize) -> Result<usize, EvidenceError> {
        let n = self.u64(what)?;
        let left = (self.bytes.len() - self.at) / each;
        usize::try_from(n).ok().filter(|&n| n <= left).ok_or_else(|| {
            EvidenceError::Truncated(format!(
                "{n} {what} cannot fit in the {} bytes left",
                self.bytes.len() - self.at
            ))
        })
    }
}
