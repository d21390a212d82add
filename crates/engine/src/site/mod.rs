//! The surveyed site: floors, states (the HMM's possible positions), the walkable graph between
//! them, the radio map, and optional zones (rooms, corridors) grouping the states. Loaded from a
//! versioned site file: JSON, or its binary encoding.

mod binary;
pub mod budget;
mod builder;
mod calibration;
mod error;
mod file;
mod floor_reliability;
mod geo;
mod graph;
mod id_hash;
mod landing;
mod pseudo;
mod reach;
mod reach_cache;
mod schema;
mod zones;

pub use builder::fit_columns;
pub use builder::{BuildOptions, SiteBuilder, TrainingScan};
pub(crate) use calibration::SPARSE_SCAN_GAP_S;
pub use calibration::{
    scaled_radii, BandScales, Calibration, PerScenario, ScenarioScales, SparseScans,
    SINCE_SPARSE_SCAN_BANDS_S, SPARSE_BANDS,
};
pub use error::SiteError;
pub(crate) use file::MAX_COORDINATE_M;
pub use floor_reliability::{FloorReliability, FLOOR_BANDS, FLOOR_MISS_BANDS};
pub use geo::{Anchor, GeoError, LatLon};
pub use graph::{Edge, Floor, Neighbours, North, State, StateKind};
pub use id_hash::IdHashing;
pub(crate) use landing::Landings;
pub use pseudo::PSEUDO_SPACING_M;
pub use reach::{Reach, ReachCut, ReachTable};
pub use reach_cache::ReachTables;
pub use schema::{FORMAT_VERSION, OLDEST_FORMAT_VERSION};
pub(crate) use zones::most_likely_zone;
pub use zones::{Zone, ZoneKind, MAX_ZONES};

use crate::radio::RadioMap;
use graph::median_edge_length;
use landing::LandingCache;
use nalgebra::Point2;
use reach_cache::ReachCache;
use std::path::Path;
use std::sync::Arc;

/// A validated site, ready for engines. Immutable; share it with `Arc`.
#[derive(Clone, Debug)]
pub struct Site {
    name: String,
    floors: Vec<Floor>,
    states: Vec<State>,
    edges: Vec<Edge>,
    /// The edges of state `i` are `adjacency[adjacency_starts[i]..adjacency_starts[i + 1]]`,
    /// as indices into `edges`: the neighbour and the length stay in the edge, so the graph
    /// holds each once (docs/tuning.md#engine-speed). 32 bits, as a site of 2³¹ edges would
    /// take 32 GB.
    adjacency_starts: Vec<u32>,
    adjacency: Vec<u32>,
    /// Shared by the site's copies (the survey's calibration replays each held-out site with
    /// many calibrations, each on a copy): a copy is cheap, and engines on copies with the same
    /// map may share their scan likelihoods
    /// ([`SharedEmissions`](crate::SharedEmissions)).
    radio: Arc<RadioMap>,
    /// The survey's reading-age limit, ns ([`Site::max_reading_age_ns`]).
    max_reading_age_ns: Option<u64>,
    north: North,
    /// Where the site frame sits on the Earth, when the file says.
    anchor: Option<Anchor>,
    spacing_m: f64,
    calibration: Calibration,
    /// Set when the transmitter ids are salted hashes.
    id_hashing: Option<IdHashing>,
    /// Named groups of states (rooms, corridors); may be empty.
    zones: Vec<Zone>,
    /// Each state's zone index, `zones::NO_ZONE` for none; empty when there are no zones.
    zone_of: Vec<u32>,
    /// Walking-distance tables built so far, shared by every engine on this site (and its
    /// clones, whose graph is the same).
    reach_tables: ReachCache,
    /// Where floor changes land ([`Site::landings`]), built when first asked, shared likewise.
    landings: LandingCache,
}

