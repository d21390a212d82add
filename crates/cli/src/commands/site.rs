//! `waymark site`: site files packed into the binary encoding and back, their transmitter ids
//! hashed with a salt, a salt checked, a site's floors and zones (or floor plans) exported as
//! IMDF for a map SDK.

use crate::shared::{fail, write_site, SaltArgs, SALT_ENV};
use std::path::PathBuf;
use std::process::ExitCode;
use waymark_engine::Site;
use waymark_survey::io::imdf::{Venue, WriteOptions};
use waymark_survey::io::FloorPlan;

/// A folder's name, as its floor's.
fn floor_name(dir: &std::path::Path) -> String {
    dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()
}

/// The time now, UTC, as ISO 8601 (`2000-01-31T12:00:00Z`), for IMDF's manifest: the civil
/// date of the days since 1970 by Howard Hinnant's `civil_from_days`.
fn utc_now_iso8601() -> String {
    let secs =
        std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs()) as i64;
    let (days, rest) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1_460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!("{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}Z", rest / 3600, rest % 3600 / 60, rest % 60)
}

#[derive(clap::Args)]
pub struct SiteArgs {
    #[command(subcommand)]
    command: SiteCommand,
}

#[derive(clap::Subcommand)]
enum SiteCommand {
    /// Write a copy of a site file whose transmitter ids are salted hashes (HMAC-SHA256,
    /// 128 bits) instead of MAC addresses and UUIDs, for shipping inside an app.
    Hash {
        /// The site file with raw ids.
        input: PathBuf,
        /// Where to write the hashed site file.
        output: PathBuf,
        #[command(flatten)]
        salt: SaltArgs,
    },
    /// Write a site file (JSON or binary) in the binary encoding, what an app should ship: it
    /// loads several times faster than JSON and without the parser's garbage (see README,
    /// "Speed and memory").
    Pack {
        /// The site file.
        input: PathBuf,
        /// Where to write the binary site file (by convention `.wmsite`).
        output: PathBuf,
    },
    /// Write a site file (binary or JSON) as JSON, to read or diff it.
    Unpack {
        /// The site file.
        input: PathBuf,
        /// Where to write the JSON.
        output: PathBuf,
    },
    /// Write a geo-referenced site's floors and zones as IMDF 1.0.0 (docs/imdf.md): a level per
    /// floor, its outline around the floor's places; a unit per zone, of its kind's category.
    /// With --plans, the levels, units and doors are those floor plans' instead.
    Export {
        /// The site file (binary or JSON); not needed with --plans.
        #[arg(required_unless_present = "plans")]
        site: Option<PathBuf>,
        /// Where to write the IMDF archive: a `.zip`, or a folder.
        #[arg(long)]
        imdf: PathBuf,
        /// Floor folders whose plans (`floor_info.json` + `geojson_map.json`, the
        /// competition's) to write, a level each, named as the folder.
        #[arg(long, num_args = 1.., conflicts_with = "site")]
        plans: Vec<PathBuf>,
        /// The venue's name when exporting --plans (a site's own name otherwise).
        #[arg(long, default_value = "venue")]
        name: String,
        /// The venue's IMDF category (`shoppingcenter`, `businesscampus`, `airport`...).
        #[arg(long, default_value = "businesscampus")]
        venue_category: String,
        /// The ISO 3166 country code of the venue's address (`ZZ`: unknown).
        #[arg(long, default_value = "ZZ")]
        country: String,
    },
    /// Say whether a site file's ids are hashed and, given a salt, whether it is the right one
    /// (exit status 1 if not).
    Check {
        /// The site file.
        site: PathBuf,
        #[command(flatten)]
        salt: SaltArgs,
    },
}

