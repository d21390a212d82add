//! `waymark eval`: a survey on the survey walks of the given floors, the test walks replayed
//! through every configuration, and their errors.

use crate::shared::{fail, print_calibration, progress_bar};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;
use waymark_eval::real::{self as evaluation, EvalOptions, CONFIGURATIONS};
use waymark_survey::calibrate::{self, FloorData, WalkSplit};
use waymark_survey::io::Trace;

#[derive(clap::Args)]
pub struct EvalArgs {
    /// Floor folders of one building: given together, they make one multi-floor site and the
    /// engine must find the floor itself. Or one folder of GetSensorData logfiles (the IPIN
    /// competitions' format), split by `--split`.
    #[arg(required = true)]
    floors: Vec<PathBuf>,
    /// How a folder of GetSensorData logfiles splits into survey and test walks:
    /// `phone:MODEL` (that phone's walks survey), `repetitions:1,3` (those repetitions survey).
    /// Floor folders split by file index whatever this says.
    #[arg(long, default_value = "repetitions:1,3")]
    split: WalkSplit,
    /// Print one JSON object instead of the tables.
    #[arg(long)]
    json: bool,
    /// Draw each test walk (floor plan, truth, tracks) and the error CDFs as SVG into DIR.
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Only these configurations (comma-separated keys); default all.
    #[arg(long, value_delimiter = ',')]
    configurations: Vec<String>,
    /// Use only the first N walk files of each floor (by name; the split applies after).
    #[arg(long)]
    max_walks: Option<usize>,
    /// Keep this share F (0 < F ≤ 1) of each floor's survey walks, the same ones on every run
    /// (walk i of the floor's survey walks by name when ⌈(i+1)·F⌉ > ⌈i·F⌉); the test walks do
    /// not change.
    #[arg(long, default_value_t = 1.0, value_parser = calibrate::parse_survey_fraction)]
    survey_fraction: f64,
    /// Give the survey walks that --survey-fraction leaves out back as walks without labels
    /// (no waypoints, no floor): their map evidence refits the site (docs/evidence.md).
    #[arg(long)]
    unlabelled_rest: bool,
    /// Test walks of these repetitions (`_repetitionRR` in a competition file's name,
    /// comma-separated) are not scored but given to the survey without labels, as
    /// --unlabelled-rest gives the walks --survey-fraction leaves out: one phone's walks
    /// labelled and the other's not, scored on the other's remaining walks.
    #[arg(long, value_delimiter = ',')]
    test_as_unlabelled: Vec<u32>,
    /// Test walks of these repetitions are not scored but surveyed, with their labels: the
    /// baseline of --test-as-unlabelled on the same test walks.
    #[arg(long, value_delimiter = ',', conflicts_with = "test_as_unlabelled")]
    test_as_labelled: Vec<u32>,
    /// The crowd protocol (docs/evidence.md#the-crowd-protocol): the test walks in K folds,
    /// each fold scored on the site refitted with the other folds' test walks given without
    /// labels (no waypoints, no floor).
    #[arg(long, conflicts_with_all = ["unlabelled_rest", "test_as_unlabelled", "test_as_labelled"])]
    crowd_folds: Option<usize>,
    /// With --unlabelled-rest: rounds of anchoring the unlabelled walks where the site is sure
    /// of them and surveying them with the labelled ones.
    #[arg(long, default_value_t = 1)]
    anchor_rounds: usize,
    /// With --unlabelled-rest: rounds of refitting with every scan's soft label after those.
    #[arg(long, default_value_t = 0)]
    evidence_rounds: usize,
    /// With --evidence-rounds: the share of each scan's posterior its evidence keeps, most
    /// probable states first (default: the survey's).
    #[arg(long)]
    evidence_mass: Option<f64>,
    /// With --evidence-rounds: the most states of each scan's posterior its evidence keeps,
    /// most probable first, 0 for all (default: the survey's).
    #[arg(long)]
    evidence_states: Option<usize>,
    /// With --unlabelled-rest: the anchored walks only pool with the labelled fingerprints
    /// they contradict, instead of replacing them (docs/evidence.md#refitting).
    #[arg(long)]
    keep_contradicted: bool,
    /// With --unlabelled-rest: where the anchored walks confirm a labelled fingerprint, keep
    /// the labelled scans' own fit instead of pooling both (`ReplaceRule::pool_confirmed`).
    #[arg(long, conflicts_with = "keep_contradicted")]
    keep_confirmed: bool,
    /// γ of Hoang eq. 14; default: calibrated by the survey.
    #[arg(long)]
    gamma: Option<f64>,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Grid spacing of the surveyed states, m (default 2).
    #[arg(long)]
    spacing_m: Option<f64>,
    /// A survey scan trains the states within this distance, m (default: chosen by the
    /// survey's cross-validation, `FINGERPRINT_RADIUS_GRID`).
    #[arg(long)]
    fingerprint_radius_m: Option<f64>,
    /// Unsurveyed states (no fingerprint) fill walkable space this far beyond the surveyed
    /// states, m, for the estimate to follow the motion off the map (default 10; 0: none).
    #[arg(long)]
    unsurveyed_margin_m: Option<f64>,
    /// Readings older than this before their scan count as not heard, ms (default 2000).
    #[arg(long)]
    max_age_ms: Option<u64>,
    /// Smallest σ a fitted fingerprint may have, dB.
    #[arg(long)]
    min_std_db: Option<f64>,
    /// Also replay the test walks as a foreground app under Android 9+'s scan throttling (at
    /// most one scan every 30 s, 4 per 2 minutes, reaches the engine; timer epochs carry the
    /// motion between) on the same site: a second table (`throttled` in JSON)
    #[arg(long)]
    throttle: bool,
    /// Hoang's fixed Σ_v, without the tracker's own distance and heading spreads.
    #[arg(long)]
    fixed_movement_variance: bool,
    /// M of Hoang eq. 4: the most likely states averaged into the estimate.
    #[arg(long)]
    top_m: Option<usize>,
    /// Lag of the fixed-lag estimate, epochs.
    #[arg(long)]
    fixed_lag: Option<usize>,
    /// The venue's plan as IMDF (a folder or `.zip`, docs/imdf.md) in place of the floor
    /// folders' `floor_info.json` + `geojson_map.json`, as `waymark survey --imdf` takes it.
    #[arg(long, conflicts_with = "no_plan")]
    imdf: Option<PathBuf>,
    /// Ignore the floor plans' walls (the walkable graph then comes from the walks alone).
    #[arg(long)]
    no_plan: bool,
    /// Leave BLE beacons out (survey and replay).
    #[arg(long)]
    no_beacons: bool,
    /// Largest σ a fitted fingerprint may have, dB.
    #[arg(long)]
    max_std_db: Option<f64>,
    /// Also learn habits from the survey walks (their waypoints as the surveyor's feedback) and
    /// run every configuration again with them: the table compares the two.
    #[arg(long)]
    habits: bool,
    /// Strength of the applied habits, as a pseudo-count per reachable move (default: chosen
    /// on held-out survey walks).
    #[arg(long)]
    habit_strength: Option<f64>,
}