impl Site {
    /// Assembles a site from parts that the caller has checked (indices in range, positive
    /// lengths); the site-file loader and [`SiteBuilder`] are the callers.
    fn from_parts(
        name: String,
        floors: Vec<Floor>,
        states: Vec<State>,
        edges: Vec<Edge>,
        radio: RadioMap,
        north: North,
    ) -> Self {
        let n = states.len();
        // The median first and the lists without a second array of cursors: a transient
        // freed after the long-lived arrays are made can stay resident (docs/tuning.md#engine-speed).
        let spacing_m = median_edge_length(&edges);
        // Where each state's list ends, then filled from the back (edges in reverse order, so
        // each list keeps the edges' order); each end moves down to its list's start.
        let mut adjacency_starts = vec![0u32; n + 1];
        for e in &edges {
            adjacency_starts[e.a as usize] += 1;
            adjacency_starts[e.b as usize] += 1;
        }
        for i in 1..=n {
            adjacency_starts[i] += adjacency_starts[i - 1];
        }
        let mut adjacency = vec![0u32; 2 * edges.len()];
        for (k, e) in edges.iter().enumerate().rev() {
            for end in [e.b, e.a] {
                adjacency_starts[end as usize] -= 1;
                adjacency[adjacency_starts[end as usize] as usize] = k as u32;
            }
        }
        Self {
            name,
            floors,
            states,
            edges,
            adjacency_starts,
            adjacency,
            radio: Arc::new(radio),
            max_reading_age_ns: None,
            north,
            anchor: None,
            spacing_m,
            calibration: Calibration::default(),
            id_hashing: None,
            zones: Vec::new(),
            zone_of: Vec::new(),
            reach_tables: ReachCache::default(),
            landings: LandingCache::default(),
        }
    }

    /// The site's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The site called `name`.
    pub fn with_name(mut self, name: impl Into<String>) -> Site {
        self.name = name.into();
        self
    }

    /// Floors, by index.
    pub fn floors(&self) -> &[Floor] {
        &self.floors
    }

    /// The level of each floor, by index: its own (`floors[].level`) when every floor has one,
    /// else its rank by elevation (levels step by one from 0). The barometer counts storeys in
    /// these levels (docs/accuracy.md#barometer).
    pub fn floor_levels(&self) -> Vec<i32> {
        let floors = &self.floors;
        if floors.iter().all(|f| f.level.is_some()) {
            return floors.iter().map(|f| f.level.unwrap_or(0)).collect();
        }
        let mut order: Vec<usize> = (0..floors.len()).collect();
        order.sort_by(|&a, &b| floors[a].elevation_m.total_cmp(&floors[b].elevation_m));
        let mut levels = vec![0; floors.len()];
        for (rank, &f) in order.iter().enumerate() {
            levels[f] = rank as i32;
        }
        levels
    }

    /// The levels between the lowest and the highest of [`Site::floor_levels`] that no floor
    /// has, ascending: storeys the building must have and nobody surveyed (levels 0 and −2
    /// surveyed: −1). The engine reports one where the barometer places the phone
    /// ([`Position::unmapped_level`](crate::Position::unmapped_level)).
    pub fn unmapped_levels(&self) -> Vec<i32> {
        levels_between(&self.floor_levels())
    }

    /// States, by index.
    pub fn states(&self) -> &[State] {
        &self.states
    }

