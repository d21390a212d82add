//! Issue 7, recovery: on two buildings, the engine is back to its normal error within 10
//! epochs of good data after being carried to the far end of the building, and after 10
//! minutes of walking without radio (`sim::recovery` states the definitions). The 20-seed
//! figures are `waymark simulate --experiment recovery` (README).

use waymark::sim::recovery::{self, RecoveryConfig, TARGET_EPOCHS};

#[test]
fn the_engine_recovers_from_a_kidnap_and_a_radio_outage_within_ten_epochs() {
    // Seeds 30-31 are used nowhere else.
    let config = RecoveryConfig { seeds: 2, first_seed: 30, cold_start: false, ..RecoveryConfig::default() };
    let report = recovery::run(&config, |_, _| {}).unwrap();
    for scenario in [&report.kidnapped, &report.radio_outage] {
        assert!(scenario.tolerance_m.is_finite() && scenario.tolerance_m < 3.0, "{scenario:?}");
        for run in &scenario.runs {
            assert!(run.disturbance_m > 30.0, "{run:?}");
            let r = run.epochs_to_recover;
            assert!(
                r.is_some_and(|r| r <= TARGET_EPOCHS),
                "{}: seed {} recovered after {r:?} epochs: {:?}",
                scenario.scenario,
                run.seed,
                run.errors_m
            );
            assert_eq!(run.errors_m.len(), config.after_epochs);
        }
    }
    // After the outage the engine soon says exactly what its undisturbed twin says.
    for run in &report.radio_outage.runs {
        assert!(run.epochs_to_forget.is_some_and(|r| r <= TARGET_EPOCHS), "{run:?}");
    }
}
