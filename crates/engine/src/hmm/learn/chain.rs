//! The Markov chain: initial distribution π and a sparse transition matrix A that stores only
//! the allowed transitions (El Gemayel §II-B: transitions between non-adjacent places are known
//! to be zero), in compressed rows.

use super::LearnError;

/// How far a distribution's sum may be from 1 before it is refused; accepted ones are divided
/// by their sum. Chosen for files written by other tools: a 100-entry row of numbers printed
/// with 9 significant digits (the f32 round-trip format) errs by at most 100 × 5e-10 = 5e-8 in
/// its sum, and a row that is not meant to be a distribution is off by far more.
pub const ROW_SUM_TOLERANCE: f64 = 1e-6;

/// Checks that `values` is a probability distribution and returns its sum.
pub(super) fn check_distribution<'a>(
    what: &dyn Fn() -> String,
    values: impl Iterator<Item = &'a f64>,
) -> Result<f64, LearnError> {
    let mut sum = 0.0;
    for &p in values {
        if !p.is_finite() {
            return Err(LearnError::NonFinite { what: what(), value: p });
        }
        if p < 0.0 {
            return Err(LearnError::Negative { what: what(), value: p });
        }
        sum += p;
    }
    if (sum - 1.0).abs() > ROW_SUM_TOLERANCE {
        return Err(LearnError::NotStochastic { what: what(), sum });
    }
    Ok(sum)
}

/// A row-stochastic N × N matrix holding only its allowed entries, row by row (compressed
/// sparse rows): 12 bytes per allowed transition and 8 per state. An allowed entry may be zero
/// (Baum-Welch can drive one there); an entry that is not stored is a structural zero and no
/// re-estimation ever makes it positive.
#[derive(Clone, Debug, PartialEq)]
pub struct SparseTransition {
    /// Row i's entries are `start[i]..start[i + 1]`.
    start: Vec<usize>,
    /// Destination state of each entry, ascending within a row.
    to: Vec<u32>,
    /// a_ij of each entry.
    probability: Vec<f64>,
}

impl SparseTransition {
    /// From rows of (destination, probability). Each row must be a distribution (within
    /// 10⁻⁶, then divided by its sum) and name each destination at most once;
    /// entries given with probability 0 stay allowed.
    pub fn from_rows(rows: Vec<Vec<(u32, f64)>>) -> Result<Self, LearnError> {
        let n = rows.len();
        if n == 0 {
            return Err(LearnError::Empty("transition".into()));
        }
        if n > u32::MAX as usize {
            return Err(LearnError::Unsupported(format!("{n} states: at most 2^32 - 1 are supported")));
        }
        let mut start = Vec::with_capacity(n + 1);
        let mut to = Vec::new();
        let mut probability = Vec::new();
        start.push(0);
        for (i, mut row) in rows.into_iter().enumerate() {
            let what = || format!("transition[{i}]");
            row.sort_by_key(|&(j, _)| j);
            for pair in row.windows(2) {
                if pair[0].0 == pair[1].0 {
                    return Err(LearnError::Duplicate { what: what(), state: pair[0].0 as usize });
                }
            }
            if let Some(&(j, _)) = row.iter().find(|&&(j, _)| j as usize >= n) {
                return Err(LearnError::StateOutOfRange { what: what(), state: j as usize, states: n });
            }
            let sum = check_distribution(&what, row.iter().map(|(_, p)| p))?;
            to.extend(row.iter().map(|&(j, _)| j));
            probability.extend(row.iter().map(|&(_, p)| p / sum));
            start.push(to.len());
        }
        Ok(Self { start, to, probability })
    }

    /// From a dense matrix: its zeros are structural (not stored), its positive entries allowed.
    pub fn from_dense(rows: &[Vec<f64>]) -> Result<Self, LearnError> {
        let n = rows.len();
        let mut sparse = Vec::with_capacity(n);
        for (i, row) in rows.iter().enumerate() {
            if row.len() != n {
                return Err(LearnError::Dimension {
                    what: format!("transition[{i}]"),
                    expected: n,
                    got: row.len(),
                });
            }
            // Validated here too, so that a NaN or negative entry is reported, not dropped.
            check_distribution(&|| format!("transition[{i}]"), row.iter())?;
            sparse.push(
                row.iter().enumerate().filter(|(_, &p)| p != 0.0).map(|(j, &p)| (j as u32, p)).collect(),
            );
        }
        Self::from_rows(sparse)
    }

    /// N.
    pub fn states(&self) -> usize {
        self.start.len() - 1
    }

    /// Number of allowed transitions (stored entries).
    pub fn allowed(&self) -> usize {
        self.to.len()
    }

    /// Row i: destinations (ascending) and their probabilities.
    pub fn row(&self, i: usize) -> (&[u32], &[f64]) {
        let range = self.start[i]..self.start[i + 1];
        (&self.to[range.clone()], &self.probability[range])
    }

