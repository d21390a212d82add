//! From posterior to position: Hoang eq. 4 on the most likely floor, and a 68% radius.

use super::transition::PRUNE_MASS;
use crate::site::Site;
use nalgebra::Point2;

/// A position estimate from the posterior.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// The floor holding the most posterior mass.
    pub floor: usize,
    /// Posterior mass on that floor.
    pub floor_probability: f64,
    /// Posterior-weighted mean of the M most likely states on that floor (Hoang eq. 4), m.
    pub position: Point2<f64>,
    /// Radius around `position` holding `mass` of the posterior, widened by the cell size, m.
    /// Always > 0.
    pub accuracy_m: f64,
    /// The same for 95% of the posterior, m; ≥ `accuracy_m`.
    pub accuracy_95_m: f64,
}

/// Posterior mass of the second radius [`Estimate::accuracy_95_m`].
pub const MASS_95: f64 = 0.95;

/// Share of a state's cell, in a corridor of cells `spacing` long, within which the true
/// position lies with probability 0.68 when it is uniform over the cell: 0.68 · spacing / 2.
/// Derived, not tuned (its effect on the radius: `docs/tuning.md#radius-factors`).
const CELL_RADIUS_PER_SPACING: f64 = 0.34;

/// Estimates the position from `posterior` (which sums to 1).
///
/// `scratch` is reused between calls so that an epoch allocates nothing once warm.
pub fn estimate(
    site: &Site,
    posterior: &[f64],
    top_m: usize,
    mass: f64,
    scratch: &mut Vec<(f64, f64)>,
) -> Estimate {
    let states = site.states();
    let (floor, floor_probability) = most_likely_floor(site, posterior);
    floor_states(site, posterior, floor, scratch);
    let position = mean_of_most_likely(site, floor, scratch, top_m);

    // The radius holding `mass` of the whole posterior: states of other floors never count
    // as inside. scratch now holds (distance, p), for the states with at least PRUNE_MASS
    // (those below hold under N · 1e-15 together: sorting them would only cost time).
    // Less than a mass on this floor: the farthest state of the floor with any mass bounds
    // what we know.
    let mut farthest: f64 = 0.0;
    scratch.clear();
    for (s, &p) in states.iter().zip(posterior) {
        if s.floor != floor || p <= 0.0 {
            continue;
        }
        let d = nalgebra::distance(&s.position, &position);
        farthest = farthest.max(d);
        if p >= PRUNE_MASS {
            scratch.push((d, p));
        }
    }
    let radius_95 = radius_holding(scratch, mass.max(MASS_95));
    let radius = radius_holding(scratch, mass);
    // Each state stands for a cell around it: the posterior radius alone is 0 when all mass
    // is on one state. Quantisation and posterior spread add as independent errors; the cell
    // term holds `mass` of a uniform position over a cell as CELL_RADIUS_PER_SPACING does 0.68.
    let with_cell = |r: f64, m: f64| {
        let cell = CELL_RADIUS_PER_SPACING / 0.68 * m * site.spacing_m();
        (r * r + cell * cell).sqrt().max(f64::EPSILON)
    };
    let accuracy_m = with_cell(radius.unwrap_or(farthest), mass);
    let accuracy_95_m = with_cell(radius_95.unwrap_or(farthest), mass.max(MASS_95)).max(accuracy_m);
    Estimate { floor, floor_probability, position, accuracy_m, accuracy_95_m }
}

/// The estimate's position (Hoang eq. 4) with each M of `grid`, on the floor [`estimate`]
/// takes: what choosing M on held-out walks compares (docs/tuning.md#mixture-components-m).
pub fn positions_by_states(site: &Site, posterior: &[f64], grid: &[usize]) -> Vec<Point2<f64>> {
    if grid.is_empty() {
        return Vec::new();
    }
    let (floor, _) = most_likely_floor(site, posterior);
    let mut scratch = Vec::new();
    floor_states(site, posterior, floor, &mut scratch);
    grid.iter().map(|&m| mean_of_most_likely(site, floor, &mut scratch, m)).collect()
}

/// The floor holding the most posterior mass, and that mass.
fn most_likely_floor(site: &Site, posterior: &[f64]) -> (usize, f64) {
    floor_masses(site, posterior)
        .into_iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .expect("a site has at least one floor")
}

/// `scratch` set to (-p, index) of the states of `floor` with any mass.
fn floor_states(site: &Site, posterior: &[f64], floor: usize, scratch: &mut Vec<(f64, f64)>) {
    scratch.clear();
    scratch.extend(
        site.states()
            .iter()
            .zip(posterior)
            .enumerate()
            .filter(|(_, (s, &p))| s.floor == floor && p > 0.0)
            .map(|(i, (_, &p))| (-p, i as f64)),
    );
}

