//! What several commands share: where a site's salt comes from, writing a site file, the
//! error line and exit status of a failed command, progress bars, and the survey's calibration
//! report (`survey` and `eval` print it).

use indicatif::{ProgressBar, ProgressStyle};
use std::borrow::Cow;
use std::path::PathBuf;
use std::process::ExitCode;
use waymark_engine::sensors::MotionScenario;
use waymark_engine::{Salt, Site};
use waymark_survey::calibrate;

/// The environment variable that may hold the salt (hex) when no `--salt-file` is given.
pub const SALT_ENV: &str = "WAYMARK_SALT";

/// Where a site's salt comes from: a file, else the environment, never a command-line value
/// (it would land in the shell's history and in `ps`).
#[derive(clap::Args)]
pub struct SaltArgs {
    /// File holding the site's salt as hex digits (at least 32; `openssl rand -hex 32 > F`).
    /// Without it, the environment variable WAYMARK_SALT (hex) if set. Site files made with a
    /// salt hold salted hashes of the transmitter ids instead of MAC addresses and UUIDs.
    #[arg(long, value_name = "FILE")]
    salt_file: Option<PathBuf>,
}

impl SaltArgs {
    /// The salt, with where it came from; `None` when neither a file nor the variable gives one.
    pub fn salt(&self) -> Result<Option<(Salt, String)>, String> {
        let (text, source) = match &self.salt_file {
            Some(path) => (
                std::fs::read_to_string(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?,
                path.display().to_string(),
            ),
            None => match std::env::var(SALT_ENV) {
                Ok(text) if !text.trim().is_empty() => (text, format!("${SALT_ENV}")),
                _ => return Ok(None),
            },
        };
        Salt::from_hex(&text)
            .map(|salt| Some((salt, source.clone())))
            .map_err(|e| format!("salt from {source}: {e}"))
    }
}

/// Prints `waymark VERB: E` on standard error; the command then exits with status 1.
pub fn fail(verb: &str, e: impl std::fmt::Display) -> ExitCode {
    eprintln!("waymark {verb}: {e}");
    ExitCode::FAILURE
}

/// Writes a site file: binary if the name ends in `.wmsite`, JSON otherwise.
pub fn write_site(path: &std::path::Path, site: &Site) -> Result<(), String> {
    let contents = if path.extension().is_some_and(|e| e == "wmsite") {
        site.to_binary()
    } else {
        site.to_json().into_bytes()
    };
    std::fs::write(path, contents).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// A bar of `len` steps, drawn on standard error unless `hidden` (a JSON run keeps it quiet).
pub fn progress_bar(hidden: bool, len: u64, message: impl Into<Cow<'static, str>>) -> ProgressBar {
    let bar = if hidden { ProgressBar::hidden() } else { ProgressBar::new(len) };
    bar.set_style(
        ProgressStyle::with_template("{msg} [{bar:30}] {pos}/{len}, {elapsed}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar.set_message(message);
    bar
}

/// The calibration: site-wide figures, then per floor the γ chosen by leave-one-walk-out, its
/// jackknife standard error, and the error curve over γ with how many walks prefer each γ.
pub fn print_calibration(c: &calibrate::CalibrationReport) {
    println!(
        "calibrated: γ {:?} site-wide (without movement {:?}), accuracy scales {:?}, step length {:?}, heading offset {:.1}°",
        c.rssi_weight,
        c.rssi_weight_without_movement,
        c.accuracy_scale,
        c.motion.as_ref().map(|m| m.step_length),
        c.motion.as_ref().map_or(0.0, |m| m.heading_offset_deg)
    );
    if let Some(rate) = c.floor_change_rate_hz {
        // docs/accuracy.md#barometer: what the barometer's floor changes run at.
        println!(
            "floor changes: {:.2} per hour walked, (changes + 1) / time over the survey walks",
            rate * 3600.0
        );
    }
    let radius_curve: Vec<String> =
        c.fingerprint_radius_mean_error_m.iter().map(|(r, e, _)| format!("{r:.1} m: {e:.2}")).collect();
    println!(
        "fingerprint radius {:.1} m{}",
        c.fingerprint_radius_m,
        if radius_curve.is_empty() {
            " (given)".to_string()
        } else {
            format!(" by 5-fold held-out engine error at each radius's best γ | {}", radius_curve.join(", "))
        }
    );
    for (name, scenario) in
        [("distance only", MotionScenario::Distance), ("heading only", MotionScenario::HeadingSpeed)]
    {
        let Some(curve) = c.gamma_by_scenario.get(scenario) else { continue };
        let curve: Vec<String> = curve
            .iter()
            .map(|p| format!("{}: {:.2} ± {:.2}", p.gamma, p.mean_error_m, p.jackknife_se_m))
            .collect();
        println!(
            "γ {name}: {} | {}",
            c.rssi_weight_by_scenario.get(scenario).map_or("as without movement".into(), |g| g.to_string()),
            curve.join(", ")
        );
    }
    println!(
        "γ per floor by leave-one-walk-out ({} sites, {:.0}% of states refitted per site); mean held-out error, m, at each γ (walks preferring it):",
        c.sites,
        100.0 * c.refitted_share
    );
    for f in &c.floors {
        let curve: Vec<String> = f
            .gamma
            .iter()
            .map(|p| format!("{}: {:.2} ({})", p.gamma, p.mean_error_m, p.walks_preferring))
            .collect();
        println!(
            "{:>4}: best γ {} ± {:.2} m, recorded {} (without movement {}), {} walks, {} epochs | {}",
            f.name,
            f.best_rssi_weight.map_or("-".into(), |g| g.to_string()),
            f.jackknife_se_m.unwrap_or(f64::NAN),
            f.rssi_weight.map_or("site-wide".into(), |g| g.to_string()),
            f.rssi_weight_without_movement.map_or("site-wide".into(), |g| g.to_string()),
            f.walks,
            f.epochs,
            curve.join(", ")
        );
    }
    println!("coverage: held-out epochs beyond the map the floor's other walks make (docs/surveying.md#is-the-survey-enough):");
    for f in &c.floors {
        let cov = &f.coverage;
        if cov.epochs == 0 {
            println!("{:>4}: no held-out epochs (a floor needs two walks or more)", f.name);
            continue;
        }
        let mean = |m: f64| if m.is_finite() { format!("{m:.2} m") } else { "-".into() };
        println!(
            "{:>4}: {:.0}% of {} (mean error {} on that map, {} beyond it)",
            f.name,
            100.0 * cov.beyond_map_share(),
            cov.epochs,
            mean(cov.mean_error_on_map_m),
            mean(cov.mean_error_beyond_map_m)
        );
    }
    let bands = |r: &calibrate::OffMapReport| -> String {
        let bands: Vec<String> = r
            .bands
            .iter()
            .map(|b| {
                let range =
                    if b.to_m == 0.0 { "on the map".into() } else { format!("{}-{} m", b.from_m, b.to_m) };
                format!(
                    "{range}: {} epochs, mean {:.2} m, 68% radius holds {:.2}, 95% {:.2}",
                    b.epochs, b.mean_error_m, b.accuracy_68_hit, b.accuracy_95_hit
                )
            })
            .collect();
        bands.join("; ")
    };
    let candidates: Vec<String> = (c.radio_fit_floor_mean_error_m.iter())
        .map(|(share, floor, error)| format!("{:.0}%: {floor:.2} nats, {error:.2} m", 100.0 * share))
        .collect();
    println!(
        "radio fit floor {} nats per radio heard (the {} quantile of the fits of {} held-out scans on the map, of least held-out error as shipped among {}); held-out walks replayed as shipped:",
        c.radio_fit_floor.map_or("-".into(), |f| format!("{f:.2}")),
        c.radio_fit_floor_share.map_or("-".into(), |s| format!("{:.0}%", 100.0 * s)),
        c.radio_fit_scans,
        candidates.join(", ")
    );
    println!("  {}", bands(&c.on_map));
    println!("  beyond the held-out map, by distance beyond it | {}", bands(&c.off_map));
    println!("  the same without the radio fit floor | {}", bands(&c.off_map_without_floor));
    let sparse = &c.sparse_scans;
    let curve: Vec<String> = sparse
        .gamma
        .iter()
        .map(|p| format!("{}: {:.2} ± {:.2}", p.gamma, p.mean_error_m, p.jackknife_se_m))
        .collect();
    let edges = waymark_engine::site::SINCE_SPARSE_SCAN_BANDS_S;
    let factors: Vec<String> = (0..=edges.len())
        .map(|band| {
            let from = band.checked_sub(1).map_or(0.0, |b| edges[b]);
            let range = edges.get(band).map_or(format!("over {from} s"), |to| format!("{from}-{to} s"));
            let scale = sparse.calibration.accuracy_scale_by_since[band]
                .map_or("-".into(), |[a, b]| format!("{a:.2}/{b:.2}"));
            format!("{range}: {scale} ({} epochs)", sparse.epochs_by_since[band])
        })
        .collect();
    println!(
        "sparse scans (held-out walks with one scan every 30 s): γ {} | {}",
        sparse.calibration.rssi_weight.map_or("site-wide".into(), |g| g.to_string()),
        curve.join(", ")
    );
    println!("  radius factors 68%/95% by time since the sparse scan | {}", factors.join(", "));
    let floor_table = |r: &calibrate::FloorReliabilityReport| -> String {
        let edges = waymark_engine::site::FLOOR_MISS_BANDS.map(|miss| 1.0 - miss);
        let bands: Vec<String> = (r.epochs_right_by_band.iter().enumerate())
            .map(|(band, [right, all])| {
                let from = band.checked_sub(1).map_or("0".into(), |b| edges[b].to_string());
                let to = edges.get(band).map_or("1".into(), f64::to_string);
                let share = r.calibration.0[band].map_or("-".into(), |p| format!("{p:.3}"));
                format!("{from}-{to}: {share} ({right} of {all} right)")
            })
            .collect();
        bands.join(", ")
    };
    if !c.floor_reliability.calibration.is_empty() || !sparse.floor_reliability.calibration.is_empty() {
        println!("floor probability reported, by the posterior's mass on the floor, on held-out epochs on the map:");
        println!("  steady scans | {}", floor_table(&c.floor_reliability));
        println!("  sparse scans | {}", floor_table(&sparse.floor_reliability));
    }
}
