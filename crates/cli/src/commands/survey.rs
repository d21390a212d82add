//! `waymark survey`: a site file from recorded survey walks, calibrated on them.

use super::evidence::read_evidence;
use crate::shared::{fail, print_calibration, progress_bar, write_site, SaltArgs};
use std::path::PathBuf;
use std::process::ExitCode;
use waymark_engine::evidence::Evidence;
use waymark_survey::calibrate::{self, CalibrationOptions, WalkSplit};
use waymark_survey::io::Trace;

#[derive(clap::Args)]
pub struct SurveyArgs {
    /// Floor folders of one building (each with `path_data_files/`, and `floor_info.json` +
    /// `geojson_map.json` if there is a plan), or one folder of GetSensorData logfiles. Every
    /// walk in them is a survey walk.
    #[arg(required = true)]
    floors: Vec<PathBuf>,
    /// The venue's plan as IMDF 1.0.0 (a folder or `.zip` of its GeoJSON files, docs/imdf.md)
    /// in place of each floor folder's `floor_info.json` + `geojson_map.json`: each floor takes
    /// the level whose short name (or name) is the folder's, framed by the folder's
    /// `floor_info.json` when it has one (its walks are measured in it).
    #[arg(long)]
    imdf: Option<PathBuf>,
    /// Where to write the site file.
    #[arg(long)]
    out: PathBuf,
    /// The site's name.
    #[arg(long, default_value = "site")]
    name: String,
    /// Unsurveyed states (no fingerprint) fill walkable space this far beyond the surveyed
    /// states, m, for the estimate to follow the motion off the map (0: none; the site then
    /// loads in builds before unsurveyed states).
    #[arg(long, default_value_t = waymark_survey::UNSURVEYED_MARGIN_M)]
    unsurveyed_margin_m: f64,
    /// Also write where the held-out walks went beyond the map the other walks made, as
    /// GeoJSON points: the stretches to walk again. Needs every floor's plan (for WGS84), and
    /// fails at once without.
    #[arg(long)]
    coverage_out: Option<PathBuf>,
    /// Walks without labels (walk files in the floors' format, their waypoints not read): each
    /// anchored where the site surveyed from the floors is sure of it and surveyed with those
    /// walks (docs/evidence.md#refitting).
    #[arg(long, num_args = 1..)]
    unlabelled: Vec<PathBuf>,
    /// With --unlabelled: rounds of anchoring the walks where the site is sure of them and
    /// surveying them with the labelled ones.
    #[arg(long, default_value_t = 1, requires = "unlabelled")]
    anchor_rounds: usize,
    /// With --unlabelled: rounds of refitting with every scan's soft label after those.
    #[arg(long, default_value_t = 0, requires = "unlabelled")]
    evidence_rounds: usize,
    /// Map evidence files (`waymark evidence collect --site` of this survey's site without
    /// them): merged, they refit the labelled survey once, as `--unlabelled` with
    /// `--anchor-rounds 0 --evidence-rounds 1` refits it with their walks
    /// (docs/evidence.md#at-scale).
    #[arg(long, num_args = 1.., conflicts_with = "unlabelled")]
    evidence: Vec<PathBuf>,
    #[command(flatten)]
    salt: SaltArgs,
}

