//! Radio: transmitter identities, scans as the app delivers them, RSSI models (Hoang §3) and the
//! radio map that turns a scan into one log-likelihood per state.

mod check;
mod gaussian;
mod hash;
mod map;
mod offset;

pub use check::MAX_RSSI_DBM;
pub(crate) use check::{check_readings, ScanError};
pub(crate) use gaussian::ln_std_normal_pdf;
pub(crate) use gaussian::unheard_model;
pub use gaussian::{
    fit_censored_moments, CensoredFit, CensoredMoments, FitOptions, Gaussian, LnCdfTable, RssiModel,
};
pub(crate) use hash::{canonical_id, hex_decode, HASH_HEX_DIGITS};
pub use hash::{Salt, ScanHasher, ID_HASH_SCHEME, ID_HASH_VERSION};
pub(crate) use map::quantise;
pub(crate) use map::LEVEL_STEP_DB;
pub(crate) use map::MAX_ABS_LEVEL_DBM;
pub(crate) use map::MAX_STORED_STD_DB;
pub(crate) use map::MIN_STD_DB;
pub use map::{BeliefMoments, RadioMap, ResolvedScan};
pub(crate) use offset::DeviceOffset;
pub use offset::DEVICE_OFFSET_PRIOR_STD_DB;

use serde::{Deserialize, Serialize};
use std::fmt;

/// A radio transmitter the phone can hear: a WiFi access point or a BLE beacon.
///
/// Identifiers are normalised on construction (lower-case hex, `:`-separated MAC, hyphenated
/// UUID) so that the same transmitter reported by Android and iOS compares equal. A site file
/// may hold salted hashes of them instead ([`Salt::hash`]): scans are then hashed with the same
/// salt before they are matched.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case", try_from = "TransmitterIdRaw")]
pub enum TransmitterId {
    /// A WiFi access point by BSSID.
    Wifi {
        /// `aa:bb:cc:dd:ee:ff`.
        bssid: String,
    },
    /// An iBeacon-style BLE beacon.
    Ble {
        /// `xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxxxx`.
        uuid: String,
        /// Beacon major number.
        major: u16,
        /// Beacon minor number.
        minor: u16,
    },
    /// A BLE beacon known only by its advertiser address (Eddystone, or iBeacons left at the
    /// factory's major = minor = 0, which cannot be told apart otherwise).
    BleAddress {
        /// `aa:bb:cc:dd:ee:ff`.
        mac: String,
    },
    /// A WiFi access point known by the salted hash of its BSSID ([`Salt::hash`]).
    HashedWifi {
        /// 32 lower-case hex digits.
        hash: String,
    },
    /// A BLE beacon known by the salted hash of its UUID, major and minor, or of its address.
    HashedBle {
        /// 32 lower-case hex digits.
        hash: String,
    },
}

/// The serde shape before normalisation, so a site file with `"AA-BB-..."` loads the same
/// transmitter as a scan with `"aa:bb:..."`.
#[derive(Deserialize)]
#[serde(rename_all = "snake_case")]
enum TransmitterIdRaw {
    Wifi { bssid: String },
    Ble { uuid: String, major: u16, minor: u16 },
    BleAddress { mac: String },
    HashedWifi { hash: String },
    HashedBle { hash: String },
}

impl TryFrom<TransmitterIdRaw> for TransmitterId {
    type Error = String;
    fn try_from(raw: TransmitterIdRaw) -> Result<Self, String> {
        match raw {
            TransmitterIdRaw::Wifi { bssid } => TransmitterId::wifi(&bssid),
            TransmitterIdRaw::Ble { uuid, major, minor } => TransmitterId::ble(&uuid, major, minor),
            TransmitterIdRaw::BleAddress { mac } => TransmitterId::ble_address(&mac),
            TransmitterIdRaw::HashedWifi { hash } => {
                Ok(TransmitterId::HashedWifi { hash: hash::hash_digits(&hash)? })
            }
            TransmitterIdRaw::HashedBle { hash } => {
                Ok(TransmitterId::HashedBle { hash: hash::hash_digits(&hash)? })
            }
        }
    }
}

/// A MAC address as `aa:bb:cc:dd:ee:ff`, from `AA:BB:..`, `aa-bb-..` or `aabb..`.
fn mac_address(text: &str) -> Result<String, String> {
    let hex = hex_digits(text.trim(), &[':', '-', '.']);
    if hex.len() != 12 || !hex.chars().all(|c| c.is_ascii_hexdigit()) {
        return Err(format!("`{text}` is not a MAC address (six hex bytes)"));
    }
    let octets: Vec<&str> = (0..6).map(|i| &hex[2 * i..2 * i + 2]).collect();
    Ok(octets.join(":"))
}

/// `text` without `separators`, lower-cased.
fn hex_digits(text: &str, separators: &[char]) -> String {
    text.chars().filter(|c| !separators.contains(c)).flat_map(char::to_lowercase).collect()
}

