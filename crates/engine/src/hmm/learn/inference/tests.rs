//! Inference against dense log-space references, on peaked emissions and structural zeros.

use super::super::chain::SparseTransition;
use super::*;
use approx::assert_relative_eq;

fn chain(initial: Vec<f64>, a: &[Vec<f64>]) -> Chain {
    Chain::new(initial, SparseTransition::from_dense(a).unwrap()).unwrap()
}

/// Every path enumerated: p(o), P(s_t | o_1..t), P(s_t | o_1..T), best path.
#[allow(clippy::type_complexity)]
fn enumerate(
    initial: &[f64],
    a: &[Vec<f64>],
    e: &[Vec<f64>],
) -> (f64, Vec<Vec<f64>>, Vec<Vec<f64>>, Vec<u32>) {
    let (n, t_len) = (initial.len(), e.len());
    let mut smoothed = vec![vec![0.0; n]; t_len];
    let mut prefix = vec![vec![0.0; n]; t_len];
    let (mut total, mut best) = (0.0, (f64::NEG_INFINITY, vec![]));
    for code in 0..n.pow(t_len as u32) {
        let path: Vec<usize> = (0..t_len).map(|t| (code / n.pow(t as u32)) % n).collect();
        let mut p = initial[path[0]] * e[0][path[0]].exp();
        // P(s_1..t, o_1..t) summed over the continuations weighs each prefix once per
        // completion; divide by the number of completions.
        let mut prefix_p = vec![p];
        for t in 1..t_len {
            p *= a[path[t - 1]][path[t]] * e[t][path[t]].exp();
            prefix_p.push(p);
        }
        for t in 0..t_len {
            smoothed[t][path[t]] += p;
            if path[t + 1..].iter().all(|&s| s == 0) {
                prefix[t][path[t]] += prefix_p[t];
            }
        }
        total += p;
        if p.ln() > best.0 {
            best = (p.ln(), path.iter().map(|&s| s as u32).collect());
        }
    }
    let norm = |rows: Vec<Vec<f64>>| {
        rows.into_iter().map(|r| {
            let s: f64 = r.iter().sum();
            r.into_iter().map(|v| v / s).collect()
        })
    };
    (total.ln(), norm(prefix).collect(), norm(smoothed).collect(), best.1)
}

#[test]
fn matches_enumeration_with_structural_zeros() {
    let initial = vec![0.5, 0.3, 0.2];
    let a = vec![vec![0.7, 0.3, 0.0], vec![0.0, 0.4, 0.6], vec![0.5, 0.0, 0.5]];
    let e =
        vec![vec![-1.0, -2.0, -0.5], vec![-3.0, -0.2, -1.0], vec![-0.1, -4.0, -2.0], vec![-2.0, -2.0, -0.3]];
    let (ll, filtered, smoothed, path) = enumerate(&initial, &a, &e);
    let decoded = decode(&chain(initial, &a), &EpochMatrix::from_rows(3, &e).unwrap()).unwrap();
    assert_relative_eq!(decoded.posterior.log_likelihood, ll, max_relative = 1e-13);
    for t in 0..4 {
        for i in 0..3 {
            assert_relative_eq!(decoded.posterior.filtered.row(t)[i], filtered[t][i], epsilon = 1e-14);
            assert_relative_eq!(decoded.posterior.smoothed.row(t)[i], smoothed[t][i], epsilon = 1e-14);
        }
    }
    assert_eq!(decoded.viterbi, path);
}

