//! The checks a scan's readings pass before anything is done with them, by an engine's epoch
//! or a survey recording alike: a scan that fails one is corrupt and is rejected whole.

use super::Scan;

/// The highest RSSI a scan may report, dBm: +100 dBm is 10 kW at the antenna, where WiFi and
/// BLE transmit at most +36 dBm EIRP. A higher value is a corrupt producer, and one far higher
/// (found by fuzzing, `engine_calls`: `f64::MAX` dBm) makes every state's log-likelihood
/// -∞, so no state explains the scan. Values at or below the clip level are fine: they read as
/// "not heard".
pub const MAX_RSSI_DBM: f64 = 100.0;

/// Why a scan's readings were refused ([`check_readings`]). The engine reports each as the
/// [`InputError`](crate::InputError) of the same name.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub(crate) enum ScanError {
    /// A scan with no readings.
    #[error("the scan has no readings")]
    EmptyScan,
    /// A reading's RSSI is NaN, infinite or below -1000 dBm.
    #[error("reading {index} ({transmitter}) has a non-finite or impossible RSSI")]
    NonFiniteRssi {
        /// Position of the reading in the scan.
        index: usize,
        /// Its transmitter.
        transmitter: String,
    },
    /// A reading's RSSI is above [`MAX_RSSI_DBM`].
    #[error("reading {index} ({transmitter}) has an RSSI of {rssi_dbm} dBm, above any receiver's")]
    RssiTooHigh {
        /// Position of the reading in the scan.
        index: usize,
        /// Its transmitter.
        transmitter: String,
        /// The RSSI, dBm.
        rssi_dbm: f64,
    },
}

/// The checks a scan's readings pass before anything is done with them (an engine's epoch, a
/// survey recording): at least one reading, every RSSI plausible and not above
/// [`MAX_RSSI_DBM`].
pub(crate) fn check_readings(scan: &Scan) -> Result<(), ScanError> {
    if scan.readings.is_empty() {
        return Err(ScanError::EmptyScan);
    }
    if let Some((index, r)) = scan.readings.iter().enumerate().find(|(_, r)| !plausible_rssi(r.rssi_dbm)) {
        return Err(ScanError::NonFiniteRssi { index, transmitter: r.transmitter.to_string() });
    }
    if let Some((index, r)) = scan.readings.iter().enumerate().find(|(_, r)| r.rssi_dbm > MAX_RSSI_DBM) {
        let transmitter = r.transmitter.to_string();
        return Err(ScanError::RssiTooHigh { index, transmitter, rssi_dbm: r.rssi_dbm });
    }
    Ok(())
}

/// Whether an RSSI can be a measurement, as far as its lower end goes: finite and not below
/// -1000 dBm (receivers report about -120 to +20). Below that it is a corrupt producer, as NaN
/// is, and near -1e154 the squared deviation of every fingerprint overflows, so no state could
/// explain the scan. Above [`MAX_RSSI_DBM`] is `RssiTooHigh`.
fn plausible_rssi(rssi_dbm: f64) -> bool {
    rssi_dbm.is_finite() && rssi_dbm >= -1000.0
}