pub fn site(args: &SiteArgs) -> ExitCode {
    match &args.command {
        SiteCommand::Hash { input, output, salt } => {
            let salt = match salt.salt() {
                Ok(Some((salt, _))) => salt,
                Ok(None) => return fail("site hash", format!("no salt: give --salt-file or set {SALT_ENV}")),
                Err(e) => return fail("site hash", e),
            };
            let hashed = match Site::load(input).and_then(|site| site.hashed(&salt)) {
                Ok(site) => site,
                Err(e) => return fail("site hash", e),
            };
            if let Err(e) = write_site(output, &hashed) {
                return fail("site hash", e);
            }
            println!(
                "{} transmitter ids hashed ({} version {}); written to {}",
                hashed.radio().transmitters().len(),
                waymark_engine::radio::ID_HASH_SCHEME,
                waymark_engine::radio::ID_HASH_VERSION,
                output.display()
            );
            ExitCode::SUCCESS
        }
        SiteCommand::Pack { input, output } | SiteCommand::Unpack { input, output } => {
            let (verb, binary) = match &args.command {
                SiteCommand::Pack { .. } => ("site pack", true),
                _ => ("site unpack", false),
            };
            let site = match Site::load(input) {
                Ok(site) => site,
                Err(e) => return fail(verb, e),
            };
            let contents = if binary { site.to_binary() } else { site.to_json().into_bytes() };
            if let Err(e) = std::fs::write(output, &contents) {
                return fail(verb, format!("cannot write {}: {e}", output.display()));
            }
            println!(
                "{} states, {} fingerprint entries: {} bytes written to {}",
                site.states().len(),
                site.radio().fingerprints().count(),
                contents.len(),
                output.display()
            );
            ExitCode::SUCCESS
        }
        SiteCommand::Export { site, imdf, plans, name, venue_category, country } => {
            let venue = if plans.is_empty() {
                let Some(path) = site else { return fail("site export", "give a site file or --plans") };
                match Site::load(path)
                    .map_err(|e| e.to_string())
                    .and_then(|s| Venue::from_site(&s).map_err(|e| e.to_string()))
                {
                    Ok(venue) => venue,
                    Err(e) => return fail("site export", e),
                }
            } else {
                let mut read = Vec::with_capacity(plans.len());
                for dir in plans {
                    match FloorPlan::read(dir) {
                        Ok(plan) => read.push((floor_name(dir), plan)),
                        Err(e) => return fail("site export", e),
                    }
                }
                let floors: Vec<(String, &FloorPlan)> = read.iter().map(|(n, p)| (n.clone(), p)).collect();
                match Venue::from_plans(name, &floors) {
                    Ok(venue) => venue,
                    Err(e) => return fail("site export", e),
                }
            };
            let options = WriteOptions {
                created: utc_now_iso8601(),
                venue_category: venue_category.clone(),
                country: country.clone(),
            };
            if let Err(e) = venue.write(imdf, &options) {
                return fail("site export", e);
            }
            let units: usize = venue.levels.iter().map(|l| l.units.len()).sum();
            let openings: usize = venue.levels.iter().map(|l| l.openings.len()).sum();
            println!(
                "IMDF {}: {} levels, {units} units, {openings} openings written to {}",
                waymark_survey::io::imdf::IMDF_VERSION,
                venue.levels.len(),
                imdf.display()
            );
            ExitCode::SUCCESS
        }
        SiteCommand::Check { site, salt } => {
            let (site, salt) = match (Site::load(site), salt.salt()) {
                (Ok(site), Ok(salt)) => (site, salt.map(|(salt, _)| salt)),
                (Err(e), _) => return fail("site check", e),
                (_, Err(e)) => return fail("site check", e),
            };
            let count = site.radio().transmitters().len();
            match (site.id_hashing(), site.scan_hasher(salt.as_ref())) {
                (None, _) => println!("{count} raw transmitter ids (MAC addresses, UUIDs): not hashed"),
                (Some(_), Ok(_)) => println!("{count} hashed transmitter ids; the salt matches"),
                (Some(_), Err(e)) => {
                    return fail("site check", format!("{count} hashed transmitter ids; {e}"))
                }
            }
            ExitCode::SUCCESS
        }
    }
}
