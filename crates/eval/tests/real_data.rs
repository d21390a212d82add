//! The recorded-data pipeline on a slice of the competition data: read, survey with
//! calibration, replay, score. Skips, saying so, when the data is not there. Where the data is
//! looked for: docs/testing.md#real-data.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use waymark_engine::Site;
use waymark_eval::real::{self, EvalOptions};
use waymark_survey::calibrate::{self, FloorData};
use waymark_survey::replay::{replay_observed, Call, ReplayOptions};

/// F1 unpacked under `target/`, or `None` (with a message) without the data.
fn floor_dir() -> Option<PathBuf> {
    // The workspace root, two levels above this crate.
    waymark_eval::data::or_skip(waymark_eval::data::site1_floor(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("../.."),
        "F1",
    ))
}

#[test]
fn a_slice_of_real_walks_surveys_calibrates_and_replays() {
    let Some(dir) = floor_dir() else { return };
    // The first 15 walk files: 12 survey walks, 3 test walks.
    let floor = FloorData::load(&dir, Some(15)).expect("the floor reads");
    assert_eq!((floor.survey.len(), floor.test.len()), (12, 3));
    assert!(floor.plan.is_some(), "F1 has a plan");
    let cached: usize = floor.survey.iter().map(|t| t.stats.cached_wifi).sum();
    assert!(cached > 0, "Android re-reports cached access points: the reader keeps their age");

    let options = EvalOptions { configurations: vec![], ..EvalOptions::default() };
    let floors = vec![floor];
    let (site, survey, calibration) =
        calibrate::survey_calibrated(&floors, &options.calibration, &|| {}).expect("survey");
    assert!(survey.floors[0].states > 50, "{survey:?}");
    let gamma = calibration.rssi_weight.expect("γ calibrated");
    assert!(calibrate::GAMMA_GRID.contains(&gamma));
    let scale = calibration.accuracy_scale.expect("radii calibrated");
    assert!(scale.iter().all(|s| s.is_finite() && *s > 0.0));
    // Per motion scenario where enough held-out epochs were on the map.
    assert!(calibration.epochs > 0);
    for scenario in waymark_engine::sensors::MotionScenario::ALL {
        let own = calibration.accuracy_scale_by_scenario.get(scenario);
        let enough = calibration.scenario_epochs[scenario.index()] >= calibrate::MIN_SCENARIO_EPOCHS;
        assert_eq!(own.is_some(), enough, "{scenario:?}: {calibration:?}");
        assert!(own.is_none_or(|s| s.iter().all(|s| s.is_finite() && *s > 0.0)));
    }
    assert!(calibration
        .accuracy_scale_by_scenario
        .get(waymark_engine::sensors::MotionScenario::DistanceHeading)
        .is_some());
    assert!(calibration.motion.is_some(), "step length and north fitted");
    // The fingerprint radius: neighbouring radii of the grid from its middle scored on
    // held-out walks, the least error chosen and surveyed with, inside what was tried unless
    // at the grid's end.
    let curve = &calibration.fingerprint_radius_mean_error_m;
    let grid = calibrate::FINGERPRINT_RADIUS_GRID;
    let tried: Vec<usize> = curve.iter().map(|c| grid.iter().position(|&r| r == c.0).unwrap()).collect();
    assert!(tried.len() >= 3 && tried.windows(2).all(|w| w[1] == w[0] + 1), "{curve:?}");
    assert!(tried.contains(&(grid.len() / 2)));
    assert!(curve.iter().all(|c| c.1.is_finite() && c.1 > 0.0 && c.2 > 0), "{curve:?}");
    let least = (0..curve.len()).min_by(|&a, &b| curve[a].1.total_cmp(&curve[b].1)).unwrap();
    assert_eq!(calibration.fingerprint_radius_m, curve[least].0);
    assert!(least > 0 || tried[0] == 0, "the search stops only at a valley: {curve:?}");
    assert!(least + 1 < curve.len() || tried[least] + 1 == grid.len(), "{curve:?}");
    // Leave-one-walk-out: every survey walk held out once, γ per floor with its curve.
    assert_eq!(calibration.sites, 12);
    let floor = &calibration.floors[0];
    assert_eq!(floor.gamma.len(), calibrate::GAMMA_GRID.len());
    assert_eq!(floor.gamma.iter().map(|p| p.walks_preferring).sum::<usize>(), floor.walks);
    // γ again on the walks the others cover end to end, replayed as shipped at every γ: their
    // least where they have enough epochs, else the first curve's.
    let least = |curve: &[(f64, f64)]| curve.iter().min_by(|a, b| a.1.total_cmp(&b.1)).map(|p| p.0);
    let searched = least(&calibration.gamma_mean_error_m).unwrap();
    let covered = &calibration.gamma_covered_mean_error_m;
    assert!(
        calibration.covered_walks <= floors[0].survey.len()
            && (calibration.covered_walks == 0) == covered.is_empty()
    );
    let full_grid = covered.iter().map(|p| p.0).eq(calibrate::GAMMA_GRID);
    assert!(covered.is_empty() || full_grid, "{covered:?}");
    if calibration.covered_epochs >= calibrate::MIN_SCENARIO_EPOCHS {
        assert_eq!(Some(gamma), least(covered));
    } else {
        assert_eq!(gamma, searched, "{calibration:?}");
    }
    // One floor: its best γ is the site-wide one, so it records none of its own.
    assert_eq!(floor.best_rssi_weight, Some(gamma));
    let floor_gamma = floor.rssi_weight;
    assert_eq!(floor_gamma, None, "{floor:?}");
    assert!(floor.jackknife_se_m.is_some_and(|se| se.is_finite() && se > 0.0), "{floor:?}");
    assert!(calibration.refitted_share > 0.0 && calibration.refitted_share < 1.0);
    assert_eq!(site.floors()[0].rssi_weight, floor_gamma);
    // M of eq. 4: every M of the grid scored at the chosen γ, the least error chosen, and at
    // M = 3 the held-out error is the γ curve's own (the same replays, up to ties in the
    // ranking of states).
    let by_m = &calibration.estimate_states_mean_error_m;
    assert_eq!(by_m.iter().map(|p| p.0).collect::<Vec<_>>(), calibrate::ESTIMATE_STATES_GRID, "{by_m:?}");
    let least = by_m.iter().min_by(|a, b| a.1.total_cmp(&b.1)).unwrap();
    assert_eq!(calibration.estimate_states, Some(least.0 as u32));
    assert_eq!(site.calibration().estimate_states, calibration.estimate_states);
    let at_gamma = calibration.gamma_mean_error_m.iter().find(|p| p.0 == gamma).unwrap().1;
    let at_3 = by_m.iter().find(|p| p.0 == 3).unwrap().1;
    assert!((at_3 - at_gamma).abs() < 0.05 * at_gamma, "{at_3} against {at_gamma}");
    // The radio fit floor, and the held-out walks replayed as shipped: every epoch of the
    // calibration's own replays again, on the map or beyond it.
    let floor_fit = calibration.radio_fit_floor;
    let enough = calibration.radio_fit_scans >= calibrate::MIN_SCENARIO_EPOCHS;
    assert_eq!(floor_fit.is_some(), enough, "{calibration:?}");
    assert!(floor_fit.is_none_or(f64::is_finite));
    assert!(calibration.radio_fit_scans > 0 && calibration.radio_fit_scans <= calibration.epochs);
    assert_eq!(site.calibration().radio_fit_floor, floor_fit);
    let epochs = |r: &calibrate::OffMapReport| r.bands.iter().map(|b| b.epochs).sum::<usize>();
    assert_eq!(epochs(&calibration.on_map), calibration.epochs, "{calibration:?}");
    assert_eq!(epochs(&calibration.off_map), calibration.epochs_off_map, "{calibration:?}");
    assert_eq!(epochs(&calibration.off_map_without_floor), calibration.epochs_off_map);
    // The floor's coverage comes from the same replays as shipped: its epochs on the map are
    // those the radius factors were fitted on.
    let coverage = &floor.coverage;
    assert_eq!(coverage.epochs - coverage.beyond_map, calibration.epochs, "{coverage:?}");
    assert!(coverage.mean_error_on_map_m.is_finite() && coverage.mean_error_on_map_m > 0.0, "{coverage:?}");
    assert!(coverage.beyond_map == 0 || coverage.mean_error_beyond_map_m.is_finite(), "{coverage:?}");
    assert_eq!(coverage.beyond_map_points.len(), coverage.beyond_map);
    // The coverage map: every such epoch as a GeoJSON point with its walk, on the floor's plan
    // (its longitude/latitude box, read from the competition's GeoJSON).
    let geojson = calibrate::coverage_geojson(&site, &calibration).expect("F1 has a plan");
    let geojson = serde_json::to_value(geojson).unwrap();
    let features = geojson["features"].as_array().unwrap();
    assert_eq!(features.len(), coverage.beyond_map);
    assert!(!features.is_empty(), "12 walks leave stretches only one of them walked");
    let [lo, hi] = floors[0].plan.as_ref().and_then(|p| p.lon_lat_box).expect("a GeoJSON plan");
    let survey_walks: Vec<&str> = floors[0].survey.iter().map(|t| t.name.as_str()).collect();
    for feature in features {
        let at = &feature["geometry"]["coordinates"];
        let (lon, lat) = (at[0].as_f64().unwrap(), at[1].as_f64().unwrap());
        assert!((lo[0]..=hi[0]).contains(&lon) && (lo[1]..=hi[1]).contains(&lat), "{feature}");
        let properties = &feature["properties"];
        assert!(survey_walks.contains(&properties["walk"].as_str().unwrap()), "{feature}");
        assert_eq!(properties["floor"], "F1");
        assert!(properties["beyond_map_m"].as_f64().is_some_and(|m| m > 0.0), "{feature}");
    }
    // GeoJSON has no frame but WGS84: a site without an anchor has no coverage map.
    let unanchored = site.clone().with_anchor(None).unwrap();
    assert!(calibrate::coverage_geojson(&unanchored, &calibration).is_none());

    // Sparse scans: the covered walks replayed throttled at the same γ, their own γ only when
    // it beats the site-wide one beyond its standard error, and a band's radius factors where
    // it has enough epochs on the map.
    let sparse = &calibration.sparse_scans;
    let tried: Vec<f64> = covered.iter().map(|p| p.0).collect();
    assert_eq!(sparse.gamma.iter().map(|p| p.gamma).collect::<Vec<_>>(), tried, "{sparse:?}");
    assert!(sparse.epochs_by_since.iter().sum::<usize>() > 0, "{sparse:?}");
    for (band, &n) in sparse.epochs_by_since.iter().enumerate() {
        let own = sparse.calibration.accuracy_scale_by_since[band];
        assert_eq!(own.is_some(), n >= calibrate::MIN_SCENARIO_EPOCHS, "{sparse:?}");
    }
    if let Some(g) = sparse.calibration.rssi_weight {
        let at = |g: f64| sparse.gamma.iter().find(|p| p.gamma == g).unwrap();
        assert!(at(gamma).mean_error_m - at(g).mean_error_m > at(g).jackknife_se_m, "{sparse:?}");
    }
    assert_eq!(site.calibration().sparse_scans, sparse.calibration);
    // One floor: the floor is never in doubt, so there is no floor probability to calibrate.
    for floor in [&calibration.floor_reliability, &sparse.floor_reliability] {
        assert!(floor.calibration.is_empty() && floor.epochs_right_by_band == [[0, 0]; 5], "{floor:?}");
    }

    // Unsurveyed states around the surveyed ones, on the floor's plan, none with a fingerprint.
    let kind = |i: u32| site.states()[i as usize].kind;
    assert!(site.states().iter().any(|s| s.kind == waymark_engine::site::StateKind::Unsurveyed));
    assert!(site
        .radio()
        .fingerprints()
        .all(|(i, _, _)| kind(i) != waymark_engine::site::StateKind::Unsurveyed));

    // The calibrated site survives its file format.
    let site = Arc::new(Site::from_json(site.to_json().as_bytes()).expect("reloads"));
    assert_eq!(site.calibration().rssi_weight, Some(gamma));
    assert_eq!(site.calibration().accuracy_scale_by_scenario, calibration.accuracy_scale_by_scenario);
    assert_eq!(site.calibration().radio_fit_floor, floor_fit);
    assert_eq!(site.calibration().sparse_scans, sparse.calibration);
    assert_eq!(site.floors()[0].rssi_weight, floor_gamma);

    // The site keeps the survey's reading-age limit, so an engine with the default
    // configuration (an app's, and the evaluation's) replays a walk as one given the survey's
    // limit does: readings the survey left out are left out. Each published position is one
    // observed epoch.
    assert_eq!(site.max_reading_age_ns(), Some(options.calibration.survey.max_reading_age_ns));
    let site_arc = Arc::new(site.clone());
    let walk = &floors[0].test[0];
    let replayed = |config: waymark_engine::EngineConfig| {
        let mut engine = waymark_engine::Engine::new(Arc::clone(&site_arc), config).unwrap();
        let mut epochs = 0;
        let r = replay_observed(&mut engine, walk, &ReplayOptions::default(), &mut |call| {
            epochs +=
                usize::from(matches!(call, Call::Scan { published: true } | Call::Timer { published: true }));
        });
        (r.positions, epochs, engine.stats().readings_stale)
    };
    let (app, app_epochs, stale) = replayed(waymark_engine::EngineConfig::default());
    let survey_limit = Some(options.calibration.survey.max_reading_age_ns);
    let (limited, _, _) =
        replayed(waymark_engine::EngineConfig { max_reading_age_ns: survey_limit, ..Default::default() });
    assert_eq!(app, limited);
    assert_eq!(app_epochs, app.len());
    assert!(stale > 0, "the walk's cached readings are left out");

    let (reports, walks) = real::evaluate_on(&site, &floors, &options, &|| {}).expect("replays");
    assert_eq!(walks.len(), 3);
    for key in real::CONFIGURATIONS {
        let m = &reports[key].pooled;
        assert!(m.epochs > 0, "{key} scored nothing");
        assert!(m.mean_m.is_finite() && m.mean_m < 40.0, "{key}: {m:?}");
        assert_eq!(m.floor_hit, 1.0, "one floor: {key}");
        // Live positions report a floor probability, smoothed ones and single scans none.
        let live = key.starts_with("forward");
        let near = |v: Option<f64>, to: f64| v.map(|v| (v - to).abs() < 1e-12);
        assert_eq!(near(m.floor_probability_mean, 1.0), live.then_some(true), "{key}: {m:?}");
        assert_eq!(near(m.floor_brier, 0.0), live.then_some(true), "{key}: {m:?}");
    }
    // The fused engine beats a single scan on average even on this small survey.
    assert!(reports["forward-auto"].pooled.mean_m < reports["wifi-mle"].pooled.mean_m + 1.0);

    // Habits from the survey walks, their strength chosen on the held-out half of them, on
    // sites surveyed as the calibrated one was.
    let options = options.surveyed_with(&calibration);
    assert_eq!(options.calibration.survey.fingerprint_radius_m, calibration.fingerprint_radius_m);
    assert!(!options.calibration.calibrate_fingerprint_radius);
    let (model, learning, selection) = real::survey_habits(&site, &floors, &options).expect("habits");
    assert!(learning.epochs > 0 && learning.feedback_epochs > 0, "{learning:?}");
    assert_eq!(selection.walks, 12, "every survey walk held out once");
    assert!(selection.epochs > 0);
    assert_eq!(selection.pass_strength, learning.strength);
    assert_eq!(selection.strengths.len(), real::HELD_OUT_STRENGTHS.len());
    for p in &selection.strengths {
        for d in [p.forward_m, p.fixed_lag_m, p.viterbi_m] {
            assert!(d[0].is_finite() && d[1].is_finite() && d[1] >= 0.0, "{p:?}");
        }
    }
    assert_eq!(real::choose_held_out_strength(&selection.strengths).is_some(), selection.strength.is_some());
    assert_eq!(model.strength(), selection.strength);
}

