//! El Gemayel et al. §IV-C's shape on the simulated floor (`waymark simulate --experiment
//! baum-welch`): with user feedback given mainly at the beginning (Fig. 5's descending
//! feedback, from 0.2 to 0), parameters learned by Baum-Welch from §IV's initialisation come
//! within a few points of the true parameters' room accuracy, stay far above the
//! initialisation to the last run, and beat no feedback from the first run. Seeds 11 and 12
//! are used nowhere else (the CLI's default is 0, `FitOptions::default()` was measured on 1-3).
//!
//! The first version of this test asked for the last run, not the best, to be within 6 points
//! (on seeds 0-3 it ended 4, 5 and 1 below and 14 above). Seed 11 refuted it: 87.4% at run 4
//! against 90.4% for the true parameters, then down to 80.6% at run 10 as the feedback fades,
//! the decline the paper reports for its descending curves ("the information fed to the
//! algorithm decreases with each run", §IV-C).

use waymark::sim::baum_welch::{self, BaumWelchExperiment, Feedback, Schedule};

fn shape(seed: u64) {
    let schedule = |name: &str, feedback| Schedule { name: name.into(), transitions_known: false, feedback };
    let experiment = BaumWelchExperiment {
        seed,
        schedules: vec![
            schedule("no feedback", Feedback::Constant(0.0)),
            schedule("decaying 0.2→0", Feedback::Decaying(0.2)),
        ],
        ..BaumWelchExperiment::default()
    };
    let report = baum_welch::run(&experiment).unwrap();
    let (none, feedback) = (&report.curves[0].accuracy, &report.curves[1].accuracy);
    let last = *feedback.last().unwrap();
    let best = feedback[1..].iter().copied().fold(0.0, f64::max);
    let summary =
        format!("true {:.3}, no feedback {none:.3?}, decaying {feedback:.3?}", report.true_accuracy);
    // The forward algorithm with the true parameters does far better than the estimates alone.
    assert!(report.true_accuracy > report.estimate_accuracy + 0.3, "{summary}");
    // Learned: within a few points of the true parameters ...
    assert!(best > report.true_accuracy - 0.06, "{summary}");
    // ... and still far above §IV's initialisation after the last run.
    assert!(last > feedback[0] + 0.5, "{summary}");
    // Feedback helps from the first run on (without it Baum-Welch stays in a local maximum).
    assert!(feedback[1] > none[1] + 0.2, "{summary}");
    assert!(feedback.iter().chain(none).all(|a| a.is_finite()));
}

#[test]
fn early_feedback_learns_the_true_parameters_seed_11() {
    shape(11);
}

#[test]
fn early_feedback_learns_the_true_parameters_seed_12() {
    shape(12);
}