impl TransmitterId {
    /// A WiFi access point from its BSSID in any common notation (`AA:BB:..`, `aa-bb-..`,
    /// `aabb..`).
    pub fn wifi(bssid: &str) -> Result<Self, String> {
        Ok(TransmitterId::Wifi { bssid: mac_address(bssid)? })
    }

    /// A BLE beacon by its advertiser MAC address, in any common notation.
    pub fn ble_address(mac: &str) -> Result<Self, String> {
        Ok(TransmitterId::BleAddress { mac: mac_address(mac)? })
    }

    /// A BLE beacon from its proximity UUID (with or without hyphens), major and minor.
    pub fn ble(uuid: &str, major: u16, minor: u16) -> Result<Self, String> {
        let hex = hex_digits(uuid.trim(), &['-']);
        if hex.len() != 32 || !hex.chars().all(|c| c.is_ascii_hexdigit()) {
            return Err(format!("`{uuid}` is not a beacon UUID (32 hex digits)"));
        }
        let uuid =
            format!("{}-{}-{}-{}-{}", &hex[0..8], &hex[8..12], &hex[12..16], &hex[16..20], &hex[20..32]);
        Ok(TransmitterId::Ble { uuid, major, minor })
    }

    /// Whether this is a BLE transmitter rather than a WiFi access point: the radio a scan
    /// listened with, which the likelihood and map evidence treat apart.
    pub fn is_ble(&self) -> bool {
        !matches!(self, TransmitterId::Wifi { .. } | TransmitterId::HashedWifi { .. })
    }

    /// Whether this is a salted hash rather than a raw id.
    pub fn is_hashed(&self) -> bool {
        matches!(self, TransmitterId::HashedWifi { .. } | TransmitterId::HashedBle { .. })
    }
}

impl fmt::Display for TransmitterId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TransmitterId::Wifi { bssid } => write!(f, "wifi {bssid}"),
            TransmitterId::Ble { uuid, major, minor } => write!(f, "ble {uuid} {major}/{minor}"),
            TransmitterId::BleAddress { mac } => write!(f, "ble {mac}"),
            TransmitterId::HashedWifi { hash } => write!(f, "wifi #{hash}"),
            TransmitterId::HashedBle { hash } => write!(f, "ble #{hash}"),
        }
    }
}

/// One transmitter heard in a scan.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Reading {
    /// Who was heard.
    pub transmitter: TransmitterId,
    /// Received signal strength, dBm. Values at or below the site's clip level mean "below
    /// the receiver's sensitivity".
    pub rssi_dbm: f64,
    /// How long before the scan's timestamp this reading was last measured, ns. Android
    /// re-reports cached access points; 0 for a fresh reading.
    #[serde(default)]
    pub age_ns: u64,
}

/// A WiFi or BLE scan: everything heard at one moment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scan {
    /// Monotonic time of the scan, ns, on the same clock as every other input.
    pub timestamp_ns: u64,
    /// The transmitters heard.
    pub readings: Vec<Reading>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_normalise() {
        assert_eq!(
            TransmitterId::wifi("AA-BB-CC-0D-0E-0F").unwrap(),
            TransmitterId::wifi("aa:bb:cc:0d:0e:0f").unwrap()
        );
        assert_eq!(TransmitterId::wifi("aabbcc0d0e0f").unwrap().to_string(), "wifi aa:bb:cc:0d:0e:0f");
        assert!(TransmitterId::wifi("aa:bb:cc").is_err());
        assert!(TransmitterId::wifi("zz:bb:cc:dd:ee:ff").is_err());
        let ble = TransmitterId::ble("FDA50693A4E24FB1AFCFC6EB07647825", 10, 7).unwrap();
        assert_eq!(ble, TransmitterId::ble("fda50693-a4e2-4fb1-afcf-c6eb07647825", 10, 7).unwrap());
        assert!(TransmitterId::ble("fda50693", 1, 1).is_err());
    }

    #[test]
    fn ids_round_trip_through_json_and_normalise_on_load() {
        let id: TransmitterId = serde_json::from_str(r#"{"wifi":{"bssid":"AA:BB:CC:DD:EE:FF"}}"#).unwrap();
        assert_eq!(id, TransmitterId::wifi("aa:bb:cc:dd:ee:ff").unwrap());
        let text = serde_json::to_string(&id).unwrap();
        assert_eq!(serde_json::from_str::<TransmitterId>(&text).unwrap(), id);
        assert!(serde_json::from_str::<TransmitterId>(r#"{"wifi":{"bssid":"nope"}}"#).is_err());
        let hashed: TransmitterId =
            serde_json::from_str(r#"{"hashed_wifi":{"hash":"3728DED7B1265406DEB8486DD6C8705E"}}"#).unwrap();
        assert_eq!(hashed, TransmitterId::HashedWifi { hash: "3728ded7b1265406deb8486dd6c8705e".into() });
        assert!(hashed.is_hashed());
        assert_eq!(
            serde_json::from_str::<TransmitterId>(&serde_json::to_string(&hashed).unwrap()).unwrap(),
            hashed
        );
        assert!(serde_json::from_str::<TransmitterId>(r#"{"hashed_ble":{"hash":"abc"}}"#).is_err());
    }
}
