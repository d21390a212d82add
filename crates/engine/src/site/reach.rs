//! Walking distances between states within a radius: the look-up table of HIPE §4.2.1
//! ("shortest accessible distance ... stored as a look-up table"), by bounded Dijkstra on the
//! walkable graph, so nobody walks through a wall.

use super::budget::{self, ReachBudget, MAX_REACHABLE_STATES};
use super::{Neighbours, Site, SiteError, StateKind};
use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};

/// For each state, the states within `radius_m` walking distance, and its graph neighbours at
/// any distance.
///
/// Entries of state `i` are ordered so that every prefix is a reachable set: first the state
/// itself and its direct neighbours (always reachable: the walker may stand on the boundary
/// between two cells, however far apart their centres are), then the others by increasing
/// walking distance.
///
/// An entry takes 3 bytes where the site allows, against 8 for a `(u32, f32)`: the state in
/// 16 bits on a site of at most 65 536 states, and the distance as an index into the table's
/// distinct distances when it has at most 256 of them (a grid's few edge lengths make few
/// sums within the radius); both exact (docs/tuning.md#engine-speed).
#[derive(Clone, Debug, PartialEq)]
pub struct ReachTable {
    radius_m: f64,
    /// Index where state `i`'s entries begin (32 bits: see [`entry_index`]).
    starts: Vec<u32>,
    /// Index where the distance-sorted part of state `i` begins.
    sorted_from: Vec<u32>,
    targets: Targets,
    distances: Distances,
}

/// The entries' states.
#[derive(Clone, Debug, PartialEq)]
enum Targets {
    /// On a site of at most 65 536 states.
    Narrow(Vec<u16>),
    Wide(Vec<u32>),
}

/// The entries' walking distances, m.
#[derive(Clone, Debug, PartialEq)]
enum Distances {
    /// Indices into `values`, the distinct distances in increasing order, so that the codes of
    /// a distance-sorted run increase too.
    Coded {
        codes: Vec<u8>,
        values: Vec<f32>,
    },
    Plain(Vec<f32>),
}

impl Targets {
    fn push(&mut self, j: u32) {
        match self {
            Targets::Narrow(v) => v.push(j as u16),
            Targets::Wide(v) => v.push(j),
        }
    }

    #[inline]
    fn get(&self, k: usize) -> u32 {
        match self {
            Targets::Narrow(v) => u32::from(v[k]),
            Targets::Wide(v) => v[k],
        }
    }

    fn len(&self) -> usize {
        match self {
            Targets::Narrow(v) => v.len(),
            Targets::Wide(v) => v.len(),
        }
    }
}

impl Distances {
    /// Appends a distance, coding it while the table has at most 256 distinct ones.
    fn push(&mut self, d: f32, code_of: &mut Vec<(u32, u8)>) {
        if let Distances::Coded { codes, values } = self {
            let code = match code_of.binary_search_by_key(&d.to_bits(), |c| c.0) {
                Ok(at) => Some(code_of[at].1),
                Err(at) if values.len() < 256 => {
                    code_of.insert(at, (d.to_bits(), values.len() as u8));
                    values.push(d);
                    Some((values.len() - 1) as u8)
                }
                Err(_) => None,
            };
            match code {
                Some(code) => return codes.push(code),
                None => *self = Distances::Plain(codes.iter().map(|&c| values[usize::from(c)]).collect()),
            }
        }
        if let Distances::Plain(v) = self {
            v.push(d);
        }
    }

    /// Renumbers the codes so that they follow the distances' order.
    fn finish(&mut self) {
        if let Distances::Coded { codes, values } = self {
            let mut order: Vec<u8> = (0..values.len() as u8).collect();
            order.sort_by(|&a, &b| values[usize::from(a)].total_cmp(&values[usize::from(b)]));
            let mut rank = [0u8; 256];
            for (r, &c) in order.iter().enumerate() {
                rank[usize::from(c)] = r as u8;
            }
            codes.iter_mut().for_each(|c| *c = rank[usize::from(*c)]);
            *values = order.iter().map(|&c| values[usize::from(c)]).collect();
        }
    }

