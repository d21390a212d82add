//! Transition models driven by the motion the inertial sensors measured: HIPE's high/low
//! regions (eqs. 5-11, Table 1) and Hoang's Gaussian on the movement vector (eqs. 11, 14).

use super::transition::{hipe_probabilities, RowBounds, Transition};
use crate::site::{ReachCut, ReachTable, Site};
use nalgebra::Vector2;

/// Where HIPE puts the high transition probability from state i (HIPE eqs. 7-10, Fig. 6).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HipeRegion {
    /// Eq. 7, measured distance: walking distance within `distance_m ± tolerance_m`.
    Ring {
        /// d, m.
        distance_m: f64,
        /// ε, m.
        tolerance_m: f64,
    },
    /// Eq. 8, measured heading and assumed speed: within `range_m` and within
    /// `tolerance_rad` of `heading_rad`.
    Sector {
        /// ρ = v_max · Δt, m.
        range_m: f64,
        /// α, radians clockwise from the site's +y axis.
        heading_rad: f64,
        /// γ, rad.
        tolerance_rad: f64,
    },
    /// Eq. 9: ring ∩ sector.
    RingSector {
        /// d, m.
        distance_m: f64,
        /// ε, m.
        tolerance_m: f64,
        /// α, rad.
        heading_rad: f64,
        /// γ, rad.
        tolerance_rad: f64,
    },
    /// Eq. 10, assumed speed only: within `range_m`.
    Disc {
        /// ρ, m.
        range_m: f64,
    },
}

impl HipeRegion {
    /// The walking distance the region reaches out to, m.
    pub fn outer_radius_m(&self) -> f64 {
        match *self {
            HipeRegion::Ring { distance_m, tolerance_m }
            | HipeRegion::RingSector { distance_m, tolerance_m, .. } => distance_m + tolerance_m,
            HipeRegion::Sector { range_m, .. } | HipeRegion::Disc { range_m } => range_m,
        }
    }
}

/// Smallest absolute difference between two angles, in [0, π].
pub fn angle_between(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    d.min(std::f64::consts::TAU - d)
}

/// Azimuth of a site-frame vector, radians clockwise from +y.
pub fn azimuth(v: Vector2<f64>) -> f64 {
    v.x.atan2(v.y)
}

/// HIPE's transition: a_h on the region, a_l = a_h / K elsewhere (eqs. 5-6).
#[derive(Clone, Copy, Debug)]
pub struct RegionsTransition<'a> {
    /// The site (state positions for directions).
    pub site: &'a Site,
    /// Walking distances.
    pub table: &'a ReachTable,
    /// This epoch's region.
    pub region: HipeRegion,
    /// K, adaptive per epoch.
    pub ratio: f64,
}

impl RegionsTransition<'_> {
    fn in_region(&self, i: usize, j: u32, walk_m: f64, near: bool) -> bool {
        let states = self.site.states();
        let heading_ok = |heading: f64, tolerance: f64| {
            let (a, b) = (&states[i], &states[j as usize]);
            if j as usize == i || a.floor != b.floor {
                return true;
            }
            angle_between(azimuth(b.position - a.position), heading) <= tolerance
        };
        match self.region {
            HipeRegion::Ring { distance_m, tolerance_m } => (walk_m - distance_m).abs() <= tolerance_m,
            HipeRegion::RingSector { distance_m, tolerance_m, heading_rad, tolerance_rad } => {
                (walk_m - distance_m).abs() <= tolerance_m && heading_ok(heading_rad, tolerance_rad)
            }
            // A state stands for a cell: the speed-bounded regions keep the direct neighbours
            // (the walker may be on the boundary between the two cells).
            HipeRegion::Sector { range_m, heading_rad, tolerance_rad } => {
                (walk_m <= range_m || near) && heading_ok(heading_rad, tolerance_rad)
            }
            HipeRegion::Disc { range_m } => walk_m <= range_m || near,
        }
    }
}

