//! The phone's RSSI offset against the survey's map, learned online in one session
//! (docs/accuracy.md#device-offset).
//!
//! Phone models read the same signal several dB apart: their antennas, front ends and
//! firmware differ, and a map surveyed with one phone scores another's scans as if every
//! access point were nearer or farther than it is. The offset is a property of the phone's
//! radio, constant over a session, so it is one scalar `b` (dB the phone reads above the
//! survey's phones), estimated as the mean of a Gaussian by a scalar Kalman filter with no
//! process noise: each scan measures `b` as the mean residual of its readings against the
//! fingerprints of where the engine believed the phone was before the scan
//! ([`RadioMap::offset_residual`](super::RadioMap::offset_residual)), with the variance of
//! that mean. Readings are corrected by the estimate before the likelihood of the next scan.

/// The prior on the offset, dB: a standard deviation wide enough that the first scans, not
/// the prior, set it (a scan of ten readings at the map's typical σ of a few dB measures it to
/// about 1-2 dB), and mean 0, the survey's own phones.
pub const DEVICE_OFFSET_PRIOR_STD_DB: f64 = 10.0;

/// How many standard deviations from 0 the estimate must be before readings are corrected by
/// it: 2, a two-sided test at about 5% that the phone reads unlike the survey's phones.
pub const DEVICE_OFFSET_Z: f64 = 2.0;

/// The largest offset the estimate takes, dB: a bound on bad input, not a tuned value (the
/// dynamic range between a phone's clip level and a reading at the access point).
pub const MAX_DEVICE_OFFSET_DB: f64 = 30.0;

/// The estimate of the phone's RSSI offset, with its uncertainty.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeviceOffset {
    /// Posterior mean, dB: what the phone reads above the survey's phones.
    mean_db: f64,
    /// Posterior variance, dB².
    variance_db2: f64,
    /// Scans that measured it.
    scans: u32,
}

impl Default for DeviceOffset {
    fn default() -> Self {
        Self { mean_db: 0.0, variance_db2: DEVICE_OFFSET_PRIOR_STD_DB * DEVICE_OFFSET_PRIOR_STD_DB, scans: 0 }
    }
}

impl DeviceOffset {
    /// The estimate, dB.
    pub fn mean_db(&self) -> f64 {
        self.mean_db
    }

    /// Its standard deviation, dB.
    pub fn std_db(&self) -> f64 {
        self.variance_db2.sqrt()
    }

    /// Scans that measured it.
    pub fn scans(&self) -> u32 {
        self.scans
    }

    /// The Kalman update with one scan's measurement: the mean residual `residual_db` with
    /// variance `variance_db2`. A measurement that is not finite, or whose variance is not
    /// positive, changes nothing.
    pub fn update(&mut self, residual_db: f64, variance_db2: f64) {
        if !(residual_db.is_finite() && variance_db2.is_finite() && variance_db2 > 0.0) {
            return;
        }
        let gain = self.variance_db2 / (self.variance_db2 + variance_db2);
        self.mean_db = (self.mean_db + gain * (residual_db - self.mean_db))
            .clamp(-MAX_DEVICE_OFFSET_DB, MAX_DEVICE_OFFSET_DB);
        self.variance_db2 *= 1.0 - gain;
        self.scans = self.scans.saturating_add(1);
    }

    /// The offset readings are corrected by, dB: the estimate once it is
    /// [`DEVICE_OFFSET_Z`] standard deviations from 0, else 0. Until the scans show that the
    /// phone reads unlike the survey's, correcting by a noisy estimate only adds its noise to
    /// every reading.
    pub fn applied_db(&self) -> f64 {
        if self.mean_db.abs() >= DEVICE_OFFSET_Z * self.std_db() {
            self.mean_db
        } else {
            0.0
        }
    }

    /// `rssi_dbm` as the survey's phones would have read it.
    pub fn correct(&self, rssi_dbm: f64) -> f64 {
        rssi_dbm - self.applied_db()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn measurements_shrink_the_variance_and_pull_the_mean() {
        let mut offset = DeviceOffset::default();
        assert_eq!(offset.correct(-60.0), -60.0);
        // One measurement as precise as the prior: halfway, half the variance; not yet two
        // standard deviations from 0, so nothing is corrected.
        offset.update(-6.0, 100.0);
        assert_relative_eq!(offset.mean_db(), -3.0);
        assert_relative_eq!(offset.std_db(), 50f64.sqrt());
        assert_eq!(offset.correct(-60.0), -60.0);
        // Many precise ones: the mean of the measurements.
        for _ in 0..200 {
            offset.update(-5.5, 4.0);
        }
        assert!((offset.mean_db() + 5.5).abs() < 0.05, "{}", offset.mean_db());
        assert!(offset.std_db() < 0.15);
        assert_eq!(offset.scans(), 201);
        assert_relative_eq!(offset.correct(-70.0), -70.0 - offset.mean_db());
    }

    #[test]
    fn bad_measurements_change_nothing_and_the_mean_is_bounded() {
        let mut offset = DeviceOffset::default();
        for (r, v) in [(f64::NAN, 1.0), (1.0, 0.0), (1.0, -1.0), (f64::INFINITY, 1.0), (1.0, f64::NAN)] {
            offset.update(r, v);
        }
        assert_eq!(offset, DeviceOffset::default());
        offset.update(1e9, 1e-9);
        assert_eq!(offset.mean_db(), MAX_DEVICE_OFFSET_DB);
    }
}