/// Two floors as one site, from a few walks each: the calibration fits how often the floor
/// was right per band of the posterior's mass on it, steady and sparse, and engines on the
/// site report it.
#[test]
fn a_two_floor_slice_calibrates_its_floor_probability() {
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let Some(dirs) = waymark_eval::data::or_skip(
        ["B1", "F1"]
            .iter()
            .map(|f| waymark_eval::data::site1_floor(&workspace, f))
            .collect::<Option<Vec<_>>>(),
    ) else {
        return;
    };
    let floors: Vec<FloorData> =
        dirs.iter().map(|d| FloorData::load(d, Some(10)).expect("the floor reads")).collect();
    let options = EvalOptions { configurations: vec!["forward-auto".into()], ..EvalOptions::default() };
    let (site, _, calibration) =
        calibrate::survey_calibrated(&floors, &options.calibration, &|| {}).expect("survey");
    for (floor, stored) in [
        (&calibration.floor_reliability, site.calibration().floor_reliability),
        (&calibration.sparse_scans.floor_reliability, site.calibration().sparse_scans.floor_reliability),
    ] {
        let epochs: usize = floor.epochs_right_by_band.iter().map(|c| c[1]).sum();
        assert!(floor.epochs_right_by_band.iter().all(|[right, all]| right <= all), "{floor:?}");
        assert_eq!(floor.calibration.is_empty(), epochs < calibrate::MIN_SCENARIO_EPOCHS, "{floor:?}");
        assert_eq!(stored, floor.calibration);
        let shares: Vec<f64> = floor.calibration.0.iter().flatten().copied().collect();
        assert!(
            shares.windows(2).all(|w| w[0] <= w[1]) && shares.iter().all(|p| (0.0..=1.0).contains(p)),
            "{floor:?}"
        );
    }
    assert!(!calibration.floor_reliability.calibration.is_empty(), "{:?}", calibration.floor_reliability);
    // The live positions report the tables' shares, and the score reads them.
    let site = Arc::new(site);
    let shares: Vec<f64> =
        [site.calibration().floor_reliability, site.calibration().sparse_scans.floor_reliability]
            .iter()
            .flat_map(|t| t.0.iter().flatten().copied())
            .collect();
    let mut engine =
        waymark_engine::Engine::new(Arc::clone(&site), waymark_engine::EngineConfig::default()).unwrap();
    let positions =
        replay_observed(&mut engine, &floors[1].test[0], &ReplayOptions::default(), &mut |_| {}).positions;
    assert!(!positions.is_empty());
    for p in &positions {
        assert!(shares.contains(&p.floor_probability), "{} not in {shares:?}", p.floor_probability);
    }
    let (reports, _) = real::evaluate_on(&site, &floors, &options, &|| {}).expect("replays");
    let m = &reports["forward-auto"].pooled;
    let (p, brier) = (m.floor_probability_mean.unwrap(), m.floor_brier.unwrap());
    assert!(p > 0.0 && p <= 1.0 && (0.0..=1.0).contains(&brier), "{m:?}");
}