pub fn eval(args: &EvalArgs) -> ExitCode {
    let started = Instant::now();
    let mut floors = match calibrate::load_building(&args.floors, &args.split, args.max_walks) {
        Ok(f) => f,
        Err(e) => return fail("eval", e),
    };
    if let Some(path) = &args.imdf {
        if let Err(e) = waymark_survey::io::imdf::plans_from_imdf(path, &mut floors) {
            return fail("eval", e);
        }
    }
    let floors: Vec<FloorData> =
        floors.into_iter().map(|f| if args.no_plan { FloorData { plan: None, ..f } } else { f }).collect();
    if args.unlabelled_rest && args.survey_fraction >= 1.0 {
        return fail(
            "eval",
            "--unlabelled-rest gives back the walks --survey-fraction leaves out: give it one below 1",
        );
    }
    // The walks given without their labels: the survey walks left out, when they are given
    // back, and the test walks of the repetitions asked for.
    let given = evaluation::WithoutLabels {
        rest: args.unlabelled_rest,
        test_unlabelled: &args.test_as_unlabelled,
        test_labelled: &args.test_as_labelled,
    };
    let (floors, unlabelled) = evaluation::split_without_labels(floors, args.survey_fraction, given);
    let unlabelled_given = given.any();
    let mut options = EvalOptions { configurations: args.configurations.clone(), ..EvalOptions::default() };
    if let Some(unknown) = options.configurations.iter().find(|c| !CONFIGURATIONS.contains(&c.as_str())) {
        return fail(
            "eval",
            format!("unknown configuration `{unknown}`; known: {}", CONFIGURATIONS.join(", ")),
        );
    }
    options.calibration.engine.rssi_weight = args.gamma;
    if let Some(s) = args.spacing_m {
        options.calibration.survey.spacing_m = s;
        options.calibration.survey.coverage_m = s;
    }
    if let Some(m) = args.unsurveyed_margin_m {
        options.calibration.survey.unsurveyed_margin_m = m;
    }
    if let Some(r) = args.fingerprint_radius_m {
        options.calibration.survey.fingerprint_radius_m = r;
        options.calibration.calibrate_fingerprint_radius = false;
    }
    if let Some(v) = args.min_std_db {
        options.calibration.survey.build.fit.min_std_db = v;
    }
    if args.fixed_movement_variance {
        options.calibration.engine.movement_vector.measured_spread = false;
    }
    if let Some(m) = args.top_m {
        options.calibration.engine.estimate_states = Some(m);
    }
    if let Some(lag) = args.fixed_lag {
        options.calibration.engine.fixed_lag_epochs = lag;
    }
    if args.no_beacons {
        options.calibration.survey.events.beacons = false;
        options.calibration.replay.events.beacons = false;
    }
    if let Some(v) = args.max_std_db {
        options.calibration.survey.build.fit.max_std_db = v;
    }
    if let Some(ms) = args.max_age_ms {
        options.calibration.survey.max_reading_age_ns = ms * 1_000_000;
    }
    if let Some(t) = args.threads {
        options.calibration.threads = t;
    }
    if let Some(q) = args.evidence_mass {
        if !(q > 0.0 && q <= 1.0) {
            return fail("eval", format!("--evidence-mass {q}: give a share above 0 and at most 1"));
        }
        options.calibration.evidence_mass = q;
    }
    if let Some(k) = args.evidence_states {
        options.calibration.evidence_states = k;
    }
    if let Some(k) = args.habit_strength {
        options.calibration.engine.habits.strength = Some(k);
    }
    let loaded_s = started.elapsed().as_secs_f64();
    if let Some(folds) = args.crowd_folds {
        return crowd(args, &floors, &options, folds, started);
    }
    let bar = progress_bar(
        args.json,
        calibrate::calibration_steps(&floors, &options.calibration) as u64,
        "calibrating (leave one walk out)",
    );
    let surveyed = if unlabelled_given {
        calibrate::survey_with_unlabelled(
            &floors,
            &unlabelled,
            &options.calibration,
            unlabelled_options(args),
            &|| bar.inc(1),
        )
        .map(|(site, survey, calibration, rounds)| (site, survey, calibration, Some(rounds)))
    } else {
        calibrate::survey_calibrated(&floors, &options.calibration, &|| bar.inc(1))
            .map(|(a, b, c)| (a, b, c, None))
    };
    let (site, survey, calibration, evidence_rounds) = match surveyed {
        Ok(s) => s,
        Err(e) => return fail("eval", e),
    };
    bar.finish_and_clear();
    let options = options.surveyed_with(&calibration);
    let surveyed_s = started.elapsed().as_secs_f64();
    let site = Arc::new(site);
    let walks: usize = floors.iter().map(|f| f.test.len()).sum();
    let bar = progress_bar(args.json, walks as u64, "replaying test walks");
    let (configurations, results) = match evaluation::evaluate_on(&site, &floors, &options, &|| bar.inc(1)) {
        Ok(r) => r,
        Err(e) => return fail("eval", e),
    };
    bar.finish_and_clear();
    if let Some(dir) = &args.plot {
        if let Err(e) = plot(dir, &floors, &results) {
            return fail("eval", e);
        }
    }
    let habits = if args.habits {
        let learning_started = Instant::now();
        let bar = progress_bar(args.json, 1, "learning habits from the survey walks");
        let (model, learning, selection) = match evaluation::survey_habits(&site, &floors, &options) {
            Ok(m) => m,
            Err(e) => return fail("eval", e),
        };
        bar.finish_and_clear();
        let learning_seconds = learning_started.elapsed().as_secs_f64();
        let with = EvalOptions { habits: Some(Arc::new(model)), ..options.clone() };
        let bar = progress_bar(args.json, walks as u64, "replaying test walks with habits");
        let (configurations, _) = match evaluation::evaluate_on(&site, &floors, &with, &|| bar.inc(1)) {
            Ok(r) => r,
            Err(e) => return fail("eval", e),
        };
        bar.finish_and_clear();
        Some(evaluation::HabitsComparison { learning, selection, learning_seconds, configurations })
    } else {
        None
    };
    let throttled = if args.throttle {
        let mut throttled = options.clone();
        throttled.calibration.replay = options.calibration.throttled_replay();
        let bar = progress_bar(args.json, walks as u64, "replaying test walks with throttled scans");
        let (configurations, _) = match evaluation::evaluate_on(&site, &floors, &throttled, &|| bar.inc(1)) {
            Ok(r) => r,
            Err(e) => return fail("eval", e),
        };
        bar.finish_and_clear();
        Some(configurations)
    } else {
        None
    };
    let test: Vec<&Trace> = floors.iter().flat_map(|f| &f.test).collect();
    let pdr = waymark_eval::pdr::evaluate_pdr(&test, &options.calibration.engine.motion_for(&site));
    let report = evaluation::EvalReport {
        configurations,
        survey,
        calibration,
        pdr,
        test_walks: walks,
        survey_fraction: args.survey_fraction,
        states: site.states().len(),
        seconds: started.elapsed().as_secs_f64(),
        habits,
        throttled,
        evidence_rounds,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report).unwrap_or_default());
    } else {
        let fraction = if args.survey_fraction < 1.0 {
            format!(" ({} of the survey walks)", args.survey_fraction)
        } else {
            String::new()
        };
        println!(
            "{} floors, {} test walks, {} states{fraction}; read {:.1} s, survey {:.1} s, replay {:.1} s",
            floors.len(),
            walks,
            report.states,
            loaded_s,
            surveyed_s - loaded_s,
            started.elapsed().as_secs_f64() - surveyed_s
        );
        print_configurations(&report.configurations);
        if let Some(throttled) = &report.throttled {
            println!("\nthe same test walks with throttled scans (one every 30 s at most):");
            print_configurations(throttled);
        }
        print_calibration(&report.calibration);
        if let Some(share) = report.configurations.values().find_map(|r| r.pooled.in_zone) {
            println!(
                "zone: the most likely zone is the zone of the state nearest the truth (or both none); \
                 the truth was in a zone at {:.1}% of the scored points",
                100.0 * share
            );
        }
        if let Some(h) = &report.habits {
            print_habits(&report.configurations, h);
        }
    }
    ExitCode::SUCCESS
}

