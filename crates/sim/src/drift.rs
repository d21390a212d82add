//! Radio drift after a survey (issue 62, docs/evidence.md#drift): a share of the office's
//! access points move, vanish or appear, so that a site surveyed before is out of date.

use crate::{Office, RadioField, OFFICE_SIZE_M};
use nalgebra::Point2;
use rand::rngs::ChaCha8Rng;
use rand::{RngExt, SeedableRng};
use serde::Serialize;
use waymark_engine::radio::TransmitterId;

/// Why a drift could not be applied.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum DriftError {
    /// The share is not a number from 0 to 1.
    #[error("the share of transmitters changed must be from 0 to 1, not {0}")]
    Share(f64),
}

/// What a drift changed, by access point index in the surveyed field.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Drift {
    /// Access points before the drift.
    pub before: usize,
    /// Moved to a new position, same id.
    pub moved: Vec<usize>,
    /// Gone.
    pub vanished: Vec<usize>,
    /// New access points (new ids) added, at the end of the drifted field's list.
    pub appeared: usize,
}

impl Drift {
    /// Access points changed: moved, vanished or new.
    pub fn changed(&self) -> usize {
        self.moved.len() + self.vanished.len() + self.appeared
    }
}

/// How `changed` access points split into moved, vanished and new ones: a third each, the
/// remainder to the moved and then the vanished. Issue 62 names the three ("replaced, moved and
/// re-powered") and gives no frequencies; a replaced access point is one that vanishes and a
/// new one (a new BSSID) that appears, and equal numbers of those keep the building's access
/// point density, so the stale map's loss is from the changes, not from fewer transmitters.
pub fn split(changed: usize) -> [usize; 3] {
    let third = changed / 3;
    let rest = changed - 3 * third;
    [third + usize::from(rest > 0), third + usize::from(rest > 1), third]
}

impl RadioField {
    /// The field after a drift of `share` of its access points (rounded to whole access
    /// points): split by [`split`], the ones that move or vanish drawn at random, a moved or new
    /// one placed uniformly over the office as the survey's were ([`Office::generate`]). Seeded.
    pub fn drifted(&self, share: f64, seed: u64) -> Result<(RadioField, Drift), DriftError> {
        if !(0.0..=1.0).contains(&share) {
            return Err(DriftError::Share(share));
        }
        let n = self.access_points.len();
        let changed = (share * n as f64).round() as usize;
        let [moved, vanished, appeared] = split(changed);
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        // A partial Fisher-Yates shuffle: the first moved + vanished indices, without repeats.
        let mut order: Vec<usize> = (0..n).collect();
        for k in 0..(moved + vanished).min(n) {
            let j = rng.random_range(k..n);
            order.swap(k, j);
        }
        let place = |rng: &mut ChaCha8Rng| {
            Point2::new(rng.random_range(0.0..OFFICE_SIZE_M.0), rng.random_range(0.0..OFFICE_SIZE_M.1))
        };
        let mut drift = Drift {
            before: n,
            moved: order[..moved].to_vec(),
            vanished: order[moved..moved + vanished].to_vec(),
            appeared,
        };
        drift.moved.sort_unstable();
        drift.vanished.sort_unstable();
        let mut access_points = Vec::with_capacity(n - vanished + appeared);
        for (k, (id, at)) in self.access_points.iter().enumerate() {
            if drift.vanished.binary_search(&k).is_ok() {
                continue;
            }
            let at = if drift.moved.binary_search(&k).is_ok() { place(&mut rng) } else { *at };
            access_points.push((id.clone(), at));
        }
        for k in 0..appeared {
            // Another prefix than the surveyed ones (02:00:00:00:..), so no id repeats.
            let id = TransmitterId::wifi(&format!("02:00:00:01:{:02x}:{:02x}", k / 256, k % 256))
                .expect("a well-formed BSSID");
            access_points.push((id, place(&mut rng)));
        }
        Ok((RadioField { access_points, ..self.clone() }, drift))
    }
}

impl Office {
    /// The office with its radio drifted ([`RadioField::drifted`]); the site stays the one
    /// fitted before, as a survey made before the drift.
    pub fn drifted(&self, share: f64, seed: u64) -> Result<(Office, Drift), DriftError> {
        let (field, drift) = self.field.drifted(share, seed)?;
        Ok((Office { field, ..self.clone() }, drift))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::OfficeConfig;

    /// The drift changes the share asked for, split a third each, and leaves the rest alone.
    #[test]
    fn the_drift_changes_the_share_asked_for() {
        let office = Office::generate(&OfficeConfig {
            access_points: 40,
            training_scans: 2,
            ..OfficeConfig::default()
        });
        for (share, changed) in [(0.0, 0), (0.3, 12), (0.5, 20), (1.0, 40)] {
            let (drifted, drift) = office.drifted(share, 7).unwrap();
            assert_eq!(drift.changed(), changed);
            assert_eq!([drift.moved.len(), drift.vanished.len(), drift.appeared], split(changed));
            let before = &office.field.access_points;
            let after = &drifted.field.access_points;
            assert_eq!(after.len(), before.len() - drift.vanished.len() + drift.appeared);
            // Moved and vanished are distinct access points of the surveyed field.
            assert!(drift.moved.iter().all(|k| !drift.vanished.contains(k)));
            for (k, (id, at)) in before.iter().enumerate() {
                let now = after.iter().find(|a| &a.0 == id);
                if drift.vanished.contains(&k) {
                    assert!(now.is_none(), "{id} vanished");
                } else if drift.moved.contains(&k) {
                    assert_ne!(now.unwrap().1, *at, "{id} moved");
                } else {
                    assert_eq!(now.unwrap().1, *at, "{id} stayed");
                }
            }
            // The new ones have ids the survey never heard, inside the office.
            for (id, at) in &after[after.len() - drift.appeared..] {
                assert!(before.iter().all(|b| &b.0 != id));
                assert!((0.0..OFFICE_SIZE_M.0).contains(&at.x) && (0.0..OFFICE_SIZE_M.1).contains(&at.y));
            }
        }
        assert_eq!(split(5), [2, 2, 1]);
        assert_eq!(split(4), [2, 1, 1]);
        assert!(matches!(office.drifted(1.5, 0), Err(DriftError::Share(_))));
        assert!(matches!(office.drifted(f64::NAN, 0), Err(DriftError::Share(_))));
    }
}