impl Transition for RegionsTransition<'_> {
    fn row(&self, i: usize, row: &mut Vec<(u32, f64)>) -> f64 {
        let outer = self.region.outer_radius_m();
        let candidates = self.table.reachable(i, outer);
        let near = self.table.near_count(i);
        for (k, (j, walk_m)) in candidates.iter().enumerate() {
            if self.in_region(i, j, f64::from(walk_m), k < near) {
                row.push((j, 0.0));
            }
        }
        if row.is_empty() {
            // No state in the ring (the grid is coarser than the tolerance there): fall back to
            // the disc it bounds, so that the measured motion still limits the move.
            row.extend(candidates.iter().map(|(j, _)| (j, 0.0)));
        }
        let (high, low) = hipe_probabilities(row.len(), self.table.state_count(), self.ratio);
        for entry in row.iter_mut() {
            entry.1 = high;
        }
        low
    }

    fn floor_ratio(&self) -> Option<f64> {
        Some(self.ratio)
    }
}

/// Hoang's transition with the movement vector: uniform over the states reachable within
/// v_max·Δt (Hoang §6.1, with HIPE's floor a_h/K elsewhere), times the movement likelihood
/// N(v; l_j - l_i, Σ_v) of eq. 11, raised to 1 - γ as in eq. 14.
///
/// With only the distance walked measured (no heading), the observation is that scalar d and
/// its likelihood is eq. 11's along-track term, N(d; w_ij, σ²) with w_ij the walking distance
/// from i to j and σ² the along-track variance: HIPE's ring (eq. 7) with a Gaussian edge
/// instead of a hard one, so that a miscounted epoch costs density, not the state.
///
/// The Mahalanobis distance is capped (at 3 by default) so that a wrong step count or heading
/// cannot make a state impossible: beyond the cap every state has the cap's density, which is
/// also the density of the floor entries.
#[derive(Clone, Copy, Debug)]
pub struct MovementVectorTransition<'a> {
    /// The site (state positions).
    pub site: &'a Site,
    /// Walking distances.
    pub table: &'a ReachTable,
    /// v_max · Δt, cut in `table`.
    pub reach: ReachCut,
    /// K of the reachability floor.
    pub ratio: f64,
    /// The measured movement vector v_t in the site frame, m; `None`: no movement term.
    pub movement_m: Option<[f64; 2]>,
    /// The measured walking distance, m, used when `movement_m` is `None` (distance without
    /// heading); `None` with it: no movement term.
    pub walked_m: Option<f64>,
    /// Σ_v along the measured movement, m² (Hoang §6.1: Σ_v = 0.25 m² · I).
    pub variance_m2: f64,
    /// Σ_v across the measured movement, m²: equal to `variance_m2` for Hoang's isotropic Σ_v;
    /// with measured spreads, along-track error comes from the step count and length,
    /// across-track from the heading.
    pub across_variance_m2: f64,
    /// Largest Mahalanobis distance taken at face value.
    pub mahalanobis_cap: f64,
    /// 1 - γ of eq. 14 (1 for eq. 3).
    pub exponent: f64,
}

/// What every entry of a row of [`MovementVectorTransition`] shares, computed once per row: the
/// measured movement, its direction and the normalisers.
struct Measured {
    v: Vector2<f64>,
    direction: Option<Vector2<f64>>,
    ln_normaliser: f64,
    ln_walked_normaliser: f64,
}

impl MovementVectorTransition<'_> {
    fn measured(&self) -> Measured {
        let v = self.movement_m.map_or(Vector2::zeros(), |[x, y]| Vector2::new(x, y));
        Measured {
            v,
            direction: v.try_normalize(1e-9),
            ln_normaliser: self.ln_normaliser(),
            ln_walked_normaliser: self.ln_walked_normaliser(),
        }
    }

    /// The squared Mahalanobis distance of `delta` from the measured movement, `None` at or
    /// beyond the cap (every such entry has the cap's density). 0 without a movement term.
    fn movement_r2(&self, m: &Measured, delta: Vector2<f64>) -> Option<f64> {
        if self.movement_m.is_none() {
            return Some(0.0);
        }
        let residual = m.v - delta;
        let r2 = match m.direction {
            Some(u) if self.across_variance_m2 != self.variance_m2 => {
                let along = residual.dot(&u);
                let across = residual.perp(&u);
                along * along / self.variance_m2 + across * across / self.across_variance_m2
            }
            // No direction to be along: the larger spread both ways.
            _ => residual.norm_squared() / self.variance_m2.max(self.across_variance_m2),
        };
        (r2 < self.mahalanobis_cap * self.mahalanobis_cap).then_some(r2)
    }

    /// The squared distance of the walking distance `walk_m` from the measured `d` along the
    /// track, `None` at or beyond the cap.
    fn walked_r2(&self, d: f64, walk_m: f64) -> Option<f64> {
        let r2 = (d - walk_m).powi(2) / self.variance_m2;
        (r2 < self.mahalanobis_cap * self.mahalanobis_cap).then_some(r2)
    }

    /// ln N at squared Mahalanobis distance `r2` under the cap, times the exponent: eq. 11
    /// with the movement vector, its along-track term with the distance alone.
    fn ln_density(&self, m: &Measured, r2: f64) -> f64 {
        let ln_normaliser = match (self.movement_m, self.walked_m) {
            (None, Some(_)) => m.ln_walked_normaliser,
            (None, None) => return 0.0,
            _ => m.ln_normaliser,
        };
        self.exponent * (-0.5 * r2 - ln_normaliser)
    }

    /// ln(2π √det Σ_v).
    fn ln_normaliser(&self) -> f64 {
        (std::f64::consts::TAU * (self.variance_m2 * self.across_variance_m2).sqrt()).ln()
    }

    /// ln √(2π σ²).
    fn ln_walked_normaliser(&self) -> f64 {
        0.5 * (std::f64::consts::TAU * self.variance_m2).ln()
    }
}