/// How the walks given without labels refit the site, as the arguments say.
fn unlabelled_options(args: &EvalArgs) -> calibrate::UnlabelledOptions {
    calibrate::UnlabelledOptions {
        anchor_rounds: args.anchor_rounds,
        evidence_rounds: args.evidence_rounds,
        replace: (!args.keep_contradicted).then_some(waymark_survey::ReplaceRule {
            pool_confirmed: !args.keep_confirmed,
            ..waymark_survey::REPLACE_RULE
        }),
    }
}

/// `--crowd-folds`: every fold surveyed, refitted with the other folds' test walks and
/// scored, the figures pooled.
fn crowd(
    args: &EvalArgs,
    floors: &[FloorData],
    options: &EvalOptions,
    folds: usize,
    started: Instant,
) -> ExitCode {
    let rounds = unlabelled_options(args);
    let steps = calibrate::calibration_steps(floors, &options.calibration) as u64;
    let walks: usize = floors.iter().map(|f| f.test.len()).sum();
    let bar =
        progress_bar(args.json, folds as u64 * steps + walks as u64, "crowd folds: survey, refit, replay");
    let evaluation::CrowdReport { configurations, folds: fold_reports, .. } =
        match evaluation::evaluate_crowd(floors, options, folds, rounds, &|| bar.inc(1)) {
            Ok(r) => r,
            Err(e) => return fail("eval", e),
        };
    bar.finish_and_clear();
    let seconds = started.elapsed().as_secs_f64();
    if args.json {
        let report = serde_json::json!({
            "configurations": configurations,
            "crowd_folds": folds,
            "folds": fold_reports,
            "test_walks": walks,
            "survey_fraction": args.survey_fraction,
            "seconds": seconds,
        });
        println!("{}", serde_json::to_string_pretty(&report).unwrap_or_default());
    } else {
        println!("{} floors, {walks} test walks in {folds} folds, each scored on a site refitted with the other folds' walks without labels; {seconds:.1} s", floors.len());
        print_configurations(&configurations);
        for (k, fold) in fold_reports.iter().enumerate() {
            println!(
                "fold {k}: {} walks scored, {} given without labels, {} states",
                fold.test_walks, fold.unlabelled_walks, fold.states
            );
        }
    }
    ExitCode::SUCCESS
}

