//! Transition models. For now the reachability model of Hoang §6.1 with HIPE's low-probability
//! floor: uniform over the states reachable in one epoch, K times less likely elsewhere.

use crate::site::ReachTable;

/// A transition model: one prediction step of the forward recursion.
pub trait Transition {
    /// `out[j] = Σ_i prior[i] · a_ij`. `prior` sums to 1 and so does `out`.
    fn predict(&self, prior: &[f64], out: &mut [f64]);
}

/// Uniform 1/U over the U states reachable from state i within `rho_m` walking distance
/// (Hoang §6.1), with every other state at 1/K of that (HIPE eqs. 5-6, 11):
/// a_h = K / (U·K + N - U), a_l = a_h / K, so that each row sums to 1.
#[derive(Clone, Copy, Debug)]
pub struct UniformReach<'a> {
    /// Walking-distance table.
    pub table: &'a ReachTable,
    /// Reach this epoch, m (at most the table's radius).
    pub rho_m: f64,
    /// HIPE's K.
    pub ratio: f64,
}

impl Transition for UniformReach<'_> {
    fn predict(&self, prior: &[f64], out: &mut [f64]) {
        let n = prior.len() as f64;
        let mut low_total = 0.0;
        out.fill(0.0);
        for (i, &p) in prior.iter().enumerate() {
            if p == 0.0 {
                continue;
            }
            let reach = self.table.reachable(i, self.rho_m);
            let u = reach.len() as f64;
            let high = self.ratio / (u * self.ratio + n - u);
            let low = high / self.ratio;
            low_total += p * low;
            let extra = p * (high - low);
            for &(j, _) in reach {
                out[j as usize] += extra;
            }
        }
        for v in out.iter_mut() {
            *v += low_total;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::site::{BuildOptions, Site, SiteBuilder, TrainingScan};
    use approx::assert_relative_eq;
    use nalgebra::Point2;

    /// Six states on a corridor, 2 m apart.
    fn corridor() -> Site {
        let mut b = SiteBuilder::new("corridor");
        let f = b.floor("G", 0.0);
        let ids: Vec<u32> = (0..6)
            .map(|k| b.state(f, Point2::new(2.0 * k as f64, 0.0), Vec::<TrainingScan>::new()))
            .collect();
        for w in ids.windows(2) {
            b.edge(w[0], w[1], None);
        }
        b.build(BuildOptions::default()).unwrap()
    }

    #[test]
    fn rows_follow_hipe_eqs_5_and_6() {
        let site = corridor();
        let table = ReachTable::build(&site, 9.0);
        let ratio = 1000.0;
        let t = UniformReach { table: &table, rho_m: 3.0, ratio };
        // Row of state 2: itself, 1 and 3 reachable (U = 3), the other three low.
        let mut prior = vec![0.0; 6];
        prior[2] = 1.0;
        let mut out = vec![0.0; 6];
        t.predict(&prior, &mut out);
        let high = ratio / (3.0 * ratio + 3.0);
        for (j, &p) in out.iter().enumerate() {
            let expected = if (1..=3).contains(&j) { high } else { high / ratio };
            assert_relative_eq!(p, expected, epsilon = 1e-15);
        }
        assert_relative_eq!(out.iter().sum::<f64>(), 1.0, epsilon = 1e-15);
    }

    #[test]
    fn sparse_prediction_equals_the_dense_matrix() {
        let site = corridor();
        let table = ReachTable::build(&site, 9.0);
        let t = UniformReach { table: &table, rho_m: 4.5, ratio: 200_000.0 };
        let prior = [0.1, 0.3, 0.0, 0.2, 0.15, 0.25];
        let mut sparse = vec![0.0; 6];
        t.predict(&prior, &mut sparse);
        // a_ij by definition: walking distance on the corridor is |i - j| * 2 m.
        for (j, &p) in sparse.iter().enumerate() {
            let dense: f64 = (0..6)
                .map(|i| {
                    let reachable = |k: usize| (k as f64 - i as f64).abs() * 2.0 <= 4.5 || k.abs_diff(i) == 1;
                    let u = (0..6).filter(|&k| reachable(k)).count() as f64;
                    let high = t.ratio / (u * t.ratio + 6.0 - u);
                    prior[i] * if reachable(j) { high } else { high / t.ratio }
                })
                .sum();
            assert_relative_eq!(p, dense, epsilon = 1e-15);
        }
    }
}
