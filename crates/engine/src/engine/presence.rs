//! Whether the person is inside each of the site's zones and the app's geofences, with
//! hysteresis, and the enter and exit events when that changes (docs/zones.md#enter-and-exit).

use super::{Engine, StatusEvent};
use crate::config::ZoneHysteresis;
use crate::geofence::{Geofence, GeofenceError};

/// Presence per zone and per geofence, as last reported.
#[derive(Clone, Debug, Default)]
pub(super) struct Presence {
    /// Per site zone, by index.
    zones: Vec<bool>,
    /// The app's geofences, in the order they were added.
    fences: Vec<Fence>,
}

#[derive(Clone, Debug)]
struct Fence {
    fence: Geofence,
    /// The site's states inside it, ascending.
    states: Vec<u32>,
    inside: bool,
}

/// A change of presence found at an epoch, applied once nothing in the epoch can fail.
#[derive(Debug)]
pub(super) enum Change {
    Zone(usize, bool),
    Fence(usize, bool),
}

/// Whether presence changes from `inside` at `mass`: in at `enter_mass` or more, out below
/// `exit_mass`; between the two it stays as it was.
fn crosses(inside: bool, mass: f64, hysteresis: &ZoneHysteresis) -> bool {
    if inside {
        mass < hysteresis.exit_mass
    } else {
        mass >= hysteresis.enter_mass
    }
}

impl Presence {
    pub(super) fn new(zones: usize) -> Self {
        Self { zones: vec![false; zones], fences: Vec::new() }
    }

    /// The status events of an epoch at `timestamp_ns` whose posterior is `posterior` and
    /// zone masses `zone_mass`, exits first, and the changes to apply.
    pub(super) fn evaluate(
        &self,
        timestamp_ns: u64,
        posterior: &[f64],
        zone_mass: &[f64],
        hysteresis: &ZoneHysteresis,
    ) -> (Vec<StatusEvent>, Vec<Change>) {
        let mut changes = Vec::new();
        for (z, (&inside, &mass)) in self.zones.iter().zip(zone_mass).enumerate() {
            if crosses(inside, mass, hysteresis) {
                changes.push((Change::Zone(z, !inside), mass));
            }
        }
        for (k, f) in self.fences.iter().enumerate() {
            let mass: f64 = f.states.iter().map(|&s| posterior[s as usize]).sum();
            if crosses(f.inside, mass, hysteresis) {
                changes.push((Change::Fence(k, !f.inside), mass));
            }
        }
        // Out of one place before into the next.
        changes.sort_by_key(|(c, _)| matches!(c, Change::Zone(_, true) | Change::Fence(_, true)));
        let events = changes
            .iter()
            .map(|&(ref change, probability)| match *change {
                Change::Zone(zone, true) => StatusEvent::ZoneEntered { timestamp_ns, zone, probability },
                Change::Zone(zone, false) => StatusEvent::ZoneExited { timestamp_ns, zone, probability },
                Change::Fence(k, entered) => {
                    let id = self.fences[k].fence.id.clone();
                    if entered {
                        StatusEvent::GeofenceEntered { timestamp_ns, id, probability }
                    } else {
                        StatusEvent::GeofenceExited { timestamp_ns, id, probability }
                    }
                }
            })
            .collect();
        (events, changes.into_iter().map(|(c, _)| c).collect())
    }

    pub(super) fn apply(&mut self, changes: Vec<Change>) {
        for change in changes {
            match change {
                Change::Zone(z, inside) => self.zones[z] = inside,
                Change::Fence(k, inside) => self.fences[k].inside = inside,
            }
        }
    }

    /// Whether the person is inside each site zone and each geofence (by id), as last
    /// reported: for snapshots.
    #[cfg(feature = "fault-injection")]
    pub(super) fn flags(&self) -> (Vec<bool>, Vec<(String, bool)>) {
        let fences = self.fences.iter().map(|f| (f.fence.id.clone(), f.inside)).collect();
        (self.zones.clone(), fences)
    }
}

impl Engine {
    /// Adds a geofence: from the next epoch on, entering and leaving it are reported as
    /// [`StatusEvent::GeofenceEntered`] and [`StatusEvent::GeofenceExited`], with the same
    /// hysteresis as the site's zones (`EngineConfig::zone_hysteresis`). A person already
    /// inside it is reported as entering at the next epoch. Refused, changing nothing: an empty
    /// or taken id, an unknown floor, a shape that is not finite or has no area, or one that
    /// holds no state of the site.
    pub fn add_geofence(&mut self, fence: Geofence) -> Result<(), GeofenceError> {
        if self.presence.fences.iter().any(|f| f.fence.id == fence.id) {
            return Err(GeofenceError::DuplicateId { id: fence.id });
        }
        let states = fence.states_inside(&self.site)?;
        self.presence.fences.push(Fence { fence, states, inside: false });
        Ok(())
    }

    /// Removes the geofence `id`, without an exit event; `false` if there was none.
    pub fn remove_geofence(&mut self, id: &str) -> bool {
        let before = self.presence.fences.len();
        self.presence.fences.retain(|f| f.fence.id != id);
        self.presence.fences.len() != before
    }

    /// The geofences, in the order they were added.
    pub fn geofences(&self) -> impl Iterator<Item = &Geofence> {
        self.presence.fences.iter().map(|f| &f.fence)
    }

    /// The posterior probability of being inside geofence `id` now (`None`: no such
    /// geofence).
    pub fn geofence_probability(&self, id: &str) -> Option<f64> {
        let fence = self.presence.fences.iter().find(|f| f.fence.id == id)?;
        let posterior = self.filter.posterior();
        Some(fence.states.iter().map(|&s| posterior[s as usize]).sum())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One zone whose mass goes through `masses`: the epochs at which it is entered (true) or
    /// left (false).
    fn crossings(masses: &[f64]) -> Vec<(usize, bool)> {
        let mut presence = Presence::new(1);
        let mut out = Vec::new();
        for (k, &m) in masses.iter().enumerate() {
            let (events, changes) = presence.evaluate(k as u64, &[], &[m], &ZoneHysteresis::default());
            for e in events {
                match e {
                    StatusEvent::ZoneEntered { zone: 0, .. } => out.push((k, true)),
                    StatusEvent::ZoneExited { zone: 0, .. } => out.push((k, false)),
                    other => panic!("{other:?}"),
                }
            }
            presence.apply(changes);
        }
        out
    }

    #[test]
    fn a_mass_must_cross_the_whole_band_to_change_presence() {
        // In at 0.68 or more, out below 0.32; in between, as before.
        assert_eq!(
            crossings(&[0.5, 0.67, 0.68, 0.4, 0.33, 0.32, 0.31, 0.6, 0.9]),
            vec![(2, true), (6, false), (8, true)]
        );
        // Hovering at an even chance says nothing.
        assert!(crossings(&[0.45, 0.55, 0.45, 0.55, 0.5]).is_empty());
    }
}
