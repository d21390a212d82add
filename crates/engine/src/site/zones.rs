//! Zones: named groups of states (rooms, corridors, halls...), the places El Gemayel et al.
//! score room-level accuracy on (§II-B: "the probability that the estimated state is the true
//! state", where a state is a room or a hallway). A state belongs to at most one zone; states
//! in none are "outside every zone" (a mall's open concourse, say).
//!
//! The engine reports the posterior mass of each zone (the sum over its states of the state
//! posterior) and the most likely zone; user feedback ("I am in the kitchen") pins the
//! posterior to a zone's states.

use super::{Site, SiteError};
use serde::{Deserialize, Serialize};

/// What kind of place a zone is. Informative only: the engine treats every kind alike.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ZoneKind {
    /// A room (an office, a kitchen, a shop). The default.
    #[default]
    Room,
    /// A corridor or aisle.
    Corridor,
    /// A large open area: a hall, an atrium, a concourse.
    Hall,
    /// A staircase.
    Stairs,
    /// A lift (elevator) or its lobby.
    Lift,
    /// An entrance.
    Entrance,
    /// Anything else.
    Other,
}

/// A named group of states.
#[derive(Clone, Debug, PartialEq)]
pub struct Zone {
    /// Its name, unique in the site ("kitchen", "F1/STARBUCKS COFFEE").
    pub name: String,
    /// What kind of place it is.
    pub kind: ZoneKind,
    /// Indices of its states into [`Site::states`], ascending.
    pub states: Vec<u32>,
}

/// `zone_of` entry of a state in no zone.
pub(super) const NO_ZONE: u32 = u32::MAX;

/// Most zones a site may have: the C ABI reports a zone as an `int32_t` (-1 for none).
pub const MAX_ZONES: usize = i32::MAX as usize;

fn invalid(path: impl Into<String>, message: impl Into<String>) -> SiteError {
    SiteError::Invalid { path: path.into(), message: message.into() }
}

/// Checks zones whose states are given by `resolve` (a state's id in a file, its index for
/// [`Site::with_zones`]) and returns them with their states as sorted indices, and each
/// state's zone (`NO_ZONE` for none; empty when there are no zones). `what` names the state
/// references in messages ("id" or "index").
pub(super) fn validate<'a>(
    zones: impl IntoIterator<Item = (String, ZoneKind, &'a [u32])>,
    state_count: usize,
    what: &str,
    resolve: impl Fn(u32) -> Option<usize>,
) -> Result<(Vec<Zone>, Vec<u32>), SiteError> {
    let mut out: Vec<Zone> = Vec::new();
    let mut zone_of: Vec<u32> = Vec::new();
    let mut names: std::collections::HashMap<String, usize> = std::collections::HashMap::new();
    for (k, (name, kind, members)) in zones.into_iter().enumerate() {
        if k >= MAX_ZONES {
            return Err(invalid("zones", format!("more than {MAX_ZONES} zones")));
        }
        if zone_of.is_empty() {
            zone_of = vec![NO_ZONE; state_count];
        }
        if name.trim().is_empty() {
            return Err(invalid(format!("zones[{k}].name"), "must not be empty"));
        }
        if let Some(first) = names.insert(name.clone(), k) {
            return Err(invalid(
                format!("zones[{k}].name"),
                format!("{name:?} is already the name of zones[{first}]"),
            ));
        }
        if members.is_empty() {
            return Err(invalid(format!("zones[{k}].states"), "a zone needs at least one state"));
        }
        let mut states = Vec::with_capacity(members.len());
        for (m, &reference) in members.iter().enumerate() {
            let path = || format!("zones[{k}].states[{m}]");
            let Some(i) = resolve(reference).filter(|&i| i < state_count) else {
                return Err(invalid(path(), format!("no state has {what} {reference}")));
            };
            match zone_of[i] {
                NO_ZONE => zone_of[i] = k as u32,
                z if z as usize == k => {
                    return Err(invalid(path(), format!("state {what} {reference} is listed twice")))
                }
                z => {
                    return Err(invalid(
                        path(),
                        format!("state {what} {reference} is already in zones[{z}]: a state belongs to at most one zone"),
                    ))
                }
            }
            states.push(i as u32);
        }
        states.sort_unstable();
        out.push(Zone { name, kind, states });
    }
    Ok((out, zone_of))
}

