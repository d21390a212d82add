//! Issue 7, recovery: on two buildings, the engine is back to its normal error within 10
//! epochs of good data after being carried to the far end of the building, and after 10
//! minutes of walking without radio. Back to normal means, for 5 epochs, within the tolerance
//! or no worse than an undisturbed engine given the same input (`sim::recovery` states the
//! rule and why). The 20- and 50-seed figures are `waymark simulate --experiment recovery`
//! (README).

use waymark_experiments::recovery::{self, RecoveryConfig, HOLD_EPOCHS, SAME_PLACE_M, TARGET_EPOCHS};

#[test]
fn the_engine_recovers_from_a_kidnap_and_a_radio_outage_within_ten_epochs() {
    // Seeds 30-31 are used nowhere else.
    let config = RecoveryConfig { seeds: 2, first_seed: 30, comparisons: false, ..RecoveryConfig::default() };
    let report = recovery::run(&config, |_, _| {}).unwrap();
    for scenario in [&report.kidnapped, &report.radio_outage] {
        let tolerance = scenario.tolerance_m;
        assert!(tolerance.is_finite() && tolerance < 3.0, "{scenario:?}");
        // The rule lets a run off wherever its reference errs as much, so the references must
        // be engines at their normal error, not lost ones: pooled over the scored epochs, within
        // the tolerance's own factor of the normal median and p90.
        let [median, p90] = scenario.reference_error_m;
        assert!(
            median <= 1.5 * scenario.normal_median_m && p90 <= 1.5 * scenario.normal_p90_m,
            "{scenario:?}"
        );
        for run in &scenario.runs {
            assert!(run.disturbance_m > 30.0, "{run:?}");
            assert_eq!(run.errors_m.len(), config.after_epochs);
            assert_eq!(run.reference_errors_m.len(), config.after_epochs);
            let r = run.epochs_to_recover;
            assert!(
                r.is_some_and(|r| r <= TARGET_EPOCHS),
                "{}: seed {} recovered after {r:?} epochs:\n  errors    {:?}\n  reference {:?}",
                scenario.scenario,
                run.seed,
                run.errors_m,
                run.reference_errors_m
            );
            // From then on, epoch by epoch, as good as the tolerance or the reference.
            let r = r.unwrap_or_default();
            for (e, reference) in
                run.errors_m.iter().zip(&run.reference_errors_m).skip(r - 1).take(HOLD_EPOCHS)
            {
                assert!(*e <= tolerance || *e <= reference + SAME_PLACE_M, "{run:?}");
            }
        }
    }
    // The outage did lose the engine (it dead-reckoned 10 minutes), so recovering was needed;
    // and soon after it the engine says exactly what its undisturbed twin says.
    for run in &report.radio_outage.runs {
        assert!(run.error_before_m > report.radio_outage.tolerance_m, "{run:?}");
        assert!(run.epochs_to_forget.is_some_and(|r| r <= TARGET_EPOCHS), "{run:?}");
    }
}
