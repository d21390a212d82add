//! Where a floor change lands: for each state and each other floor, the state of that floor
//! nearest it in the site frame (docs/accuracy.md#barometer). The barometer's floor changes
//! move the phone up or down, not across the plan.

use super::Site;
use rstar::primitives::GeomWithData;
use rstar::RTree;
use std::sync::{Arc, OnceLock};

/// For each state i and floor g, the state of floor g nearest i in the site frame (i itself on
/// its own floor).
#[derive(Debug)]
pub(crate) struct Landings {
    floors: usize,
    /// `nearest[i * floors + g]`.
    nearest: Vec<u32>,
}

impl Landings {
    fn build(site: &Site) -> Self {
        let floors = site.floors().len();
        let at = |i: usize| {
            let s = &site.states()[i];
            let origin = site.floors()[s.floor].origin_m;
            [s.position.x + origin[0], s.position.y + origin[1]]
        };
        let mut on_floor: Vec<Vec<GeomWithData<[f64; 2], u32>>> = vec![Vec::new(); floors];
        for (i, s) in site.states().iter().enumerate() {
            on_floor[s.floor].push(GeomWithData::new(at(i), i as u32));
        }
        let trees: Vec<RTree<GeomWithData<[f64; 2], u32>>> =
            on_floor.into_iter().map(RTree::bulk_load).collect();
        let mut nearest = Vec::with_capacity(site.states().len() * floors);
        for (i, s) in site.states().iter().enumerate() {
            for (g, tree) in trees.iter().enumerate() {
                let landing =
                    if g == s.floor { Some(i as u32) } else { tree.nearest_neighbor(&at(i)).map(|p| p.data) };
                // A floor without states: the state stays where it is (no move is written there).
                nearest.push(landing.unwrap_or(i as u32));
            }
        }
        Self { floors, nearest }
    }

    /// The state of floor `g` nearest state `i`; `i` itself where `g` has no state.
    pub(crate) fn on(&self, i: usize, g: usize) -> u32 {
        self.nearest[i * self.floors + g]
    }
}

/// [`Site::landings`]' memory, shared by the site's copies.
#[derive(Clone, Debug, Default)]
pub(super) struct LandingCache(Arc<OnceLock<Arc<Landings>>>);

impl Site {
    /// Where a floor change from each state lands on each floor ([`Landings`]), built on the
    /// first call and shared by the site's copies.
    pub(crate) fn landings(&self) -> Arc<Landings> {
        Arc::clone(self.landings.0.get_or_init(|| Arc::new(Landings::build(self))))
    }
}

#[cfg(test)]
mod tests {
    use crate::site::{BuildOptions, SiteBuilder};
    use nalgebra::Point2;

    #[test]
    fn a_floor_change_lands_on_the_nearest_state_of_the_other_floor() {
        let mut b = SiteBuilder::new("two floors");
        let (f0, f1) = (b.floor("ground", 0.0), b.floor("first", 4.0));
        let a = b.state(f0, Point2::new(0.0, 0.0), vec![]);
        let c = b.state(f0, Point2::new(10.0, 0.0), vec![]);
        // The first floor drawn in its own frame, 5 m east of the ground floor's.
        let up_a = b.state(f1, Point2::new(-4.0, 0.5), vec![]);
        let up_c = b.state(f1, Point2::new(4.0, -1.0), vec![]);
        b.floor_geo(f1, Some(1), [5.0, 0.0]);
        b.floor_geo(f0, Some(0), [0.0, 0.0]);
        b.edge(a, c, None);
        b.edge(up_a, up_c, None);
        let site = b.build(BuildOptions::default()).unwrap();
        let landings = site.landings();
        assert_eq!(landings.on(a as usize, f1), up_a);
        assert_eq!(landings.on(c as usize, f1), up_c);
        assert_eq!(landings.on(up_c as usize, f0), c);
        assert_eq!(landings.on(up_a as usize, f0), a);
        assert_eq!(landings.on(up_c as usize, f1), up_c);
    }
}