    #[inline]
    fn get(&self, k: usize) -> f32 {
        match self {
            Distances::Coded { codes, values } => values[usize::from(codes[k])],
            Distances::Plain(v) => v[k],
        }
    }

    /// How many of the distinct coded distances are within `rho_m` (0 for plain distances).
    fn codes_within(&self, rho_m: f64) -> usize {
        match self {
            Distances::Coded { values, .. } => values.partition_point(|&d| f64::from(d) <= rho_m),
            Distances::Plain(_) => 0,
        }
    }

    /// How many of the distance-sorted entries `from..to` are within `cut`.
    fn within(&self, from: usize, to: usize, cut: ReachCut) -> usize {
        match self {
            Distances::Coded { codes, .. } => {
                codes[from..to].partition_point(|&c| usize::from(c) < cut.codes_within)
            }
            Distances::Plain(v) => v[from..to].partition_point(|&d| f64::from(d) <= cut.rho_m),
        }
    }
}

/// A reach looked up once in one table's distances ([`ReachTable::cut`]), for the rows of an
/// epoch: each row is then cut with one search instead of two (docs/tuning.md#engine-speed).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReachCut {
    rho_m: f64,
    /// How many of the table's distinct coded distances are within `rho_m`.
    codes_within: usize,
}

impl ReachCut {
    /// The reach, m.
    pub fn rho_m(&self) -> f64 {
        self.rho_m
    }
}

/// The states reachable from one state with their walking distances, m
/// ([`ReachTable::reachable`]).
#[derive(Clone, Copy, Debug)]
pub struct Reach<'a> {
    table: &'a ReachTable,
    from: usize,
    to: usize,
}

impl<'a> Reach<'a> {
    /// Number of states.
    pub fn len(&self) -> usize {
        self.to - self.from
    }

    /// Whether there are none (never: a state reaches itself).
    pub fn is_empty(&self) -> bool {
        self.to == self.from
    }

    /// The `k`-th (state, walking distance).
    #[inline]
    pub fn get(&self, k: usize) -> (u32, f32) {
        let at = self.from + k;
        debug_assert!(at < self.to);
        (self.table.targets.get(at), self.table.distances.get(at))
    }

    /// (state, walking distance), in the table's order.
    #[inline]
    pub fn iter(&self) -> impl ExactSizeIterator<Item = (u32, f32)> + 'a {
        let table = self.table;
        (self.from..self.to).map(move |at| (table.targets.get(at), table.distances.get(at)))
    }
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

/// An entry's index in 32 bits: a table of 2³² entries would hold 8 GB of states alone, more
/// than any device this runs on allocates, so the index always fits (saturating otherwise).
fn entry_index(index: usize) -> u32 {
    u32::try_from(index).unwrap_or(u32::MAX)
}

/// A table built without a budget: only the budget refuses.
fn unlimited(table: Result<ReachTable, SiteError>) -> ReachTable {
    table.unwrap_or_else(|e| unreachable!("a table built without a budget was refused: {e}"))
}

impl ReachTable {
    /// Runs a Dijkstra bounded at `radius_m` from every state, with no limit on the table's
    /// size: for tools and tests on sites they built. An engine's tables come from
    /// [`Site::reach_tables`], within the site budget ([`budget`]).
    pub fn build(site: &Site, radius_m: f64) -> Self {
        unlimited(Self::build_over(site, radius_m, false, None, None))
    }

    /// The table of the surveyed map alone, when the site has
    /// [`StateKind::Unsurveyed`] states (`None` without): paths and targets keep to the other
    /// states, and an unsurveyed state reaches only itself. The engine predicts with it while
    /// the radio explains what it hears, so that the states at the map's edge do not leak mass
    /// into space the radio has ruled out (docs/tuning.md#unsurveyed-states). No limit, as
    /// [`build`](Self::build).
    pub fn build_surveyed(site: &Site, radius_m: f64) -> Option<Self> {
        has_unsurveyed(site).then(|| unlimited(Self::build_over(site, radius_m, true, None, None)))
    }