impl Site {
    /// The zones, by index.
    pub fn zones(&self) -> &[Zone] {
        &self.zones
    }

    /// The zone of state `i`, if it is in one.
    pub fn zone_of(&self, i: usize) -> Option<usize> {
        self.zone_of.get(i).copied().filter(|&z| z != NO_ZONE).map(|z| z as usize)
    }

    /// The index of the zone called `name`.
    pub fn zone_index(&self, name: &str) -> Option<usize> {
        self.zones.iter().position(|z| z.name == name)
    }

    /// An outline of zone `zone` for a map: its floor (the one holding most of its states) and
    /// the convex hull, in that floor's frame, m, counter-clockwise and not closed, of the
    /// squares of side [`spacing_m`](Self::spacing_m) around its states there: the area the
    /// engine places someone in when it says they are in the zone. `None` for an unknown
    /// index.
    pub fn zone_outline(&self, zone: usize) -> Option<(usize, Vec<[f64; 2]>)> {
        use geo::ConvexHull;
        let states = &self.zones.get(zone)?.states;
        let mut per_floor = vec![0usize; self.floors.len()];
        for &i in states {
            per_floor[self.states[i as usize].floor] += 1;
        }
        let floor = (0..per_floor.len()).max_by_key(|&f| (per_floor[f], std::cmp::Reverse(f)))?;
        let half = self.spacing_m.max(0.1) / 2.0;
        let corners: Vec<geo::Point<f64>> = states
            .iter()
            .map(|&i| &self.states[i as usize])
            .filter(|s| s.floor == floor)
            .flat_map(|s| {
                let (x, y) = (s.position.x, s.position.y);
                [(-half, -half), (half, -half), (half, half), (-half, half)]
                    .map(|(dx, dy)| geo::Point::new(x + dx, y + dy))
            })
            .collect();
        let hull = geo::MultiPoint::from(corners).convex_hull();
        let mut ring: Vec<[f64; 2]> = hull.exterior().coords().map(|c| [c.x, c.y]).collect();
        ring.pop();
        Some((floor, ring))
    }

    /// The site with `zones` in place of its own, their states given by index. Checked as a
    /// site file's zones are: non-empty unique names, at least one state each, indices in
    /// range, no state in two zones.
    pub fn with_zones(mut self, zones: Vec<Zone>) -> Result<Site, SiteError> {
        let n = self.states.len();
        let (zones, zone_of) =
            validate(zones.iter().map(|z| (z.name.clone(), z.kind, &z.states[..])), n, "index", |i| {
                Some(i as usize)
            })?;
        self.zones = zones;
        self.zone_of = zone_of;
        Ok(self)
    }

    /// Posterior mass of each zone from the state posterior `posterior`, into `out` (one value
    /// per zone, overwritten); returns the mass outside every zone.
    pub fn zone_mass(&self, posterior: &[f64], out: &mut [f64]) -> f64 {
        out.fill(0.0);
        let mut outside = 0.0;
        if self.zone_of.is_empty() {
            return posterior.iter().sum();
        }
        for (&z, &p) in self.zone_of.iter().zip(posterior) {
            match out.get_mut(z as usize) {
                Some(m) => *m += p,
                None => outside += p,
            }
        }
        outside
    }
}

