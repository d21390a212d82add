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
use super::schema::{
    parse_json, EdgeFile, FingerprintFile, Fingerprints, FloorFile, GaussianFile, IdHashFile, RadioFile,
    SiteFile, StateFile, ZoneFile, FORMAT_VERSION,
};
use super::{Edge, Floor, Site, SiteError, State};
use crate::radio::{
    quantise, Gaussian, RadioMap, Salt, ScanHasher, HASH_HEX_DIGITS, ID_HASH_SCHEME, ID_HASH_VERSION,
    MAX_ABS_LEVEL_DBM, MAX_STORED_STD_DB, MIN_STD_DB,
};
use crate::NS_PER_MS;
use nalgebra::Point2;
use std::collections::HashMap;

/// How a site's transmitter ids are hashed: [`ID_HASH_SCHEME`] version [`ID_HASH_VERSION`]
/// (the only one this build reads), and the salt check that tells the right salt.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct IdHashing {
    salt_check: String,
}

impl IdHashing {
    /// HMAC-SHA256(salt, `waymark salt check`), 128 bits as 32 lower-case hex digits.
    pub fn salt_check(&self) -> &str {
        &self.salt_check
    }
}

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
                    salt_check: h.salt_check.clone(),
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

    /// The same site with every transmitter id replaced by its hash under `salt`
    /// ([`Salt::hash`]) and the salt check recorded, ready to ship without raw MAC addresses.
    /// Engines on it need the same salt ([`EngineConfig::site_salt`](crate::EngineConfig::site_salt)).
    pub fn hashed(&self, salt: &Salt) -> Result<Site, SiteError> {
        if self.id_hashing.is_some() {
            return Err(invalid("radio.id_hash", "the site's transmitter ids are hashed already"));
        }
        let radio = &self.radio;
        let ids = radio.transmitters().iter().map(|id| salt.hash(id)).collect();
        let map = RadioMap::new(
            radio.model(),
            radio.clip_dbm(),
            radio.unheard(),
            ids,
            radio.state_count(),
            radio.fingerprints(),
        )
        .and_then(|map| map.with_shared_radios(radio.shared_radios().to_vec()))
        .map_err(|m| invalid("radio.transmitters", m))?;
        Ok(Site {
            radio: std::sync::Arc::new(map),
            id_hashing: Some(IdHashing { salt_check: salt.check_value() }),
            ..self.clone()
        })
    }

    /// What an engine on this site matches scans with: `None` for raw ids, a [`ScanHasher`]
    /// for hashed ones. Fails when the ids are hashed and `salt` is missing or is not the one
    /// they were hashed with. A salt given for a site with raw ids is not needed and is
    /// ignored (with a log warning).
    pub fn scan_hasher(&self, salt: Option<&Salt>) -> Result<Option<ScanHasher>, SiteError> {
        match (&self.id_hashing, salt) {
            (None, None) => Ok(None),
            (None, Some(_)) => {
                log::warn!("a salt was given, but the site's transmitter ids are not hashed: it is not used");
                Ok(None)
            }
            (Some(_), None) => Err(SiteError::SaltRequired),
            (Some(h), Some(salt)) if salt.matches_check(&h.salt_check) => {
                Ok(Some(ScanHasher::new(salt.clone())))
            }
            (Some(_), Some(_)) => Err(SiteError::WrongSalt),
        }
    }
}

