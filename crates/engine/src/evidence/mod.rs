//! Map evidence from walks without labels: what the scans of a walk say about each state's
//! fingerprints, weighted by where the walk probably was (docs/evidence.md).
//!
//! For each state and transmitter, [`Evidence`] holds the sufficient statistics of the
//! censored-Gaussian fit (Hoang §3, eqs. 6-7): the weight of the scans that heard the
//! transmitter above the clip level, Σ w·r and Σ w·r² of their readings, and per state the
//! weight of all scans of each radio (those that did not hear it are the censored samples).
//! A scan's weight at a state is the walk's posterior probability of that state when the scan
//! was made: soft labels, after El Gemayel et al.'s Baum-Welch, which re-estimates emissions
//! from posteriors (eqs. 10-13).
//!
//! Evidence is a value that merges: the sums are fixed-point integers, so that merging is
//! exactly associative and commutative, and evidence merged in any order, on one machine or
//! many, encodes to the same bytes ([`Evidence::to_bytes`]). It holds state indices and
//! 128-bit hashes of transmitter ids ([`TransmitterKey`]), never a timestamp, a position
//! sequence or a raw id (docs/privacy.md#evidence).

mod encode;
#[cfg(test)]
mod tests;

use crate::radio::{canonical_id, hex_decode, CensoredMoments, TransmitterId, HASH_HEX_DIGITS};
use crate::site::Site;
use sha2::{Digest, Sha256};
use std::collections::BTreeMap;

pub use encode::{EVIDENCE_FORMAT_VERSION, MAX_EVIDENCE_BYTES};

/// Fixed-point units of a scan's weight: a scan whose posterior is all at one state weighs
/// 2¹² there. A state believed less than half a unit (1.2·10⁻⁴) gets nothing from the scan,
/// which bounds the entries a scan adds (docs/evidence.md#file-format).
pub(crate) const WEIGHT_UNITS: f64 = 4096.0;

/// Fixed-point units of a reading above the clip level, per dB: a quarter dB. Phones report
/// whole dBm; a reading averaged on the phone is kept within 0.125 dB, an eighth of the
/// least σ a fingerprint has (`FitOptions::min_std_db`, 1 dB).
pub(crate) const RSSI_UNITS_PER_DB: f64 = 4.0;

/// The most states of a scan's posterior its map evidence keeps, most probable first: one, its
/// mode. Chosen on held-out survey walks (docs/evidence.md#at-scale), for a walk and a session alike: of the whole posterior,
/// its most probable 90% or 50%, and its 4, 2 or 1 most probable states, the mode refitted
/// the site of least held-out error, in the fewest bytes. The state keeps its probability, so
/// a vague scan, whose mode holds little of it, weighs little.
pub const EVIDENCE_STATES_PER_SCAN: usize = 1;

/// `posterior`'s most probable states into `kept`: the fewest whose probabilities sum to
/// `mass` (all of them from 1 on), at most `states` of them (0: no limit). By probability,
/// ties by state, so that the same posterior keeps the same states on every machine. Their
/// probabilities are kept as they are.
pub fn most_probable(posterior: &[(u32, f64)], mass: f64, states: usize, kept: &mut Vec<(u32, f64)>) {
    kept.clear();
    kept.extend_from_slice(posterior);
    if mass >= 1.0 && (states == 0 || states >= posterior.len()) {
        return;
    }
    kept.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    let limit = if states == 0 { kept.len() } else { states };
    let mut total = 0.0;
    let mut keep = 0;
    for &(_, p) in kept.iter().take(limit) {
        if total >= mass {
            break;
        }
        total += p;
        keep += 1;
    }
    kept.truncate(keep);
}

/// Which part of each scan's posterior evidence keeps ([`most_probable`]): its most probable
/// states up to `mass` of it and at most `states` of them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EvidenceOptions {
    /// The share of the posterior kept; 1 keeps all of it.
    pub mass: f64,
    /// The most states kept; 0 keeps every state.
    pub states: usize,
}

impl Default for EvidenceOptions {
    /// The mode alone ([`EVIDENCE_STATES_PER_SCAN`]).
    fn default() -> Self {
        Self { mass: 1.0, states: EVIDENCE_STATES_PER_SCAN }
    }
}

/// A transmitter as evidence knows it: its radio and a 128-bit hash of its id. On a site made
/// with a salt this is the salted hash the site itself holds (docs/privacy.md); otherwise the
/// first 128 bits of SHA-256 of the id's canonical text, which hides nothing from someone who
/// can try every address, so a site whose evidence leaves the phone should have a salt.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct TransmitterKey {
    /// BLE rather than WiFi.
    pub ble: bool,
    /// The hash.
    pub hash: [u8; 16],
}