#[test]
fn emissions_thousands_of_nats_apart_stay_finite() {
    // The best-explaining state is reachable only with probability 1e-250 each time.
    let a = vec![vec![1.0 - 1e-250, 1e-250], vec![0.5, 0.5]];
    let rows: Vec<Vec<f64>> =
        (0..200).map(|t| if t % 2 == 0 { vec![-5000.0, 0.0] } else { vec![0.0, -3000.0] }).collect();
    let chain = chain(vec![1.0, 0.0], &a);
    let e = EpochMatrix::from_rows(2, &rows).unwrap();
    let p = forward_backward(&chain, &e).unwrap();
    assert!(p.log_likelihood.is_finite());
    for t in 0..200 {
        for m in [&p.filtered, &p.smoothed] {
            let s: f64 = m.row(t).iter().sum();
            assert_relative_eq!(s, 1.0, epsilon = 1e-12);
            assert!(m.row(t).iter().all(|v| v.is_finite() && *v >= 0.0));
        }
    }
    let (path, lp) = viterbi(&chain, &e).unwrap();
    assert!(lp.is_finite());
    assert_eq!(path.len(), 200);
}

/// ln Σ exp over a full row, for the dense reference below.
fn dense_lse(v: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = v.collect();
    let m = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if m == f64::NEG_INFINITY {
        return m;
    }
    m + v.iter().map(|x| (x - m).exp()).sum::<f64>().ln()
}

#[test]
#[allow(clippy::needless_range_loop)] // the reference is written with indices, as the equations are
fn expected_counts_match_a_dense_log_space_reference_under_peaked_emissions() {
    // Two groups of three states closed by structural zeros; the group that explains the
    // sequence best is 900 nats behind the other at epoch 0, so its filtered probability
    // there is e^-900. The reference: unscaled ln α, ln β over full N × N, then eqs. 8-9.
    let a: Vec<Vec<f64>> = vec![
        vec![0.5, 0.5, 0.0, 0.0, 0.0, 0.0],
        vec![0.0, 0.3, 0.7, 0.0, 0.0, 0.0],
        vec![0.6, 0.0, 0.4, 0.0, 0.0, 0.0],
        vec![0.0, 0.0, 0.0, 0.2, 0.8, 0.0],
        vec![0.0, 0.0, 0.0, 0.0, 0.5, 0.5],
        vec![0.0, 0.0, 0.0, 0.9, 0.0, 0.1],
    ];
    let pi: Vec<f64> = vec![0.2, 0.2, 0.1, 0.2, 0.2, 0.1];
    let (n, epochs) = (6, 1200);
    let rows: Vec<Vec<f64>> = (0..epochs)
        .map(|t| {
            let (first, second) = if t == 0 { (0.0, -900.0) } else { (-700.0 - (t % 7) as f64, -1.0) };
            (0..n).map(|i| if i < 3 { first } else { second } - 0.5 * ((t * 5 + i * 3) % 4) as f64).collect()
        })
        .collect();
    let ln_a = |i: usize, j: usize| a[i][j].ln();
    let mut la = vec![vec![0.0; n]; epochs];
    let mut lb = vec![vec![0.0; n]; epochs];
    for i in 0..n {
        la[0][i] = pi[i].ln() + rows[0][i];
    }
    for t in 1..epochs {
        for j in 0..n {
            la[t][j] = dense_lse((0..n).map(|i| la[t - 1][i] + ln_a(i, j))) + rows[t][j];
        }
    }
    for t in (0..epochs - 1).rev() {
        for i in 0..n {
            lb[t][i] = dense_lse((0..n).map(|j| ln_a(i, j) + rows[t + 1][j] + lb[t + 1][j]));
        }
    }
    let ll = dense_lse(la[epochs - 1].iter().copied());
    let c = chain(pi.clone(), &a);
    let e = EpochMatrix::from_rows(n, &rows).unwrap();
    let mut smoothed = EpochMatrix::zeros(n, epochs);
    let counts =
        expected_counts(&c, &[(e.clone(), vec![])], |_, t, g| smoothed.row_mut(t).copy_from_slice(g))
            .unwrap();
    let (_, viterbi_lp) = viterbi(&c, &e).unwrap();
    assert!(counts.log_likelihood >= viterbi_lp, "{} < {viterbi_lp}", counts.log_likelihood);
    assert_relative_eq!(counts.log_likelihood, ll, max_relative = 1e-9);
    let close = |got: f64, want: f64| (got - want).abs() <= 1e-6 * got.abs().max(want.abs()).max(1e-100);
    for t in 0..epochs {
        for i in 0..n {
            let want = (la[t][i] + lb[t][i] - ll).exp();
            assert!(close(smoothed.row(t)[i], want), "γ_{t}({i}): {} vs {want}", smoothed.row(t)[i]);
        }
    }
    // Group 2 carries the sequence from epoch 0 on.
    assert!(smoothed.row(0)[3..].iter().sum::<f64>() > 0.999);
    let transition = c.transition();
    for i in 0..n {
        let (to, _) = transition.row(i);
        for (k, &j) in transition.row_range(i).zip(to) {
            let j = j as usize;
            let want: f64 = (0..epochs - 1)
                .map(|t| (la[t][i] + ln_a(i, j) + rows[t + 1][j] + lb[t + 1][j] - ll).exp())
                .sum();
            assert!(close(counts.transitions[k], want), "ξ({i}, {j}): {} vs {want}", counts.transitions[k]);
        }
    }
}