    /// [`build`](Self::build) and [`build_surveyed`](Self::build_surveyed) of `site` within
    /// one [`ReachBudget`] for the two: refused, before the budget is passed, when the site
    /// is over a limit of [`budget`]. With a `base` (a site over the same grid and its tables),
    /// each row it can is taken from the base's table at the same radius instead of running
    /// its Dijkstra: the same tables, entry for entry ([`Reuse`]).
    pub(super) fn build_both(
        site: &Site,
        radius_m: f64,
        base: Option<(&Site, &super::ReachTables)>,
    ) -> Result<(Self, Option<Self>), SiteError> {
        let matched = base.map(|(base_site, tables)| (Match::new(site, base_site), tables));
        let reuse = |surveyed: bool| {
            let (matched, tables) = matched.as_ref()?;
            let table = if surveyed { tables.1.as_deref() } else { Some(&*tables.0) };
            let base = table.filter(|t| t.radius_m == radius_m)?;
            Some(Reuse { base, matched })
        };
        let budget = &mut ReachBudget::new();
        let whole = Self::build_over(site, radius_m, false, reuse(false), Some(budget))?;
        let surveyed = match has_unsurveyed(site) {
            true => Some(Self::build_over(site, radius_m, true, reuse(true), Some(budget))?),
            false => None,
        };
        Ok((whole, surveyed))
    }

    /// The table; with a budget, refused as soon as a state reaches more than
    /// [`MAX_REACHABLE_STATES`] or the entries or the edges walked would pass what is left of
    /// it: the table never grows past the budget, and a site over it costs little time.
    fn build_over(
        site: &Site,
        radius_m: f64,
        surveyed_only: bool,
        reuse: Option<Reuse>,
        mut budget: Option<&mut ReachBudget>,
    ) -> Result<Self, SiteError> {
        let n = site.states().len();
        let mut starts = Vec::with_capacity(n + 1);
        let mut sorted_from = Vec::with_capacity(n);
        let mut targets = if n <= 1 << 16 { Targets::Narrow(Vec::new()) } else { Targets::Wide(Vec::new()) };
        let mut distances = Distances::Coded { codes: Vec::new(), values: Vec::new() };
        let mut code_of = Vec::new();
        // One state's entries before they are written into the table.
        let mut entries: Vec<(u32, f32)> = Vec::new();
        let mut dist = vec![f64::INFINITY; n];
        let mut touched: Vec<u32> = Vec::new();
        let mut heap = BinaryHeap::new();
        let unsurveyed: Vec<bool> = site.states().iter().map(|s| s.kind == StateKind::Unsurveyed).collect();
        // Whether a state is the source or one of its neighbours, for the row being built: a
        // look-up, where searching the neighbours for every state reached made a row cost its
        // length times the source's edges.
        let mut near_mark = vec![false; n];
        let too_many = |source: usize| {
            budget::over(
                "MAX_REACHABLE_STATES",
                MAX_REACHABLE_STATES as u64,
                format!(
                    "states[{source}] (id {}) reaches more states within {radius_m} m",
                    site.states()[source].id
                ),
            )
        };
        for source in 0..n {
            starts.push(entry_index(targets.len()));
            if let Some(row) = reuse.as_ref().and_then(|r| r.row(source)) {
                if let Some(budget) = budget.as_deref_mut() {
                    budget.take_entries(row.len, radius_m)?;
                }
                sorted_from.push(starts[source] + entry_index(row.near));
                for (j, d) in row.entries {
                    targets.push(j);
                    distances.push(d, &mut code_of);
                }
                continue;
            }
            entries.clear();
            let neighbours = |u: usize| {
                if surveyed_only && unsurveyed[u] {
                    Neighbours::default()
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
                let edges = neighbours(u as usize);
                if let Some(budget) = budget.as_deref_mut() {
                    budget.take_edge_visits(edges.len() as u64, radius_m)?;
                }
                for (v, length) in edges {
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
                if budget.is_some() && touched.len() > MAX_REACHABLE_STATES {
                    return Err(too_many(source));
                }
            }
            let near = neighbours(source);
            // Self and neighbours first (a neighbour beyond the radius gets its edge length).
            entries.push((source as u32, 0.0));
            near_mark[source] = true;
            for (v, length) in near.clone().filter(|&(v, _)| !skip(v)) {
                if !near_mark[v as usize] {
                    near_mark[v as usize] = true;
                    let d = dist[v as usize].min(length);
                    entries.push((v, d as f32));
                }
            }
            sorted_from.push(starts[source] + entry_index(entries.len()));
            let from = entries.len();
            entries.extend(
                touched.iter().filter(|&&j| !near_mark[j as usize]).map(|&j| (j, dist[j as usize] as f32)),
            );
            entries[from..].sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
            if let Some(budget) = budget.as_deref_mut() {
                budget.take_entries(entries.len(), radius_m)?;
            }
            for &j in &touched {
                dist[j as usize] = f64::INFINITY;
            }
            touched.clear();
            for &(j, _) in &entries[..from] {
                near_mark[j as usize] = false;
            }
            for &(j, d) in &entries {
                targets.push(j);
                distances.push(d, &mut code_of);
            }
        }
        starts.push(entry_index(targets.len()));
        distances.finish();
        match &mut targets {
            Targets::Narrow(t) => t.shrink_to_fit(),
            Targets::Wide(t) => t.shrink_to_fit(),
        }
        match &mut distances {
            Distances::Coded { codes, .. } => codes.shrink_to_fit(),
            Distances::Plain(d) => d.shrink_to_fit(),
        }
        Ok(Self { radius_m, starts, sorted_from, targets, distances })
    }

    /// The radius the table was built for, m.
    pub fn radius_m(&self) -> f64 {
        self.radius_m
    }

    /// States reachable from `i` within `rho_m` (at most the table radius), with their walking
    /// distance: the state itself, its neighbours, and every state within `rho_m`.
    pub fn reachable(&self, i: usize, rho_m: f64) -> Reach<'_> {
        self.reachable_within(i, self.cut(rho_m))
    }

    /// `rho_m` looked up in this table, for [`reachable_within`](Self::reachable_within).
    pub fn cut(&self, rho_m: f64) -> ReachCut {
        ReachCut { rho_m, codes_within: self.distances.codes_within(rho_m) }
    }

    /// [`reachable`](Self::reachable) within a cut of this table (of another table, the
    /// states listed are not those within its reach).
    pub fn reachable_within(&self, i: usize, cut: ReachCut) -> Reach<'_> {
        let (from, sorted_from, to) =
            (self.starts[i] as usize, self.sorted_from[i] as usize, self.starts[i + 1] as usize);
        let within = self.distances.within(sorted_from, to, cut);
        Reach { table: self, from, to: sorted_from + within }
    }