    /// Walkable edges.
    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    /// Walkable neighbours of state `i` with the edge length.
    pub fn neighbours(&self, i: usize) -> Neighbours<'_> {
        Neighbours {
            from: i as u32,
            edges: &self.edges,
            slots: self.adjacency[self.adjacency_starts[i] as usize..self.adjacency_starts[i + 1] as usize]
                .iter(),
        }
    }

    /// The radio map.
    pub fn radio(&self) -> &RadioMap {
        &self.radio
    }

    /// The radio map as its copies share it ([`SharedEmissions`](crate::SharedEmissions)).
    pub(crate) fn shared_radio_map(&self) -> &Arc<RadioMap> {
        &self.radio
    }

    /// Readings last measured longer than this before their scan were left out of the
    /// fingerprints, as not heard (Android re-reports cached access points): engines on the
    /// site leave them out too unless configured otherwise
    /// ([`EngineConfig::max_reading_age_ns`](crate::EngineConfig::max_reading_age_ns)), so a
    /// scan means what it meant to the survey and its calibration. `None`: every reading was
    /// used, or the file does not say (before format version 4).
    pub fn max_reading_age_ns(&self) -> Option<u64> {
        self.max_reading_age_ns
    }

    /// The site with `radios` as the groups of its transmitters (by index) that one radio
    /// sends, each counted once in a scan's likelihood ([`RadioMap::with_shared_radios`]).
    pub fn with_shared_radios(mut self, radios: Vec<Vec<u32>>) -> Result<Site, SiteError> {
        self.radio = Arc::unwrap_or_clone(self.radio)
            .with_shared_radios(radios)
            .map(Arc::new)
            .map_err(|message| SiteError::Invalid { path: "radio.shared_radios".into(), message })?;
        Ok(self)
    }

    /// The site with the survey's reading-age limit ([`max_reading_age_ns`](Self::max_reading_age_ns)).
    /// Site files keep it in whole milliseconds, rounded up.
    pub fn with_max_reading_age_ns(mut self, max_age_ns: Option<u64>) -> Site {
        self.max_reading_age_ns = max_age_ns;
        self
    }

    /// The site frame's orientation on the Earth.
    pub fn north(&self) -> North {
        self.north
    }

    /// What the survey calibrated.
    pub fn calibration(&self) -> &Calibration {
        &self.calibration
    }

    /// How the transmitter ids are hashed; `None` when they are raw MAC addresses and UUIDs.
    pub fn id_hashing(&self) -> Option<&IdHashing> {
        self.id_hashing.as_ref()
    }

    /// The site with `calibration`; `Err((path, message))` if a value is out of range.
    pub fn with_calibration(mut self, calibration: Calibration) -> Result<Site, SiteError> {
        calibration.check().map_err(|(path, message)| SiteError::Invalid { path, message })?;
        self.calibration = calibration;
        Ok(self)
    }

    /// The site with each floor's calibrated γ, `weights[f]` = (with, without a movement
    /// likelihood) for floor `f`; `Err` naming `floors[f].rssi_weight` if one is out of (0, 1]
    /// or there are more entries than floors. Floors past the end keep theirs.
    pub fn with_floor_rssi_weights(mut self, weights: &[[Option<f64>; 2]]) -> Result<Site, SiteError> {
        if weights.len() > self.floors.len() {
            return Err(SiteError::Invalid {
                path: "floors".into(),
                message: format!("{} floor weights for {} floors", weights.len(), self.floors.len()),
            });
        }
        for (f, [with, without]) in weights.iter().enumerate() {
            let floor = Floor {
                rssi_weight: *with,
                rssi_weight_without_movement: *without,
                ..self.floors[f].clone()
            };
            floor.check(f).map_err(|(path, message)| SiteError::Invalid { path, message })?;
            self.floors[f] = floor;
        }
        Ok(self)
    }

    /// The site with `north`.
    pub fn with_north(mut self, north: North) -> Site {
        self.north = north;
        self
    }

    /// Where the site frame sits on the Earth; `None` when the site is not geo-referenced.
    pub fn anchor(&self) -> Option<&Anchor> {
        self.anchor.as_ref()
    }

    /// The site with `anchor` (`None`: not geo-referenced); `Err` naming `anchor.<field>` if a
    /// value is out of range.
    pub fn with_anchor(mut self, anchor: Option<Anchor>) -> Result<Site, SiteError> {
        if let Some(a) = &anchor {
            a.check().map_err(|(field, message)| SiteError::Invalid {
                path: format!("anchor.{field}"),
                message,
            })?;
        }
        self.anchor = anchor;
        Ok(self)
    }

    /// The logical level of floor `floor` (an index into [`floors`](Self::floors)): -1 for
    /// the first basement, as the building numbers it; `None` for an unknown index or a site
    /// file that gives no level.
    pub fn floor_level(&self, floor: usize) -> Option<i32> {
        self.floors.get(floor).and_then(|f| f.level)
    }

    /// The point (x, y), m, of floor `floor`'s frame as latitude/longitude; `None` when the
    /// site has no anchor or the floor index is unknown.
    pub fn lat_lon(&self, floor: usize, x: f64, y: f64) -> Option<LatLon> {
        let (anchor, origin) = (self.anchor.as_ref()?, self.floors.get(floor)?.origin_m);
        Some(anchor.to_lat_lon(x + origin[0], y + origin[1]))
    }

    /// A latitude/longitude as a point of floor `floor`'s frame, m. Without a floor, the
    /// floors must share one frame (the same `origin_m`). Fails when the site has no anchor,
    /// the coordinates are out of range, the floor is unknown, or it is needed and missing.
    pub fn site_point(&self, floor: Option<usize>, at: LatLon) -> Result<Point2<f64>, GeoError> {
        let anchor = self.anchor.as_ref().ok_or(GeoError::NotGeoReferenced)?;
        let at = LatLon::new(at.lat_deg, at.lon_deg)?;
        let origin = match floor {
            Some(f) => {
                let floors = self.floors.len();
                self.floors.get(f).ok_or(GeoError::UnknownFloor { floor: f, floors })?.origin_m
            }
            None => {
                let first = self.floors[0].origin_m;
                if self.floors.iter().any(|f| f.origin_m != first) {
                    return Err(GeoError::FloorRequired);
                }
                first
            }
        };
        let [x, y] = anchor.to_site(at);
        Ok(Point2::new(x - origin[0], y - origin[1]))
    }

    /// The true bearing, degrees clockwise from north, of a heading in radians clockwise from
    /// the site's +y axis (a position's); `None` when the site has no anchor.
    pub fn bearing_deg(&self, heading_rad: f64) -> Option<f64> {
        self.anchor.as_ref().map(|a| a.bearing_deg(heading_rad))
    }

    /// Typical distance between neighbouring states (median edge length), m: the size of the
    /// cell each state stands for.
    pub fn spacing_m(&self) -> f64 {
        self.spacing_m
    }
}