impl TransmitterKey {
    /// The key of `id`: its own hash when it is hashed, else the SHA-256 of its canonical text.
    pub fn of(id: &TransmitterId) -> TransmitterKey {
        let ble = id.is_ble();
        let mut hash = [0u8; 16];
        match id {
            TransmitterId::HashedWifi { hash: digits } | TransmitterId::HashedBle { hash: digits } => {
                // Site files and `Salt::hash` only make 32 hex digits; anything else keys by
                // the text's own hash below.
                match hex_decode(digits).filter(|b| digits.len() == HASH_HEX_DIGITS && b.len() == 16) {
                    Some(bytes) => hash.copy_from_slice(&bytes),
                    None => hash.copy_from_slice(&Sha256::digest(digits.as_bytes())[..16]),
                }
            }
            _ => {
                let text = canonical_id(id).unwrap_or_default();
                hash.copy_from_slice(&Sha256::digest(text.as_bytes())[..16]);
            }
        }
        TransmitterKey { ble, hash }
    }

    /// The radio's index: 0 WiFi, 1 BLE.
    fn radio(&self) -> usize {
        usize::from(self.ble)
    }
}

/// One state's and transmitter's sums: the weight of the scans that heard it above the clip
/// level, Σ w·u and Σ w·u² of their readings (weights in 1/4096 of a scan, readings u in
/// quarter dB above the clip level, so that every sum is small and positive;
/// docs/evidence.md#merging).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HeardSums {
    /// Σ w.
    pub weight: u64,
    /// Σ w·u.
    pub sum: u128,
    /// Σ w·u².
    pub sum_squares: u128,
}

impl HeardSums {
    fn checked_add(self, other: HeardSums) -> Option<HeardSums> {
        Some(HeardSums {
            weight: self.weight.checked_add(other.weight)?,
            sum: self.sum.checked_add(other.sum)?,
            sum_squares: self.sum_squares.checked_add(other.sum_squares)?,
        })
    }
}

/// Why evidence was refused. Nothing is changed when one is returned.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum EvidenceError {
    /// Evidence of another site (other states or another clip level) cannot be merged.
    #[error("evidence of site {found:016x} cannot join evidence of site {expected:016x}")]
    OtherSite {
        /// The site key of the evidence given.
        found: u64,
        /// This evidence's.
        expected: u64,
    },
    /// A state index beyond the site.
    #[error("state {state} is not one of the site's {states} states")]
    UnknownState {
        /// The index given.
        state: u32,
        /// The site's state count.
        states: u32,
    },
    /// A weight that is not a probability, or a scan whose weights sum to more than 1.
    #[error("posterior weights must be finite, non-negative and sum to at most 1: {0}")]
    InvalidWeight(String),
    /// A reading that is not finite.
    #[error("a reading of {0} dBm is not finite")]
    InvalidReading(f64),
    /// A sum would overflow its integer (more evidence than any fleet gathers).
    #[error("a sum of the evidence would overflow")]
    Overflow,
    /// Bytes that are not evidence.
    #[error("not evidence: {0}")]
    NotEvidence(String),
    /// Evidence written by a newer Waymark.
    #[error("evidence format {found} is newer than this build reads ({supported})")]
    NewerFormat {
        /// The format version of the bytes.
        found: u16,
        /// The newest this build reads.
        supported: u16,
    },
    /// Bytes that end early.
    #[error("evidence truncated: {0}")]
    Truncated(String),
    /// Bytes whose checksum or structure is wrong.
    #[error("evidence corrupt: {0}")]
    Corrupt(String),
    /// Bytes over [`MAX_EVIDENCE_BYTES`].
    #[error("evidence of {0} bytes is over the limit of {MAX_EVIDENCE_BYTES}")]
    TooLarge(usize),
}

/// Evidence about a site's fingerprints from walks without labels (the module's description).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Evidence {
    /// Which site's states the indices are of ([`Evidence::site_key`]).
    site_key: u64,
    /// The site's state count.
    states: u32,
    /// The clip level the readings were judged against, in 0.01 dB (the radio map's step).
    clip: i64,
    /// Per state, the weight of the scans of each radio (WiFi, BLE) at it.
    scanned: BTreeMap<u32, [u64; 2]>,
    /// Per state and transmitter, the readings heard above the clip level.
    heard: BTreeMap<(u32, TransmitterKey), HeardSums>,
    /// Walks (or sessions) this evidence was gathered from.
    walks: u64,
}

impl Evidence {
    /// Empty evidence for `site`.
    pub fn new(site: &Site) -> Evidence {
        Evidence {
            site_key: Self::site_key(site),
            states: site.states().len() as u32,
            clip: (site.radio().clip_dbm() * 100.0).round() as i64,
            scanned: BTreeMap::new(),
            heard: BTreeMap::new(),
            walks: 0,
        }
    }

