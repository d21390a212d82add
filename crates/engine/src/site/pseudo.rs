//! Pseudo states (Hoang §5): states inserted along the walkable edges between surveyed states,
//! whose fingerprints are synthesised from the two surveyed ends by eqs. 12-13, so that the
//! HMM's grid is fine without surveying more.

use super::{Edge, Site, State, StateKind};
use crate::radio::{Gaussian, RadioMap};
use std::collections::BTreeMap;

/// Hoang §6.1: pseudo states "such that the Euclidean distance between neighboring states is
/// not more than 0.75 m (which is close to the measured average step length)".
pub const PSEUDO_SPACING_M: f64 = 0.75;

/// Eqs. 12-13: the model at fraction `s` of the way from state i (model `a`) to state k
/// (model `b`), with d(j,i) = s·L and d(k,j) = (1-s)·L. It is the normalised product
/// N(μ_i, σ_i²)^(1-s) · N(μ_k, σ_k²)^s: precision-weighted, exact at both ends.
pub fn interpolate(a: &Gaussian, b: &Gaussian, s: f64) -> Gaussian {
    let (vi, vk) = (a.std_db * a.std_db, b.std_db * b.std_db);
    let (d_ji, d_kj) = (s, 1.0 - s);
    let denominator = vi * d_ji + vk * d_kj;
    let mean = (vk * d_kj * a.mean_dbm + vi * d_ji * b.mean_dbm) / denominator;
    // d(i,k) = 1 in units of L.
    let var = vk * vi / denominator;
    Gaussian { mean_dbm: mean, std_db: var.sqrt() }
}

