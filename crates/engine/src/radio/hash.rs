//! Keyed hashes of transmitter ids, so that a site file shipped inside a public app holds no
//! raw MAC address (scheme `hmac-sha256-128`, version 1).
//!
//! Each id is canonicalised (what [`TransmitterId`]'s constructors already do: lower-case,
//! `:`-separated MAC; lower-case hyphenated UUID), written as one of
//!
//! ```text
//! wifi:aa:bb:cc:dd:ee:ff
//! ble:fda50693-a4e2-4fb1-afcf-c6eb07647825:1:7        (uuid:major:minor, decimal)
//! ble_address:aa:bb:cc:dd:ee:ff
//! ```
//!
//! and hashed with HMAC-SHA256 keyed by the site's salt; the first 128 bits, as 32 lower-case
//! hex digits, replace it ([`TransmitterId::HashedWifi`] / [`TransmitterId::HashedBle`]: the
//! radio stays visible, since the likelihood treats WiFi and BLE scans apart). The site file
//! also stores the salt check, HMAC-SHA256(salt, `waymark salt check`) truncated the same way,
//! so that an engine given no salt or the wrong one fails at once instead of matching nothing.
//! Any tool with an HMAC can reproduce these values (test vectors below).

use super::{Reading, Scan, TransmitterId};
use hmac::{Hmac, Mac};
use sha2::Sha256;
use std::collections::HashMap;
use std::fmt;

/// The id-hashing scheme this build reads and writes.
pub const ID_HASH_SCHEME: &str = "hmac-sha256-128";
/// Its version.
pub const ID_HASH_VERSION: u32 = 1;
/// The shortest salt accepted, bytes: 128 bits, so the salt itself cannot be guessed.
pub const MIN_SALT_BYTES: usize = 16;
/// Hex digits of a hashed id or a salt check (128 bits).
pub const HASH_HEX_DIGITS: usize = 32;
/// The message whose HMAC is the salt check. No canonical id can equal it.
const SALT_CHECK_LABEL: &[u8] = b"waymark salt check";
/// Most raw ids an engine keeps the hash of; past it the cache starts again (a scan of a busy
/// mall hears a few hundred transmitters, a site a few thousand).
pub const ID_CACHE_CAPACITY: usize = 4096;

/// The secret a site's transmitter ids are hashed with. It never appears in the site file, in
/// `Debug` output or in an error message.
#[derive(Clone)]
pub struct Salt {
    bytes: Vec<u8>,
    /// HMAC-SHA256 with the key schedule done, cloned for each id.
    keyed: Hmac<Sha256>,
}

impl fmt::Debug for Salt {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Salt(<{} bytes, redacted>)", self.bytes.len())
    }
}

impl PartialEq for Salt {
    fn eq(&self, other: &Self) -> bool {
        self.bytes == other.bytes
    }
}

impl Salt {
    /// A salt of at least 16 bytes (32 random bytes are recommended:
    /// `openssl rand -hex 32`).
    pub fn new(bytes: impl Into<Vec<u8>>) -> Result<Salt, String> {
        let bytes = bytes.into();
        if bytes.len() < MIN_SALT_BYTES {
            return Err(format!(
                "a salt needs at least {MIN_SALT_BYTES} bytes ({} hex digits), got {}",
                2 * MIN_SALT_BYTES,
                bytes.len()
            ));
        }
        let keyed = <Hmac<Sha256> as Mac>::new_from_slice(&bytes)
            .map_err(|_| "HMAC-SHA256 refused the salt as a key".to_owned())?;
        Ok(Salt { bytes, keyed })
    }

    /// A salt written as hex digits (what a salt file or `WAYMARK_SALT` holds); whitespace,
    /// such as a trailing newline, is ignored.
    pub fn from_hex(text: &str) -> Result<Salt, String> {
        let digits: String = text.chars().filter(|c| !c.is_whitespace()).collect();
        let bytes = hex_decode(&digits).ok_or("a salt is written as an even number of hex digits")?;
        Salt::new(bytes)
    }

    /// The salt's bytes.
    pub fn as_bytes(&self) -> &[u8] {
        &self.bytes
    }

    fn mac128(&self, message: &[u8]) -> String {
        let mut mac = self.keyed.clone();
        mac.update(message);
        hex_encode(&mac.finalize().into_bytes()[..HASH_HEX_DIGITS / 2])
    }

