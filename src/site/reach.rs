//! Walking distances between states within a radius: the look-up table of HIPE §4.2.1
//! ("shortest accessible distance ... stored as a look-up table"), by bounded Dijkstra on the
//! walkable graph, so nobody walks through a wall.

use super::{Site, StateKind};
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// For each state, the states within `radius_m` walking distance, and its graph neighbours at
/// any distance.
///
/// Entries of state `i` are ordered so that every prefix is a reachable set: first the state
/// itself and its direct neighbours (always reachable: the walker may stand on the boundary
/// between two cells, however far apart their centres are), then the others by increasing
/// walking distance.
#[derive(Clone, Debug)]
pub struct ReachTable {
    radius_m: f64,
    starts: Vec<usize>,
    /// Index where the distance-sorted part of state `i` begins.
    sorted_from: Vec<usize>,
    entries: Vec<(u32, f32)>,
}

#[derive(PartialEq)]
struct Frontier(f64, u32);
impl Eq for Frontier {}
impl Ord for Frontier {
    fn cmp(&self, other: &Self) -> Ordering {
        other.0.total_cmp(&self.0).then(other.1.cmp(&self.1))
    }
}
impl PartialOrd for Frontier {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl ReachTable {
    /// Runs a Dijkstra bounded at `radius_m` from every state.
    pub fn build(site: &Site, radius_m: f64) -> Self {
        Self::build_over(site, radius_m, false)
    }

    /// The table of the surveyed map alone, when the site has
    /// [`StateKind::Unsurveyed`] states (`None` without): paths and targets keep to the other
    /// states, and an unsurveyed state reaches only itself. The engine predicts with it while
    /// the radio explains what it hears, so that the states at the map's edge do not leak mass
    /// into space the radio has ruled out (docs/tuning.md#unsurveyed-states).
    pub fn build_surveyed(site: &Site, radius_m: f64) -> Option<Self> {
        site.states()
            .iter()
            .any(|s| s.kind == StateKind::Unsurveyed)
            .then(|| Self::build_over(site, radius_m, true))
    }

    fn build_over(site: &Site, radius_m: f64, surveyed_only: bool) -> Self {
        let n = site.states().len();
        let mut starts = Vec::with_capacity(n + 1);
        let mut sorted_from = Vec::with_capacity(n);
        let mut entries = Vec::new();
        let mut dist = vec![f64::INFINITY; n];
        let mut touched: Vec<u32> = Vec::new();
        let mut heap = BinaryHeap::new();
        let unsurveyed: Vec<bool> = site.states().iter().map(|s| s.kind == StateKind::Unsurveyed).collect();
        let none: &[(u32, f64)] = &[];
        for source in 0..n {
            starts.push(entries.len());
            let neighbours = |u: usize| {
                if surveyed_only && unsurveyed[u] {
                    none
                } else {
                    site.neighbours(u)
                }
            };
            // Between surveyed states the walking distance stays on the surveyed graph:
            // nobody walked the unsurveyed space, so it shortens no known route. (The surveyed
            // map's table never enters it at all: `skip`.)
            let blocked =
                |u: u32, v: u32| !unsurveyed[source] && unsurveyed[u as usize] && !unsurveyed[v as usize];
            let skip = |v: u32| surveyed_only && unsurveyed[v as usize];
            dist[source] = 0.0;
            touched.push(source as u32);
            heap.push(Frontier(0.0, source as u32));
            while let Some(Frontier(d, u)) = heap.pop() {
                if d > dist[u as usize] {
                    continue;
                }
                for &(v, length) in neighbours(u as usize) {
                    if skip(v) || blocked(u, v) {
                        continue;
                    }
                    let next = d + length;
                    if next <= radius_m && next < dist[v as usize] {
                        if dist[v as usize].is_infinite() {
                            touched.push(v);
                        }
                        dist[v as usize] = next;
                        heap.push(Frontier(next, v));
                    }
                }
            }
            let near = neighbours(source);
            let is_near = |j: u32| j as usize == source || near.iter().any(|&(v, _)| v == j);
            // Self and neighbours first (a neighbour beyond the radius gets its edge length).
            entries.push((source as u32, 0.0));
            for &(v, length) in near.iter().filter(|&&(v, _)| !skip(v)) {
                if !entries[starts[source]..].iter().any(|&(j, _)| j == v) {
                    let d = dist[v as usize].min(length);
                    entries.push((v, d as f32));
                }
            }
            sorted_from.push(entries.len());
            let from = entries.len();
            entries.extend(touched.iter().filter(|&&j| !is_near(j)).map(|&j| (j, dist[j as usize] as f32)));
            entries[from..].sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
            for &j in &touched {
                dist[j as usize] = f64::INFINITY;
            }
            touched.clear();
        }
        starts.push(entries.len());
        Self { radius_m, starts, sorted_from, entries }
    }

    /// The radius the table was built for, m.
    pub fn radius_m(&self) -> f64 {
        self.radius_m
    }