/// A real floor plan (hundreds of rooms in lon/lat) drawn under a walk: every ring of the plan
/// and the walk's truth end up in the SVG.
#[test]
fn a_real_floor_plan_draws_under_a_walk() {
    use waymark_eval::plot::{plot_walk, Track};
    let Some(dir) = floor_dir() else { return };
    let plan = waymark_survey::io::FloorPlan::read(&dir).expect("F1's plan reads");
    let rings: usize =
        plan.outline.iter().chain(plan.rooms.iter().map(|r| &r.polygon)).map(|p| p.rings.len()).sum();
    assert!(rings > 100, "F1 has over a hundred shop outlines, got {rings}");
    let out = std::env::temp_dir().join(format!("waymark-real-plan-{}", std::process::id()));
    std::fs::create_dir_all(&out).unwrap();
    let file = out.join("walk.svg");
    let truth = [(plan.width_m * 0.2, plan.height_m * 0.2), (plan.width_m * 0.8, plan.height_m * 0.7)];
    let estimate = [(plan.width_m * 0.25, plan.height_m * 0.2)];
    plot_walk(&file, "F1", Some(&plan), &truth, &[Track { label: "estimate", points: &estimate }]).unwrap();
    let svg = std::fs::read_to_string(&file).unwrap();
    assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
    assert!(svg.matches("<polyline").count() > rings, "every ring and the truth are drawn");
    assert!(svg.contains("estimate"), "the legend names the track");
    std::fs::remove_dir_all(out).ok();
}