    /// The hashed form of `id`; an id that is already hashed is returned as it is.
    pub fn hash(&self, id: &TransmitterId) -> TransmitterId {
        let Some(message) = canonical_id(id) else { return id.clone() };
        let hash = self.mac128(message.as_bytes());
        match id {
            TransmitterId::Wifi { .. } => TransmitterId::HashedWifi { hash },
            _ => TransmitterId::HashedBle { hash },
        }
    }

    /// The salt check a site file stores: HMAC-SHA256(salt, `waymark salt check`), 128 bits
    /// as hex.
    pub fn check_value(&self) -> String {
        self.mac128(SALT_CHECK_LABEL)
    }

    /// Whether `check` (32 hex digits) is this salt's check value, compared in constant time.
    pub fn matches_check(&self, check: &str) -> bool {
        let Some(expected) = hex_decode(check).filter(|b| b.len() == HASH_HEX_DIGITS / 2) else {
            return false;
        };
        let mut mac = self.keyed.clone();
        mac.update(SALT_CHECK_LABEL);
        mac.verify_truncated_left(&expected).is_ok()
    }
}

/// The canonical text of a raw id that its hash is taken of (the module's list); `None` for an
/// id that is already hashed.
pub(crate) fn canonical_id(id: &TransmitterId) -> Option<String> {
    match id {
        TransmitterId::Wifi { bssid } => Some(format!("wifi:{bssid}")),
        TransmitterId::Ble { uuid, major, minor } => Some(format!("ble:{uuid}:{major}:{minor}")),
        TransmitterId::BleAddress { mac } => Some(format!("ble_address:{mac}")),
        TransmitterId::HashedWifi { .. } | TransmitterId::HashedBle { .. } => None,
    }
}

/// Hashes the ids of an engine's scans with the site's salt, remembering up to
/// 4 096 of them so that a transmitter heard again costs a lookup, not an HMAC.
#[derive(Clone, Debug)]
pub struct ScanHasher {
    salt: Salt,
    cache: HashMap<TransmitterId, TransmitterId>,
    /// The last hashed scan; its buffer is reused.
    scan: Scan,
}

impl ScanHasher {
    /// A hasher for `salt`.
    pub fn new(salt: Salt) -> Self {
        Self { salt, cache: HashMap::new(), scan: Scan { timestamp_ns: 0, readings: Vec::new() } }
    }

    /// `scan` with every reading's id hashed (RSSI, age and order kept), for matching against
    /// a hashed site's radio map.
    pub fn hash_scan(&mut self, scan: &Scan) -> &Scan {
        self.scan.timestamp_ns = scan.timestamp_ns;
        self.scan.readings.clear();
        for r in &scan.readings {
            let transmitter = match self.cache.get(&r.transmitter) {
                Some(hashed) => hashed.clone(),
                None => {
                    let hashed = self.salt.hash(&r.transmitter);
                    if self.cache.len() >= ID_CACHE_CAPACITY {
                        self.cache.clear();
                    }
                    self.cache.insert(r.transmitter.clone(), hashed.clone());
                    hashed
                }
            };
            self.scan.readings.push(Reading { transmitter, rssi_dbm: r.rssi_dbm, age_ns: r.age_ns });
        }
        &self.scan
    }

    /// How many ids are cached.
    pub fn cached(&self) -> usize {
        self.cache.len()
    }
}

fn hex_encode(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    let mut text = String::with_capacity(2 * bytes.len());
    for b in bytes {
        text.push(DIGITS[usize::from(b >> 4)] as char);
        text.push(DIGITS[usize::from(b & 15)] as char);
    }
    text
}

pub(crate) fn hex_decode(text: &str) -> Option<Vec<u8>> {
    let digits = text.as_bytes();
    if !digits.len().is_multiple_of(2) {
        return None;
    }
    let value = |d: u8| (d as char).to_digit(16).map(|v| v as u8);
    digits.chunks(2).map(|pair| Some(value(pair[0])? << 4 | value(pair[1])?)).collect()
}

/// `text` as a hashed id's digits (32 hex digits, lower-cased), or why not.
pub(super) fn hash_digits(text: &str) -> Result<String, String> {
    let digits = text.trim().to_ascii_lowercase();
    if digits.len() != HASH_HEX_DIGITS || !digits.bytes().all(|c| c.is_ascii_hexdigit()) {
        return Err(format!("`{text}` is not a hashed id ({HASH_HEX_DIGITS} hex digits)"));
    }
    Ok(digits)
}