impl Transition for MovementVectorTransition<'_> {
    fn row(&self, i: usize, row: &mut Vec<(u32, f64)>) -> f64 {
        self.prepared().row(i, row)
    }

    fn row_on(&self, i: usize, weights: &[f64], row: &mut Vec<(u32, f64)>) -> f64 {
        self.prepared().row_on(i, weights, row)
    }

    fn bounds(&self) -> Option<RowBounds<'_>> {
        let (cap, most) = self.ln_movement_range();
        Some(RowBounds {
            table: self.table,
            reach: self.reach,
            ratio: self.ratio,
            floor_factor: cap.exp(),
            ln_most_factor: most,
        })
    }
}

/// A [`MovementVectorTransition`] with what all its rows share computed once: the measured movement,
/// its direction, the normalisers and the density at the Mahalanobis cap. Its rows are the
/// model's, value for value; an epoch writes thousands of them.
pub struct PreparedHoang<'t, 'a> {
    model: &'t MovementVectorTransition<'a>,
    measured: Measured,
    /// exp of the movement term at the cap.
    capped: f64,
}

impl<'a> MovementVectorTransition<'a> {
    /// The model ready to write many rows.
    pub fn prepared(&self) -> PreparedHoang<'_, 'a> {
        PreparedHoang { model: self, measured: self.measured(), capped: self.ln_movement_range().0.exp() }
    }
}

impl Transition for PreparedHoang<'_, '_> {
    fn row(&self, i: usize, row: &mut Vec<(u32, f64)>) -> f64 {
        self.row_where(i, row, |_| true)
    }

    fn row_on(&self, i: usize, weights: &[f64], row: &mut Vec<(u32, f64)>) -> f64 {
        self.row_where(i, row, |j| weights.get(j as usize).is_some_and(|&w| w != 0.0))
    }

    fn bounds(&self) -> Option<RowBounds<'_>> {
        self.model.bounds()
    }
}

impl PreparedHoang<'_, '_> {
    /// Row `i`'s entries whose j is `wanted`, in the row's order, and its floor weight: each
    /// entry's weight depends on its own j alone, so the others need not be computed.
    #[inline]
    fn row_where(&self, i: usize, row: &mut Vec<(u32, f64)>, wanted: impl Fn(u32) -> bool) -> f64 {
        let (t, m) = (self.model, &self.measured);
        let states = t.site.states();
        let reach = t.table.reachable_within(i, t.reach);
        let (high, low) = hipe_probabilities(reach.len(), t.table.state_count(), t.ratio);
        let from = &states[i];
        // Entries at the Mahalanobis cap (most of a row: the reach is wider than the spread)
        // all weigh `high · exp(cap)`: one exponential for all of them.
        let high_capped = high * self.capped;
        for (j, walk_m) in reach.iter() {
            if !wanted(j) {
                continue;
            }
            let to = &states[j as usize];
            let delta = if to.floor == from.floor {
                to.position - from.position
            } else {
                // Between floors the plan distance is the walk along the stairs.
                m.direction.unwrap_or_else(Vector2::zeros) * f64::from(walk_m)
            };
            let r2 = match (t.movement_m, t.walked_m) {
                (None, Some(d)) => t.walked_r2(d, f64::from(walk_m)),
                _ => t.movement_r2(m, delta),
            };
            let a = match r2 {
                Some(r2) => high * t.ln_density(m, r2).exp(),
                None => high_capped,
            };
            row.push((j, a));
        }
        low * self.capped
    }
}

