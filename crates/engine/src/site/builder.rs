//! Building a site from surveyed places and their training scans: fits every transmitter's
//! RSSI model at every state (Hoang §3) and derives the map's "unheard" model.

use super::{Anchor, Edge, Floor, North, Site, SiteError, State, StateKind, Zone, ZoneKind};
use crate::radio::{
    unheard_model, FitOptions, Gaussian, RadioMap, RssiModel, Scan, TransmitterId, MAX_STORED_STD_DB,
};
use nalgebra::Point2;
use std::collections::{BTreeMap, BTreeSet};

/// A scan taken during the survey at a state.
pub type TrainingScan = Scan;

/// Collects floors, states with their training scans, and walkable edges; [`build`](Self::build)
/// fits the radio map.
#[derive(Clone, Debug, Default)]
pub struct SiteBuilder {
    name: String,
    floors: Vec<Floor>,
    states: Vec<(State, Vec<TrainingScan>)>,
    edges: Vec<(u32, u32, Option<f64>)>,
    north: North,
    anchor: Option<Anchor>,
    zones: Vec<Zone>,
    /// A floor index given to [`floor_geo`](Self::floor_geo) that does not exist.
    unknown_floor: Option<usize>,
}

impl SiteBuilder {
    /// An empty site called `name`.
    pub fn new(name: &str) -> Self {
        Self { name: name.to_owned(), ..Self::default() }
    }

    /// Adds a floor; returns its index.
    pub fn floor(&mut self, name: &str, elevation_m: f64) -> usize {
        self.floors.push(Floor { name: name.to_owned(), elevation_m, ..Floor::default() });
        self.floors.len() - 1
    }

    /// Adds a surveyed state with the scans recorded there; returns its id (= index).
    pub fn state(&mut self, floor: usize, position: Point2<f64>, scans: Vec<TrainingScan>) -> u32 {
        let id = self.states.len() as u32;
        let training_scans = scans.len() as u32;
        self.states.push((State { id, floor, position, kind: StateKind::Surveyed, training_scans }, scans));
        id
    }

    /// Sets the site frame's orientation on the Earth.
    pub fn north(&mut self, north: North) {
        self.north = north;
    }

    /// Geo-references the site: where its frame sits on the Earth (checked at
    /// [`build`](Self::build)).
    pub fn anchor(&mut self, anchor: Anchor) {
        self.anchor = Some(anchor);
    }

    /// Sets floor `floor`'s logical level and where its frame's origin is in the site frame
    /// ([`Floor::level`], [`Floor::origin_m`]); checked at [`build`](Self::build). An unknown
    /// index is refused there too.
    pub fn floor_geo(&mut self, floor: usize, level: Option<i32>, origin_m: [f64; 2]) {
        match self.floors.get_mut(floor) {
            Some(f) => {
                f.level = level;
                f.origin_m = origin_m;
            }
            None => self.unknown_floor = Some(floor),
        }
    }

    /// Adds a walkable edge; `length_m` `None` means the straight line (same floor only).
    pub fn edge(&mut self, a: u32, b: u32, length_m: Option<f64>) {
        self.edges.push((a, b, length_m));
    }

    /// Groups states (by id) into a zone: a room, a corridor... Checked at
    /// [`build`](Self::build): names unique and not empty, each state in at most one zone.
    pub fn zone(&mut self, name: &str, kind: ZoneKind, states: Vec<u32>) {
        self.zones.push(Zone { name: name.to_owned(), kind, states });
    }

