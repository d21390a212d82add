//! Site files: serde JSON with a `format_version` ([`FORMAT_VERSION`]). Loading checks everything an engine relies
//! on and names what is wrong and where; it never panics.
//!
//! A site file may hold salted hashes of its transmitter ids instead of raw MAC addresses and
//! UUIDs: `radio.id_hash` then names the scheme and stores the salt check, and every entry of
//! `radio.transmitters` is `hashed_wifi` or `hashed_ble` (see [`crate::radio::Salt`]). Files
//! without `id_hash` are read exactly as before.
//!
//! An optional top-level `zones` array groups states into named places (rooms, corridors):
//! `{"name": "kitchen", "kind": "room", "states": [state ids]}`, each state in at most one
//! zone. Files without `zones` are read, and written, exactly as before.

use super::budget::{
    self, MAX_EDGES_PER_STATE, MAX_FINGERPRINT_ENTRIES, MAX_STATES, MAX_TRANSMITTERS_PER_STATE,
};
use super::error::invalid;
use super::id_hash::id_hashing;
use super::schema::{
    parse_json, EdgeFile, FingerprintFile, Fingerprints, FloorFile, GaussianFile, IdHashFile, RadioFile,
    SiteFile, StateFile, ZoneFile, FORMAT_VERSION,
};
use super::{Edge, Floor, Site, SiteError, State};
use crate::radio::{
    quantise, Gaussian, RadioMap, ID_HASH_SCHEME, ID_HASH_VERSION, MAX_ABS_LEVEL_DBM, MAX_STORED_STD_DB,
    MIN_STD_DB,
};
use crate::NS_PER_MS;
use nalgebra::Point2;
use std::collections::HashMap;

/// Largest |x| and |y| of a state, m. Found with the `site_file` fuzz harness: states at
/// ±1e308 m made distances overflow to an infinite accuracy radius. 1000 km is more than any
/// building's frame, and keeps every distance and its square finite.
pub const MAX_COORDINATE_M: f64 = 1e6;

/// A validated Gaussian; `path` (formatted only on error) says where it was in the file.
fn gaussian(path: impl FnOnce() -> String, g: &GaussianFile) -> Result<Gaussian, SiteError> {
    let (mean, std) = (g.mean_dbm, g.std_db);
    // The radio map stores levels to 0.01 dB in 16 bits (`radio::LEVEL_STEP_DB`): with σ ≥
    // 0.01 dB and levels within ±320 dBm, every accepted reading (at most +100 dBm) has a
    // finite log-likelihood.
    Gaussian::new(mean, std)
        .filter(|_| mean.abs() <= MAX_ABS_LEVEL_DBM && (MIN_STD_DB..=MAX_STORED_STD_DB).contains(&std))
        .ok_or_else(|| {
            invalid(
                path(),
                format!(
                    "mean_dbm must be within ±{MAX_ABS_LEVEL_DBM} and std_db within \
                     [{MIN_STD_DB}, {MAX_STORED_STD_DB}] (got {mean}, {std})"
                ),
            )
        })
}

/// A site file's fingerprint entries as `(state, transmitter, mean, σ)` in
/// [`LEVEL_STEP_DB`](crate::radio::LEVEL_STEP_DB) steps, state by state, for
/// [`RadioMap::from_steps`].
struct Entries<'a> {
    states: &'a [StateFile],
    fingerprints: Fingerprints<'a>,
    /// How many states have been started (the one being read is the last), its next entry
    /// and the number it has.
    started: usize,
    k: usize,
    count: usize,
    /// The columns' index of the next entry.
    next: usize,
}

