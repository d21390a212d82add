//! Shortest paths on the site's adjacency list: A* (Hart, Nilsson & Raphael 1968) towards one
//! goal state with the straight line on the plan as its heuristic, Dijkstra (A* with a zero
//! heuristic) towards the nearest of several. The graph is already a compressed adjacency list
//! ([`Site::neighbours`]), so a few lines here replace a graph crate in what phones link.

use super::edge_cost;
use crate::site::Site;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// A frontier entry: (estimated total, state), smallest first.
#[derive(PartialEq)]
struct Open(f64, u32);
impl Eq for Open {}
impl Ord for Open {
    fn cmp(&self, other: &Self) -> Ordering {
        other.0.total_cmp(&self.0).then(other.1.cmp(&self.1))
    }
}
impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

/// The states of a shortest path from `start` to the first state `is_goal` accepts, both
/// included, or `None` when none is reachable. `goal`, when the goal is one state, guides the
/// search: the heuristic is the straight line to it on the plan, which never exceeds the walk
/// since no edge costs less than its straight line ([`edge_cost`]), so the path stays optimal.
pub(super) fn shortest_path(
    site: &Site,
    start: u32,
    is_goal: impl Fn(u32) -> bool,
    goal: Option<u32>,
) -> Option<Vec<u32>> {
    let states = site.states();
    let heuristic = |s: u32| {
        goal.map_or(0.0, |g| nalgebra::distance(&states[s as usize].position, &states[g as usize].position))
    };
    let n = states.len();
    let mut cost = vec![f64::INFINITY; n];
    let mut previous = vec![u32::MAX; n];
    let mut closed = vec![false; n];
    let mut open = BinaryHeap::new();
    cost[start as usize] = 0.0;
    open.push(Open(heuristic(start), start));
    while let Some(Open(_, u)) = open.pop() {
        if closed[u as usize] {
            continue;
        }
        closed[u as usize] = true;
        if is_goal(u) {
            let mut path = vec![u];
            let mut at = u;
            while at != start {
                at = previous[at as usize];
                path.push(at);
            }
            path.reverse();
            return Some(path);
        }
        for (v, length) in site.neighbours(u as usize) {
            let next = cost[u as usize] + edge_cost(site, u, v, length);
            if next < cost[v as usize] {
                cost[v as usize] = next;
                previous[v as usize] = u;
                open.push(Open(next + heuristic(v), v));
            }
        }
    }
    None
}