impl Site {
    /// The site with pseudo states on every same-floor edge between two surveyed states, so
    /// that neighbours are at most `max_spacing_m` apart. Edges between floors (stairs, lifts)
    /// and edges touching pseudo states are kept as they are. A pseudo state joins the zone of
    /// the nearer end of its edge (of the first end, halfway), or none if that end is in none.
    pub fn with_pseudo_states(&self, max_spacing_m: f64) -> Site {
        let radio = self.radio();
        let unheard = radio.unheard();
        let mut models: Vec<BTreeMap<u32, Gaussian>> = vec![BTreeMap::new(); self.states.len()];
        for (state, tx, g) in radio.fingerprints() {
            models[state as usize].insert(tx, g);
        }
        let mut states = self.states.clone();
        let mut triples: Vec<(u32, u32, Gaussian)> = radio.fingerprints().collect();
        let mut edges = Vec::with_capacity(self.edges.len());
        let mut next_id = self.states.iter().map(|s| s.id).max().map_or(0, |m| m + 1);
        let mut zones = self.zones.clone();
        for e in &self.edges {
            let (a, b) = (&self.states[e.a as usize], &self.states[e.b as usize]);
            let splittable = a.floor == b.floor
                && a.kind == StateKind::Surveyed
                && b.kind == StateKind::Surveyed
                && max_spacing_m > 0.0
                && e.length_m > max_spacing_m;
            if !splittable {
                edges.push(*e);
                continue;
            }
            let pieces = (e.length_m / max_spacing_m).ceil() as usize;
            let piece = e.length_m / pieces as f64;
            let mut previous = e.a;
            for k in 1..pieces {
                let s = k as f64 / pieces as f64;
                let index = states.len() as u32;
                states.push(State {
                    id: next_id,
                    floor: a.floor,
                    position: a.position + (b.position - a.position) * s,
                    kind: StateKind::Pseudo,
                    training_scans: 0,
                });
                next_id += 1;
                let nearer = if s <= 0.5 { e.a } else { e.b };
                if let Some(z) = self.zone_of(nearer as usize) {
                    zones[z].states.push(index);
                }
                let (ma, mb) = (&models[e.a as usize], &models[e.b as usize]);
                for tx in ma.keys().chain(mb.keys().filter(|t| !ma.contains_key(t))) {
                    let ga = ma.get(tx).unwrap_or(&unheard);
                    let gb = mb.get(tx).unwrap_or(&unheard);
                    triples.push((index, *tx, interpolate(ga, gb, s)));
                }
                edges.push(Edge { a: previous, b: index, length_m: piece });
                previous = index;
            }
            edges.push(Edge { a: previous, b: e.b, length_m: piece });
        }
        let map = RadioMap::new(
            radio.model(),
            radio.clip_dbm(),
            unheard,
            radio.transmitters().to_vec(),
            states.len(),
            triples,
        )
        .and_then(|map| map.with_shared_radios(radio.shared_radios().to_vec()))
        .expect("pseudo states add valid, distinct (state, transmitter) pairs to a valid map");
        let mut site =
            Site::from_parts(self.name.clone(), self.floors.clone(), states, edges, map, self.north);
        site.calibration = self.calibration;
        site.id_hashing = self.id_hashing.clone();
        site.anchor = self.anchor;
        site.max_reading_age_ns = self.max_reading_age_ns;
        // Pseudo states come after the surveyed ones: each zone's list stays ascending.
        site.with_zones(zones).expect("pseudo states are new states, each added to at most one zone")
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::site::{BuildOptions, SiteBuilder};
    use approx::assert_relative_eq;
    use nalgebra::Point2;

    #[test]
    fn eqs_12_13_by_hand() {
        let a = Gaussian::new(-60.0, 2.0).unwrap();
        let b = Gaussian::new(-80.0, 4.0).unwrap();
        // Ends are exact.
        assert_relative_eq!(interpolate(&a, &b, 0.0).mean_dbm, -60.0);
        assert_relative_eq!(interpolate(&a, &b, 1.0).std_db, 4.0);
        // Halfway, L = 1: μ = (16·0.5·(-60) + 4·0.5·(-80)) / (4·0.5 + 16·0.5) = -64,
        // σ² = 16·4 / 10 = 6.4.
        let mid = interpolate(&a, &b, 0.5);
        assert_relative_eq!(mid.mean_dbm, -64.0, epsilon = 1e-12);
        assert_relative_eq!(mid.std_db * mid.std_db, 6.4, epsilon = 1e-12);
    }

    #[test]
    fn edges_are_split_to_the_spacing() {
        let mut b = SiteBuilder::new("line");
        let f = b.floor("G", 0.0);
        let s0 = b.state(f, Point2::new(0.0, 0.0), vec![]);
        let s1 = b.state(f, Point2::new(3.0, 0.0), vec![]);
        b.edge(s0, s1, None);
        let site = b.build(BuildOptions::default()).unwrap().with_pseudo_states(PSEUDO_SPACING_M);
        assert_eq!(site.states().len(), 5);
        assert_eq!(site.edges().len(), 4);
        assert!(site.edges().iter().all(|e| (e.length_m - 0.75).abs() < 1e-12));
        assert_eq!(site.states()[2].kind, StateKind::Pseudo);
        assert_relative_eq!(site.states()[3].position.x, 1.5);
        // The file format keeps them.
        let again = Site::from_json(site.to_json().as_bytes()).unwrap();
        assert_eq!(again.states(), site.states());
    }

    #[test]
    fn pseudo_states_join_the_zone_of_the_nearer_end() {
        use crate::site::{Zone, ZoneKind};
        let mut b = SiteBuilder::new("room and corridor");
        let f = b.floor("G", 0.0);
        let s: Vec<u32> = (0..3).map(|k| b.state(f, Point2::new(3.0 * k as f64, 0.0), vec![])).collect();
        b.edge(s[0], s[1], None);
        b.edge(s[1], s[2], None);
        let zones = vec![
            Zone { name: "room".into(), kind: ZoneKind::Room, states: vec![0] },
            Zone { name: "corridor".into(), kind: ZoneKind::Corridor, states: vec![1] },
        ];
        let site = b.build(BuildOptions::default()).unwrap().with_zones(zones).unwrap();
        let pseudo = site.with_pseudo_states(PSEUDO_SPACING_M);
        // Edge 0-1 gets pseudo states at 0.75, 1.5 and 2.25 m; 1-2 at 3.75, 4.5 and 5.25 m.
        let zone_at = |x: f64| {
            let i = pseudo.states().iter().position(|st| (st.position.x - x).abs() < 1e-9).unwrap();
            pseudo.zone_of(i)
        };
        assert_eq!([zone_at(0.75), zone_at(1.5), zone_at(2.25)], [Some(0), Some(0), Some(1)]);
        assert_eq!(
            [zone_at(3.75), zone_at(4.5), zone_at(5.25), zone_at(6.0)],
            [Some(1), Some(1), None, None]
        );
        let again = Site::from_json(pseudo.to_json().as_bytes()).unwrap();
        assert_eq!(again.zones(), pseudo.zones());
    }
}
