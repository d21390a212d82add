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