impl Iterator for Entries<'_> {
    type Item = Result<(u32, u32, i16, u16), String>;

    fn next(&mut self) -> Option<Self::Item> {
        while self.k == self.count {
            let s = self.states.get(self.started)?;
            self.count = match self.fingerprints {
                Fingerprints::Nested => s.fingerprint.len(),
                Fingerprints::Columns(c) => c.count(self.started),
            };
            (self.started, self.k) = (self.started + 1, 0);
        }
        let (i, k) = (self.started - 1, self.k);
        self.k += 1;
        let entry = match self.fingerprints {
            Fingerprints::Nested => {
                let f = &self.states[i].fingerprint[k];
                let g = Gaussian { mean_dbm: f.mean_dbm, std_db: f.std_db };
                let Some((mean, std)) = quantise(&g) else {
                    return Some(Err(format!("states[{i}].fingerprint[{k}] is outside the stored range")));
                };
                (f.tx, mean, std)
            }
            Fingerprints::Columns(c) => {
                self.next += 1;
                c.entry_steps(self.next - 1)
            }
        };
        Some(Ok((i as u32, entry.0 as u32, entry.1, entry.2)))
    }
}

impl Site {
    /// Loads a site file from JSON bytes.
    pub fn from_json(bytes: &[u8]) -> Result<Site, SiteError> {
        Site::from_file(parse_json(bytes)?, Fingerprints::Nested)
    }

    /// The site as site-file JSON (current format version).
    pub fn to_json(&self) -> String {
        serde_json::to_string(&self.to_file(true)).expect("a site serialises: every float in it is finite")
    }

    /// The site as the serde model of its file; `nested` puts each state's fingerprint in it
    /// (JSON), otherwise every state's array is left empty (the binary header).
    pub(super) fn to_file(&self, nested: bool) -> SiteFile {
        let mut fingerprints: Vec<Vec<FingerprintFile>> =
            (0..self.states.len()).map(|_| Vec::new()).collect();
        for (state, tx, g) in self.radio.fingerprints().filter(|_| nested) {
            fingerprints[state as usize].push(FingerprintFile {
                tx: tx as usize,
                mean_dbm: g.mean_dbm,
                std_db: g.std_db,
            });
        }
        let unheard = self.radio.unheard();
        SiteFile {
            format_version: FORMAT_VERSION,
            name: self.name.clone(),
            north: self.north,
            anchor: self.anchor,
            floors: self
                .floors
                .iter()
                .map(|f| FloorFile {
                    name: f.name.clone(),
                    elevation_m: f.elevation_m,
                    level: f.level,
                    origin_m: (f.origin_m != [0.0, 0.0]).then_some(f.origin_m),
                    rssi_weight: f.rssi_weight,
                    rssi_weight_without_movement: f.rssi_weight_without_movement,
                })
                .collect(),
            radio: RadioFile {
                model: self.radio.model(),
                clip_dbm: self.radio.clip_dbm(),
                unheard: GaussianFile { mean_dbm: unheard.mean_dbm, std_db: unheard.std_db },
                id_hash: self.id_hashing.as_ref().map(|h| IdHashFile {
                    scheme: ID_HASH_SCHEME.to_owned(),
                    version: ID_HASH_VERSION,
                    salt_check: h.salt_check().to_owned(),
                }),
                max_reading_age_ms: self.max_reading_age_ns.map(|ns| ns.div_ceil(NS_PER_MS)),
                shared_radios: self.radio.shared_radios().to_vec(),
                transmitters: self.radio.transmitters().to_vec(),
            },
            states: self
                .states
                .iter()
                .zip(fingerprints)
                .map(|(s, fingerprint)| StateFile {
                    id: s.id,
                    floor: s.floor,
                    x: s.position.x,
                    y: s.position.y,
                    kind: s.kind,
                    training_scans: s.training_scans,
                    fingerprint,
                })
                .collect(),
            edges: self
                .edges
                .iter()
                .map(|e| {
                    let (a, b) = (&self.states[e.a as usize], &self.states[e.b as usize]);
                    let straight = a.floor == b.floor
                        && (nalgebra::distance(&a.position, &b.position) - e.length_m).abs() < 1e-9;
                    EdgeFile { from: a.id, to: b.id, length_m: (!straight).then_some(e.length_m) }
                })
                .collect(),
            calibration: self.calibration,
            zones: self
                .zones
                .iter()
                .map(|z| ZoneFile {
                    name: z.name.clone(),
                    kind: z.kind,
                    states: z.states.iter().map(|&i| self.states[i as usize].id).collect(),
                })
                .collect(),
        }
    }

