//! How often the floor an engine reports is right, per band of the posterior's mass on it
//! (docs/accuracy.md#floor-probability).

use serde::{Deserialize, Serialize};

/// Edges of the floor probability's bands, as the posterior's mass off the chosen floor: a
/// decade each from an even split down to one in a thousand, the range in which held-out
/// epochs are found wrong (docs/accuracy.md#floor-probability).
pub const FLOOR_MISS_BANDS: [f64; 4] = [0.5, 0.1, 0.01, 0.001];

/// Bands of the posterior's floor mass ([`FLOOR_MISS_BANDS`], the last one open).
pub const FLOOR_BANDS: usize = FLOOR_MISS_BANDS.len() + 1;

/// The share of held-out epochs whose floor was right, per band of the posterior's mass on
/// the floor ([`FloorReliability::band`]); `None`: not fitted. The survey's calibration fits
/// it as it fits the radius factors, so that the floor probability an app reads holds as
/// often as it says, where the posterior's own mass is overconfident because the survey is
/// sparse.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct FloorReliability(pub [Option<f64>; FLOOR_BANDS]);

impl FloorReliability {
    /// Whether no band is fitted.
    pub fn is_empty(&self) -> bool {
        self.0.iter().all(Option::is_none)
    }

    /// The band of a posterior mass `p` on the floor: for how many of [`FLOOR_MISS_BANDS`]
    /// it is above one minus the edge.
    pub fn band(p: f64) -> usize {
        FLOOR_MISS_BANDS.iter().take_while(|&&miss| p > 1.0 - miss).count()
    }

    /// The floor probability to report for a posterior mass `p`: its band's share, else `p`.
    pub fn report(&self, p: f64) -> f64 {
        self.0[Self::band(p)].unwrap_or(p)
    }

    /// The first share out of [0, 1], as (band, share).
    pub(super) fn invalid(&self) -> Option<(usize, f64)> {
        (self.0.iter().enumerate())
            .find_map(|(band, share)| share.filter(|s| !(0.0..=1.0).contains(s)).map(|s| (band, s)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bands are decades of the mass off the floor, each closed at its upper end of mass.
    #[test]
    fn floor_bands_are_decades_of_the_mass_off_the_floor() {
        assert_eq!(
            [0.0, 0.5, 0.51, 0.9, 0.91, 0.99, 0.995, 0.999, 0.9995, 1.0].map(FloorReliability::band),
            [0, 0, 1, 1, 2, 2, 3, 3, 4, 4]
        );
        let table = FloorReliability([None, Some(0.6), Some(0.8), Some(0.9), Some(0.97)]);
        assert_eq!(table.report(0.3), 0.3, "an unfitted band reports the posterior's mass");
        assert_eq!(table.report(0.95), 0.8);
        assert_eq!(table.report(1.0), 0.97);
        assert_eq!(FloorReliability::default().report(0.95), 0.95);
    }
}