/// One row per configuration, pooled.
fn print_configurations(
    configurations: &std::collections::BTreeMap<String, evaluation::ConfigurationReport>,
) {
    // Room-level accuracy only for a site with zones (from named plan polygons).
    let zones = configurations.values().any(|r| r.pooled.zone_hit.is_some());
    println!(
        "{:<26} {:>7} {:>7} {:>7} {:>7} {:>7} {:>6} {:>6} {:>6}{} {:>7}",
        "configuration",
        "mean",
        "rmse",
        "p50",
        "p90",
        "max",
        "hit68",
        "hit95",
        "floor",
        if zones { format!(" {:>6}", "zone") } else { String::new() },
        "epochs"
    );
    for (key, r) in configurations {
        let m = &r.pooled;
        let zone = match (zones, m.zone_hit) {
            (false, _) => String::new(),
            (true, Some(hit)) => format!(" {hit:>6.3}"),
            (true, None) => format!(" {:>6}", "-"),
        };
        println!(
            "{key:<26} {:>7.2} {:>7.2} {:>7.2} {:>7.2} {:>7.1} {:>6.2} {:>6.2} {:>6.3}{zone} {:>7}",
            m.mean_m,
            m.rmse_m,
            m.p50_m,
            m.p90_m,
            m.max_m,
            m.accuracy_68_hit,
            m.accuracy_95_hit,
            m.floor_hit,
            m.epochs
        );
    }
}

