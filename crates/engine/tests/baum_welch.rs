//! El Gemayel et al. §IV's shape on the simulated floor (`waymark simulate --experiment
//! baum-welch`), from §IV's initialisation (means at the cell centres, Σ = 2500 I, eq. 15):
//!
//! - Fig. 4: with the transition matrix known, the learned emissions approach the true
//!   parameters' room accuracy, and end above the initialisation on every seed;
//! - Fig. 5: with user feedback given mainly at the beginning (the descending feedback, from
//!   0.2 to 0), learning all the parameters approaches the true parameters too, and feedback is
//!   ahead of no feedback from the first run on every seed ("higher feedback rates at the
//!   beginning accelerate the learning curve"; without it Baum-Welch "may converge to a local
//!   maximum", §IV-C).
//!
//! Which local maximum Baum-Welch climbs depends on the seed (the walks, the biases, the
//! epochs with feedback), so "approach" is a median over six seeds, 17-22, used nowhere else
//! (the CLI's default is 0, `FitOptions::default()` was measured on 1-3): the last run within 5
//! points of the true parameters. Measured before this test was written (seeds 17-22, run 10
//! minus true): transitions known −1.4, +4.9, −1.8, −10.2, −2.3, +1.7 (median −1.6); decaying
//! −0.7, −8.8, −8.5, −2.6, −1.9, +1.2 (median −2.3).
//!
//! History of the claim:
//!
//! - before `FitOptions::mean_prior_weight` and with the anchors on the building's own corners,
//!   learning with the transitions known ended below §IV's initialisation (seed 0: 67% before,
//!   20% after, true parameters 87%), and the decaying curve's best run was only asserted
//!   within 15 points (median), since each seed's last run within 6 points was refuted by
//!   seeds 11 and 12 and the median of the best runs over seeds 11-16 within 6 points by 19,
//!   13, 12, 11, 5 and 4 points below;
//! - the true parameters at least 30 points above the position estimates alone, per seed:
//!   refuted (seed 17 then; on seed 2 now the true parameters score 42%: per-cell moments of a
//!   room with heavy-tailed estimates, `src/sim/baum_welch.rs`).

use waymark_experiments::baum_welch::{self, BaumWelchExperiment, BaumWelchReport, Feedback, Schedule};

fn experiment(seed: u64) -> BaumWelchReport {
    let schedule =
        |name: &str, transitions_known, feedback| Schedule { name: name.into(), transitions_known, feedback };
    let experiment = BaumWelchExperiment {
        seed,
        schedules: vec![
            schedule("A known", true, Feedback::Constant(0.0)),
            schedule("no feedback", false, Feedback::Constant(0.0)),
            schedule("decaying 0.2→0", false, Feedback::Decaying(0.2)),
        ],
        ..BaumWelchExperiment::default()
    };
    baum_welch::run(&experiment).unwrap()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    0.5 * (v[(n - 1) / 2] + v[n / 2])
}

#[test]
fn learned_parameters_approach_the_true_ones_and_feedback_speeds_it_up() {
    let seeds: Vec<u64> = (17..=22).collect();
    let reports: Vec<BaumWelchReport> = std::thread::scope(|scope| {
        let handles: Vec<_> = seeds
            .chunks(3)
            .map(|chunk| scope.spawn(move || chunk.iter().map(|&s| experiment(s)).collect::<Vec<_>>()))
            .collect();
        handles.into_iter().flat_map(|h| h.join().unwrap()).collect()
    });
    let (mut known_gaps, mut feedback_gaps) = (Vec::new(), Vec::new());
    for (seed, report) in seeds.iter().zip(&reports) {
        let [known, none, feedback] = [0, 1, 2].map(|k| &report.curves[k].accuracy);
        let summary = format!(
            "seed {seed}: true {:.3}, estimates {:.3}, A known {known:.3?}, no feedback {none:.3?}, decaying \
             {feedback:.3?}",
            report.true_accuracy, report.estimate_accuracy
        );
        println!("{summary}");
        assert!(known.iter().chain(none).chain(feedback).all(|a| a.is_finite()), "{summary}");
        // Fig. 4: learning the emissions improves on §IV's initialisation.
        assert!(*known.last().unwrap() > known[0], "{summary}");
        // Fig. 5: feedback is ahead from the first run, and far above the initialisation at the
        // last.
        assert!(feedback[1] > none[1], "{summary}");
        assert!(*feedback.last().unwrap() > feedback[0] + 0.3, "{summary}");
        known_gaps.push(known.last().unwrap() - report.true_accuracy);
        feedback_gaps.push(feedback.last().unwrap() - report.true_accuracy);
    }
    let (known_median, feedback_median) = (median(known_gaps.clone()), median(feedback_gaps.clone()));
    println!("last run minus true: A known {known_gaps:.3?} (median {known_median:.3}), decaying {feedback_gaps:.3?} (median {feedback_median:.3})");
    assert!(known_median > -0.05, "A known, last run minus true {known_gaps:.3?}");
    assert!(feedback_median > -0.05, "decaying feedback, last run minus true {feedback_gaps:.3?}");
}
