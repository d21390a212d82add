//! A site for timing the engine at building scale without `waymark survey`'s calibration (its
//! thousands of held-out replays): every walk of the floors surveyed at a given fingerprint
//! radius, with γ given instead of calibrated (the states, fingerprints and walking-distance
//! tables are those of `waymark survey` at that radius; no radius factors, no radio fit
//! floor). `site_epoch_time` then times an engine on it (`docs/results.md#speed`).
//!
//! ```text
//! cargo run --release -p waymark-eval --example timing_site -- OUT.wmsite RADIUS_M GAMMA GAMMA_STILL FLOOR...
//! ```

use std::path::PathBuf;
use waymark_engine::site::Calibration;
use waymark_survey::calibrate::{survey_inputs, FloorData};
use waymark_survey::SurveyOptions;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [out, radius, gamma, still, floors @ ..] = args.as_slice() else {
        eprintln!("usage: timing_site OUT.wmsite RADIUS_M GAMMA GAMMA_STILL FLOOR...");
        std::process::exit(2);
    };
    let number = |s: &str| s.parse::<f64>().unwrap_or_else(|e| panic!("`{s}`: {e}"));
    let floors: Vec<FloorData> = floors
        .iter()
        .map(|d| {
            let mut floor = FloorData::load(&PathBuf::from(d), None).unwrap_or_else(|e| panic!("{d}: {e}"));
            // Every walk surveys, as `waymark survey` does.
            floor.survey.append(&mut floor.test);
            floor
        })
        .collect();
    let options = SurveyOptions { fingerprint_radius_m: number(radius), ..SurveyOptions::default() };
    let all: Vec<&waymark_survey::io::Trace> = floors.iter().flat_map(|f| &f.survey).collect();
    let motion = waymark_survey::calibrate_motion(&all, &waymark_engine::EngineConfig::default().motion);
    let north = motion.as_ref().map_or_else(Default::default, |m| m.north());
    let (site, _) = waymark_survey::survey("timing", &survey_inputs(&floors), north, &options)
        .unwrap_or_else(|e| panic!("survey: {e}"));
    let calibration = Calibration {
        rssi_weight: Some(number(gamma)),
        rssi_weight_without_movement: Some(number(still)),
        step_length: motion.as_ref().map(|m| m.step_length),
        ..Calibration::default()
    };
    let site = site.with_calibration(calibration).unwrap_or_else(|e| panic!("calibration: {e}"));
    std::fs::write(out, site.to_binary()).unwrap_or_else(|e| panic!("{out}: {e}"));
    println!("{} states written to {out}", site.states().len());
}