/// The configurations without and with habits, side by side.
fn print_habits(
    without: &std::collections::BTreeMap<String, evaluation::ConfigurationReport>,
    habits: &evaluation::HabitsComparison,
) {
    let l = &habits.learning;
    println!(
        "\nhabits from the survey walks: {} epochs in {} segments ({} with feedback), {} iterations, \
         {} transitions learned, largest segment {} states, {} restarts; {:.1} s",
        l.epochs,
        l.segments,
        l.feedback_epochs,
        l.iterations,
        l.learned_transitions,
        l.largest_segment_states,
        l.restarts,
        habits.learning_seconds
    );
    let s = &habits.selection;
    println!(
        "strength on {} held-out survey walks ({} epochs), mean error with the other half's habits \
         minus without, ± SE, m:",
        s.walks, s.epochs
    );
    println!("{:>8} {:>17} {:>17} {:>17}", "κ", "forward", "fixed-lag", "viterbi");
    for p in &s.strengths {
        let cell = |d: [f64; 2]| format!("{:+.3} ± {:.3}", d[0], d[1]);
        println!(
            "{:>8} {:>17} {:>17} {:>17}",
            p.strength,
            cell(p.forward_m),
            cell(p.fixed_lag_m),
            cell(p.viterbi_m)
        );
    }
    let shown = |k: Option<f64>| k.map_or("none".to_string(), |k| format!("{k:.3}"));
    println!(
        "strength applied: {} (the learning pass alone, by move prediction: {})",
        shown(s.strength),
        shown(s.pass_strength)
    );
    println!(
        "{:<26} {:>15} {:>15} {:>13} {:>13} {:>7}",
        "configuration", "mean (without)", "mean (habits)", "p50", "hit68", "floor"
    );
    for (key, with) in &habits.configurations {
        let Some(plain) = without.get(key) else { continue };
        let (a, b) = (&plain.pooled, &with.pooled);
        println!(
            "{key:<26} {:>15.3} {:>15.3} {:>6.2}→{:<6.2} {:>6.3}→{:<6.3} {:>7.3}",
            a.mean_m, b.mean_m, a.p50_m, b.p50_m, a.accuracy_68_hit, b.accuracy_68_hit, b.floor_hit
        );
    }
}