    /// The key of what evidence depends on in a site: its states (floor and position, in
    /// order) and its clip level, hashed with SHA-256. A site refitted from evidence keeps the
    /// key while its states stay, so evidence gathered on either merges.
    pub fn site_key(site: &Site) -> u64 {
        let mut hasher = Sha256::new();
        hasher.update(b"waymark evidence site");
        hasher.update((site.states().len() as u64).to_le_bytes());
        for state in site.states() {
            hasher.update((state.floor as u64).to_le_bytes());
            hasher.update(state.position.x.to_bits().to_le_bytes());
            hasher.update(state.position.y.to_bits().to_le_bytes());
        }
        hasher.update(site.radio().clip_dbm().to_bits().to_le_bytes());
        let digest = hasher.finalize();
        u64::from_le_bytes(digest[..8].try_into().unwrap_or_default())
    }

    /// This evidence's site key.
    pub fn key(&self) -> u64 {
        self.site_key
    }

    /// The clip level readings were judged against, dBm.
    pub fn clip_dbm(&self) -> f64 {
        self.clip as f64 / 100.0
    }

    /// Walks (or sessions) merged into this evidence: each [`Evidence::add_walk`] counts one.
    pub fn walks(&self) -> u64 {
        self.walks
    }

    /// Counts one more walk. Scans are added with [`Evidence::add_scan`].
    pub fn add_walk(&mut self) {
        self.walks = self.walks.saturating_add(1);
    }

    /// Whether it holds nothing.
    pub fn is_empty(&self) -> bool {
        self.scanned.is_empty() && self.heard.is_empty() && self.walks == 0
    }

    /// (state, transmitter) pairs heard.
    pub fn heard_entries(&self) -> usize {
        self.heard.len()
    }

    /// States some scan weighs on.
    pub fn states_scanned(&self) -> usize {
        self.scanned.len()
    }

    /// Distinct transmitters heard.
    pub fn transmitters(&self) -> usize {
        let mut keys: Vec<&TransmitterKey> = self.heard.keys().map(|(_, k)| k).collect();
        keys.sort_unstable();
        keys.dedup();
        keys.len()
    }

    /// The site's state count.
    pub fn state_count(&self) -> u32 {
        self.states
    }

    /// Adds one scan: `posterior`, where the phone was when it was made, as (state, probability)
    /// pairs (the states left out have none), and its readings by transmitter; `radios` says
    /// which radios the scan listened with (WiFi, BLE), since a BLE-only scan says nothing of
    /// the access points. Readings at or below the clip level count as not heard, a repeated
    /// transmitter once (its strongest reading). Refused, changing nothing: a state beyond the
    /// site, a probability that is not finite or negative, probabilities that sum to more than
    /// 1, a reading that is not finite.
    pub fn add_scan(
        &mut self,
        posterior: &[(u32, f64)],
        readings: &[(TransmitterKey, f64)],
        radios: [bool; 2],
    ) -> Result<(), EvidenceError> {
        let mut total = 0.0;
        for &(state, p) in posterior {
            if state >= self.states {
                return Err(EvidenceError::UnknownState { state, states: self.states });
            }
            if !(p.is_finite() && p >= 0.0) {
                return Err(EvidenceError::InvalidWeight(format!("{p} at state {state}")));
            }
            total += p;
        }
        // The sum of a posterior's probabilities, as a float sum, may pass 1 by rounding.
        if total > 1.0 + 1e-9 {
            return Err(EvidenceError::InvalidWeight(format!("they sum to {total}")));
        }
        if let Some(&(_, r)) = readings.iter().find(|(_, r)| !r.is_finite()) {
            return Err(EvidenceError::InvalidReading(r));
        }
        // The strongest reading of each transmitter heard above the clip level, as units
        // above it (a reading above it by less than half a unit counts as one unit).
        let clip = self.clip_dbm();
        let mut heard: BTreeMap<TransmitterKey, u64> = BTreeMap::new();
        for &(key, rssi) in readings.iter().filter(|&&(_, r)| r > clip) {
            // Readings are finite (checked above) and at most `MAX_RSSI_DBM`-ish in practice;
            // the conversion saturates for anything wilder.
            let u = (((rssi - clip) * RSSI_UNITS_PER_DB).round() as u64).max(1);
            let strongest = heard.entry(key).or_insert(u);
            *strongest = (*strongest).max(u);
        }
        // The additions, checked against what is there before any is made, so that an
        // overflow leaves this evidence as it was.
        let mut scans: Vec<(u32, [u64; 2])> = Vec::with_capacity(posterior.len());
        let mut readings: Vec<((u32, TransmitterKey), HeardSums)> = Vec::new();
        for &(state, p) in posterior {
            let w = (p * WEIGHT_UNITS).round() as u64;
            if w == 0 {
                continue;
            }
            scans.push((state, radios.map(|on| if on { w } else { 0 })));
            for (&key, &u) in heard.iter().filter(|(key, _)| radios[key.radio()]) {
                let (w, u) = (u128::from(w), u128::from(u));
                let reading = HeardSums { weight: w as u64, sum: w * u, sum_squares: w * u * u };
                readings.push(((state, key), reading));
            }
        }
        self.add_checked(&scans, &readings)
    }