#[test]
fn the_museum_reads_as_two_phones_three_floors_and_one_frame() {
    let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let Some(dir) = waymark_eval::data::or_skip(waymark_eval::data::ipin2023_t3(&workspace)) else { return };
    let walks = |floors: &[FloorData]| floors.iter().map(|f| f.survey.len() + f.test.len()).sum::<usize>();
    // Every walk surveys: 50 logfiles, two of them changing floors. Trial 51 goes
    // 0, -1, -2, -1, 0, -1, -2, -1, 0 and trial 52 0, -2, 0, -2, 0; their stays of two points
    // or more (seven and three) survey, so 48 + 10 walks on single floors.
    let all = calibrate::load_building(std::slice::from_ref(&dir), &calibrate::WalkSplit::All, None)
        .expect("reads");
    assert_eq!(all.iter().map(|f| f.name.as_str()).collect::<Vec<_>>(), ["L-2", "L-1", "L0"]);
    assert_eq!(walks(&all), 58);
    // Each stay is at least ten seconds of walking: a few scans, hundreds of samples.
    for trace in all.iter().flat_map(|f| &f.survey) {
        assert!(trace.waypoints.len() >= 2 && trace.wifi_scans.len() >= 2, "{}", trace.name);
        assert!(trace.accelerometer.len() > 100 && !trace.pressure.is_empty(), "{}", trace.name);
        // The frame is the museum's: a few hundred metres at most from its centre.
        assert!(trace.waypoints.iter().all(|w| w.x.hypot(w.y) < 200.0), "{}", trace.name);
    }
    // Cross-phone: one phone surveys, the other's 24 or 26 walks test.
    for (model, tests) in [("SM-A520F", 26), ("SM-G930F", 24)] {
        let floors = calibrate::load_building(
            std::slice::from_ref(&dir),
            &calibrate::WalkSplit::Phone(model.into()),
            None,
        )
        .expect("reads");
        assert_eq!(floors.iter().map(|f| f.test.len()).sum::<usize>(), tests, "{model}");
        for trace in floors.iter().flat_map(|f| &f.survey) {
            assert!(trace.device.as_deref().is_some_and(|d| d.ends_with(model)), "{}", trace.name);
        }
    }
}