pub fn survey(args: &SurveyArgs) -> ExitCode {
    // Every walk surveys.
    let mut floors = match calibrate::load_building(&args.floors, &WalkSplit::All, None) {
        Ok(f) => f,
        Err(e) => return fail("survey", e),
    };
    if let Some(path) = &args.imdf {
        if let Err(e) = waymark_survey::io::imdf::plans_from_imdf(path, &mut floors) {
            return fail("survey", e);
        }
    }
    // A coverage map needs WGS84, which only plans for every floor give: say so before the
    // calibration's minutes, not after.
    if args.coverage_out.is_some() {
        let plans: Vec<_> = floors.iter().map(|f| f.plan.as_ref()).collect();
        if waymark_survey::geo_reference(&plans).0.is_none() {
            let missing: Vec<&str> =
                floors.iter().filter(|f| f.plan.is_none()).map(|f| f.name.as_str()).collect();
            return fail(
                "survey",
                if missing.is_empty() {
                    "--coverage-out needs a geo-referenced site, and the plans give no place on the Earth"
                        .to_owned()
                } else {
                    format!(
                        "--coverage-out needs a geo-referenced site, which needs every floor's plan: none for {}",
                        missing.join(", ")
                    )
                },
            );
        }
    }
    let options = calibration_options(args.unsurveyed_margin_m);
    let bar = progress_bar(
        false,
        calibrate::calibration_steps(&floors, &options) as u64,
        "calibrating (leave one walk out)",
    );
    let mut unlabelled = Vec::with_capacity(args.unlabelled.len());
    for path in &args.unlabelled {
        match Trace::read(path) {
            Ok(trace) => unlabelled.push(Trace { waypoints: Vec::new(), ..trace }),
            Err(e) => return fail("survey", e),
        }
    }
    // The evidence files, merged: read before the calibration's minutes, so a bad file fails at once.
    let mut evidence: Option<Evidence> = None;
    for path in &args.evidence {
        let read = match read_evidence(path) {
            Ok(e) => e,
            Err(e) => return fail("survey", e),
        };
        match &mut evidence {
            None => evidence = Some(read),
            Some(merged) => {
                if let Err(e) = merged.merge(&read) {
                    return fail("survey", format!("{}: {e}", path.display()));
                }
            }
        }
    }
    let surveyed = if let Some(evidence) = &evidence {
        calibrate::survey_with_evidence(&floors, evidence, &options, &|| bar.inc(1))
            .map(|(a, b, c, round)| (a, b, c, vec![round]))
    } else if unlabelled.is_empty() {
        calibrate::survey_calibrated(&floors, &options, &|| bar.inc(1)).map(|(a, b, c)| (a, b, c, Vec::new()))
    } else {
        let rounds = calibrate::UnlabelledOptions {
            anchor_rounds: args.anchor_rounds,
            evidence_rounds: args.evidence_rounds,
            ..calibrate::UnlabelledOptions::default()
        };
        calibrate::survey_with_unlabelled(&floors, &unlabelled, &options, rounds, &|| bar.inc(1))
    };
    let (site, report, calibration, rounds) = match surveyed {
        Ok(s) => s,
        Err(e) => return fail("survey", e),
    };
    bar.finish_and_clear();
    for (k, round) in rounds.iter().enumerate() {
        if evidence.is_none() && k < args.anchor_rounds {
            println!(
                "{} of {} walks without labels anchored and surveyed: {} states",
                round.walks,
                unlabelled.len(),
                round.site_states
            );
        } else {
            println!(
                "map evidence of {} walks at {} states ({} entries, {} bytes) refitted the site: {} states",
                round.walks, round.states, round.entries, round.bytes, round.site_states
            );
        }
    }
    let site = site.with_name(&args.name);
    let site = match args.salt.salt() {
        Err(e) => return fail("survey", e),
        Ok(None) => site,
        Ok(Some((salt, source))) => match site.hashed(&salt) {
            Ok(hashed) => {
                println!("transmitter ids hashed with the salt from {source}");
                hashed
            }
            Err(e) => return fail("survey", e),
        },
    };
    if let Err(e) = write_site(&args.out, &site) {
        return fail("survey", e);
    }
    if let Some(path) = &args.coverage_out {
        // Checked before the calibration; only a site that lost its anchor on the way fails here.
        let Some(geojson) = calibrate::coverage_geojson(&site, &calibration) else {
            return fail(
                "survey",
                format!("{} written, but it is not geo-referenced: no coverage map", args.out.display()),
            );
        };
        if let Err(e) = std::fs::write(path, geojson.to_string()) {
            return fail("survey", format!("{}: {e}", path.display()));
        }
        let points = geojson.features.len();
        println!(
            "coverage map: {points} held-out epochs beyond the others' map written to {}",
            path.display()
        );
    }
    for f in &report.floors {
        println!(
            "{:>4}: {} walks, {} scans → {} states and {} unsurveyed around them, {} edges ({} through walls the plan has, walked)",
            f.name, f.walks, f.scans, f.states, f.unsurveyed_states, f.edges, f.walked_edges
        );
    }
    print_calibration(&calibration);
    match site.anchor() {
        Some(a) => {
            let levels: Vec<String> = site
                .floors()
                .iter()
                .map(|f| format!("{} {}", f.name, f.level.map_or("-".into(), |l| l.to_string())))
                .collect();
            println!(
                "geo-referenced from the plans: origin {:.7}, {:.7}, scale {:.5} x {:.5}; levels {}",
                a.lat_deg,
                a.lon_deg,
                a.scale[0],
                a.scale[1],
                levels.join(", ")
            );
        }
        None => println!("not geo-referenced (a floor has no plan)"),
    }
    println!(
        "{} transmitters ({} radios send two or more); site written to {}",
        report.transmitters,
        report.shared_radios,
        args.out.display()
    );
    ExitCode::SUCCESS
}

/// The calibration, engine and replay options `waymark survey` surveys with: what `waymark
/// evidence collect` must replay walks with for its evidence to be the survey's own.
pub fn calibration_options(unsurveyed_margin_m: f64) -> CalibrationOptions {
    let mut options = CalibrationOptions::default();
    options.survey.unsurveyed_margin_m = unsurveyed_margin_m;
    options
}