/// The most likely zone given the masses of [`Site::zone_mass`]: the zone with the most mass,
/// or `None` when more mass is outside every zone than in any one of them; with the
/// probability of that answer.
pub fn most_likely_zone(masses: &[f64], outside: f64) -> (Option<usize>, f64) {
    let best = masses.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1).then(b.0.cmp(&a.0)));
    match best {
        Some((z, &m)) if m >= outside => (Some(z), m),
        _ => (None, outside),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::site::{BuildOptions, SiteBuilder};
    use nalgebra::Point2;

    fn line(n: usize) -> Site {
        let mut b = SiteBuilder::new("line");
        let f = b.floor("G", 0.0);
        let ids: Vec<u32> = (0..n).map(|k| b.state(f, Point2::new(3.0 * k as f64, 0.0), vec![])).collect();
        for w in ids.windows(2) {
            b.edge(w[0], w[1], None);
        }
        b.build(BuildOptions::default()).unwrap()
    }

    fn zone(name: &str, states: &[u32]) -> Zone {
        Zone { name: name.into(), kind: ZoneKind::Room, states: states.to_vec() }
    }

    #[test]
    fn a_zone_outline_covers_its_states_cells_and_no_other_state() {
        // States 3 m apart on a line: spacing 3, so cells 1.5 m either side.
        let site = line(5).with_zones(vec![zone("a", &[1, 2]), zone("b", &[4])]).unwrap();
        let (floor, ring) = site.zone_outline(0).unwrap();
        assert_eq!(floor, 0);
        let xs: Vec<f64> = ring.iter().map(|p| p[0]).collect();
        let ys: Vec<f64> = ring.iter().map(|p| p[1]).collect();
        let min = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
        let max = |v: &[f64]| v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        assert_eq!((min(&xs), max(&xs), min(&ys), max(&ys)), (1.5, 7.5, -1.5, 1.5));
        assert_eq!(ring.len(), 4, "a rectangle, not closed: {ring:?}");
        assert_eq!(site.zone_outline(1).unwrap().1.len(), 4);
        assert_eq!(site.zone_outline(2), None);
    }

    #[test]
    fn zones_sum_the_posterior_of_their_states() {
        let site = line(5).with_zones(vec![zone("a", &[1, 0]), zone("b", &[3])]).unwrap();
        assert_eq!(site.zones()[0].states, vec![0, 1], "sorted");
        assert_eq!((site.zone_of(0), site.zone_of(2), site.zone_of(3)), (Some(0), None, Some(1)));
        assert_eq!(site.zone_index("b"), Some(1));
        assert_eq!(site.zone_index("c"), None);
        let mut out = vec![9.0; 2];
        let outside = site.zone_mass(&[0.1, 0.2, 0.3, 0.25, 0.15], &mut out);
        assert!((out[0] - 0.3).abs() < 1e-12 && (out[1] - 0.25).abs() < 1e-12);
        assert!((outside - 0.45).abs() < 1e-12);
        assert_eq!(most_likely_zone(&out, outside), (None, outside));
        assert_eq!(most_likely_zone(&out, 0.1), (Some(0), out[0]));
        assert_eq!(most_likely_zone(&[], 1.0), (None, 1.0));
        // Ties go to the lower index, and a zone beats "outside" on a tie.
        assert_eq!(most_likely_zone(&[0.5, 0.5], 0.0), (Some(0), 0.5));
        assert_eq!(most_likely_zone(&[0.5], 0.5), (Some(0), 0.5));
        let plain = line(3);
        assert!(plain.zones().is_empty() && plain.zone_of(0).is_none());
        assert_eq!(plain.zone_mass(&[0.5, 0.25, 0.25], &mut []), 1.0);
    }

    #[test]
    fn bad_zones_are_named() {
        let cases = [
            (vec![zone("", &[0])], "zones[0].name"),
            (vec![zone("a", &[0]), zone("a", &[1])], "zones[1].name"),
            (vec![zone("a", &[])], "zones[0].states"),
            (vec![zone("a", &[0, 7])], "zones[0].states[1]"),
            (vec![zone("a", &[0, 0])], "zones[0].states[1]"),
            (vec![zone("a", &[0]), zone("b", &[1, 0])], "zones[1].states[1]"),
        ];
        for (zones, path) in cases {
            match line(3).with_zones(zones.clone()) {
                Err(SiteError::Invalid { path: p, message }) => assert_eq!(p, path, "{message}"),
                other => panic!("{zones:?}: expected Invalid at {path}, got {other:?}"),
            }
        }
    }
}