/// Eq. 4 over the `m` most likely of the states in `scratch` ([`floor_states`], reordered).
fn mean_of_most_likely(site: &Site, floor: usize, scratch: &mut [(f64, f64)], m: usize) -> Point2<f64> {
    let states = site.states();
    if scratch.is_empty() {
        // No mass on any state of the floor (cannot happen with a normalised posterior and a
        // floor chosen by mass); the first state of the floor keeps the output on the site.
        return states.iter().find(|s| s.floor == floor).map_or(Point2::origin(), |s| s.position);
    }
    let m = m.min(scratch.len()).max(1);
    if m < scratch.len() {
        scratch.select_nth_unstable_by(m - 1, |a, b| a.0.total_cmp(&b.0));
    }
    let (mut sum, mut weight) = (nalgebra::Vector2::zeros(), 0.0);
    for &(neg_p, i) in &scratch[..m] {
        sum += states[i as usize].position.coords * -neg_p;
        weight -= neg_p;
    }
    Point2::from(sum / weight)
}

/// Posterior mass per floor. States come in runs on one floor; each run is summed in four
/// lanes, where adding state by state into the floor's total waited on the previous add
/// (most of the estimate's time on a large site, docs/tuning.md#engine-speed).
fn floor_masses(site: &Site, posterior: &[f64]) -> Vec<f64> {
    let states = site.states();
    let mut mass = vec![0.0; site.floors().len()];
    let mut start = 0;
    while start < states.len().min(posterior.len()) {
        let floor = states[start].floor;
        let run = states[start..].iter().take_while(|s| s.floor == floor).count();
        let run_mass = posterior.get(start..start + run).map_or(0.0, sum_in_lanes);
        mass[floor] += run_mass;
        start += run;
    }
    mass
}

/// Σ values, in four lanes.
fn sum_in_lanes(values: &[f64]) -> f64 {
    let chunks = values.chunks_exact(4);
    let tail: f64 = chunks.remainder().iter().sum();
    let (mut a, mut b, mut c, mut d) = (0.0, 0.0, 0.0, 0.0);
    for chunk in chunks {
        a += chunk[0];
        b += chunk[1];
        c += chunk[2];
        d += chunk[3];
    }
    (a + b) + (c + d) + tail
}

/// The smallest distance within which `items` (distance, mass) hold at least `mass`, if they
/// hold that much at all: what walking them in order of distance finds, by selection in
/// expected linear time rather than a sort (the estimate is a tenth of an epoch at building
/// scale, docs/tuning.md#engine-speed). Reorders `items`.
fn radius_holding(items: &mut [(f64, f64)], mass: f64) -> Option<f64> {
    // No mass to hold: the nearest item, the first the walk reaches.
    if mass <= 0.0 {
        return items.iter().map(|&(d, _)| d).min_by(f64::total_cmp);
    }
    // items[..lo] are inside, holding `held` (< mass); the answer is among items[lo..hi].
    let (mut lo, mut hi, mut held) = (0, items.len(), 0.0);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        items[lo..hi].select_nth_unstable_by(mid - lo, |a, b| a.0.total_cmp(&b.0));
        let below: f64 = items[lo..mid].iter().map(|&(_, p)| p).sum();
        if held + below >= mass {
            hi = mid;
        } else if held + below + items[mid].1 >= mass {
            return Some(items[mid].0);
        } else {
            (lo, held) = (mid + 1, held + below + items[mid].1);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn positions_by_states_are_the_estimates_with_each_m() {
        let mut b = crate::site::SiteBuilder::new("grid");
        let f = b.floor("G", 0.0);
        for k in 0..24 {
            b.state(f, Point2::new((k % 6) as f64, (k / 6) as f64), vec![]);
        }
        let site = b.build(crate::site::BuildOptions::default()).unwrap();
        let n = site.states().len();
        // Distinct masses, so that the M most likely states are one set.
        let weights: Vec<f64> = (0..n).map(|i| 1.0 + ((i * 7919) % n) as f64).collect();
        let total: f64 = weights.iter().sum();
        let posterior: Vec<f64> = weights.iter().map(|w| w / total).collect();
        let grid = [1, 2, 3, 10, n + 5];
        let by_m = positions_by_states(&site, &posterior, &grid);
        for (&m, p) in grid.iter().zip(&by_m) {
            let e = estimate(&site, &posterior, m, 0.68, &mut Vec::new());
            // The same states, summed perhaps in another order.
            assert!((e.position - p).norm() < 1e-12, "M = {m}: {} against {p}", e.position);
        }
        assert!(positions_by_states(&site, &posterior, &[]).is_empty());
    }

    /// Walking the items in order of distance, as the radius is defined.
    fn by_sorting(items: &[(f64, f64)], mass: f64) -> Option<f64> {
        let mut sorted = items.to_vec();
        sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut inside = 0.0;
        sorted
            .iter()
            .find(|&&(_, p)| {
                inside += p;
                inside >= mass
            })
            .map(|&(d, _)| d)
    }

    proptest! {
        /// Masses in 1/1024 steps add exactly in any order, so selection and sorting agree
        /// to the bit, ties in distance included.
        #[test]
        fn selection_finds_the_radius_sorting_finds(
            items in prop::collection::vec((0u32..40, 0u32..64), 0..300),
            mass in 0u32..1100,
        ) {
            let items: Vec<(f64, f64)> =
                items.iter().map(|&(d, p)| (f64::from(d) * 0.5, f64::from(p) / 1024.0)).collect();
            let mass = f64::from(mass) / 1024.0;
            prop_assert_eq!(radius_holding(&mut items.clone(), mass), by_sorting(&items, mass));
        }
    }
}