impl Site {
    /// Loads a site file in either encoding: binary ([`Site::to_binary`]) when the bytes start
    /// with its signature, JSON otherwise. More than [`budget::MAX_SITE_FILE_BYTES`] is
    /// refused unread.
    pub fn from_bytes(bytes: &[u8]) -> Result<Site, SiteError> {
        if bytes.len() as u64 > budget::MAX_SITE_FILE_BYTES {
            return Err(file_too_large(bytes.len() as u64, budget::MAX_SITE_FILE_BYTES));
        }
        if binary::is_binary(bytes) {
            binary::decode(bytes)
        } else {
            Site::from_json(bytes)
        }
    }

    /// Loads a site file from disk. It reads no more than [`budget::MAX_SITE_FILE_BYTES`],
    /// and stops after the first block when that does not begin like a site file in either
    /// encoding (`/dev/zero`, an image).
    pub fn load(path: impl AsRef<Path>) -> Result<Site, SiteError> {
        let path = path.as_ref();
        Site::from_bytes(&read_site_file(path)?)
    }
}

fn file_too_large(bytes: u64, limit: u64) -> SiteError {
    let size = if bytes > limit { "larger".to_owned() } else { format!("{bytes} bytes") };
    budget::over("MAX_SITE_FILE_BYTES", limit, format!("the site file is {size}"))
}

/// Bytes read before the start of a file is checked ([`read_bounded`]).
const FIRST_BLOCK_BYTES: u64 = 64 * 1024;

/// A site file's bytes ([`read_bounded`] up to [`budget::MAX_SITE_FILE_BYTES`]).
fn read_site_file(path: &Path) -> Result<Vec<u8>, SiteError> {
    let io = |e: std::io::Error| SiteError::Io { path: path.display().to_string(), message: e.to_string() };
    let file = std::fs::File::open(path).map_err(io)?;
    // The size the file says it has, to allocate once: only a hint (a device, a pipe or a
    // file that grows says otherwise), so the reading is bounded as well.
    let hint = file.metadata().map_or(0, |m| m.len());
    read_bounded(file, hint, budget::MAX_SITE_FILE_BYTES, io)
}

/// Reads a site file of at most `limit` bytes, said to be `hint` bytes long: refused unread
/// when the hint is over the limit, as soon as the reading passes it, or after the first block
/// when that shows it is no site file ([`not_a_site_file`]). `io` names a failed read.
fn read_bounded(
    reader: impl std::io::Read,
    hint: u64,
    limit: u64,
    io: impl Fn(std::io::Error) -> SiteError,
) -> Result<Vec<u8>, SiteError> {
    use std::io::Read;
    if hint > limit {
        return Err(file_too_large(hint, limit));
    }
    let mut limited = reader.take(limit + 1);
    let mut bytes = Vec::with_capacity(FIRST_BLOCK_BYTES.min(hint + 1) as usize);
    (&mut limited).take(FIRST_BLOCK_BYTES).read_to_end(&mut bytes).map_err(&io)?;
    if let Some(e) = not_a_site_file(&bytes) {
        return Err(e);
    }
    bytes.reserve((hint as usize + 1).saturating_sub(bytes.len()));
    limited.read_to_end(&mut bytes).map_err(io)?;
    if bytes.len() as u64 > limit {
        return Err(file_too_large(bytes.len() as u64, limit));
    }
    Ok(bytes)
}