/// The file's id hashing, checked against its transmitters: with `id_hash`, every id must be
/// hashed; without, none may be.
fn id_hashing(radio: &RadioFile) -> Result<Option<IdHashing>, SiteError> {
    let hashing = match &radio.id_hash {
        None => None,
        Some(h) if h.scheme != ID_HASH_SCHEME || h.version != ID_HASH_VERSION => {
            return Err(SiteError::UnsupportedIdHash { scheme: h.scheme.clone(), version: h.version })
        }
        Some(h) => {
            let check = h.salt_check.to_ascii_lowercase();
            if check.len() != HASH_HEX_DIGITS || !check.bytes().all(|c| c.is_ascii_hexdigit()) {
                return Err(invalid(
                    "radio.id_hash.salt_check",
                    format!("must be {HASH_HEX_DIGITS} hex digits"),
                ));
            }
            Some(IdHashing { salt_check: check })
        }
    };
    if let Some(k) = radio.transmitters.iter().position(|id| id.is_hashed() != hashing.is_some()) {
        let message = if hashing.is_some() {
            "a raw id in a site whose ids are hashed (radio.id_hash)"
        } else {
            "a hashed id needs radio.id_hash (the scheme and the salt check)"
        };
        return Err(invalid(format!("radio.transmitters[{k}]"), message));
    }
    Ok(hashing)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::radio::TransmitterId;
    use crate::site::{GeoError, ZoneKind};

    const GOOD: &str = r#"{
      "format_version": 1,
      "name": "tiny",
      "floors": [{"name": "G"}],
      "radio": {"clip_dbm": -100, "unheard": {"mean_dbm": -115, "std_db": 5},
                "transmitters": [{"wifi": {"bssid": "00:11:22:33:44:55"}}]},
      "states": [
        {"id": 7, "floor": 0, "x": 0, "y": 0, "training_scans": 10,
         "fingerprint": [{"tx": 0, "mean_dbm": -60, "std_db": 4}]},
        {"id": 9, "floor": 0, "x": 3, "y": 4}
      ],
      "edges": [{"from": 7, "to": 9}]
    }"#;

    fn err(text: &str) -> SiteError {
        Site::from_json(text.as_bytes()).unwrap_err()
    }

    #[test]
    fn loads_and_round_trips() {
        let site = Site::from_json(GOOD.as_bytes()).unwrap();
        assert_eq!(site.states().len(), 2);
        assert_eq!(site.edges()[0].length_m, 5.0);
        assert_eq!(site.neighbours(1).collect::<Vec<_>>(), [(0, 5.0)]);
        let again = Site::from_json(site.to_json().as_bytes()).unwrap();
        assert_eq!(again.to_json(), site.to_json());
        assert_eq!(again.states(), site.states());
    }

    /// States without a fingerprint first, between and last: every model reaches the map at
    /// its own state, from JSON and from the binary file's columns.
    #[test]
    fn models_reach_their_states_around_states_without_any() {
        let json = r#"{
          "format_version": 1,
          "name": "gaps",
          "floors": [{"name": "G"}],
          "radio": {"clip_dbm": -100, "unheard": {"mean_dbm": -115, "std_db": 5},
                    "transmitters": [{"wifi": {"bssid": "00:11:22:33:44:55"}},
                                     {"wifi": {"bssid": "00:11:22:33:44:66"}}]},
          "states": [
            {"id": 1, "floor": 0, "x": 0, "y": 0},
            {"id": 2, "floor": 0, "x": 2, "y": 0, "training_scans": 3,
             "fingerprint": [{"tx": 1, "mean_dbm": -61.5, "std_db": 4}, {"tx": 0, "mean_dbm": -70, "std_db": 3}]},
            {"id": 3, "floor": 0, "x": 4, "y": 0},
            {"id": 4, "floor": 0, "x": 6, "y": 0},
            {"id": 5, "floor": 0, "x": 8, "y": 0, "training_scans": 2,
             "fingerprint": [{"tx": 0, "mean_dbm": -55.25, "std_db": 2.5}]},
            {"id": 6, "floor": 0, "x": 10, "y": 0}
          ],
          "edges": [{"from": 1, "to": 2}]
        }"#;
        let expected = [(1, 0, -70.0, 3.0), (4, 0, -55.25, 2.5), (1, 1, -61.5, 4.0)];
        let from_json = Site::from_json(json.as_bytes()).unwrap();
        let from_binary = Site::from_bytes(&from_json.to_binary()).unwrap();
        for site in [from_json, from_binary] {
            let models: Vec<(u32, u32, f64, f64)> =
                site.radio().fingerprints().map(|(s, t, g)| (s, t, g.mean_dbm, g.std_db)).collect();
            assert_eq!(models, expected);
        }
    }

    #[test]
    fn floor_gammas_round_trip_in_both_encodings_and_old_files_have_none() {
        let plain = Site::from_json(GOOD.as_bytes()).unwrap();
        assert_eq!(plain.floors()[0].rssi_weight, None);
        assert!(!plain.to_json().contains("rssi_weight"));
        let site = plain.with_floor_rssi_weights(&[[Some(0.03), Some(0.1)]]).unwrap();
        let json = site.to_json();
        assert!(json.contains(r#""floors":[{"name":"G","elevation_m":0.0,"rssi_weight":0.03,"rssi_weight_without_movement":0.1}]"#), "{json}");
        let again = Site::from_json(json.as_bytes()).unwrap();
        assert_eq!(again.floors(), site.floors());
        let packed = Site::from_bytes(&site.to_binary()).unwrap();
        assert_eq!(packed.floors(), site.floors());
        assert_eq!(packed.to_json(), json);
    }

    #[test]
    fn truncated_file_is_named_as_such() {
        for cut in [10, GOOD.len() / 2, GOOD.len() - 3] {
            assert!(matches!(err(&GOOD[..cut]), SiteError::Truncated { .. }), "cut at {cut}");
        }
    }

    #[test]
    fn errors_say_what_and_where() {
        assert!(matches!(err("{\"format_version\": 1,, }"), SiteError::Syntax { line: 1, .. }));
        let newer = FORMAT_VERSION + 1;
        assert_eq!(
            err(&GOOD.replace("\"format_version\": 1", &format!("\"format_version\": {newer}"))),
            SiteError::NewerFormat { found: newer.into(), supported: FORMAT_VERSION }
        );
        let cases = [
            (GOOD.replace("\"format_version\": 1,", ""), "format_version"),
            (
                GOOD.replace("{\"name\": \"G\"}", "{\"name\": \"G\", \"rssi_weight\": 1.5}"),
                "floors[0].rssi_weight",
            ),
            (
                GOOD.replace("{\"name\": \"G\"}", "{\"name\": \"G\", \"rssi_weight_without_movement\": 0}"),
                "floors[0].rssi_weight_without_movement",
            ),
            (GOOD.replace("\"std_db\": 4", "\"std_db\": 0"), "states[0].fingerprint[0]"),
            (GOOD.replace("\"tx\": 0", "\"tx\": 3"), "states[0].fingerprint[0].tx"),
            (GOOD.replace("\"id\": 9", "\"id\": 7"), "states[1].id"),
            (GOOD.replace("\"to\": 9", "\"to\": 8"), "edges[0].to"),
            (GOOD.replace("\"x\": 3", "\"x\": \"3\""), "states[1].x"),
            (GOOD.replace("\"floor\": 0, \"x\": 3", "\"floor\": 4, \"x\": 3"), "states[1].floor"),
            (GOOD.replace("\"bssid\": \"00:11:22:33:44:55\"", "\"bssid\": \"zz\""), "radio.transmitters[0]"),
            (GOOD.replace("\"training_scans\": 10,", "\"trainingscans\": 10,"), "states[0]"),
            (
                GOOD.replace("{\"from\": 7, \"to\": 9}", "{\"from\": 7, \"to\": 9, \"length_m\": -1}"),
                "edges[0].length_m",
            ),
        ];
        for (text, path) in cases {
            match err(&text) {
                SiteError::Invalid { path: p, message } => {
                    assert!(p.starts_with(path), "expected {path}, got {p}: {message}")
                }
                other => panic!("expected Invalid at {path}, got {other:?}"),
            }
        }
    }

    const SALT: &str = "000102030405060708090a0b0c0d0e0f101112131415161718191a1b1c1d1e1f";

    #[test]
    fn hashed_site_holds_no_raw_id_and_round_trips() {
        let salt = Salt::from_hex(SALT).unwrap();
        let raw = Site::from_json(GOOD.as_bytes()).unwrap();
        assert!(raw.id_hashing().is_none());
        assert!(!raw.to_json().contains("id_hash"), "raw files are written as before");
        let hashed = raw.hashed(&salt).unwrap();
        let text = hashed.to_json();
        assert!(!text.contains("00:11:22") && !text.contains("bssid"), "{text}");
        assert!(
            text.contains(r#""id_hash":{"scheme":"hmac-sha256-128","version":1,"salt_check":"#),
            "{text}"
        );
        let again = Site::from_json(text.as_bytes()).unwrap();
        assert_eq!(again.to_json(), text);
        assert_eq!(again.radio().transmitters(), &[salt.hash(&raw.radio().transmitters()[0])]);
        assert_eq!(again.id_hashing().unwrap().salt_check(), salt.check_value());
        let fingerprints =
            |s: &Site| s.radio().fingerprints().map(|(a, b, g)| (a, b, g.mean_dbm)).collect::<Vec<_>>();
        assert_eq!(fingerprints(&again), fingerprints(&raw));
        assert!(matches!(hashed.hashed(&salt), Err(SiteError::Invalid { .. })), "hashed twice");
        let pseudo = hashed.with_pseudo_states(1.0);
        assert!(pseudo.states().len() > hashed.states().len());
        assert_eq!(pseudo.id_hashing(), hashed.id_hashing(), "pseudo states keep the hashing");
    }

    #[test]
    fn the_salt_must_be_the_sites() {
        let salt = Salt::from_hex(SALT).unwrap();
        let other = Salt::new([9u8; 16]).unwrap();
        let raw = Site::from_json(GOOD.as_bytes()).unwrap();
        let hashed = raw.hashed(&salt).unwrap();
        assert!(matches!(hashed.scan_hasher(Some(&salt)), Ok(Some(_))));
        assert_eq!(hashed.scan_hasher(None).unwrap_err(), SiteError::SaltRequired);
        assert_eq!(hashed.scan_hasher(Some(&other)).unwrap_err(), SiteError::WrongSalt);
        assert!(matches!(raw.scan_hasher(Some(&salt)), Ok(None)), "a salt for raw ids is ignored");
        assert!(matches!(raw.scan_hasher(None), Ok(None)));
        for e in [SiteError::SaltRequired, SiteError::WrongSalt] {
            assert!(!e.to_string().contains(SALT), "{e}");
        }
    }

    #[test]
    fn hashed_files_are_checked() {
        let salt = Salt::from_hex(SALT).unwrap();
        let text = Site::from_json(GOOD.as_bytes()).unwrap().hashed(&salt).unwrap().to_json();
        let check = salt.check_value();
        let version = text.replace("\"version\":1", "\"version\":2");
        assert!(matches!(err(&version), SiteError::UnsupportedIdHash { version: 2, .. }));
        let scheme = text.replace("hmac-sha256-128", "hmac-sha3");
        assert!(matches!(err(&scheme), SiteError::UnsupportedIdHash { .. }));
        let hashed_id = salt.hash(&TransmitterId::wifi("00:11:22:33:44:55").unwrap());
        let TransmitterId::HashedWifi { hash } = &hashed_id else { panic!("{hashed_id:?}") };
        let cases = [
            (text.replace(&check, "abc"), "radio.id_hash.salt_check"),
            (
                text.replace(
                    &format!("{{\"hashed_wifi\":{{\"hash\":\"{hash}\"}}}}"),
                    r#"{"wifi":{"bssid":"00:11:22:33:44:55"}}"#,
                ),
                "radio.transmitters[0]",
            ),
            (
                GOOD.replace(
                    r#"{"wifi": {"bssid": "00:11:22:33:44:55"}}"#,
                    &format!(r#"{{"hashed_wifi": {{"hash": "{hash}"}}}}"#),
                ),
                "radio.transmitters[0]",
            ),
            (text.replace(hash, "xyz"), "radio.transmitters[0]"),
            (text.replace("\"salt_check\"", "\"salt\""), "radio.id_hash"),
        ];
        for (text, path) in cases {
            match err(&text) {
                SiteError::Invalid { path: p, message } => {
                    assert!(p.starts_with(path), "expected {path}, got {p}: {message}")
                }
                other => panic!("expected Invalid at {path}, got {other:?}"),
            }
        }
    }

    #[test]
    fn values_too_large_or_too_small_to_compute_with_are_refused() {
        // Found with the `site_file` fuzz harness: each of these loaded, and then gave an
        // infinite accuracy radius or a -inf likelihood at every state.
        let cases = [
            (GOOD.replace("\"x\": 3, \"y\": 4", "\"x\": 1e308, \"y\": -1e308"), "states[1].x"),
            (GOOD.replace("\"std_db\": 4", "\"std_db\": 1e-300"), "states[0].fingerprint[0]"),
            (GOOD.replace("\"mean_dbm\": -60", "\"mean_dbm\": -1e300"), "states[0].fingerprint[0]"),
            (GOOD.replace("\"std_db\": 5", "\"std_db\": 0.001"), "radio.unheard"),
            (GOOD.replace("\"clip_dbm\": -100", "\"clip_dbm\": -1e5"), "radio.clip_dbm"),
        ];
        for (text, path) in cases {
            match err(&text) {
                SiteError::Invalid { path: p, .. } => {
                    assert!(p.starts_with(path), "expected {path}, got {p}")
                }
                other => panic!("expected Invalid at {path}, got {other:?}"),
            }
        }
        let edge = GOOD
            .replace("\"x\": 3, \"y\": 4", "\"x\": 1e6, \"y\": -1e6")
            .replace("\"std_db\": 4", "\"std_db\": 0.01");
        assert!(Site::from_json(edge.as_bytes()).is_ok(), "the limits themselves load");
    }

    const ZONES: &str = r#","zones": [{"name": "kitchen", "states": [7]}, {"name": "hall", "kind": "corridor", "states": [9]}]}"#;

    fn with_zones(zones: &str) -> String {
        let end = GOOD.rfind('}').unwrap();
        format!("{}{}", &GOOD[..end], zones)
    }

    #[test]
    fn zones_load_and_round_trip_in_both_encodings() {
        let site = Site::from_json(with_zones(ZONES).as_bytes()).unwrap();
        assert_eq!(site.zones().len(), 2);
        assert_eq!(site.zones()[0].kind, ZoneKind::Room, "room by default");
        assert_eq!(site.zones()[1].kind, ZoneKind::Corridor);
        assert_eq!((site.zone_of(0), site.zone_of(1)), (Some(0), Some(1)));
        let json = site.to_json();
        assert!(json.contains(r#""zones":[{"name":"kitchen","kind":"room","states":[7]}"#), "{json}");
        let again = Site::from_json(json.as_bytes()).unwrap();
        assert_eq!(again.zones(), site.zones());
        assert_eq!(again.to_json(), json);
        let packed = Site::from_bytes(&site.to_binary()).unwrap();
        assert_eq!(packed.zones(), site.zones());
        assert_eq!(packed.to_json(), json);
        // Without zones, nothing is written.
        let plain = Site::from_json(GOOD.as_bytes()).unwrap();
        assert!(plain.zones().is_empty() && !plain.to_json().contains("zones"));
        assert!(Site::from_bytes(&plain.to_binary()).unwrap().zones().is_empty());
    }

    #[test]
    fn bad_zones_are_named_by_path() {
        let cases = [
            (r#","zones": [{"name": "", "states": [7]}]}"#, "zones[0].name"),
            (r#","zones": [{"name": "a", "states": [7]}, {"name": "a", "states": [9]}]}"#, "zones[1].name"),
            (r#","zones": [{"name": "a", "states": []}]}"#, "zones[0].states"),
            (r#","zones": [{"name": "a", "states": [7, 8]}]}"#, "zones[0].states[1]"),
            (r#","zones": [{"name": "a", "states": [9, 9]}]}"#, "zones[0].states[1]"),
            (
                r#","zones": [{"name": "a", "states": [7]}, {"name": "b", "states": [9, 7]}]}"#,
                "zones[1].states[1]",
            ),
            (r#","zones": [{"name": "a", "kind": "cellar", "states": [7]}]}"#, "zones[0].kind"),
            (r#","zones": [{"name": "a", "states": [7], "floor": 0}]}"#, "zones[0]"),
            (r#","zones": [{"states": [7]}]}"#, "zones[0]"),
            (r#","zones": {"name": "a"}}"#, "zones"),
        ];
        for (zones, path) in cases {
            match err(&with_zones(zones)) {
                SiteError::Invalid { path: p, message } => {
                    assert!(p.starts_with(path), "{zones}: expected {path}, got {p}: {message}")
                }
                other => panic!("{zones}: expected Invalid at {path}, got {other:?}"),
            }
        }
        let message = err(&with_zones(cases[5].0)).to_string();
        assert!(message.contains("already in zones[0]"), "{message}");
    }

    const ANCHOR: &str = r#","anchor": {"lat_deg": 30.292, "lon_deg": 120.074, "scale": [0.999, 1.004]}}"#;

    #[test]
    fn anchor_levels_and_origins_round_trip_in_both_encodings() {
        let text = with_zones(ANCHOR).replace(
            r#""floors": [{"name": "G"}]"#,
            r#""floors": [{"name": "G", "level": -1, "origin_m": [2.5, -3]}]"#,
        );
        let site = Site::from_json(text.as_bytes()).unwrap();
        let anchor = site.anchor().unwrap();
        assert_eq!((anchor.lat_deg, anchor.azimuth_rad, anchor.scale), (30.292, 0.0, [0.999, 1.004]));
        assert_eq!((site.floor_level(0), site.floor_level(1)), (Some(-1), None));
        assert_eq!(site.floors()[0].origin_m, [2.5, -3.0]);
        let json = site.to_json();
        assert!(
            json.contains(
                r#""anchor":{"lat_deg":30.292,"lon_deg":120.074,"azimuth_rad":0.0,"scale":[0.999,1.004]}"#
            ),
            "{json}"
        );
        assert!(json.contains(r#""level":-1,"origin_m":[2.5,-3.0]"#), "{json}");
        assert_eq!(Site::from_json(json.as_bytes()).unwrap().to_json(), json);
        let packed = Site::from_bytes(&site.to_binary()).unwrap();
        assert_eq!(packed.to_json(), json);
        assert_eq!(site.with_pseudo_states(1.0).anchor(), site.anchor(), "pseudo states keep the anchor");
        // Without them, nothing is written.
        let plain = Site::from_json(GOOD.as_bytes()).unwrap();
        assert!(plain.anchor().is_none() && plain.floor_level(0).is_none());
        let json = plain.to_json();
        assert!(!json.contains("anchor") && !json.contains("level") && !json.contains("origin_m"), "{json}");
    }

    #[test]
    fn positions_convert_through_the_anchor_and_the_floor_origin() {
        let text = with_zones(ANCHOR).replace(
            r#""floors": [{"name": "G"}]"#,
            r#""floors": [{"name": "G"}, {"name": "1", "origin_m": [10, 0]}]"#,
        );
        let site = Site::from_json(text.as_bytes()).unwrap();
        let anchor = *site.anchor().unwrap();
        assert_eq!(site.lat_lon(0, 3.0, 4.0), Some(anchor.to_lat_lon(3.0, 4.0)));
        assert_eq!(site.lat_lon(1, 3.0, 4.0), Some(anchor.to_lat_lon(13.0, 4.0)));
        assert_eq!(site.lat_lon(2, 3.0, 4.0), None);
        let at = anchor.to_lat_lon(13.0, 4.0);
        let p = site.site_point(Some(1), at).unwrap();
        assert!((p.x - 3.0).abs() < 1e-6 && (p.y - 4.0).abs() < 1e-6, "{p}");
        assert_eq!(site.site_point(None, at), Err(GeoError::FloorRequired));
        assert_eq!(site.site_point(Some(2), at), Err(GeoError::UnknownFloor { floor: 2, floors: 2 }));
        let bad = crate::site::LatLon { lat_deg: f64::NAN, lon_deg: 0.0 };
        assert!(matches!(site.site_point(Some(0), bad), Err(GeoError::InvalidCoordinate { .. })));
        assert_eq!(site.bearing_deg(0.0), Some(0.0));
        let plain = Site::from_json(GOOD.as_bytes()).unwrap();
        assert_eq!(plain.site_point(None, at), Err(GeoError::NotGeoReferenced));
        assert_eq!((plain.lat_lon(0, 0.0, 0.0), plain.bearing_deg(0.0)), (None, None));
        // One frame for every floor: no floor needed.
        let one_frame = Site::from_json(with_zones(ANCHOR).as_bytes()).unwrap();
        let p = one_frame.site_point(None, anchor.to_lat_lon(3.0, 4.0)).unwrap();
        assert!((p.x - 3.0).abs() < 1e-6 && (p.y - 4.0).abs() < 1e-6, "{p}");
    }

    #[test]
    fn bad_anchors_and_origins_are_named_by_path() {
        let cases = [
            (r#","anchor": {"lat_deg": 95, "lon_deg": 0}}"#, "anchor.lat_deg"),
            (r#","anchor": {"lat_deg": 0, "lon_deg": 0, "scale": [1, -1]}}"#, "anchor.scale"),
            (r#","anchor": {"lat_deg": 0}}"#, "anchor"),
            (r#","anchor": {"lat_deg": 0, "lon_deg": 0, "height_m": 3}}"#, "anchor"),
        ];
        for (anchor, path) in cases {
            match err(&with_zones(anchor)) {
                SiteError::Invalid { path: p, message } => {
                    assert!(p.starts_with(path), "{anchor}: expected {path}, got {p}: {message}")
                }
                other => panic!("{anchor}: expected Invalid at {path}, got {other:?}"),
            }
        }
        let origin = GOOD.replace(r#"{"name": "G"}"#, r#"{"name": "G", "origin_m": [1e7, 0]}"#);
        assert!(matches!(err(&origin), SiteError::Invalid { path, .. } if path == "floors[0].origin_m"));
        let level = GOOD.replace(r#"{"name": "G"}"#, r#"{"name": "G", "level": 1.5}"#);
        assert!(
            matches!(err(&level), SiteError::Invalid { path, .. } if path.starts_with("floors[0].level"))
        );
    }

    /// A second document or any other data after the site's is refused, never ignored: the
    /// file loaded as its first document (issue 60, item 7). A UTF-8 byte order mark is skipped;
    /// a UTF-16 one is named.
    #[test]
    fn data_after_the_document_is_refused_and_a_utf8_bom_skipped() {
        for tail in ["{}", "x", "\0", &GOOD[..40]] {
            let text = format!("{GOOD}\n{tail}");
            match err(&text) {
                SiteError::Syntax { line: 14, message, .. } => {
                    assert!(message.contains("after the end of the site's JSON document"), "{message}")
                }
                other => panic!("{tail:?}: {other:?}"),
            }
            let packed = Site::from_json(GOOD.as_bytes()).unwrap().to_binary();
            assert!(Site::from_bytes(&[&packed[..], tail.as_bytes()].concat()).is_err(), "binary + {tail:?}");
        }
        assert!(Site::from_json(format!("{GOOD} \n\t\r\n").as_bytes()).is_ok(), "white space may follow");
        let with_bom = [&b"\xEF\xBB\xBF"[..], GOOD.as_bytes()].concat();
        assert_eq!(
            Site::from_bytes(&with_bom).unwrap().to_json(),
            Site::from_json(GOOD.as_bytes()).unwrap().to_json()
        );
        let utf16 = [&b"\xFF\xFE"[..], GOOD.as_bytes()].concat();
        match Site::from_bytes(&utf16).unwrap_err() {
            SiteError::Syntax { message, .. } => assert!(message.contains("UTF-16"), "{message}"),
            other => panic!("{other:?}"),
        }
    }

    /// The limits checked at load name themselves (docs/errors.md#site-limits).
    #[test]
    fn edges_and_transmitters_per_state_are_limited() {
        use crate::site::budget::{MAX_EDGES_PER_STATE, MAX_TRANSMITTERS_PER_STATE};
        let over = |text: &str| match err(text) {
            SiteError::OverLimit { name, .. } => name,
            other => panic!("{other:?}"),
        };
        // A hub joined to more states than a state may have edges.
        let spokes = MAX_EDGES_PER_STATE + 1;
        let states: Vec<String> =
            (0..=spokes).map(|i| format!(r#"{{"id": {i}, "floor": 0, "x": {i}, "y": 1}}"#)).collect();
        let edges: Vec<String> = (1..=spokes).map(|i| format!(r#"{{"from": 0, "to": {i}}}"#)).collect();
        let hub = format!(
            r#"{{"format_version": 7, "name": "hub", "floors": [{{"name": "G"}}],
                "radio": {{"clip_dbm": -100, "unheard": {{"mean_dbm": -115, "std_db": 5}}, "transmitters": []}},
                "states": [{}], "edges": [{}]}}"#,
            states.join(","),
            edges.join(",")
        );
        assert_eq!(over(&hub), "MAX_EDGES_PER_STATE");
        let fewer = hub.replace(&format!(r#",{{"from": 0, "to": {spokes}}}"#), "");
        assert!(Site::from_json(fewer.as_bytes()).is_ok(), "the limit itself loads");
        // A state modelling more transmitters than a state may.
        let count = MAX_TRANSMITTERS_PER_STATE + 1;
        let ids: Vec<String> = (0..count)
            .map(|k| format!(r#"{{"wifi": {{"bssid": "02:00:00:00:{:02x}:{:02x}"}}}}"#, k >> 8, k & 255))
            .collect();
        let entries: Vec<String> =
            (0..count).map(|k| format!(r#"{{"tx": {k}, "mean_dbm": -60, "std_db": 4}}"#)).collect();
        let loud = GOOD
            .replace(r#"{"wifi": {"bssid": "00:11:22:33:44:55"}}"#, &ids.join(","))
            .replace(r#"{"tx": 0, "mean_dbm": -60, "std_db": 4}"#, &entries.join(","));
        assert_eq!(over(&loud), "MAX_TRANSMITTERS_PER_STATE");
    }

    #[test]
    fn io_error_names_the_path() {
        let e = Site::load("/nonexistent/site.json").unwrap_err();
        assert!(e.to_string().contains("/nonexistent/site.json"));
    }
}
