//! The only place that knows about uniffi and the C ABI: thin wrappers over the pure engine
//! (the `waymark-engine` crate). Kotlin and Swift see [`uniffi`]'s types, re-exported at the
//! crate's root; C (and dart:ffi, React Native, Unity) sees [`c`]'s exported functions,
//! through the header `bindings/c/waymark.h`. Both wrap one engine handle (`handle.rs`: the
//! lock, the panic boundary, listener delivery and error mapping) and report failures with
//! one error ([`error`]).

mod c;
mod delivery;
pub mod error;
mod handle;
pub mod logging;
mod panic;
mod record;
pub mod uniffi;

use waymark_engine::radio::TransmitterId;

/// Nanoseconds in a millisecond: apps give reading ages in ms, the engine keeps ns.
pub(crate) const NS_PER_MS: u64 = 1_000_000;

/// Which transmitter a BLE beacon reading from an app is, by one rule for Kotlin, Swift and C:
///
/// - An iBeacon with a UUID and major/minor not both 0 is `Ble { uuid, major, minor }`; an
///   address given with it is checked but not used.
/// - A beacon with no UUID (`""`), or with major = minor = 0 (an iBeacon left at the factory
///   setting, which its UUID does not tell apart), and an advertiser address is
///   `BleAddress { mac }`.
/// - With a UUID, major = minor = 0 and no address, it is `Ble { uuid, 0, 0 }`.
///
/// No address is `None`, NULL or `""`. An address or UUID that does not parse, or neither a
/// UUID nor an address, is an error (the scan is rejected).
pub(crate) fn beacon_id(
    uuid: &str,
    major: u16,
    minor: u16,
    address: Option<&str>,
) -> Result<TransmitterId, String> {
    let address = address.map(str::trim).filter(|a| !a.is_empty());
    let by_address = address.map(TransmitterId::ble_address).transpose()?;
    let uuid = uuid.trim();
    match by_address {
        Some(id) if uuid.is_empty() || (major == 0 && minor == 0) => Ok(id),
        _ if uuid.is_empty() => Err("a beacon reading needs a UUID or an address".into()),
        _ => TransmitterId::ble(uuid, major, minor),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beacon_id_rule() {
        const UUID: &str = "fda50693-a4e2-4fb1-afcf-c6eb07647825";
        const MAC: &str = "aa:bb:cc:dd:ee:0f";
        let address = TransmitterId::ble_address(MAC).unwrap();
        assert_eq!(beacon_id("", 0, 0, Some("AA-BB-CC-DD-EE-0F")), Ok(address.clone()));
        assert_eq!(beacon_id("", 3, 4, Some(MAC)), Ok(address.clone()));
        assert_eq!(beacon_id(UUID, 0, 0, Some(MAC)), Ok(address));
        assert_eq!(beacon_id(UUID, 0, 1, Some(MAC)), TransmitterId::ble(UUID, 0, 1));
        assert_eq!(beacon_id(UUID, 0, 0, None), TransmitterId::ble(UUID, 0, 0));
        assert_eq!(beacon_id(UUID, 0, 0, Some(" ")), TransmitterId::ble(UUID, 0, 0));
        assert!(beacon_id("", 0, 0, None).is_err());
        assert!(beacon_id("", 0, 0, Some("")).is_err());
        assert!(beacon_id("", 0, 0, Some("not a mac")).is_err());
        assert!(beacon_id(UUID, 1, 2, Some("not a mac")).is_err(), "a bad address is never ignored");
        assert!(beacon_id("not a uuid", 1, 2, None).is_err());
    }
}
