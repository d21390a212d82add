//! `site_cost`: any bytes through `Site::from_bytes` and `Engine::new`, for what a site file
//! costs, not only whether it crashes: the site budget (`waymark_engine::site::budget`,
//! docs/errors.md#site-limits) must hold for every input. Run it under libFuzzer's memory and
//! time limits, which fail any input that passes them, with the `site_file` corpus as more
//! seeds:
//!
//! ```sh
//! cargo +nightly fuzz run site_cost fuzz/corpus/site_cost fuzz/corpus/site_file -- \
//!     -rss_limit_mb=256 -malloc_limit_mb=256 -timeout=2 -max_len=1048576
//! ```
//!
//! The target reports the cost it found as coverage: each power of two of the states, of the
//! walking-distance tables' entries and of their longest row takes its own branch, so
//! libFuzzer keeps an input that costs more than any before it and mutates on toward the
//! limits, where a plain crash search would drop it as nothing new.
//!
//! `fuzz/corpus/site_cost/seed-dense-line-600.json` is `tests/common`'s
//! `dense_line_site_json(600)`: 600 states 13 mm apart, each within reach of every other.

use waymark_engine::site::budget::{
    MAX_EDGES_PER_STATE, MAX_FINGERPRINT_ENTRIES, MAX_REACHABLE_STATES, MAX_REACH_ENTRIES, MAX_STATES,
};
use waymark_engine::{Engine, EngineConfig, Error, Site, SiteError};

/// One fuzz input.
pub fn run(data: &[u8]) {
    let Ok(site) = Site::from_bytes(data) else { return };
    let states = site.states().len();
    assert!(states <= MAX_STATES);
    assert!(site.radio().fingerprints().count() <= MAX_FINGERPRINT_ENTRIES);
    cost(0, states);
    let config = EngineConfig::default();
    let tables = site.reach_tables(config.reach_radius_m);
    match &tables {
        Ok((whole, map)) => {
            let entries = whole.len() + map.as_ref().map_or(0, |m| m.len());
            assert!(entries <= MAX_REACH_ENTRIES, "{entries} table entries");
            let longest = (0..states).map(|i| whole.reachable(i, whole.radius_m()).len()).max().unwrap_or(0);
            // A row holds the states within reach and the state's neighbours beyond it.
            assert!(longest <= MAX_REACHABLE_STATES + MAX_EDGES_PER_STATE, "a row of {longest}");
            cost(1, entries);
            cost(2, longest);
        }
        Err(SiteError::OverLimit { .. }) => cost(3, 0),
        Err(e) => panic!("the tables were refused for another reason than the budget: {e}"),
    }
    match Engine::new(std::sync::Arc::new(site), config) {
        Ok(_) => assert!(tables.is_ok()),
        Err(Error::Site(SiteError::OverLimit { .. })) => assert!(tables.is_err()),
        // The site's calibration may hold a step-length model the tracker refuses.
        Err(Error::InvalidConfig(_)) => {}
        Err(e) => panic!("unexpected engine error: {e}"),
    }
}

/// Takes a branch of its own for each measure and power of two of `amount`: the coverage
/// libFuzzer steers by.
fn cost(measure: u32, amount: usize) {
    let bits = usize::BITS - amount.leading_zeros();
    macro_rules! branches {
        ($($bits:literal)*) => {
            match bits {
                $($bits => reached::<$bits>(measure),)*
                _ => reached::<64>(measure),
            }
        };
    }
    branches!(0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24 25 26 27 28 29 30 31 32);
}

/// One branch per power of two (and per measure, by the `match` inside).
#[inline(never)]
fn reached<const BITS: u32>(measure: u32) {
    match measure {
        0 => std::hint::black_box(("states", BITS)),
        1 => std::hint::black_box(("entries", BITS)),
        2 => std::hint::black_box(("longest row", BITS)),
        _ => std::hint::black_box(("refused", BITS)),
    };
}
