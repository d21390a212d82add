//! Hoang §6.1 on the simulated office: the whole pipeline (training scans, EM fit, site, engine)
//! must position to within the paper's ballpark.

use waymark_engine::radio::RssiModel;
use waymark_experiments as experiments;
use waymark_experiments::Experiment;
use waymark_sim as sim;
use waymark_sim::OfficeConfig;

fn experiment(seed: u64, model: RssiModel) -> Experiment {
    let base = Experiment::rssi_only();
    Experiment { office: OfficeConfig { seed, model, ..base.office.clone() }, walks: 20, ..base }
}

#[test]
fn rssi_only_tracking_is_near_hoangs_figure() {
    // Hoang Table 1, RSSI only: 1.74 m. Seeds 11-12 are used nowhere else.
    for seed in [11, 12] {
        let report = experiments::run(&experiment(seed, RssiModel::CensoredGaussian)).unwrap();
        let s = &report.summary;
        assert_eq!(report.states, 81);
        assert!(s.epochs > 2000, "{s:?}");
        assert!(s.mean_error_m < 2.0, "{s:?}");
        assert!(s.p90_error_m < 4.0, "{s:?}");
        // The 68% radius is neither wildly over- nor under-confident.
        assert!(s.accuracy_68_hit > 0.55 && s.accuracy_68_hit < 0.85, "{s:?}");
    }
}

#[test]
fn fusion_from_raw_imu_beats_radio_alone() {
    // The demo's engine: Hoang transitions, pseudo states, raw IMU. Seed 13 is used nowhere else.
    let fused = Experiment {
        office: OfficeConfig { seed: 13, ..OfficeConfig::default() },
        walks: 10,
        ..Experiment::default()
    };
    let radio = Experiment { office: fused.office.clone(), walks: 10, ..Experiment::rssi_only() };
    let (fused, radio) =
        (experiments::run(&fused).unwrap().summary, experiments::run(&radio).unwrap().summary);
    assert!(fused.mean_error_m < 0.7 * radio.mean_error_m, "fused {fused:?}\nradio {radio:?}");
    assert!(fused.p90_error_m < radio.p90_error_m, "fused {fused:?}\nradio {radio:?}");
}

#[test]
fn the_demo_is_deterministic() {
    let a = experiments::run(&experiment(3, RssiModel::CensoredGaussian)).unwrap();
    let b = experiments::run(&experiment(3, RssiModel::CensoredGaussian)).unwrap();
    assert_eq!(a.summary, b.summary);
    assert_eq!(a.first_track, b.first_track);
}

#[test]
fn the_simulated_site_survives_its_own_file_format() {
    let office = sim::Office::generate(&OfficeConfig::default());
    let text = office.site.to_json();
    let again = waymark_engine::Site::from_json(text.as_bytes()).unwrap();
    assert_eq!(again.to_json(), text);
    assert_eq!(again.states().len(), 81);
    assert_eq!(again.radio().transmitters().len(), 15);
}

#[test]
fn both_papers_orderings_hold_on_a_few_walks() {
    use waymark_experiments::{run_papers, PaperExperiment};
    // Seed 21 is used nowhere else; 10 walks keep the debug-build test short.
    let report = run_papers(&PaperExperiment { seed: 21, runs: 10, ..PaperExperiment::default() }).unwrap();
    let t = &report.hoang_table1;
    assert!(t.rssi_step_pseudo < t.rssi_step, "{t:?}");
    assert!(t.rssi_step < t.rssi_step_uncensored, "{t:?}");
    assert!(t.rssi_step_uncensored < t.rssi_only, "{t:?}");
    assert!(t.rssi_step_pseudo <= 0.8 * t.rssi_step, "pseudo-state gain below 20%: {t:?}");
    let h = &report.hipe_table5;
    assert!(h.distance_heading.mean_m <= h.distance.mean_m, "{h:?}");
    assert!(h.distance.mean_m <= h.heading_speed.mean_m, "{h:?}");
    assert!(h.speed.mean_m < h.mle.mean_m, "{h:?}");
    assert!(report.states_with_pseudo > 4 * report.surveyed_states);
}
