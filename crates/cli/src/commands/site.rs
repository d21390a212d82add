//! `waymark site`: site files packed into the binary encoding and back, their transmitter ids
//! hashed with a salt, a salt checked.

use crate::shared::{fail, write_site, SaltArgs, SALT_ENV};
use std::path::PathBuf;
use std::process::ExitCode;
use waymark_engine::Site;

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