    /// Adds per-state scan weights and per-entry sums, or nothing if any sum would overflow.
    fn add_checked(
        &mut self,
        scans: &[(u32, [u64; 2])],
        readings: &[((u32, TransmitterKey), HeardSums)],
    ) -> Result<(), EvidenceError> {
        // A state or entry may come more than once: checked against the running totals.
        let mut scan_totals: BTreeMap<u32, [u64; 2]> = BTreeMap::new();
        for &(state, w) in scans {
            let total = scan_totals
                .entry(state)
                .or_insert_with(|| self.scanned.get(&state).copied().unwrap_or_default());
            for radio in 0..2 {
                total[radio] = total[radio].checked_add(w[radio]).ok_or(EvidenceError::Overflow)?;
            }
        }
        let mut reading_totals: BTreeMap<(u32, TransmitterKey), HeardSums> = BTreeMap::new();
        for &(entry, sums) in readings {
            let total = reading_totals
                .entry(entry)
                .or_insert_with(|| self.heard.get(&entry).copied().unwrap_or_default());
            *total = total.checked_add(sums).ok_or(EvidenceError::Overflow)?;
        }
        self.scanned.extend(scan_totals);
        self.heard.extend(reading_totals);
        Ok(())
    }

    /// Adds `other` (evidence of the same site): exactly associative and commutative.
    /// Refused, changing nothing: evidence of another site, or a sum that would overflow.
    pub fn merge(&mut self, other: &Evidence) -> Result<(), EvidenceError> {
        if (other.site_key, other.states, other.clip) != (self.site_key, self.states, self.clip) {
            return Err(EvidenceError::OtherSite { found: other.site_key, expected: self.site_key });
        }
        let walks = self.walks.checked_add(other.walks).ok_or(EvidenceError::Overflow)?;
        let scans: Vec<(u32, [u64; 2])> = other.scanned.iter().map(|(&s, &w)| (s, w)).collect();
        let readings: Vec<((u32, TransmitterKey), HeardSums)> =
            other.heard.iter().map(|(&e, &h)| (e, h)).collect();
        self.add_checked(&scans, &readings)?;
        self.walks = walks;
        Ok(())
    }

    /// The weight of the scans of each radio (WiFi, BLE) at `state`, in scans.
    pub fn scanned(&self, state: u32) -> [f64; 2] {
        self.scanned.get(&state).map_or([0.0; 2], |w| w.map(|w| w as f64 / WEIGHT_UNITS))
    }

    /// The transmitters heard at `state`, with their sums.
    pub fn heard_at(&self, state: u32) -> impl Iterator<Item = (TransmitterKey, HeardSums)> + '_ {
        self.heard
            .range((state, TransmitterKey::MIN)..=(state, TransmitterKey::MAX))
            .map(|(&(_, k), &s)| (k, s))
    }

    /// The moments of the censored fit of `key` at `state` (weights in scans, readings in
    /// dBm, the scans of its radio that did not hear it at the clip level), for
    /// [`fit_censored_moments`](crate::radio::fit_censored_moments); `None` where no scan of
    /// its radio was made there, or none heard it.
    pub fn moments(&self, state: u32, key: &TransmitterKey) -> Option<CensoredMoments> {
        let scans = self.scanned.get(&state)?[key.radio()];
        let heard = self.heard.get(&(state, *key)).filter(|h| h.weight > 0)?;
        let (w, scale) = (WEIGHT_UNITS, RSSI_UNITS_PER_DB);
        Some(CensoredMoments::from_sums_above_clip(
            scans as f64 / w,
            heard.weight as f64 / w,
            heard.sum as f64 / (w * scale),
            heard.sum_squares as f64 / (w * scale * scale),
            self.clip_dbm(),
        ))
    }
}

impl TransmitterKey {
    /// The least key, for ranges.
    const MIN: TransmitterKey = TransmitterKey { ble: false, hash: [0; 16] };
    /// The greatest key.
    const MAX: TransmitterKey = TransmitterKey { ble: true, hash: [u8::MAX; 16] };
}
