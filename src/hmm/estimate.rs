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
    let mut floor_mass = vec![0.0; site.floors().len()];
    for (s, &p) in states.iter().zip(posterior) {
        floor_mass[s.floor] += p;
    }
    let (floor, &floor_probability) = floor_mass
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .expect("a site has at least one floor");

    // Eq. 4 over the M most likely states of that floor; scratch holds (-p, index).
    scratch.clear();
    scratch.extend(
        states
            .iter()
            .zip(posterior)
            .enumerate()
            .filter(|(_, (s, &p))| s.floor == floor && p > 0.0)
            .map(|(i, (_, &p))| (-p, i as f64)),
    );
    let m = top_m.min(scratch.len()).max(1);
    let position = if scratch.is_empty() {
        // No mass on any state of the floor (cannot happen with a normalised posterior and a
        // floor chosen by mass); the first state of the floor keeps the output on the site.
        states.iter().find(|s| s.floor == floor).map_or(Point2::origin(), |s| s.position)
    } else {
        if m < scratch.len() {
            scratch.select_nth_unstable_by(m - 1, |a, b| a.0.total_cmp(&b.0));
        }
        let (mut sum, mut weight) = (nalgebra::Vector2::zeros(), 0.0);
        for &(neg_p, i) in &scratch[..m] {
            sum += states[i as usize].position.coords * -neg_p;
            weight -= neg_p;
        }
        Point2::from(sum / weight)
    };

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
    scratch.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let mut inside = 0.0;
    let (mut radius, mut radius_95) = (None, None);
    for &(d, p) in scratch.iter() {
        inside += p;
        if inside >= mass && radius.is_none() {
            radius = Some(d);
        }
        if inside >= mass.max(MASS_95) {
            radius_95 = Some(d);
            break;
        }
    }
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