    /// Range of row i's entries in [`Self::probabilities`].
    pub fn row_range(&self, i: usize) -> std::ops::Range<usize> {
        self.start[i]..self.start[i + 1]
    }

    /// Destination of every stored entry, row after row.
    pub(super) fn destinations(&self) -> &[u32] {
        &self.to
    }

    /// Probability of every stored entry, row after row.
    pub fn probabilities(&self) -> &[f64] {
        &self.probability
    }

    /// The same pattern with new probabilities (one per stored entry; rows already normalised).
    pub(super) fn with_probabilities(&self, probability: Vec<f64>) -> Self {
        debug_assert_eq!(probability.len(), self.to.len());
        Self { start: self.start.clone(), to: self.to.clone(), probability }
    }

    /// a_ij (0 when not allowed).
    pub fn get(&self, i: usize, j: usize) -> f64 {
        let (to, p) = self.row(i);
        to.binary_search(&(j as u32)).map_or(0.0, |k| p[k])
    }

    /// The dense N × N matrix.
    pub fn to_dense(&self) -> Vec<Vec<f64>> {
        let n = self.states();
        (0..n)
            .map(|i| {
                let mut row = vec![0.0; n];
                let (to, p) = self.row(i);
                for (&j, &a) in to.iter().zip(p) {
                    row[j as usize] = a;
                }
                row
            })
            .collect()
    }
}

/// A Markov chain: initial distribution and transitions over the same N states.
#[derive(Clone, Debug, PartialEq)]
pub struct Chain {
    initial: Vec<f64>,
    transition: SparseTransition,
}

impl Chain {
    /// Checks that `initial` is a distribution over the transition's states (within
    /// 10⁻⁶, then divided by its sum).
    pub fn new(mut initial: Vec<f64>, transition: SparseTransition) -> Result<Self, LearnError> {
        let n = transition.states();
        if initial.len() != n {
            return Err(LearnError::Dimension { what: "initial".into(), expected: n, got: initial.len() });
        }
        let sum = check_distribution(&|| "initial".into(), initial.iter())?;
        initial.iter_mut().for_each(|p| *p /= sum);
        Ok(Self { initial, transition })
    }

    /// N.
    pub fn states(&self) -> usize {
        self.initial.len()
    }

    /// π.
    pub fn initial(&self) -> &[f64] {
        &self.initial
    }

    /// A.
    pub fn transition(&self) -> &SparseTransition {
        &self.transition
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dense_zeros_are_structural_and_rows_are_checked() {
        let a =
            SparseTransition::from_dense(&[vec![0.5, 0.5, 0.0], vec![0.0, 0.0, 1.0], vec![0.2, 0.3, 0.5]])
                .unwrap();
        assert_eq!(a.allowed(), 6);
        assert_eq!(a.row(1), (&[2u32][..], &[1.0][..]));
        assert_eq!(a.get(0, 2), 0.0);
        assert_eq!(a.to_dense()[2], vec![0.2, 0.3, 0.5]);
        let bad = |rows: &[Vec<f64>]| SparseTransition::from_dense(rows).unwrap_err();
        assert!(matches!(bad(&[vec![0.5, 0.4], vec![0.0, 1.0]]), LearnError::NotStochastic { .. }));
        assert!(matches!(bad(&[vec![1.5, -0.5], vec![0.0, 1.0]]), LearnError::Negative { .. }));
        assert!(matches!(bad(&[vec![f64::NAN, 1.0], vec![0.0, 1.0]]), LearnError::NonFinite { .. }));
        assert!(matches!(bad(&[vec![1.0], vec![0.0, 1.0]]), LearnError::Dimension { .. }));
        assert!(matches!(bad(&[vec![0.0, 0.0], vec![0.0, 1.0]]), LearnError::NotStochastic { .. }));
        assert!(matches!(bad(&[]), LearnError::Empty(_)));
    }

    #[test]
    fn sparse_rows_are_sorted_and_checked() {
        let a =
            SparseTransition::from_rows(vec![vec![(1, 0.25), (0, 0.75)], vec![(1, 0.0), (0, 1.0)]]).unwrap();
        assert_eq!(a.row(0), (&[0u32, 1][..], &[0.75, 0.25][..]));
        assert_eq!(a.allowed(), 4);
        assert!(matches!(
            SparseTransition::from_rows(vec![vec![(0, 0.5), (0, 0.5)]]).unwrap_err(),
            LearnError::Duplicate { .. }
        ));
        assert!(matches!(
            SparseTransition::from_rows(vec![vec![(3, 1.0)]]).unwrap_err(),
            LearnError::StateOutOfRange { .. }
        ));
        let chain = Chain::new(vec![0.5, 0.5 + 1e-9], a.clone()).unwrap();
        assert!((chain.initial().iter().sum::<f64>() - 1.0).abs() < 1e-15);
        assert!(matches!(Chain::new(vec![1.0], a).unwrap_err(), LearnError::Dimension { .. }));
    }
}