    /// Fits every state's fingerprints with `model` and assembles the site.
    pub fn build(self, options: BuildOptions) -> Result<Site, SiteError> {
        if self.states.is_empty() {
            return Err(SiteError::Invalid {
                path: "states".into(),
                message: "a site needs at least one state".into(),
            });
        }
        let ids: Vec<TransmitterId> = self
            .states
            .iter()
            .flat_map(|(_, scans)| {
                scans.iter().flat_map(|s| s.readings.iter().map(|r| r.transmitter.clone()))
            })
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect();
        let index: BTreeMap<&TransmitterId, u32> =
            ids.iter().enumerate().map(|(i, id)| (id, i as u32)).collect();
        let fit = options.stored_fit();
        let index = &index;
        let fit_state = |s: usize, scans: &[TrainingScan]| -> Vec<(u32, u32, Gaussian)> {
            let readings = scans.iter().enumerate().flat_map(|(k, scan)| {
                scan.readings.iter().map(move |r| (index[&r.transmitter], k as u32, r.rssi_dbm))
            });
            fit_columns(readings.collect(), scans.len(), options.model, &fit)
                .into_iter()
                .map(|(tx, g)| (s as u32, tx, g))
                .collect()
        };
        // States fit independently: one chunk per core (a building's survey is thousands of
        // states with hundreds of transmitters each).
        let threads =
            std::thread::available_parallelism().map_or(1, |n| n.get()).min(self.states.len().max(1));
        let chunk = self.states.len().div_ceil(threads);
        let triples: Vec<(u32, u32, Gaussian)> = std::thread::scope(|scope| {
            let workers: Vec<_> = self
                .states
                .chunks(chunk)
                .enumerate()
                .map(|(c, states)| {
                    let fit_state = &fit_state;
                    scope.spawn(move || {
                        states
                            .iter()
                            .enumerate()
                            .flat_map(|(k, (_, scans))| fit_state(c * chunk + k, scans))
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            workers
                .into_iter()
                .flat_map(|w| w.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
                .collect()
        });
        self.assemble(options, ids, triples)
    }

    /// Adds a state whose fingerprints the caller fits itself (see
    /// [`build_fitted`](Self::build_fitted)), trained on `training_scans` scans.
    pub fn fitted_state(&mut self, floor: usize, position: Point2<f64>, training_scans: u32) -> u32 {
        let id = self.states.len() as u32;
        self.states
            .push((State { id, floor, position, kind: StateKind::Surveyed, training_scans }, Vec::new()));
        id
    }

    /// Adds a state with no fingerprint ([`StateKind::Unsurveyed`]): walkable space nobody
    /// surveyed, where the estimate may go only while the radio does not explain what the
    /// phone hears.
    pub fn unsurveyed_state(&mut self, floor: usize, position: Point2<f64>) -> u32 {
        let id = self.states.len() as u32;
        self.states.push((
            State { id, floor, position, kind: StateKind::Unsurveyed, training_scans: 0 },
            Vec::new(),
        ));
        id
    }

    /// Assembles the site from fingerprints fitted by the caller: (state, index into `ids`,
    /// model), with the same "unheard" model and checks as [`build`](Self::build).
    pub fn build_fitted(
        self,
        options: BuildOptions,
        ids: Vec<TransmitterId>,
        triples: Vec<(u32, u32, Gaussian)>,
    ) -> Result<Site, SiteError> {
        if self.states.is_empty() {
            return Err(SiteError::Invalid {
                path: "states".into(),
                message: "a site needs at least one state".into(),
            });
        }
        self.assemble(options, ids, triples)
    }

    fn assemble(
        self,
        options: BuildOptions,
        ids: Vec<TransmitterId>,
        triples: Vec<(u32, u32, Gaussian)>,
    ) -> Result<Site, SiteError> {
        let clip = options.fit.clip_dbm;
        let average_std = if triples.is_empty() {
            options.fit.min_std_db
        } else {
            triples.iter().map(|t| t.2.std_db).sum::<f64>() / triples.len() as f64
        };
        let mut counts: Vec<u32> =
            self.states.iter().map(|(s, _)| s.training_scans).filter(|&n| n > 0).collect();
        counts.sort_unstable();
        let typical_scans = counts.get(counts.len() / 2).copied().unwrap_or(1);
        let unheard = match options.model {
            RssiModel::CensoredGaussian => unheard_model(clip, average_std, typical_scans),
            // Disregarding censoring, a never-heard transmitter is "always at c".
            RssiModel::NaiveGaussian => Gaussian::new(clip, average_std),
        }
        .ok_or_else(|| SiteError::Invalid {
            path: "radio.unheard".into(),
            message: "clip level and spreads must be finite".into(),
        })?;
        if let Some(floor) = self.unknown_floor {
            return Err(SiteError::Invalid {
                path: "floors".into(),
                message: format!("floor {floor} does not exist (the site has {} floors)", self.floors.len()),
            });
        }
        for (i, f) in self.floors.iter().enumerate() {
            f.check(i).map_err(|(path, message)| SiteError::Invalid { path, message })?;
        }
        let states: Vec<State> = self.states.into_iter().map(|(s, _)| s).collect();
        for (i, s) in states.iter().enumerate() {
            if s.floor >= self.floors.len() || !(s.position.x.is_finite() && s.position.y.is_finite()) {
                return Err(SiteError::Invalid {
                    path: format!("states[{i}]"),
                    message: format!("floor {} must exist and the position must be finite", s.floor),
                });
            }
        }
        let mut edges = Vec::with_capacity(self.edges.len());
        for (k, (a, b, length)) in self.edges.into_iter().enumerate() {
            let (sa, sb) = match (states.get(a as usize), states.get(b as usize)) {
                (Some(sa), Some(sb)) if a != b => (sa, sb),
                _ => {
                    return Err(SiteError::Invalid {
                        path: format!("edges[{k}]"),
                        message: format!("edge {a}-{b} does not join two existing states"),
                    })
                }
            };
            let length_m = length.unwrap_or_else(|| nalgebra::distance(&sa.position, &sb.position));
            if !(length_m.is_finite() && length_m > 0.0) {
                return Err(SiteError::Invalid {
                    path: format!("edges[{k}].length_m"),
                    message: format!("must be finite and > 0 (got {length_m})"),
                });
            }
            edges.push(Edge { a, b, length_m });
        }
        let map = RadioMap::new(options.model, clip, unheard, ids, states.len(), triples)
            .map_err(|m| SiteError::Invalid { path: "radio".into(), message: m })?;
        Site::from_parts(self.name, self.floors, states, edges, map, self.north)
            .with_anchor(self.anchor)?
            .with_zones(self.zones)
    }
}

/// Fits one state's fingerprints from its training scans given as (transmitter, scan index,
/// RSSI) readings over `scans` scans: per transmitter heard (with a finite RSSI), the column of
/// its readings with "not heard" at the clip level `fit.clip_dbm` (the stronger reading when a
/// scan has two), fitted with `model`. Sorted by transmitter. The fit depends only on the
/// columns, so a state fitted again from the same scans gets the same models.
pub fn fit_columns(
    mut readings: Vec<(u32, u32, f64)>,
    scans: usize,
    model: RssiModel,
    fit: &FitOptions,
) -> Vec<(u32, Gaussian)> {
    let clip = fit.clip_dbm;
    readings.retain(|r| r.2.is_finite());
    readings.sort_unstable_by_key(|r| (r.0, r.1));
    let mut out = Vec::new();
    let mut column = vec![clip; scans];
    for group in readings.chunk_by(|a, b| a.0 == b.0) {
        column.fill(clip);
        for &(_, k, rssi) in group {
            let v = &mut column[k as usize];
            *v = v.max(rssi.max(clip));
        }
        if let Some(g) = model.fit(&column, fit) {
            out.push((group[0].0, g));
        }
    }
    out
}

/// How [`SiteBuilder::build`] fits fingerprints.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BuildOptions {
    /// Censored EM (Hoang §3) or the naive fit.
    pub model: RssiModel,
    /// Clip level, σ floor and EM stopping rule.
    pub fit: FitOptions,
}

impl BuildOptions {
    /// `fit` as the builder applies it: the radio map stores σ up to
    /// `radio::MAX_STORED_STD_DB`, so a fit wider than that (a transmitter heard once,
    /// unconstrained EM) is capped there.
    pub fn stored_fit(&self) -> FitOptions {
        FitOptions { max_std_db: self.fit.max_std_db.min(MAX_STORED_STD_DB), ..self.fit }
    }
}