    /// How many of the first entries of state `i`'s [`reachable`](Self::reachable) slice are the
    /// state itself and its direct neighbours.
    pub fn near_count(&self, i: usize) -> usize {
        (self.sorted_from[i] - self.starts[i]) as usize
    }

    /// Number of states the table covers.
    pub fn state_count(&self) -> usize {
        self.sorted_from.len()
    }

    /// Entries stored, for memory accounting.
    pub fn len(&self) -> usize {
        self.targets.len()
    }

    /// Whether the table is empty (a site always has states, so never in practice).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

fn has_unsurveyed(site: &Site) -> bool {
    site.states().iter().any(|s| s.kind == StateKind::Unsurveyed)
}

/// How the states of a site correspond to those of a base site over the same grid (a site
/// the survey built without some of its walks, and the site of them all), for
/// [`ReachTable::build_both_reusing`].
struct Match {
    /// Per base state: its state in the site (`u32::MAX`: none).
    from_base: Vec<u32>,
    /// Per base state: whether the site has it with the same kind and the same edges, in the
    /// same order, to the same states, each of the same kind; all false when the site does
    /// not number these states in the base's order.
    unchanged: Vec<bool>,
    /// Per state of the site: its base state (`u32::MAX`: none).
    to_base: Vec<u32>,
}

impl Match {
    fn new(site: &Site, base: &Site) -> Self {
        let key = |s: &super::State| (s.floor, s.position.x.to_bits(), s.position.y.to_bits());
        let index: HashMap<_, u32> =
            base.states().iter().enumerate().map(|(i, s)| (key(s), i as u32)).collect();
        let to_base: Vec<u32> =
            site.states().iter().map(|s| index.get(&key(s)).copied().unwrap_or(u32::MAX)).collect();
        let mut from_base = vec![u32::MAX; base.states().len()];
        let mut unchanged = vec![false; base.states().len()];
        for (i, &b) in to_base.iter().enumerate() {
            if b == u32::MAX {
                continue;
            }
            from_base[b as usize] = i as u32;
            let mine = site.neighbours(i).map(|(j, length)| (to_base[j as usize], length.to_bits()));
            let theirs = base.neighbours(b as usize).map(|(j, length)| (j, length.to_bits()));
            unchanged[b as usize] =
                site.states()[i].kind == base.states()[b as usize].kind && mine.eq(theirs);
        }
        // Whether a step may be taken depends on the kinds at both ends (`build_over`'s
        // `blocked` and `skip`): a state beside one that changed kind is changed too.
        let kept = unchanged.clone();
        for (b, same) in unchanged.iter_mut().enumerate() {
            *same = *same
                && base.neighbours(b).all(|(j, _)| {
                    kept[j as usize]
                        || from_base[j as usize] != u32::MAX
                            && site.states()[from_base[j as usize] as usize].kind
                                == base.states()[j as usize].kind
                });
        }
        // The rows taken keep the base's order only if the site numbers the unchanged states
        // in the base's order: otherwise take none.
        let mut order = to_base.iter().filter(|&&b| b != u32::MAX && unchanged[b as usize]);
        let mut last = None;
        if !order.all(|&b| last.replace(b) < Some(b)) {
            unchanged.fill(false);
        }
        Match { from_base, unchanged, to_base }
    }
}

/// A base table to take rows from. A state's row is the base row of its base state when that
/// state and every state in its row are unchanged ([`Match`]): a path within the radius then
/// runs through unchanged states only, each with the same edges, so the Dijkstra finds the
/// same states at the same distances, and the site orders the unchanged states of a row as the
/// base does (the survey numbers states floor by floor, surveyed then unsurveyed, each in cell
/// order), so the entries come in the same order.
struct Reuse<'a> {
    base: &'a ReachTable,
    matched: &'a Match,
}