/// Why a file that begins with `start` cannot be a site file, if it cannot: neither the binary
/// signature nor, after an optional byte order mark and white space, the `{` (or `[`) a JSON
/// site file begins with. The error is the one the JSON reader gives at that byte.
fn not_a_site_file(start: &[u8]) -> Option<SiteError> {
    let signature = &binary::SIGNATURE[..start.len().min(binary::SIGNATURE.len())];
    if start.starts_with(signature) {
        return None;
    }
    let json = start.strip_prefix(schema::UTF8_BOM).unwrap_or(start);
    match json.iter().find(|b| !b" \t\r\n".contains(b)) {
        None | Some(b'{' | b'[') => None,
        Some(_) => Site::from_json(start).err(),
    }
}

/// The levels between the lowest and the highest of `levels` that `levels` lacks, ascending
/// ([`Site::unmapped_levels`]).
pub fn levels_between(levels: &[i32]) -> Vec<i32> {
    let (Some(&low), Some(&high)) = (levels.iter().min(), levels.iter().max()) else {
        return Vec::new();
    };
    (low..=high).filter(|l| !levels.contains(l)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_levels_between_are_those_between_the_lowest_and_highest_that_are_missing() {
        assert_eq!(levels_between(&[0, -2]), [-1]);
        assert_eq!(levels_between(&[3, -1, 0]), [1, 2]);
        assert!(levels_between(&[-1, 0, 1]).is_empty());
        assert!(levels_between(&[]).is_empty());
    }

    /// The reading stops at the limit, whatever the file said its size was, and after the
    /// first block when that is no site file: `/dev/zero` made `Site::load` read about 0.5 GB
    /// before it failed (issue 60, item 10).
    #[test]
    fn site_files_are_read_no_further_than_needed() {
        let io = |e: std::io::Error| SiteError::Io { path: "test".into(), message: e.to_string() };
        let read = |bytes: &[u8], hint: u64, limit: u64| read_bounded(bytes, hint, limit, io);
        let json = [&b"{"[..], &[b' '; 200]].concat();
        assert_eq!(read(&json, 0, 201).unwrap(), json, "a file that says it is empty (a pipe)");
        for hint in [0, 10, 200] {
            match read(&json, hint, 200) {
                Err(SiteError::OverLimit { name: "MAX_SITE_FILE_BYTES", limit: 200, what }) => {
                    assert_eq!(what, "the site file is larger")
                }
                other => panic!("{other:?}"),
            }
        }
        assert!(matches!(read(&json, 500, 201), Err(SiteError::OverLimit { .. })), "refused unread");
        // Never more than the first block of an endless stream that is no site file.
        let mut counted = CountingReader { inner: std::io::repeat(0), read: 0 };
        match read_bounded(&mut counted, 0, budget::MAX_SITE_FILE_BYTES, io) {
            Err(SiteError::Syntax { line: 1, column: 1, .. }) => {}
            other => panic!("{other:?}"),
        }
        assert_eq!(counted.read, FIRST_BLOCK_BYTES);
        // What may still be a site file is read on: either encoding's start, after white
        // space and a byte order mark.
        for start in [&binary::SIGNATURE[..3], &binary::SIGNATURE[..], b"\xEF\xBB\xBF \n{", b"", b"\t\r\n "] {
            assert!(not_a_site_file(start).is_none(), "{start:?}");
        }
        assert!(not_a_site_file(b"\x89PNG\r\n").is_some());
    }

    /// Counts the bytes read through it.
    struct CountingReader<R> {
        inner: R,
        read: u64,
    }

    impl<R: std::io::Read> std::io::Read for CountingReader<R> {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = self.inner.read(buf)?;
            self.read += n as u64;
            Ok(n)
        }
    }
}