/// One SVG per test walk (plan, truth, the live, Viterbi and k-NN tracks) and the pooled error
/// CDF of every configuration.
fn plot(
    dir: &std::path::Path,
    floors: &[FloorData],
    results: &[evaluation::WalkResult],
) -> Result<(), String> {
    use waymark_eval::plot::{plot_cdf, plot_walk, Track};
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let tests: Vec<(usize, &Trace)> =
        floors.iter().enumerate().flat_map(|(f, floor)| floor.test.iter().map(move |t| (f, t))).collect();
    let mut errors: std::collections::BTreeMap<&str, Vec<f64>> = std::collections::BTreeMap::new();
    for (result, &(f, trace)) in results.iter().zip(&tests) {
        let truth: Vec<(f64, f64)> = trace.waypoints.iter().map(|w| (w.x, w.y)).collect();
        let shown = ["forward-auto", "viterbi-auto", "wifi-knn"];
        let points: Vec<(&str, Vec<(f64, f64)>)> = shown
            .iter()
            .filter_map(|key| {
                result.estimates.get(*key).map(|e| (*key, e.iter().map(|p| (p.x, p.y)).collect()))
            })
            .collect();
        let tracks: Vec<Track> = points.iter().map(|(label, p)| Track { label, points: p }).collect();
        let title = format!("{} {} ({:.0} m)", floors[f].name, trace.name, trace.path_length_m());
        let path = dir.join(format!("{}-{}.svg", floors[f].name, trace.name));
        plot_walk(&path, &title, floors[f].plan.as_ref(), &truth, &tracks).map_err(|e| e.to_string())?;
        for (key, estimates) in &result.estimates {
            let (epochs, _) = waymark_survey::scoring::score_scans(trace, f, estimates, None);
            errors.entry(key).or_default().extend(epochs.iter().map(|s| s.penalised_m()));
        }
    }
    let curves: Vec<(&str, &[f64])> = errors.iter().map(|(k, v)| (*k, v.as_slice())).collect();
    plot_cdf(&dir.join("error-cdf.svg"), "Error CDF, all test walks", &curves).map_err(|e| e.to_string())?;
    eprintln!("{} walk plots and error-cdf.svg written to {}", results.len(), dir.display());
    Ok(())
}

#[cfg(test)]
mod eval_args_tests {
    use super::EvalArgs;
    use clap::Parser;

    #[derive(Parser)]
    struct Eval {
        #[command(flatten)]
        args: EvalArgs,
    }

    #[test]
    fn the_survey_fraction_is_one_by_default_and_must_be_in_zero_to_one() {
        let parse = |extra: &[&str]| Eval::try_parse_from(["eval", "F1"].iter().chain(extra));
        assert_eq!(parse(&[]).map(|e| e.args.survey_fraction).ok(), Some(1.0));
        assert_eq!(parse(&["--survey-fraction", "0.25"]).map(|e| e.args.survey_fraction).ok(), Some(0.25));
        for bad in ["0", "-0.5", "1.5", "NaN", "half"] {
            let error = parse(&[&format!("--survey-fraction={bad}")]).err().map(|e| e.kind());
            assert_eq!(error, Some(clap::error::ErrorKind::ValueValidation), "{bad}");
        }
    }
}