/// A row taken from the base table: its entries in the site's states, how many there are, and
/// how many of them come before the distance-sorted part.
struct Row<I> {
    entries: I,
    len: usize,
    near: usize,
}

impl Reuse<'_> {
    fn row(&self, source: usize) -> Option<Row<impl Iterator<Item = (u32, f32)> + '_>> {
        let m = self.matched;
        let b = *m.to_base.get(source)?;
        if b == u32::MAX {
            return None;
        }
        let reach = self.base.reachable(b as usize, self.base.radius_m);
        if !reach.iter().all(|(j, _)| m.unchanged[j as usize]) {
            return None;
        }
        let near = self.base.near_count(b as usize);
        Some(Row { entries: reach.iter().map(|(j, d)| (m.from_base[j as usize], d)), len: reach.len(), near })
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
        assert!(matches!(table.distances, Distances::Coded { .. }));
        let from0: Vec<(u32, f32)> = table.reachable(0, 5.0).iter().collect();
        assert_eq!(from0, vec![(0, 0.0), (1, 2.0), (2, 4.0)]);
        assert_eq!(table.reachable(0, 3.0).len(), 2);
        // State 4 is 1 m away in a straight line but 13 m on foot: not within 5 m.
        assert!(!from0.iter().any(|&(j, _)| j == 4));
        // A neighbour beyond the radius is still reachable (its edge is 7 m).
        assert_eq!(table.reachable(3, 1.0).iter().collect::<Vec<_>>(), [(3, 0.0), (2, 2.0), (4, 7.0)]);
        assert!(ReachTable::build_surveyed(&site, 5.0).is_none(), "no unsurveyed states");
    }

    /// A 14 x 10 grid of 1 m cells, 8-connected but through a wall between x = 4 and 5 for
    /// y < 8: `kind` says which cells are surveyed (`Some(true)`), unsurveyed or absent. States
    /// come floor by floor, surveyed then unsurveyed, each in cell order, as the survey numbers
    /// them; edges in cell order.
    fn grid_site(kind: impl Fn(i32, i32) -> Option<bool>) -> Site {
        let mut b = SiteBuilder::new("grid");
        let f = b.floor("G", 0.0);
        let cells: Vec<(i32, i32)> = (0..10).flat_map(|y| (0..14).map(move |x| (x, y))).collect();
        let mut id = std::collections::BTreeMap::new();
        for surveyed in [true, false] {
            for &(x, y) in cells.iter().filter(|&&(x, y)| kind(x, y) == Some(surveyed)) {
                let at = Point2::new(f64::from(x), f64::from(y));
                let state = if surveyed { b.fitted_state(f, at, 1) } else { b.unsurveyed_state(f, at) };
                id.insert((x, y), state);
            }
        }
        for &(x, y) in &cells {
            for (dx, dy) in [(1, 0), (-1, 1), (0, 1), (1, 1)] {
                let wall = y < 8 && (x.min(x + dx), x.max(x + dx)) == (4, 5);
                if let (Some(&a), Some(&c), false) = (id.get(&(x, y)), id.get(&(x + dx, y + dy)), wall) {
                    b.edge(a, c, None);
                }
            }
        }
        b.build(Default::default()).unwrap()
    }

    #[test]
    fn tables_built_from_a_base_sites_rows_are_those_built_from_scratch() {
        // Unsurveyed beyond x = 9 and above y = 7, where the way around the wall is.
        let base = grid_site(|x, y| Some(x < 10 && y < 8));
        // Without a patch of cells, and another patch no longer surveyed.
        let site = grid_site(|x, y| {
            let hole = (11..=13).contains(&x) && (1..=3).contains(&y);
            // And (5, 7), beside the way around the wall: a path from a surveyed state west of
            // the wall, which may not leave unsurveyed space for a surveyed state, may now
            // enter it.
            let lost = ((6..=8).contains(&x) && y <= 2) || (x, y) == (5, 7);
            (!hole).then_some(x < 10 && y < 8 && !lost)
        });
        for radius in [3.0, 5.0] {
            let base_tables = base.reach_tables(radius).unwrap();
            let (whole, surveyed) =
                ReachTable::build_both(&site, radius, Some((&base, &base_tables))).unwrap();
            assert_eq!(whole, ReachTable::build(&site, radius));
            assert_eq!(surveyed, ReachTable::build_surveyed(&site, radius));
            // Some rows were taken from the base, not all.
            let matched = Match::new(&site, &base);
            let table = base_tables.0;
            let reuse = Reuse { base: &table, matched: &matched };
            let taken = (0..site.states().len()).filter(|&i| reuse.row(i).is_some()).count();
            assert!(taken > 0 && taken < site.states().len(), "{taken}");
        }
        // Through the site's cache, and from the site itself.
        assert_eq!(*site.reach_tables_from(&base, 5.0).unwrap().0, ReachTable::build(&site, 5.0));
        assert_eq!(*base.reach_tables_from(&base, 5.0).unwrap().0, ReachTable::build(&base, 5.0));
    }

    /// A corridor with 400 different edge lengths has more than 256 distinct walking
    /// distances: they are written out, and read back the same as the coded ones.
    #[test]
    fn many_distinct_distances_are_written_out() {
        let mut b = SiteBuilder::new("irregular");
        let f = b.floor("G", 0.0);
        let lengths: Vec<f64> = (0..400).map(|k| 1.0 + 0.001 * f64::from(k)).collect();
        let mut x = 0.0;
        let mut ids = vec![b.state(f, Point2::new(0.0, 0.0), Vec::<TrainingScan>::new())];
        for &length in &lengths {
            x += length;
            ids.push(b.state(f, Point2::new(x, 0.0), Vec::<TrainingScan>::new()));
            b.edge(ids[ids.len() - 2], ids[ids.len() - 1], Some(length));
        }
        let site = b.build(Default::default()).unwrap();
        let table = ReachTable::build(&site, 1000.0);
        assert!(matches!(table.distances, Distances::Plain(_)));
        let few = ReachTable::build(&site, 2.5);
        for (table, rho) in [(&table, 1000.0f64), (&table, 7.5), (&few, 2.5), (&few, 1.5)] {
            for i in [0usize, 17, 399] {
                // Walking distances along the corridor, summed as the Dijkstra sums them.
                let mut expected = vec![(i as u32, 0.0f32)];
                let near: Vec<u32> = [i.checked_sub(1), Some(i + 1).filter(|&j| j <= 400)]
                    .into_iter()
                    .flatten()
                    .map(|j| j as u32)
                    .collect();
                expected.extend(near.iter().map(|&j| (j, lengths[i.min(j as usize)] as f32)));
                let mut far = Vec::new();
                for dir in [-1i64, 1] {
                    let (mut j, mut d) = (i as i64, 0.0f64);
                    while (0..=400).contains(&(j + dir)) {
                        d += lengths[(j.min(j + dir)) as usize];
                        j += dir;
                        if d > rho.min(table.radius_m()) {
                            break;
                        }
                        if !near.contains(&(j as u32)) {
                            far.push((j as u32, d as f32));
                        }
                    }
                }
                far.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
                expected.extend(far);
                assert_eq!(
                    table.reachable(i, rho).iter().collect::<Vec<_>>(),
                    expected,
                    "from {i} within {rho}"
                );
            }
        }
    }

    /// A table over a budget is refused as soon as it would pass it, naming the limit; the
    /// same table within it is the unlimited one (docs/errors.md#site-limits).
    #[test]
    fn a_budget_refuses_the_table_that_would_pass_it() {
        let site = corridor();
        let refused = |entries: usize, visits: u64| {
            let budget = &mut ReachBudget::of(entries, visits);
            match ReachTable::build_over(&site, 5.0, false, None, Some(budget)) {
                Err(SiteError::OverLimit { name, .. }) => Some(name),
                Err(e) => panic!("{e}"),
                Ok(table) => {
                    assert_eq!(table, ReachTable::build(&site, 5.0));
                    None
                }
            }
        };
        let table = ReachTable::build(&site, 5.0);
        // Each popped state's edges: 1 + 2 + 2 + 2 + 1 per row of the corridor at most.
        let visits: u64 = 5 * 2 * site.edges().len() as u64;
        assert_eq!(refused(table.len(), visits), None);
        assert_eq!(refused(table.len() - 1, visits), Some("MAX_REACH_ENTRIES"));
        assert_eq!(refused(table.len(), 3), Some("MAX_REACH_EDGE_VISITS"));
        // More states within reach of one than a row may hold.
        let mut b = SiteBuilder::new("line");
        let f = b.floor("G", 0.0);
        let n = MAX_REACHABLE_STATES + 1;
        let ids: Vec<u32> = (0..n)
            .map(|i| b.state(f, Point2::new(i as f64 * 1e-3, 0.0), Vec::<TrainingScan>::new()))
            .collect();
        for w in ids.windows(2) {
            b.edge(w[0], w[1], None);
        }
        let line = b.build(Default::default()).unwrap();
        match line.reach_tables(9.0) {
            Err(e @ SiteError::OverLimit { name: "MAX_REACHABLE_STATES", .. }) => {
                assert!(e.to_string().contains("states[0] (id 0) reaches more states within 9 m"), "{e}")
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(ReachTable::build(&line, 9.0).len(), n * n, "without a budget, every state");
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
        assert_eq!(map.reachable(u[0] as usize, 20.0).iter().collect::<Vec<_>>(), [(u[0], 0.0)]);
        // The site hands out the same tables to every engine.
        let (a, a_map) = site.reach_tables(20.0).unwrap();
        let (b, _) = site.reach_tables(20.0).unwrap();
        assert!(std::sync::Arc::ptr_eq(&a, &b));
        assert_eq!(a_map.map(|m| m.len()), Some(map.len()));
    }
}