#[cfg(test)]
mod tests {
    use super::*;

    const SALT_HEX: &str = "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f";

    fn salt() -> Salt {
        Salt::from_hex(SALT_HEX).unwrap()
    }

    /// Test vectors, also checked with Python's `hmac.new(salt, msg, "sha256").hexdigest()[:32]`.
    #[test]
    fn test_vectors() {
        let s = salt();
        let wifi = TransmitterId::wifi("AA-BB-CC-DD-EE-FF").unwrap();
        assert_eq!(
            s.hash(&wifi),
            TransmitterId::HashedWifi { hash: "3728ded7b1265406deb8486dd6c8705e".into() }
        );
        let ble = TransmitterId::ble("FDA50693A4E24FB1AFCFC6EB07647825", 1, 7).unwrap();
        assert_eq!(
            s.hash(&ble),
            TransmitterId::HashedBle { hash: "61be74edd11dc2df052549db7e3f70ee".into() }
        );
        assert_eq!(s.check_value(), "0e8d590ef00c6ecaaa2bdc1adea54cc0");
    }

    #[test]
    fn hashes_are_keyed_canonical_and_separate_radios() {
        let (a, b) = (salt(), Salt::new([7u8; 16]).unwrap());
        let wifi = TransmitterId::wifi("aa:bb:cc:dd:ee:ff").unwrap();
        let ble = TransmitterId::ble_address("aa:bb:cc:dd:ee:ff").unwrap();
        assert_eq!(a.hash(&wifi), a.hash(&TransmitterId::wifi("AABBCCDDEEFF").unwrap()));
        assert_ne!(a.hash(&wifi), b.hash(&wifi));
        assert!(matches!(a.hash(&ble), TransmitterId::HashedBle { .. }));
        assert_ne!(a.hash(&wifi).to_string(), a.hash(&ble).to_string());
        let hashed = a.hash(&wifi);
        assert_eq!(a.hash(&hashed), hashed, "hashing twice changes nothing");
        assert!(!hashed.to_string().contains("aa:bb"));
    }

    #[test]
    fn salt_check_tells_salts_apart() {
        let (a, b) = (salt(), Salt::new([7u8; 16]).unwrap());
        assert!(a.matches_check(&a.check_value()));
        assert!(a.matches_check(&a.check_value().to_uppercase()));
        assert!(!b.matches_check(&a.check_value()));
        assert!(!a.matches_check("nope"));
        assert!(!a.matches_check(&a.check_value()[..30]));
    }

    #[test]
    fn salts_are_long_enough_and_never_printed() {
        assert!(Salt::new([1u8; 15]).unwrap_err().contains("16 bytes"));
        assert!(Salt::from_hex("abc").is_err());
        assert!(Salt::from_hex("zz".repeat(16).as_str()).is_err());
        assert_eq!(Salt::from_hex(&format!("  {SALT_HEX}\n")).unwrap(), salt());
        let shown = format!("{:?}", salt());
        assert!(!shown.contains("0001") && shown.contains("32 bytes"), "{shown}");
    }

    #[test]
    fn scan_hasher_caches_within_a_bound() {
        let mut hasher = ScanHasher::new(salt());
        let reading = |i: usize| Reading {
            transmitter: TransmitterId::wifi(&format!("02:00:00:00:{:02x}:{:02x}", i / 256, i % 256))
                .unwrap(),
            rssi_dbm: -70.0,
            age_ns: i as u64,
        };
        let scan = Scan { timestamp_ns: 5, readings: (0..3).map(reading).chain([reading(1)]).collect() };
        let hashed = hasher.hash_scan(&scan).clone();
        assert_eq!(hashed.timestamp_ns, 5);
        assert_eq!(hashed.readings.len(), 4);
        assert_eq!(hashed.readings[1], hashed.readings[3], "a duplicate stays a duplicate");
        assert_eq!(hashed.readings[2].age_ns, 2);
        assert_eq!(hasher.cached(), 3);
        let many = Scan { timestamp_ns: 6, readings: (0..ID_CACHE_CAPACITY + 10).map(reading).collect() };
        hasher.hash_scan(&many);
        assert!(hasher.cached() <= ID_CACHE_CAPACITY);
        assert_eq!(hasher.hash_scan(&scan).readings, hashed.readings);
    }
}
