//! The site budget (docs/errors.md#site-limits): a small site file crafted to be costly is
//! refused with `SiteError::OverLimit` naming the limit, in little memory, through the core,
//! the FFI and `Site::load`.

#[path = "../crates/engine/tests/common/mod.rs"]
mod common;

use std::process::Command;
use std::sync::Arc;
use waymark as ffi;
use waymark_engine::site::budget::MAX_SITE_FILE_BYTES;
use waymark_engine::{Engine, EngineConfig, Error, Site, SiteError};

/// Set in the child process that [`refused_within_256_mb_of_address_space`] runs under the
/// limit.
const CHILD: &str = "WAYMARK_SITE_BUDGET_CHILD";

/// The address space the child may use, KiB: the 256 MB the budget must keep a refusal within.
const ADDRESS_SPACE_KIB: u32 = 256 * 1024;

/// CPU seconds after which the child is killed: not a measurement (the refusal takes a few
/// milliseconds), a guard so that a budget that no longer holds cannot stall the suite.
const CPU_GUARD_S: u32 = 60;

/// The budget's reproduction, run in a child process limited to 256 MB of address space
/// (`ulimit -v`): 20 000 states packed on a line (2.3 MB in JSON) must be refused by
/// `Engine::new`, in both encodings and through the FFI, and `/dev/zero` by `Site::load`,
/// where they aborted the process ("memory allocation of 1073741824 bytes failed").
#[test]
fn refused_within_256_mb_of_address_space() {
    if std::env::var_os(CHILD).is_some() {
        return dense_site_and_endless_file_are_refused();
    }
    let exe = std::env::current_exe().expect("the test binary's path");
    let output = Command::new("sh")
        .arg("-c")
        .arg(format!(r#"ulimit -v {ADDRESS_SPACE_KIB} && ulimit -t {CPU_GUARD_S} && exec "$0" "$@""#))
        .arg(exe)
        .args(["--exact", "refused_within_256_mb_of_address_space", "--test-threads=1", "--nocapture"])
        .env(CHILD, "1")
        .output()
        .expect("sh runs");
    assert!(
        output.status.success(),
        "the child failed ({}):\n{}\n{}",
        output.status,
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    // The child ran the test, not nothing.
    assert!(String::from_utf8_lossy(&output.stdout).contains("1 passed"), "{output:?}");
}

fn dense_site_and_endless_file_are_refused() {
    let json = common::dense_line_site_json(20_000);
    let binary = Site::from_json(json.as_bytes()).expect("the site file itself is valid").to_binary();
    for bytes in [json.as_bytes(), &binary[..]] {
        let site = Arc::new(Site::from_bytes(bytes).expect("the site file itself is valid"));
        match Engine::new(site, EngineConfig::default()) {
            Err(Error::Site(e @ SiteError::OverLimit { name: "MAX_REACHABLE_STATES", .. })) => {
                let message = e.to_string();
                assert!(message.contains("MAX_REACHABLE_STATES") && message.contains("4096"), "{message}");
            }
            Err(e) => panic!("refused for another reason: {e}"),
            Ok(_) => panic!("an engine on 20 000 states within 9 m of each other"),
        }
        match ffi::PositioningEngine::from_site_bytes(bytes.to_vec(), ffi::EngineOptions::default()) {
            Err(ffi::PositioningError::InvalidSite { reason }) => {
                assert!(reason.contains("MAX_REACHABLE_STATES"), "{reason}")
            }
            Err(e) => panic!("refused for another reason: {e}"),
            Ok(_) => panic!("the FFI made an engine on the dense site"),
        }
    }
    if std::path::Path::new("/dev/zero").exists() {
        match Site::load("/dev/zero") {
            Err(SiteError::Syntax { line: 1, column: 1, .. }) => {}
            other => panic!("/dev/zero: {other:?}"),
        }
    }
}

/// A site file larger than the limit is refused before it is read: a sparse file that says
/// it is one byte over.
#[test]
fn a_file_over_the_size_limit_is_refused_unread() {
    let file = tempfile::NamedTempFile::new().unwrap();
    file.as_file().set_len(MAX_SITE_FILE_BYTES + 1).unwrap();
    match Site::load(file.path()) {
        Err(e @ SiteError::OverLimit { name: "MAX_SITE_FILE_BYTES", .. }) => {
            assert!(e.to_string().contains("MAX_SITE_FILE_BYTES"), "{e}")
        }
        other => panic!("{other:?}"),
    }
}

/// A dense site small enough to be within the budget still loads and positions.
#[test]
fn a_dense_site_within_the_budget_loads() {
    let site = Arc::new(Site::from_json(common::dense_line_site_json(2_000).as_bytes()).unwrap());
    let mut engine =
        Engine::new(site, EngineConfig::default()).expect("2 000 states within reach is allowed");
    let scan = waymark_engine::Scan {
        timestamp_ns: 1_000_000_000,
        readings: vec![waymark_engine::Reading {
            transmitter: waymark_engine::radio::TransmitterId::wifi("02:00:00:00:00:01").unwrap(),
            rssi_dbm: -60.0,
            age_ns: 0,
        }],
    };
    engine.push_scan(&scan).expect("a scan of the site's transmitter");
}
