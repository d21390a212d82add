//! The walkable graph's parts: floors, the states (the HMM's possible positions, Hoang §5),
//! the edges between them and how the site's frame sits on the Earth.

use super::MAX_COORDINATE_M;
use nalgebra::Point2;
use serde::{Deserialize, Serialize};

/// A floor of the site.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Floor {
    /// Display name ("B1", "F2", ...).
    pub name: String,
    /// Height of the floor above the site's reference, m.
    pub elevation_m: f64,
    /// The building's own number for the floor (its logical level: -1 for the first
    /// basement), as Core Location's `CLFloor.level`; `None` when the site file gives none.
    pub level: Option<i32>,
    /// Where this floor's frame has its origin in the site frame, m: (0, 0) when every floor is
    /// drawn in the site frame; the plans of a survey that frames each floor on its own box (the
    /// competition's) differ ([`Site::lat_lon`](super::Site::lat_lon) adds it before the anchor).
    pub origin_m: [f64; 2],
    /// γ of Hoang eq. 14 while the engine is on this floor (its latest estimate's floor), in epochs
    /// with a movement likelihood, chosen by leave-one-walk-out over the floor's survey walks
    /// (Hoang §6.2's jackknife). `None`: the site-wide
    /// [`Calibration::rssi_weight`](super::Calibration::rssi_weight).
    pub rssi_weight: Option<f64>,
    /// The same in epochs without a movement likelihood; `None`: the site-wide
    /// [`Calibration::rssi_weight_without_movement`](super::Calibration::rssi_weight_without_movement).
    pub rssi_weight_without_movement: Option<f64>,
}

impl Floor {
    /// The first γ out of (0, 1], as (path, message), the floor being `floors[index]`.
    pub(crate) fn check(&self, index: usize) -> Result<(), (String, String)> {
        if !self.origin_m.iter().all(|v| v.is_finite() && v.abs() <= MAX_COORDINATE_M) {
            return Err((
                format!("floors[{index}].origin_m"),
                format!("must be within ±{MAX_COORDINATE_M} m, got {:?}", self.origin_m),
            ));
        }
        for (name, gamma) in [
            ("rssi_weight", self.rssi_weight),
            ("rssi_weight_without_movement", self.rssi_weight_without_movement),
        ] {
            if let Some(g) = gamma {
                if !(g > 0.0 && g <= 1.0) {
                    return Err((format!("floors[{index}].{name}"), format!("must be in (0, 1], got {g}")));
                }
            }
        }
        Ok(())
    }
}

/// Whether a state was surveyed (has measured fingerprints) or synthesised between surveyed
/// states (Hoang §5).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StateKind {
    /// Fingerprints fitted from training scans taken here.
    #[default]
    Surveyed,
    /// Fingerprints synthesised from neighbouring surveyed states (Hoang eqs. 12-13).
    Pseudo,
    /// No fingerprint: walkable space next to the surveyed area that no survey walk reached.
    /// The radio scores it as a place where no transmitter of the map is modelled, so a scan
    /// the map explains leaves it almost no mass; when the map does not explain a scan the
    /// motion alone can carry the estimate onto it.
    Unsurveyed,
}

/// A possible user position: one hidden state of the HMM.
#[derive(Clone, Debug, PartialEq)]
pub struct State {
    /// The id the site file gives it.
    pub id: u32,
    /// Index into [`Site::floors`](super::Site::floors).
    pub floor: usize,
    /// Position in the floor's metric frame, m.
    pub position: Point2<f64>,
    /// Surveyed or pseudo.
    pub kind: StateKind,
    /// How many training scans the fingerprint was fitted from.
    pub training_scans: u32,
}

/// How the site's frame sits on the Earth, for turning compass readings into site headings.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct North {
    /// Azimuth of the site's +y axis, radians clockwise from true north.
    #[serde(default)]
    pub site_rotation_rad: f64,
    /// Magnetic declination at the site (true minus magnetic azimuth), rad, east positive.
    #[serde(default)]
    pub declination_rad: f64,
}

/// A walkable connection between two states.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Edge {
    /// State index.
    pub a: u32,
    /// State index.
    pub b: u32,
    /// Walking length, m.
    pub length_m: f64,
}

/// The walkable neighbours of a state with their edge lengths, (state, m), in the order of the
/// site's edges ([`Site::neighbours`](super::Site::neighbours)); the default is no neighbour.
#[derive(Clone, Debug, Default)]
pub struct Neighbours<'a> {
    /// The state whose neighbours these are: each is the other end of an edge.
    pub(super) from: u32,
    pub(super) edges: &'a [Edge],
    pub(super) slots: std::slice::Iter<'a, u32>,
}

impl Iterator for Neighbours<'_> {
    type Item = (u32, f64);

    fn next(&mut self) -> Option<(u32, f64)> {
        self.slots.next().map(|&k| {
            let edge = &self.edges[k as usize];
            (if edge.a == self.from { edge.b } else { edge.a }, edge.length_m)
        })
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        self.slots.size_hint()
    }
}

impl ExactSizeIterator for Neighbours<'_> {}

/// Typical distance between neighbouring states: the median edge length, m (0 without edges).
pub(super) fn median_edge_length(edges: &[Edge]) -> f64 {
    if edges.is_empty() {
        return 0.0;
    }
    let mut lengths: Vec<f64> = edges.iter().map(|e| e.length_m).collect();
    let middle = lengths.len() / 2;
    // In place: a sort would take a buffer as large again.
    *lengths.select_nth_unstable_by(middle, f64::total_cmp).1
}

#[cfg(test)]
mod tests {
    use crate::site::{SiteBuilder, TrainingScan};
    use nalgebra::Point2;

    /// Each state's neighbours are the other ends of its edges, in the order of the site's
    /// edges, whichever end of an edge the state is.
    #[test]
    fn neighbours_are_the_other_ends_of_the_edges() {
        let mut b = SiteBuilder::new("triangle");
        let f = b.floor("G", 0.0);
        let ids: Vec<u32> = [(0.0, 0.0), (1.0, 0.0), (0.0, 2.0)]
            .iter()
            .map(|&(x, y)| b.state(f, Point2::new(x, y), Vec::<TrainingScan>::new()))
            .collect();
        b.edge(ids[0], ids[1], Some(1.0));
        b.edge(ids[1], ids[2], Some(2.0));
        b.edge(ids[2], ids[0], Some(3.0));
        let site = b.build(Default::default()).unwrap();
        let of = |i: usize| site.neighbours(i).collect::<Vec<_>>();
        assert_eq!(of(0), [(1, 1.0), (2, 3.0)]);
        assert_eq!(of(1), [(0, 1.0), (2, 2.0)]);
        assert_eq!(of(2), [(1, 2.0), (0, 3.0)]);
        assert_eq!(site.neighbours(2).len(), 2);
    }
}
