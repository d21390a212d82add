//! What a site may cost: limits on a site file's size, on what the loader keeps of it, and on
//! the walking-distance tables an engine builds from it (docs/errors.md#site-limits). Each
//! limit is checked before the allocation it bounds, and a site over one is refused with
//! [`SiteError::OverLimit`] naming it. Without them a 2.3 MB file of 20 000 states a few
//! millimetres apart made the tables ask for gigabytes: their rows grow with the square of
//! the states within reach.
//!
//! The limits are far above any real site, with the largest measured as the reference: the
//! five-floor mall of the competition data (22 543 states, 2.9 million fingerprint entries,
//! 1.55 million table entries at the default 9 m reach, 27.6 MB binary;
//! docs/results.md#speed-and-memory), its floor F1 alone as `waymark survey` builds it, and the
//! simulated building-scale site of `waymark bench` at 50 000 states.

use super::SiteError;

/// Largest site file, bytes, in either encoding: checked while a file is read
/// ([`Site::load`](super::Site::load) reads no further) and on the bytes handed to
/// [`Site::from_bytes`](super::Site::from_bytes). The mall's binary file is 27.6 MB and its
/// JSON about 130 MB (F1's is 35.9 MB for 0.82 million fingerprint entries); the JSON of the
/// bench's 50 000-state site, about 400 MB, is the largest any tool writes.
pub const MAX_SITE_FILE_BYTES: u64 = 1 << 30;

/// Most states: every engine allocates its filters per state. 46 times the mall's 22 543, 21
/// times the bench's largest site.
pub const MAX_STATES: usize = 1 << 20;

/// Most edges at one state: a state's edges are walked once for every state that reaches it,
/// so they multiply the tables' building time. The survey's grid joins a state to its 8
/// neighbours, and no real or simulated site has a state with more than 8.
pub const MAX_EDGES_PER_STATE: usize = 64;

/// Most transmitters one state's fingerprint models: at most 655 on F1 (2 531 transmitters),
/// about 200 on the simulated sites; a phone's scan lists a few hundred at most.
pub(crate) const MAX_TRANSMITTERS_PER_STATE: usize = 4096;

/// Most fingerprint entries in a site, what its radio map holds (4 bytes each, 12 while the
/// map is built): 11.6 times the mall's 2.9 million, 3.6 times the bench's 50 000-state
/// site's 9.2 million.
pub const MAX_FINGERPRINT_ENTRIES: usize = 1 << 25;

/// Most states within the reach radius of one state, itself included: a row of the
/// walking-distance table. At the default 9 m the survey's 2 m grid has at most 61 (F1 and
/// the bench's sites), the simulated office with pseudo states 0.75 m apart 94; 4 096 is a
/// state every 0.25 m all around.
pub const MAX_REACHABLE_STATES: usize = 4096;

/// Most entries in the walking-distance tables of one radius, the whole graph's and the
/// surveyed map's together (3 to 8 bytes each, docs/tuning.md#engine-speed): 5.4 times the
/// mall's 1.55 million, 2.8 times the bench's 50 000-state site's 3.0 million. Building this
/// many takes about half a second (docs/errors.md#site-limits).
pub const MAX_REACH_ENTRIES: usize = 1 << 23;

/// Most edges the walking-distance tables of one radius may walk while they are built (each
/// state's bounded Dijkstra walks the edges of every state it reaches): what the build's
/// time grows with, once the entries are bounded, on a site whose states have many edges.
/// 1.8 million on F1 and 24 million on the bench's 50 000-state site; this many take about
/// half a second (docs/errors.md#site-limits).
pub(crate) const MAX_REACH_EDGE_VISITS: u64 = 1 << 26;

/// The refusal of a site over the limit `name` (`limit`), `what` saying where.
pub(super) fn over(name: &'static str, limit: u64, what: impl Into<String>) -> SiteError {
    SiteError::OverLimit { name, limit, what: what.into() }
}

/// What the walking-distance tables of one radius may still take while they are built.
#[derive(Debug)]
pub(super) struct ReachBudget {
    entries: usize,
    edge_visits: u64,
}

impl ReachBudget {
    /// The whole allowance of [`MAX_REACH_ENTRIES`] and [`MAX_REACH_EDGE_VISITS`].
    pub(super) fn new() -> Self {
        Self::of(MAX_REACH_ENTRIES, MAX_REACH_EDGE_VISITS)
    }

    /// An allowance of `entries` and `edge_visits` (smaller ones in tests).
    pub(super) fn of(entries: usize, edge_visits: u64) -> Self {
        Self { entries, edge_visits }
    }

    /// Takes `entries` more table entries, before they are stored.
    pub(super) fn take_entries(&mut self, entries: usize, radius_m: f64) -> Result<(), SiteError> {
        self.entries = self.entries.checked_sub(entries).ok_or_else(|| {
            over(
                "MAX_REACH_ENTRIES",
                MAX_REACH_ENTRIES as u64,
                format!("the walking-distance tables within {radius_m} m need more entries"),
            )
        })?;
        Ok(())
    }

    /// Takes `visits` more edge visits.
    pub(super) fn take_edge_visits(&mut self, visits: u64, radius_m: f64) -> Result<(), SiteError> {
        self.edge_visits = self.edge_visits.checked_sub(visits).ok_or_else(|| {
            over(
                "MAX_REACH_EDGE_VISITS",
                MAX_REACH_EDGE_VISITS,
                format!("building the walking-distance tables within {radius_m} m walks more edges"),
            )
        })?;
        Ok(())
    }
}