#[test]
fn pinned_epochs_condition_the_posterior() {
    let initial = vec![1.0 / 3.0; 3];
    let a = vec![vec![0.8, 0.1, 0.1], vec![0.1, 0.8, 0.1], vec![0.1, 0.1, 0.8]];
    let rows = vec![vec![-1.0, -1.2, -3.0], vec![-2.0, -0.5, -1.0], vec![-1.0, -1.0, -1.0]];
    let mut e = EpochMatrix::from_rows(3, &rows).unwrap();
    e.pin(&[Known { epoch: 1, states: vec![0, 2] }]).unwrap();
    let p = forward_backward(&chain(initial.clone(), &a), &e).unwrap();
    assert_eq!(p.filtered.row(1)[1], 0.0);
    assert_eq!(p.smoothed.row(1)[1], 0.0);
    // The same as enumerating with state 1 impossible at epoch 1.
    let mut masked = rows.clone();
    masked[1][1] = -1e4;
    let (ll, _, smoothed, _) = enumerate(&initial, &a, &masked);
    assert_relative_eq!(p.log_likelihood, ll, max_relative = 1e-12);
    assert_relative_eq!(p.smoothed.row(0)[2], smoothed[0][2], epsilon = 1e-14);
    let bad = |k: Known| e.clone().pin(&[k]).unwrap_err();
    assert!(matches!(bad(Known { epoch: 3, states: vec![0] }), LearnError::Dimension { .. }));
    assert!(matches!(bad(Known { epoch: 0, states: vec![5] }), LearnError::StateOutOfRange { .. }));
    assert!(matches!(bad(Known { epoch: 0, states: vec![] }), LearnError::Empty(_)));
}

#[test]
fn impossible_sequences_are_errors_not_nans() {
    let c = chain(vec![1.0, 0.0], &[vec![1.0, 0.0], vec![0.0, 1.0]]);
    let e = EpochMatrix::from_rows(2, &[vec![0.0, 0.0], vec![f64::NEG_INFINITY, 0.0]]).unwrap();
    assert_eq!(forward_backward(&c, &e).unwrap_err(), LearnError::Impossible { sequence: 0, epoch: 1 });
    assert_eq!(viterbi(&c, &e).unwrap_err(), LearnError::Impossible { sequence: 0, epoch: 1 });
    assert!(matches!(EpochMatrix::from_rows(2, &[vec![f64::NAN, 0.0]]), Err(LearnError::NonFinite { .. })));
    assert!(matches!(EpochMatrix::from_rows(2, &[vec![0.0]]), Err(LearnError::Dimension { .. })));
    let e3 = EpochMatrix::from_rows(3, &[vec![0.0; 3]]).unwrap();
    assert!(matches!(forward_backward(&c, &e3), Err(LearnError::Dimension { .. })));
}