impl MovementVectorTransition<'_> {
    /// The movement term at the Mahalanobis cap (the floor entries' density) and the largest
    /// any entry can have (at distance 0 or at the cap, whichever the exponent's sign makes
    /// larger): every row entry is `high · exp` of a value between the two.
    fn ln_movement_range(&self) -> (f64, f64) {
        let ln_normaliser = match (self.movement_m, self.walked_m) {
            (Some(_), _) => self.ln_normaliser(),
            (None, Some(_)) => self.ln_walked_normaliser(),
            (None, None) => return (0.0, 0.0),
        };
        let cap = self.exponent * (-0.5 * self.mahalanobis_cap * self.mahalanobis_cap - ln_normaliser);
        let centre = self.exponent * (-0.5 * 0.0 - ln_normaliser);
        (cap, cap.max(centre))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::site::{BuildOptions, SiteBuilder};
    use approx::assert_relative_eq;
    use nalgebra::Point2;

    /// A 5 x 5 grid, 1 m apart, 4-connected.
    fn grid() -> Site {
        let mut b = SiteBuilder::new("grid");
        let f = b.floor("G", 0.0);
        let ids: Vec<Vec<u32>> = (0..5)
            .map(|y| (0..5).map(|x| b.state(f, Point2::new(x as f64, y as f64), vec![])).collect())
            .collect();
        for y in 0..5 {
            for x in 0..5 {
                if x + 1 < 5 {
                    b.edge(ids[y][x], ids[y][x + 1], None);
                }
                if y + 1 < 5 {
                    b.edge(ids[y][x], ids[y + 1][x], None);
                }
            }
        }
        b.build(BuildOptions::default()).unwrap()
    }

    fn high_set(t: &dyn Transition, i: usize) -> Vec<u32> {
        let mut row = Vec::new();
        t.row(i, &mut row);
        let mut js: Vec<u32> = row.iter().map(|e| e.0).collect();
        js.sort_unstable();
        js
    }

    #[test]
    fn hipe_regions_are_rings_sectors_and_discs() {
        let site = grid();
        let table = ReachTable::build(&site, 9.0);
        let centre = 12; // (2, 2)
        let at = |x: u32, y: u32| y * 5 + x;
        let t = |region| RegionsTransition { site: &site, table: &table, region, ratio: 1000.0 };
        // Ring of walking distance 2 ± 0.5 around the centre: the 8 states two steps away.
        let ring = high_set(&t(HipeRegion::Ring { distance_m: 2.0, tolerance_m: 0.5 }), centre);
        assert_eq!(ring.len(), 8);
        assert!(ring.contains(&at(2, 0)) && ring.contains(&at(1, 1)) && !ring.contains(&at(2, 1)));
        // Ring ∩ sector heading +y (north) ± 50°: (2,4), (1,3), (3,3).
        let north = HipeRegion::RingSector {
            distance_m: 2.0,
            tolerance_m: 0.5,
            heading_rad: 0.0,
            tolerance_rad: 50f64.to_radians(),
        };
        assert_eq!(high_set(&t(north), centre), vec![at(1, 3), at(3, 3), at(2, 4)]);
        // Disc of 1 m: the centre and its 4 neighbours.
        assert_eq!(high_set(&t(HipeRegion::Disc { range_m: 1.0 }), centre).len(), 5);
        // Sector east (+x, 90°) ± 30° within 2 m: centre, (3,2), (4,2).
        let east = HipeRegion::Sector {
            range_m: 2.0,
            heading_rad: 90f64.to_radians(),
            tolerance_rad: 30f64.to_radians(),
        };
        assert_eq!(high_set(&t(east), centre), vec![centre as u32, at(3, 2), at(4, 2)]);
        // Every row sums to one.
        let tr = t(north);
        let mut row = Vec::new();
        let low = tr.row(centre, &mut row);
        assert_relative_eq!(
            row.iter().map(|e| e.1).sum::<f64>() + low * (25 - row.len()) as f64,
            1.0,
            epsilon = 1e-12
        );
    }

    /// Hoang's model on the grid with a measured movement of 1 m east, Σ_v (along, across).
    fn one_metre_east<'a>(
        site: &'a Site,
        table: &'a ReachTable,
        [along, across]: [f64; 2],
        cap: f64,
    ) -> MovementVectorTransition<'a> {
        MovementVectorTransition {
            site,
            table,
            reach: table.cut(4.5),
            ratio: 200_000.0,
            movement_m: Some([1.0, 0.0]),
            walked_m: None,
            variance_m2: along,
            across_variance_m2: across,
            mahalanobis_cap: cap,
            exponent: 1.0,
        }
    }

    #[test]
    fn hoang_movement_likelihood_peaks_at_the_measured_vector() {
        let site = grid();
        let table = ReachTable::build(&site, 9.0);
        let t = one_metre_east(&site, &table, [0.25, 0.25], 3.0);
        let mut row = Vec::new();
        let floor = t.row(12, &mut row);
        let weight = |j: u32| row.iter().find(|e| e.0 == j).unwrap().1;
        let (high, low) = hipe_probabilities(row.len(), 25, 200_000.0);
        // Moving one metre east lands on (3, 2) = 13: the density at the mean, 1/(2π·0.25).
        assert_relative_eq!(weight(13), high / (std::f64::consts::TAU * 0.25), epsilon = 1e-12);
        // Staying put is 1 m = 2σ off: exp(-2) less.
        assert_relative_eq!(weight(12), weight(13) * (-2.0f64).exp(), epsilon = 1e-12);
        // Far off is capped at 3σ, and so is the floor.
        assert_relative_eq!(
            weight(10),
            high / (std::f64::consts::TAU * 0.25) * (-4.5f64).exp(),
            epsilon = 1e-12
        );
        assert_relative_eq!(floor, low / (std::f64::consts::TAU * 0.25) * (-4.5f64).exp(), epsilon = 1e-15);
    }

    #[test]
    fn anisotropic_movement_spread_is_along_and_across_the_movement() {
        let site = grid();
        let table = ReachTable::build(&site, 9.0);
        let t = one_metre_east(&site, &table, [1.0, 0.25], 10.0);
        // 1 m short along the movement (staying put): 1σ along; 1 m beside the target: 2σ across.
        let normaliser = std::f64::consts::TAU * (1.0f64 * 0.25).sqrt();
        let m = t.measured();
        let ln = |delta| t.movement_r2(&m, delta).map(|r2| t.ln_density(&m, r2)).unwrap();
        assert_relative_eq!(ln(Vector2::new(0.0, 0.0)), -0.5 - normaliser.ln(), epsilon = 1e-12);
        assert_relative_eq!(ln(Vector2::new(1.0, 1.0)), -2.0 - normaliser.ln(), epsilon = 1e-12);
        // 11 m short along: 11σ, beyond the cap of 10.
        assert_eq!(t.movement_r2(&m, Vector2::new(-10.0, 0.0)), None);
    }

    #[test]
    fn row_on_is_the_row_on_the_weighted_states_bit_for_bit() {
        let site = grid();
        let table = ReachTable::build(&site, 9.0);
        // Anisotropic (direction and both spreads), isotropic, and distance alone.
        let vector = one_metre_east(&site, &table, [0.3, 0.1], 3.0);
        let round = one_metre_east(&site, &table, [0.3, 0.3], 3.0);
        let walked = MovementVectorTransition { movement_m: None, walked_m: Some(1.5), ..vector };
        // Every third state weighted, by weights so small that only their sign tells them.
        let weights: Vec<f64> =
            (0..25).map(|j| if j % 3 == 0 { 1e-200 * (j + 1) as f64 } else { 0.0 }).collect();
        let bits = |row: &[(u32, f64)]| row.iter().map(|&(j, a)| (j, a.to_bits())).collect::<Vec<_>>();
        for t in [vector, round, walked] {
            for i in 0..25 {
                let (mut full, mut on) = (Vec::new(), Vec::new());
                let floor = t.row(i, &mut full);
                assert_eq!(t.row_on(i, &weights, &mut on).to_bits(), floor.to_bits());
                full.retain(|&(j, _)| weights[j as usize] != 0.0);
                assert_eq!(bits(&on), bits(&full));
            }
        }
    }

    #[test]
    fn distance_alone_is_a_gaussian_ring_in_walking_distance() {
        let site = grid();
        let table = ReachTable::build(&site, 9.0);
        let t = MovementVectorTransition {
            movement_m: None,
            walked_m: Some(2.0),
            ..one_metre_east(&site, &table, [0.25, 0.25], 3.0)
        };
        let mut row = Vec::new();
        let floor = t.row(12, &mut row);
        let weight = |j: u32| row.iter().find(|e| e.0 == j).unwrap().1;
        let (high, _) = hipe_probabilities(row.len(), 25, 200_000.0);
        let peak = high / (std::f64::consts::TAU * 0.25).sqrt();
        // Every state 2 m away on the 4-connected grid, whatever the direction, is at the peak:
        // two east (14), two west (10), one north and one east (18, walked round the corner).
        for j in [14, 10, 2, 22, 18, 6] {
            assert_relative_eq!(weight(j), peak, epsilon = 1e-12);
        }
        // One metre away (13, 11) is 1 m = 2σ short; staying put (12) is capped at 3σ, as is
        // the floor.
        assert_relative_eq!(weight(13), peak * (-2.0f64).exp(), epsilon = 1e-12);
        assert_relative_eq!(weight(12), peak * (-4.5f64).exp(), epsilon = 1e-12);
        assert_relative_eq!(
            floor / weight(12),
            hipe_probabilities(row.len(), 25, 200_000.0).1 / high,
            epsilon = 1e-12
        );
    }

    #[test]
    fn angles_wrap() {
        assert_relative_eq!(angle_between(3.1, -3.1), std::f64::consts::TAU - 6.2, epsilon = 1e-12);
        assert_relative_eq!(angle_between(0.0, std::f64::consts::PI), std::f64::consts::PI);
        assert_relative_eq!(azimuth(Vector2::new(1.0, 0.0)), std::f64::consts::FRAC_PI_2);
    }

    /// A model with its bounds hidden (`.1` false: the Viterbi step then expands every row of
    /// the beam), counting the rows written.
    struct Counted<'a>(&'a dyn Transition, bool, std::cell::Cell<usize>);

    impl Transition for Counted<'_> {
        fn row(&self, i: usize, row: &mut Vec<(u32, f64)>) -> f64 {
            self.2.set(self.2.get() + 1);
            self.0.row(i, row)
        }

        fn bounds(&self) -> Option<RowBounds<'_>> {
            self.0.bounds().filter(|_| self.1)
        }
    }

    #[test]
    fn rows_skipped_by_their_bounds_change_no_viterbi_score_nor_back_pointer() {
        use crate::hmm::transition::{viterbi_step, UniformReach};
        let site = grid();
        let table = ReachTable::build(&site, 9.0);
        // Scores spread over 60 nats (beyond the beam for some), a few -inf, by a fixed LCG.
        let mut seed = 7u64;
        let mut delta = || {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            let u = (seed >> 11) as f64 / (1u64 << 53) as f64;
            if u < 0.05 {
                f64::NEG_INFINITY
            } else {
                -60.0 * u
            }
        };
        let mut models: Vec<MovementVectorTransition> = Vec::new();
        for (movement_m, walked_m) in [(Some([1.0, 0.0]), None), (None, Some(2.0)), (None, None)] {
            for exponent in [1.0, 0.97, -0.5] {
                models.push(MovementVectorTransition {
                    movement_m,
                    walked_m,
                    exponent,
                    ratio: 50.0,
                    ..one_metre_east(&site, &table, [0.1, 0.4], 3.0)
                });
            }
        }
        let uniform = UniformReach { table: &table, rho_m: 2.0, ratio: 1000.0 };
        let mut transitions: Vec<&dyn Transition> = models.iter().map(|m| m as &dyn Transition).collect();
        transitions.push(&uniform);
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for (k, t) in transitions.iter().enumerate() {
            let (bounded, unbounded) =
                (Counted(*t, true, Default::default()), Counted(*t, false, Default::default()));
            for trial in 0..20 {
                let d: Vec<f64> = (0..25).map(|_| delta()).collect();
                let (mut out, mut back) = (vec![0.0; 25], vec![0u32; 25]);
                let (mut all_out, mut all_back) = (vec![0.0; 25], vec![0u32; 25]);
                viterbi_step(&bounded, &d, &mut out, &mut back, &mut Vec::new());
                viterbi_step(&unbounded, &d, &mut all_out, &mut all_back, &mut Vec::new());
                assert_eq!(bits(&out), bits(&all_out), "model {k}, trial {trial}");
                assert_eq!(back, all_back, "model {k}, trial {trial}");
            }
            assert!(bounded.2.get() < unbounded.2.get(), "model {k}: some rows skipped");
            // The bounds are the row's own floor and at least each of its weights.
            for i in 0..25 {
                let mut row = Vec::new();
                let floor = t.row(i, &mut row);
                let bounds = t.bounds().unwrap();
                let (bound_floor, ln_most) = (bounds.floor(i), bounds.ln_most(i));
                assert_eq!(floor.to_bits(), bound_floor.to_bits(), "model {k}, row {i}");
                assert!(row.iter().all(|e| e.1.ln() <= ln_most + 1e-12), "model {k}, row {i}");
            }
        }
    }

    #[test]
    fn one_pass_for_the_viterbi_step_and_the_prediction_is_exactly_the_two_steps() {
        use crate::hmm::{ForwardFilter, ViterbiWindow};
        let site = grid();
        let table = ReachTable::build(&site, 9.0);
        let t = MovementVectorTransition { exponent: 0.97, ..one_metre_east(&site, &table, [0.1, 0.4], 3.0) };
        let (mut fused, mut fused_path) = (ForwardFilter::new(25), ViterbiWindow::new(25, 8));
        let (mut apart, mut apart_path) = (ForwardFilter::new(25), ViterbiWindow::new(25, 8));
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for epoch in 0..12u64 {
            // Emissions hundreds of nats apart, some states ruled out.
            let e: Vec<f64> = (0..25u64)
                .map(|j| {
                    if (j + epoch) % 7 == 0 {
                        f64::NEG_INFINITY
                    } else {
                        -(((j * 37 + epoch * 11) % 23) as f64) * 9.0
                    }
                })
                .collect();
            let a = fused.step_with_viterbi(&mut fused_path, epoch, &t, &e);
            apart_path.step(epoch, &t, &e);
            let b = apart.step(Some(&t), &e);
            assert_eq!(a.map(f64::to_bits), b.map(f64::to_bits), "epoch {epoch}");
            assert_eq!(bits(fused.posterior()), bits(apart.posterior()), "epoch {epoch}");
            assert_eq!(fused_path.path(), apart_path.path(), "epoch {epoch}");
        }
        // A wrong-length emission: the same error, nothing changed.
        assert_eq!(
            fused.step_with_viterbi(&mut fused_path, 99, &t, &[0.0; 3]),
            apart.step(Some(&t), &[0.0; 3])
        );
    }

    #[test]
    fn rows_skipped_by_their_bounds_change_no_smoothed_posterior() {
        use crate::hmm::transition::UniformReach;
        use crate::hmm::{FixedLagSmoother, ForwardFilter};
        let site = grid();
        let table = ReachTable::build(&site, 9.0);
        let hoang = MovementVectorTransition {
            reach: table.cut(2.0),
            exponent: 0.97,
            ..one_metre_east(&site, &table, [0.1, 0.4], 3.0)
        };
        let walked = MovementVectorTransition { movement_m: None, walked_m: Some(1.0), ..hoang };
        let uniform = UniformReach { table: &table, rho_m: 1.5, ratio: 1000.0 };
        let transitions: [&dyn Transition; 3] = [&hoang, &walked, &uniform];
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for (k, &t) in transitions.iter().enumerate() {
            // Three flat epochs leave mass on every state, then a scan rules out all but the
            // grid's first row: rows away from it hold no later mass.
            let mut filter = ForwardFilter::new(25);
            let mut smoother = FixedLagSmoother::new(4);
            filter.step(None, &[0.0; 25]).unwrap();
            for epoch in 1..=4u64 {
                let e: Vec<f64> =
                    (0..25).map(|j| if epoch < 4 || j < 5 { -((j % 3) as f64) } else { -60.0 }).collect();
                smoother.begin(epoch - 1, filter.posterior(), ());
                filter.step(Some(t), &e).unwrap();
                smoother.finish(filter.predicted(), filter.posterior());
            }
            let (bounded, unbounded) =
                (Counted(t, true, Default::default()), Counted(t, false, Default::default()));
            for lag in 1..=4 {
                let (mut skipped, mut every) = (Vec::new(), Vec::new());
                let a = smoother.smooth(lag, filter.posterior(), &mut skipped, |_, f| f(&bounded));
                let b = smoother.smooth(lag, filter.posterior(), &mut every, |_, f| f(&unbounded));
                assert_eq!((a, bits(&skipped)), (b, bits(&every)), "model {k}, lag {lag}");
            }
            assert!(bounded.2.get() < unbounded.2.get(), "model {k}: some rows skipped");
        }
    }
}
