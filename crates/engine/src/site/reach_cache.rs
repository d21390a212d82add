//! The walking-distance tables of a site ([`ReachTable`]), built once per radius and shared by
//! every engine on the site and its copies.

use super::{ReachTable, Site, SiteError};
use std::sync::{Arc, Mutex};

/// The walking-distance tables of a site, per radius: the whole graph's and the surveyed
/// map's ([`ReachTable::build_surveyed`]).
pub type ReachTables = (Arc<ReachTable>, Option<Arc<ReachTable>>);

/// [`Site::reach_tables`]'s memory: the tables of the latest few radii asked for, shared by
/// every engine on the site, since building them is costly (docs/tuning.md#unsurveyed-states).
#[derive(Clone, Default)]
pub(super) struct ReachCache(Arc<Mutex<Vec<(u64, ReachTables)>>>);

impl std::fmt::Debug for ReachCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let radii = self.0.lock().map_or(0, |c| c.len());
        write!(f, "ReachCache({radii} radii)")
    }
}

/// Radii [`ReachCache`] keeps tables for: an engine's and a habit pass's (the same radius),
/// and one more that a caller tries.
const REACH_CACHE_RADII: usize = 2;

impl Site {
    /// The walking-distance tables within `radius_m`: the whole graph's and, when the site has
    /// [`StateKind::Unsurveyed`](super::StateKind::Unsurveyed) states, the surveyed map's. Built
    /// once per radius and shared. Refused ([`SiteError::OverLimit`]) when they would pass the site
    /// budget ([`budget::MAX_REACHABLE_STATES`](super::budget::MAX_REACHABLE_STATES),
    /// [`budget::MAX_REACH_ENTRIES`](super::budget::MAX_REACH_ENTRIES),
    /// `budget::MAX_REACH_EDGE_VISITS`): the build stops
    /// there, having allocated no more.
    pub fn reach_tables(&self, radius_m: f64) -> Result<ReachTables, SiteError> {
        self.cached_reach_tables(radius_m, || ReachTable::build_both(self, radius_m, None))
    }

    /// [`reach_tables`](Self::reach_tables), taking every row it can from `base`'s tables at
    /// the same radius: `base` is a site surveyed over the same grid, such as the site of every
    /// survey walk for a site surveyed without one of them, which differs from it only around
    /// that walk's path. The tables are the same, entry for entry, as those built from scratch
    /// (docs/tuning.md#evaluation-speed).
    pub fn reach_tables_from(&self, base: &Site, radius_m: f64) -> Result<ReachTables, SiteError> {
        // Before this site's cache is locked: `base` may share it.
        let theirs = base.reach_tables(radius_m)?;
        self.cached_reach_tables(radius_m, || ReachTable::build_both(self, radius_m, Some((base, &theirs))))
    }

    /// The cached tables of `radius_m`, or those `build` makes, cached.
    fn cached_reach_tables(
        &self,
        radius_m: f64,
        build: impl FnOnce() -> Result<(ReachTable, Option<ReachTable>), SiteError>,
    ) -> Result<ReachTables, SiteError> {
        let key = radius_m.to_bits();
        // A panic while building leaves the cache as it was: recover it.
        let mut cache = self.reach_tables.0.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some((_, tables)) = cache.iter().find(|(k, _)| *k == key) {
            return Ok(tables.clone());
        }
        let (whole, surveyed) = build()?;
        let tables = (Arc::new(whole), surveyed.map(Arc::new));
        if cache.len() >= REACH_CACHE_RADII {
            cache.remove(0);
        }
        cache.push((key, tables.clone()));
        Ok(tables)
    }
}