    /// States reachable from `i` within `rho_m` (at most the table radius), with their walking
    /// distance: the state itself, its neighbours, and every state within `rho_m`.
    pub fn reachable(&self, i: usize, rho_m: f64) -> &[(u32, f32)] {
        let sorted = &self.entries[self.sorted_from[i]..self.starts[i + 1]];
        let within = sorted.partition_point(|&(_, d)| f64::from(d) <= rho_m);
        &self.entries[self.starts[i]..self.sorted_from[i] + within]
    }

    /// How many of the first entries of state `i`'s [`reachable`](Self::reachable) slice are the
    /// state itself and its direct neighbours.
    pub fn near_count(&self, i: usize) -> usize {
        self.sorted_from[i] - self.starts[i]
    }

    /// Number of states the table covers.
    pub fn state_count(&self) -> usize {
        self.sorted_from.len()
    }

    /// Entries stored, for memory accounting.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether the table is empty (a site always has states, so never in practice).
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::site::{SiteBuilder, TrainingScan};
    use nalgebra::Point2;

    /// A corridor 0-1-2-3 with 2 m spacing, and a state 4 one metre from state 0 through a
    /// wall: only reachable around it via state 3 (6 m + 1 m).
    fn corridor() -> Site {
        let mut b = SiteBuilder::new("corridor");
        let f = b.floor("G", 0.0);
        let points = [(0.0, 0.0), (2.0, 0.0), (4.0, 0.0), (6.0, 0.0), (0.0, 1.0)];
        let ids: Vec<u32> =
            points.iter().map(|&(x, y)| b.state(f, Point2::new(x, y), Vec::<TrainingScan>::new())).collect();
        for w in ids[..4].windows(2) {
            b.edge(w[0], w[1], None);
        }
        b.edge(ids[3], ids[4], Some(7.0));
        b.build(Default::default()).unwrap()
    }

    #[test]
    fn distances_follow_the_graph() {
        let site = corridor();
        let table = ReachTable::build(&site, 5.0);
        let from0: Vec<(u32, f32)> = table.reachable(0, 5.0).to_vec();
        assert_eq!(from0, vec![(0, 0.0), (1, 2.0), (2, 4.0)]);
        assert_eq!(table.reachable(0, 3.0).len(), 2);
        // State 4 is 1 m away in a straight line but 13 m on foot: not within 5 m.
        assert!(!from0.iter().any(|&(j, _)| j == 4));
        // A neighbour beyond the radius is still reachable (its edge is 7 m).
        assert_eq!(table.reachable(3, 1.0), &[(3, 0.0), (2, 2.0), (4, 7.0)]);
        assert!(ReachTable::build_surveyed(&site, 5.0).is_none(), "no unsurveyed states");
    }

    /// Surveyed states 0-1-2-3 around three sides of a square (4 m sides), unsurveyed 4 and 5
    /// across its open side: walking between surveyed states never cuts through unsurveyed
    /// space, walking from it may; the surveyed map's table leaves it out.
    #[test]
    fn unsurveyed_space_shortens_no_surveyed_route() {
        let mut b = SiteBuilder::new("square");
        let f = b.floor("G", 0.0);
        let ids: Vec<u32> = [(0.0, 0.0), (0.0, 4.0), (4.0, 4.0), (4.0, 0.0)]
            .iter()
            .map(|&(x, y)| b.state(f, Point2::new(x, y), Vec::<TrainingScan>::new()))
            .collect();
        let u = [b.unsurveyed_state(f, Point2::new(1.5, 0.0)), b.unsurveyed_state(f, Point2::new(2.5, 0.0))];
        for w in ids.windows(2) {
            b.edge(w[0], w[1], None);
        }
        b.edge(ids[0], u[0], None);
        b.edge(u[0], u[1], None);
        b.edge(u[1], ids[3], None);
        let site = b.build(Default::default()).unwrap();
        let whole = ReachTable::build(&site, 20.0);
        let at = |table: &ReachTable, i: u32, j: u32| {
            table.reachable(i as usize, 20.0).iter().find(|e| e.0 == j).map(|e| e.1)
        };
        // 0 → 3: around the square (12 m), not across it (4 m).
        assert_eq!(at(&whole, 0, 3), Some(12.0));
        assert_eq!(at(&whole, 0, u[1]), Some(2.5));
        // From unsurveyed space, any way back.
        assert_eq!(at(&whole, u[0], 3), Some(2.5));
        let map = ReachTable::build_surveyed(&site, 20.0).unwrap();
        assert_eq!(at(&map, 0, 3), Some(12.0));
        assert!(map.reachable(0, 20.0).iter().all(|e| !u.contains(&e.0)));
        assert_eq!(map.reachable(u[0] as usize, 20.0), &[(u[0], 0.0)]);
        // The site hands out the same tables to every engine.
        let (a, a_map) = site.reach_tables(20.0);
        let (b, _) = site.reach_tables(20.0);
        assert!(std::sync::Arc::ptr_eq(&a, &b));
        assert_eq!(a_map.map(|m| m.len()), Some(map.len()));
    }
}