    pub(super) fn from_file(file: SiteFile, fingerprints: Fingerprints) -> Result<Site, SiteError> {
        if file.floors.is_empty() {
            return Err(invalid("floors", "a site needs at least one floor"));
        }
        for (i, f) in file.floors.iter().enumerate() {
            if !f.elevation_m.is_finite() {
                return Err(invalid(format!("floors[{i}].elevation_m"), "must be finite"));
            }
        }
        if file.states.is_empty() {
            return Err(invalid("states", "a site needs at least one state"));
        }
        if file.states.len() > MAX_STATES {
            return Err(budget::over(
                "MAX_STATES",
                MAX_STATES as u64,
                format!("the site has {} states", file.states.len()),
            ));
        }
        let radio = &file.radio;
        let max_reading_age_ms = radio.max_reading_age_ms;
        if !radio.clip_dbm.is_finite() || radio.clip_dbm.abs() > MAX_ABS_LEVEL_DBM {
            return Err(invalid("radio.clip_dbm", format!("must be within ±{MAX_ABS_LEVEL_DBM}")));
        }
        let unheard = gaussian(|| "radio.unheard".into(), &radio.unheard)?;
        let id_hashing = id_hashing(radio)?;
        let tx_count = radio.transmitters.len();
        let mut ids = HashMap::with_capacity(file.states.len());
        let mut states = Vec::with_capacity(file.states.len());
        let mut seen_in = vec![0usize; tx_count];
        let mut next_column_entry = 0;
        let mut fingerprint_entries = 0;
        for (i, s) in file.states.iter().enumerate() {
            let at = |field: &str| format!("states[{i}].{field}");
            if let Some(first) = ids.insert(s.id, i) {
                return Err(invalid(at("id"), format!("id {} is already used by states[{first}]", s.id)));
            }
            if s.floor >= file.floors.len() {
                return Err(invalid(
                    at("floor"),
                    format!("floor {} does not exist (the site has {} floors)", s.floor, file.floors.len()),
                ));
            }
            let inside = |v: f64| v.is_finite() && v.abs() <= MAX_COORDINATE_M;
            if !(inside(s.x) && inside(s.y)) {
                return Err(invalid(at("x"), format!("coordinates must be within ±{MAX_COORDINATE_M} m")));
            }
            let count = match fingerprints {
                Fingerprints::Nested => s.fingerprint.len(),
                Fingerprints::Columns(_) if !s.fingerprint.is_empty() => {
                    return Err(invalid(at("fingerprint"), "must be empty in a binary site file's header"))
                }
                Fingerprints::Columns(c) => c.count(i),
            };
            if count > MAX_TRANSMITTERS_PER_STATE {
                return Err(budget::over(
                    "MAX_TRANSMITTERS_PER_STATE",
                    MAX_TRANSMITTERS_PER_STATE as u64,
                    format!("{} models {count} transmitters", at("fingerprint")),
                ));
            }
            fingerprint_entries += count;
            if fingerprint_entries > MAX_FINGERPRINT_ENTRIES {
                return Err(budget::over(
                    "MAX_FINGERPRINT_ENTRIES",
                    MAX_FINGERPRINT_ENTRIES as u64,
                    format!("the fingerprints up to {} have more entries", at("fingerprint")),
                ));
            }
            for k in 0..count {
                let (tx, mean_dbm, std_db) = match fingerprints {
                    Fingerprints::Nested => {
                        let f = &s.fingerprint[k];
                        (f.tx, f.mean_dbm, f.std_db)
                    }
                    Fingerprints::Columns(c) => c.entry(next_column_entry + k),
                };
                // Paths are formatted only for an error: once per entry, they were a third of
                // the load time of a 10 000-state site.
                let path = || format!("states[{i}].fingerprint[{k}]");
                if tx >= tx_count {
                    return Err(invalid(
                        format!("{}.tx", path()),
                        format!("transmitter {tx} does not exist (radio.transmitters has {tx_count})"),
                    ));
                }
                // seen_in[t] holds 1 + the last state that modelled transmitter t.
                if seen_in[tx] == i + 1 {
                    return Err(invalid(
                        format!("{}.tx", path()),
                        format!("transmitter {tx} is modelled twice"),
                    ));
                }
                seen_in[tx] = i + 1;
                gaussian(path, &GaussianFile { mean_dbm, std_db })?;
            }
            next_column_entry += count;
            states.push(State {
                id: s.id,
                floor: s.floor,
                position: Point2::new(s.x, s.y),
                kind: s.kind,
                training_scans: s.training_scans,
            });
        }
        let mut edges = Vec::with_capacity(file.edges.len());
        let mut degree = vec![0u32; states.len()];
        for (k, e) in file.edges.iter().enumerate() {
            let at = |field: &str| format!("edges[{k}].{field}");
            let lookup = |id: u32, field: &str| {
                ids.get(&id).copied().ok_or_else(|| invalid(at(field), format!("no state has id {id}")))
            };
            let (a, b) = (lookup(e.from, "from")?, lookup(e.to, "to")?);
            if a == b {
                return Err(invalid(at("to"), "an edge must join two different states"));
            }
            for end in [a, b] {
                degree[end] += 1;
                if degree[end] as usize > MAX_EDGES_PER_STATE {
                    return Err(budget::over(
                        "MAX_EDGES_PER_STATE",
                        MAX_EDGES_PER_STATE as u64,
                        format!("edges[{k}] gives state id {} more edges", states[end].id),
                    ));
                }
            }
            let (sa, sb) = (&states[a], &states[b]);
            let length_m = match e.length_m {
                Some(l) if l.is_finite() && l > 0.0 => l,
                Some(l) => return Err(invalid(at("length_m"), format!("must be finite and > 0 (got {l})"))),
                None if sa.floor != sb.floor => {
                    return Err(invalid(at("length_m"), "required for an edge between floors (stairs, lift)"))
                }
                None => {
                    let d = nalgebra::distance(&sa.position, &sb.position);
                    if d <= 0.0 {
                        return Err(invalid(at("to"), "the two states are at the same place: give length_m"));
                    }
                    d
                }
            };
            edges.push(Edge { a: a as u32, b: b as u32, length_m });
        }
        let floors: Vec<Floor> = file
            .floors
            .into_iter()
            .map(|f| Floor {
                name: f.name,
                elevation_m: f.elevation_m,
                level: f.level,
                origin_m: f.origin_m.unwrap_or([0.0, 0.0]),
                rssi_weight: f.rssi_weight,
                rssi_weight_without_movement: f.rssi_weight_without_movement,
            })
            .collect();
        for (i, f) in floors.iter().enumerate() {
            f.check(i).map_err(|(path, message)| invalid(path, message))?;
        }
        // Checked above, the entries are read again as the map takes them: a list of them
        // between the file and the map was the largest part of the load's peak memory
        // (docs/tuning.md#engine-speed). The columns hold them as the map stores them.
        let entries = Entries { states: &file.states, fingerprints, started: 0, k: 0, count: 0, next: 0 };
        let map = RadioMap::from_steps(
            radio.model,
            radio.clip_dbm,
            unheard,
            file.radio.transmitters,
            states.len(),
            entries,
        )
        .map_err(|m| invalid("radio.transmitters", m))?
        .with_shared_radios(file.radio.shared_radios)
        .map_err(|m| invalid("radio.shared_radios", m))?;
        if !(file.north.site_rotation_rad.is_finite() && file.north.declination_rad.is_finite()) {
            return Err(invalid("north", "angles must be finite"));
        }
        let (zones, zone_of) = super::zones::validate(
            file.zones.iter().map(|z| (z.name.clone(), z.kind, &z.states[..])),
            states.len(),
            "id",
            |id| ids.get(&id).copied(),
        )?;
        let site = Site::from_parts(file.name, floors, states, edges, map, file.north)
            .with_max_reading_age_ns(max_reading_age_ms.map(|ms| ms.saturating_mul(NS_PER_MS)));
        let site = site.with_calibration(file.calibration)?.with_anchor(file.anchor)?;
        Ok(Site { id_hashing, zones, zone_of, ..site })
    }
}

#[cfg(test)]
pub(super) mod tests;
